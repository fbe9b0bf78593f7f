"""The stage cache (bake/cache/): a bake that loads stages from the cache writes the same bytes as
a cold bake, from every stage on; inputs and config changes invalidate exactly what they should;
damaged, foreign and hostile entries are ignored with a warning; the folder stays under its cap;
the report says which stages came from the cache; a sweep computes the stages before its key once."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from bake import cache as cache_mod
from bake import cli, pipeline
from bake.cache import CacheError, DiskStore, Unsupported, decode_entry, encode_entry
from bake.cache import keys
from bake.cache.format import FORMAT, MAGIC
from bake.scene import Material, make_scene


# --------------------------------------------------------------------------- a model that uses every stage
def _png(path: Path, n: int = 8) -> None:
    from PIL import Image

    y, x = np.mgrid[0:n, 0:n]
    img = np.zeros((n, n, 3), np.uint8)
    img[..., 0] = np.where((x + y) % 2 == 0, 220, 40)
    img[..., 1] = (x * 255 // max(1, n - 1)).astype(np.uint8)
    img[..., 2] = (y * 255 // max(1, n - 1)).astype(np.uint8)
    Image.fromarray(img).save(path)


def write_model(folder: Path, n: int = 12) -> Path:
    """A bumpy textured ground of n x n quads with UVs, and an untextured box on it: quads for
    triangulate, a curved surface for simplify, a texture, two materials, shadows."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["mtllib scene.mtl"]
    xs = np.linspace(-1, 1, n + 1)
    for j in range(n + 1):
        for i in range(n + 1):
            x, z = xs[i], xs[j]
            lines.append(f"v {x:.6f} {0.15 * np.sin(3 * x) * np.cos(2 * z):.6f} {z:.6f}")
            lines.append(f"vt {i / n:.6f} {j / n:.6f}")
    lines.append("usemtl ground")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            b, c, d = a + 1, a + n + 2, a + n + 1
            lines.append(f"f {a}/{a} {d}/{d} {c}/{c} {b}/{b}")
    base = (n + 1) ** 2
    box = [(-.3, .1, -.3), (.3, .1, -.3), (.3, .1, .3), (-.3, .1, .3),
           (-.3, .6, -.3), (.3, .6, -.3), (.3, .6, .3), (-.3, .6, .3)]
    lines += [f"v {x} {y} {z}" for x, y, z in box]
    lines.append("usemtl box")
    for f in ((1, 2, 3, 4), (5, 8, 7, 6), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 8, 4), (4, 8, 5, 1)):
        lines.append("f " + " ".join(str(base + k) for k in f))
    (folder / "scene.obj").write_text("\n".join(lines) + "\n")
    (folder / "scene.mtl").write_text("newmtl ground\nKd 0.9 0.9 0.9\nmap_Kd ground.png\n"
                                      "newmtl box\nKd 0.8 0.3 0.2\n")
    _png(folder / "ground.png")
    return folder / "scene.obj"


# Two configs between them run every stage: (a) a lightmap from the textures stage's atlas and a
# BVH; (b) per-triangle light with AO, and a BSP tree.
CONFIG_A = """
[input]
path = "scene.obj"
[transform]
center = "base"
fit = 10
[mesh.simplify]
enabled = true
target_ratio = 0.6
error_samples = 2000
[textures]
enabled = true
max_size = 16
[textures.lightmap]
enabled = true
resolution = 32
[lighting]
enabled = true
target = "lightmap"
ambient = [0.2, 0.2, 0.2]
[[lighting.lights]]
kind = "sun"
direction = [0.4, -1.0, 0.3]
[lighting.ao]
enabled = true
samples = 8
[bvh]
enabled = true
[report]
html = false  # (time: the previews are tested elsewhere)
"""

CONFIG_B = """
[input]
path = "scene.obj"
[transform]
fit = 10
[mesh.simplify]
enabled = true
target_ratio = 0.6
error_samples = 2000
[textures]
enabled = true
max_size = 16
[lighting]
enabled = true
target = "triangle"
ambient = [0.2, 0.2, 0.2]
[[lighting.lights]]
kind = "sun"
direction = [0.4, -1.0, 0.3]
angle = 2.0
[lighting.ao]
enabled = true
samples = 8
[bsp]
enabled = true
[report]
html = false
"""

# (the stage that must run again, a key of it to change); None = nothing changed
CHANGES = {
    "a": [("transform", "transform.center=\"bounds\""), ("triangulate", "mesh.triangulate.method=\"fan\""),
          ("clean", "mesh.clean.weld_tolerance=1e-6"), ("simplify", "mesh.simplify.target_ratio=0.5"),
          ("textures", "textures.lightmap.padding=3"), ("lighting", "lighting.ao.samples=12"),
          ("bvh", "bvh.leaf_size=2"), ("export", "export.precision=4"), (None, None)],
    "b": [("textures", "textures.max_size=8"), ("lighting", "lighting.ambient=[0.3, 0.2, 0.2]"),
          ("bsp", "bsp.seed=1"), ("export", "export.color_format=\"hex\""), (None, None)],
}
CONFIGS = {"a": CONFIG_A, "b": CONFIG_B}


def bake(config: Path, out: Path, *sets: str) -> dict:
    args = ["run", str(config), "--out", str(out), "--quiet"]
    for s in sets:
        args += ["--set", s]
    assert cli.main(args) == 0
    return json.loads((out / "report.json").read_text())


def outputs(out: Path) -> dict[str, bytes]:
    """Every file a bake wrote except the report (which holds times)."""
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and ".bake-cache" not in p.parts and not p.name.startswith("report")}


def same_records(a: dict, b: dict) -> None:
    """The stages' figures (not their times) agree."""
    for sa, sb in zip(a["stages"], b["stages"], strict=True):
        assert sa["name"] == sb["name"]
        assert sa["counts_in"] == sb["counts_in"] and sa["counts_out"] == sb["counts_out"], sa["name"]
        assert sa["accuracy"] == sb["accuracy"], sa["name"]
        assert sa["warnings"] == sb["warnings"], sa["name"]


@pytest.fixture(scope="module")
def primed(tmp_path_factory):
    """A model, both configs, and a cache filled by one bake of each."""
    root = tmp_path_factory.mktemp("cache")
    write_model(root / "model")
    out = {}
    for name, text in CONFIGS.items():
        cfg = root / "model" / f"{name}.toml"
        cfg.write_text(text + f'\n[cache]\ndir = "../cache-{name}"\n')
        rep = bake(cfg, root / f"prime-{name}")
        assert rep["cache"]["from_cache"] == [] and rep["cache"]["stored"] == [s["name"] for s in rep["stages"]]
        out[name] = cfg
    return root, out


@pytest.mark.parametrize("which,restart,change", [(w, r, c) for w in CHANGES for r, c in CHANGES[w]],
                         ids=[f"{w}-{r or 'all-cached'}" for w in CHANGES for r, _ in CHANGES[w]])
def test_a_cached_bake_writes_the_same_bytes_as_a_cold_one(primed, tmp_path, which, restart, change):
    root, cfgs = primed
    sets = [change] if change else []
    cold = bake(cfgs[which], tmp_path / "cold", "cache.dir=\"none\"", *sets)
    assert cold["cache"] is None
    warm = bake(cfgs[which], tmp_path / "warm", *sets)
    names = [s["name"] for s in cold["stages"]]
    # the bake started at the stage whose key changed, with everything before it from the cache
    first = names.index(restart) if restart else len(names)
    assert warm["cache"]["from_cache"] == names[:first]
    assert warm["cache"]["warnings"] == []
    for st in warm["stages"]:
        assert bool((st["details"].get("cache") or {}).get("from_cache")) == (st["name"] in names[:first])
    assert outputs(tmp_path / "warm") == outputs(tmp_path / "cold")
    assert len(outputs(tmp_path / "cold")) >= 8  # lists, lists.json, .sb3, .sprite3, costumes
    same_records(cold, warm)
    # and a bake of the changed config is now a cache hit all the way
    again = bake(cfgs[which], tmp_path / "again", *sets)
    assert again["cache"]["from_cache"] == names
    assert outputs(tmp_path / "again") == outputs(tmp_path / "cold")


def test_the_report_says_which_stages_came_from_the_cache(primed, tmp_path, capsys):
    root, cfgs = primed
    assert cli.main(["run", str(cfgs["b"]), "--out", str(tmp_path / "o"), "--set", "bsp.seed=7",
                     "--set", "report.html=true"]) == 0
    text = capsys.readouterr().out
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    loaded = rep["cache"]["from_cache"]
    assert loaded[-1] == "lighting"
    for st in rep["stages"]:
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(st["name"] + " "))
        assert ("from the cache (computed in" in line) == (st["name"] in loaded), line
    md = (tmp_path / "o" / "report.md").read_text()
    assert md.count("from the cache (computed in") == len(loaded)
    html = (tmp_path / "o" / "report.html").read_text()
    assert html.count("from the cache (computed in") == len(loaded)
    eff = {e["name"]: e for e in rep["effects"]}
    assert eff["simplify"]["reason"].startswith("from the stage cache") and eff["bsp"]["reason"] == "stage ran"
    # the stage that was loaded carries the load time, those before it nothing; all keep the time they took
    assert all(s["seconds"] == 0.0 for s in rep["stages"][:len(loaded) - 1])
    assert all(s["details"]["cache"]["computed_seconds"] > 0 for s in rep["stages"][:len(loaded)])


# --------------------------------------------------------------------------- inputs
def _stages(rep: dict) -> list[str]:
    return [s["name"] for s in rep["stages"]]


def test_input_files_bytes_invalidate_and_mtime_alone_does_not(tmp_path):
    model = write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"
    first = bake(cfg, out)
    lists0 = json.loads((out / "lists.json").read_text())["lists"]
    # touching a file (same bytes) changes nothing
    for p in (model, model.with_suffix(".mtl"), model.parent / "ground.png"):
        os.utime(p, (p.stat().st_atime + 100, p.stat().st_mtime + 100))
    assert bake(cfg, out)["cache"]["from_cache"] == _stages(first)
    # the .mtl's bytes: the import runs again, so does everything after it
    mtl = model.with_suffix(".mtl")
    mtl.write_text(mtl.read_text().replace("Kd 0.8 0.3 0.2", "Kd 0.2 0.3 0.8"))
    rep = bake(cfg, out)
    assert rep["cache"]["from_cache"] == []
    lists1 = json.loads((out / "lists.json").read_text())["lists"]
    assert lists1["mat colors"] != lists0["mat colors"]
    cold = bake(cfg, tmp_path / "cold1", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold1")
    same_records(rep, cold)
    # the texture's bytes
    _png(model.parent / "ground.png", n=4)
    rep = bake(cfg, out)
    assert rep["cache"]["from_cache"] == []
    assert json.loads((out / "lists.json").read_text())["lists"]["tri colors"] != lists1["tri colors"]
    # the model's bytes
    model.write_text(model.read_text().replace("v -0.3 0.6 -0.3", "v -0.3 0.7 -0.3"))
    assert bake(cfg, out)["cache"]["from_cache"] == []
    bake(cfg, tmp_path / "cold2", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold2")


def test_a_texture_that_appears_later_is_picked_up(tmp_path):
    """The .mtl names a texture that is not there (a warning); when the file appears the cached
    import must not be used: the folder's model files are part of the key."""
    model = write_model(tmp_path / "m")
    png = model.parent / "ground.png"
    keep = png.read_bytes()
    png.unlink()
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"
    rep = bake(cfg, out)
    assert any("texture" in w or "ground.png" in w for s in rep["stages"] for w in s["warnings"])
    assert bake(cfg, out)["cache"]["from_cache"] == _stages(rep)
    png.write_bytes(keep)
    rep2 = bake(cfg, out)
    assert rep2["cache"]["from_cache"] == []
    bake(cfg, tmp_path / "cold", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")


def test_config_sections_invalidate_their_stage_and_later_ones_only(tmp_path):
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"
    names = _stages(bake(cfg, out))
    # keys outside any stage's section (report, cache size) change nothing
    assert bake(cfg, out, "report.preview_width=200", "cache.max_mb=500")["cache"]["from_cache"] == names
    # a key of a stage that is switched off changes nothing either
    assert bake(cfg, out, "bvh.leaf_size=2")["cache"]["from_cache"] == names
    # switching a stage on runs it and the stages after it
    rep = bake(cfg, out, "bvh.enabled=true")
    assert rep["cache"]["from_cache"] == names[:names.index("bsp") + 1]
    # the output folder is not part of any key: another folder with the same cache dir hits
    assert bake(cfg, tmp_path / "elsewhere", "cache.dir=\"../out/.bake-cache/stages\"")["cache"]["from_cache"] == names


def test_a_new_tool_version_does_not_use_old_entries(tmp_path, monkeypatch):
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    bake(cfg, tmp_path / "out")
    monkeypatch.setattr(keys, "tool_fingerprint", lambda: "another version")
    assert bake(cfg, tmp_path / "out")["cache"]["from_cache"] == []


def test_the_fingerprint_covers_every_source_file(tmp_path):
    pkg = Path(pipeline.__file__).resolve().parent  # the bake package
    copy = tmp_path / "bake"
    shutil.copytree(pkg, copy, ignore=shutil.ignore_patterns("__pycache__"))
    fp = keys.fingerprint_of(copy)
    assert fp == keys.tool_fingerprint()  # the same bytes: the same fingerprint
    f = copy / "bsp" / "split.py"
    f.write_text(f.read_text() + "\n# a comment\n")
    assert keys.fingerprint_of(copy) != fp


def test_an_input_that_changes_during_the_bake_is_not_cached(tmp_path, monkeypatch):
    """The author saves the model while the import reads it: which bytes the import saw is not
    known, so nothing of this bake is stored."""
    model = write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    import bake.importers.stage as importers

    real = importers.stage

    def editing(scene, section):
        out = real(scene, section)
        model.write_text(model.read_text() + "\n# saved\n")
        return out

    monkeypatch.setattr(importers, "stage", editing)
    rep = bake(cfg, tmp_path / "out")
    assert rep["cache"]["stored"] == []
    assert any("changed during the bake" in w for w in rep["cache"]["warnings"])
    monkeypatch.setattr(importers, "stage", real)
    # the next bake reads the saved model, computes and stores it
    rep = bake(cfg, tmp_path / "out")
    assert rep["cache"]["from_cache"] == [] and rep["cache"]["stored"] == _stages(rep)


@pytest.mark.slow
def test_a_bake_killed_at_any_moment_leaves_a_cache_that_gives_the_cold_result(tmp_path):
    """SIGKILL during a bake (entries are written to a temporary name and renamed): the next bake
    uses whatever was stored and writes the same bytes as a cold bake."""
    import random
    import signal
    import subprocess
    import sys
    import time

    rng = random.Random(21)
    write_model(tmp_path / "m", n=20)
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    cmd = [sys.executable, "-m", "bake.cli", "run", str(cfg), "--quiet"]
    t = time.perf_counter()
    subprocess.run(cmd + ["--out", str(tmp_path / "cold"), "--set", 'cache.dir="none"'], check=True, timeout=300)
    duration = time.perf_counter() - t
    cold = outputs(tmp_path / "cold")
    for k in range(3):
        out = tmp_path / f"out{k}"
        out.mkdir()
        p = subprocess.Popen(cmd + ["--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(rng.uniform(0.4, 1.0) * duration)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        assert subprocess.run(cmd + ["--out", str(out)], timeout=300, capture_output=True, text=True).stderr == ""
        assert outputs(out) == cold
        rep = json.loads((out / "report.json").read_text())
        assert rep["cache"]["warnings"] == []


# --------------------------------------------------------------------------- damaged entries
def _entries(folder: Path) -> list[Path]:
    return sorted(folder.glob("*" + cache_mod.ENTRY_SUFFIX), key=lambda p: p.stat().st_mtime_ns)


def _entry_of(folder: Path, stage: str) -> Path:
    for p in folder.glob("*" + cache_mod.ENTRY_SUFFIX):
        head = p.read_bytes()[:4096]
        if f'"stage":"{stage}"'.encode() in head:
            return p
    raise AssertionError(stage)


class _Evil:
    def __reduce__(self):
        return (os.system, ("touch EVIL-PICKLE-RAN",))


def _flip(p: Path) -> None:
    b = bytearray(p.read_bytes())
    b[len(b) // 2] ^= 0x40
    p.write_bytes(bytes(b))


def _truncate(p: Path) -> None:
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 3])


def _empty(p: Path) -> None:
    p.write_bytes(b"")


def _pickle(p: Path) -> None:
    p.write_bytes(pickle.dumps({"scene": _Evil()}))


def _foreign(p: Path) -> None:
    """A valid entry of another stage copied under this entry's name."""
    other = _entry_of(p.parent, "transform")
    p.write_bytes(other.read_bytes())


def _hostile(p: Path) -> None:
    """A well-formed entry with a correct checksum whose objects name os.system."""
    b = p.read_bytes()
    magic, fmt, hlen = struct.unpack("<12sIQ", b[:24])
    header = json.loads(b[24:24 + hlen])
    header["tree"] = ["d", 0, ["scene", ["f", "os:system"], "records", ["l", 1, []]]]
    header["blobs"] = []
    p.write_bytes(b"".join(encode_entry_raw(header)))


def encode_entry_raw(header: dict) -> list[bytes]:
    import hashlib

    body = json.dumps(header, separators=(",", ":")).encode()
    head = struct.pack("<12sIQ", MAGIC, FORMAT, len(body))
    chunks = [head, body, b"\0" * (-(len(head) + len(body)) % 64)]
    chunks.append(hashlib.sha256(b"".join(chunks)).digest())
    return chunks


@pytest.mark.parametrize("damage", [_flip, _truncate, _empty, _pickle, _foreign, _hostile],
                         ids=["bit-flip", "truncated", "empty", "pickle", "foreign", "names-os.system"])
def test_a_damaged_or_foreign_entry_is_ignored_with_a_warning(tmp_path, damage, monkeypatch):
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"
    names = _stages(bake(cfg, out))
    folder = out / ".bake-cache" / "stages"
    bad = _entry_of(folder, "lighting")
    damage(bad)
    monkeypatch.chdir(tmp_path)
    rep = bake(cfg, out, "bsp.seed=3")  # restarts at bsp: wants the lighting entry
    assert not (tmp_path / "EVIL-PICKLE-RAN").exists()
    warn = rep["cache"]["warnings"]
    assert len(warn) == 1 and "lighting entry" in warn[0] and bad.name in warn[0], warn
    # the bake fell back to the entry before it and ran lighting again, with the warning in its record
    assert rep["cache"]["from_cache"] == names[:names.index("lighting")]
    light = next(s for s in rep["stages"] if s["name"] == "lighting")
    assert any("lighting entry" in w for w in light["warnings"])
    bake(cfg, tmp_path / "cold", "bsp.seed=3", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")
    # the bad entry was replaced by a good one
    assert bake(cfg, out, "bsp.seed=3")["cache"]["from_cache"] == names


def test_a_damaged_manifest_is_ignored_with_a_warning(tmp_path):
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"
    names = _stages(bake(cfg, out))
    folder = out / ".bake-cache" / "stages"
    deps = [p for p in folder.glob("*" + cache_mod.DEPS_SUFFIX) if '"stage": "bsp"' in p.read_text()]
    assert len(deps) == 1
    deps[0].write_text('{"format": 1, "files": "oops"')
    rep = bake(cfg, out)
    assert rep["cache"]["from_cache"] == names[:names.index("bsp")]
    assert len(rep["cache"]["warnings"]) == 1 and "manifest" in rep["cache"]["warnings"][0]
    bake(cfg, tmp_path / "cold", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")


def test_decoding_refuses_what_is_not_ours():
    key = "k" * 64
    for tree, why in ((["f", "os:system"], "not a scratch-bake type"),
                      (["o", 0, "subprocess:Popen", []], "not a scratch-bake type"),
                      (["o", 0, "bake.cache.session:Session", []], "not a stored dataclass"),  # a plain class
                      (["f", "bake.cache.session:StageCache"], "not a stored function"),
                      (["o", 0, "bake.scene:Scene", ["__class__", None]], "bad attribute name"),
                      (["a", 0, 0, "|O", [1], "C"], "bad array"),
                      (["x"], "unknown node")):
        header = {"key": key, "stage": "s", "tool": keys.tool_fingerprint(), "blobs": [[0, 8]], "tree": tree}
        chunks = encode_entry_raw(header)
        chunks.insert(-1, b"\0" * 64)  # the blob area
        import hashlib

        chunks[-1] = hashlib.sha256(b"".join(chunks[:-1])).digest()
        buf = np.frombuffer(b"".join(chunks), np.uint8).copy()
        with pytest.raises(CacheError, match=why):
            decode_entry(buf, key, "s")


# --------------------------------------------------------------------------- the entry format
def _payload():
    pos = np.arange(12, dtype=np.float64).reshape(4, 3)
    shared = np.array([1, 2, 3], np.int64)
    s = make_scene(pos, [[0, 1, 2], [0, 2, 3]], materials=(Material("m", texture=Path("/x/y.png"),
                                                                    texture_data=b"\x89PNG"),))
    from bake.textures.stage import albedo_provider

    s = s.with_artefacts(texture_outputs={1: shared, "same": shared, "f": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
                              "rec": np.zeros(2, dtype=[("a", "<i4"), ("b", "<f8", (2,))]),
                              "empty": np.zeros((0, 3)), "scalars": (np.float32(1.5), np.int16(-3), np.bool_(True)),
                              "floats": [float("nan"), -0.0, 1e-300, float("inf")], "set": {3, 1, 2},
                              "fn": albedo_provider, "tuple": (1, [2, (3,)]), "bytes": bytearray(b"ab")})
    return {"scene": s, "records": []}


def test_entries_round_trip_types_identity_and_layout():
    data = _payload()
    buf = np.frombuffer(b"".join(encode_entry("k", "s", data)), np.uint8).copy()
    back = decode_entry(buf, "k", "s")
    x, y = data["scene"].artefacts.texture_outputs, back["scene"].artefacts.texture_outputs
    assert y["same"] is y[1]  # shared objects stay shared
    assert y["f"].flags.f_contiguous and not y["f"].flags.c_contiguous and np.array_equal(y["f"], x["f"])
    assert y["rec"].dtype == x["rec"].dtype and y["rec"].tobytes() == x["rec"].tobytes()
    assert y["empty"].shape == (0, 3)
    assert [type(v) for v in y["scalars"]] == [np.float32, np.int16, np.bool_] and y["scalars"][0] == 1.5
    assert np.isnan(y["floats"][0]) and str(y["floats"][1]) == "-0.0" and y["floats"][2:] == x["floats"][2:]
    assert y["set"] == {1, 2, 3} and y["fn"] is x["fn"] and y["tuple"] == (1, [2, (3,)])
    assert type(y["bytes"]) is bytearray
    m = back["scene"].materials[0]
    assert m == data["scene"].materials[0] and isinstance(m.texture, Path)
    assert y[1].flags.writeable and y[1].flags.aligned
    # deterministic: the same objects, or equal ones built again, encode to the same bytes
    assert b"".join(encode_entry("k", "s", data)) == b"".join(encode_entry("k", "s", _payload()))


def test_unsupported_values_are_refused_when_storing():
    for bad in (lambda: 1, np.array([object()]), object(), Path):
        with pytest.raises(Unsupported):
            encode_entry("k", "s", {"v": bad})


# --------------------------------------------------------------------------- size cap and switches
def test_the_size_cap_drops_the_least_recently_used_entries(tmp_path):
    store = DiskStore(tmp_path, max_bytes=10_000)
    for i in range(8):
        store.write(f"{i:064x}.stage", [bytes(3000)])
        os.utime(tmp_path / f"{i:064x}.stage", ns=(10**18 + i * 10**9, 10**18 + i * 10**9))
    assert store.read(f"{1:064x}.stage") is not None  # a hit makes entry 1 the most recent
    gone = store.trim()
    left = sorted(p.name[:64] for p in tmp_path.iterdir())
    assert sum(p.stat().st_size for p in tmp_path.iterdir()) <= 10_000
    assert left == [f"{i:064x}" for i in (1, 6, 7)]
    assert sorted(g[:64] for g in gone) == [f"{i:064x}" for i in (0, 2, 3, 4, 5)]


def test_a_bake_keeps_the_cache_under_its_cap(tmp_path):
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"
    bake(cfg, out)
    folder = out / ".bake-cache" / "stages"
    full = sum(p.stat().st_size for p in folder.iterdir())
    cap = full / 3
    rep = bake(cfg, out, f"cache.max_mb={cap / 2**20}", "bsp.seed=5")
    assert sum(p.stat().st_size for p in folder.iterdir()) <= cap
    assert rep["cache"]["from_cache"]  # it used the cache before trimming it


def test_cache_none_writes_no_cache(tmp_path):
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B + '\n[cache]\ndir = "none"\n')
    rep = bake(cfg, tmp_path / "out")
    assert rep["cache"] is None and not (tmp_path / "out" / ".bake-cache" / "stages").exists()
    res = pipeline.run(pipeline.load_config_for(cfg))  # the API without an output folder: no cache
    assert res.cache is None


# --------------------------------------------------------------------------- sweeps
def test_a_lighting_sweep_runs_the_stages_before_lighting_once(tmp_path, monkeypatch):
    from bake import sweep as sweep_mod
    import bake.mesh.simplify.stage as simplify_mod

    write_model(tmp_path / "m")
    cfg_path = tmp_path / "m" / "b.toml"
    cfg_path.write_text(CONFIG_B)
    calls = []
    real = simplify_mod.stage

    def counting(scene, section):
        calls.append(1)
        return real(scene, section)

    monkeypatch.setattr(simplify_mod, "stage", counting)
    values = [4, 8, 16]
    cfg = pipeline.load_config_for(cfg_path)
    reused = sweep_mod.sweep(cfg, "lighting.ao.samples", values)  # cache off: in memory
    assert len(calls) == 1
    assert reused["cache"]["where"] == "memory"
    lit = ["import", "transform", "triangulate", "clean", "simplify", "textures"]
    assert [r["cached_stages"] for r in reused["rows"]] == [lit] * len(values)
    calls.clear()
    plain = sweep_mod.sweep(cfg, "lighting.ao.samples", values, cache=None)  # every row from scratch
    assert len(calls) == len(values) + 1  # warm-up + one per value
    for a, b in zip(reused["rows"], plain["rows"], strict=True):
        for k in ("value", "triangles", "bytes", "accuracy", "rmse", "max_error", "face_rmse", "image_rmse",
                  "rays", "reported_error", "components"):
            assert a.get(k) == b.get(k), k
    # with the bake's folder cache, a sweep after `bake run` computes nothing before lighting
    out = tmp_path / "out"
    bake(cfg_path, out)
    calls.clear()
    assert cli.main(["sweep", str(cfg_path), "--vary", "lighting.ao.samples=4,8", "--out", str(out),
                     "--quiet"]) == 0
    assert calls == []
    table = json.loads((out / "sweeps" / "lighting.ao.samples.json").read_text())
    assert table["cache"]["where"] == ".bake-cache/stages"  # (in the output folder)


def test_advice_that_reads_other_sections_follows_this_bakes_config(tmp_path):
    """The import's warning about textures.enabled = false reads a later stage's section: a cached
    import record gets it for the config of the bake that loads it, not the one that stored it."""
    write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B)
    out = tmp_path / "out"

    def import_warnings(rep):
        return [w for w in rep["stages"][0]["warnings"] if "textures.enabled = false" in w]

    off = bake(cfg, out, "textures.enabled=false")
    assert len(import_warnings(off)) == 1
    on = bake(cfg, out)  # the import comes from the cache
    assert "import" in on["cache"]["from_cache"] and import_warnings(on) == []
    again = bake(cfg, out, "textures.enabled=false")
    assert again["cache"]["from_cache"] == _stages(again) and len(import_warnings(again)) == 1
