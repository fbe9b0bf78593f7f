"""Scratch archives: what we write validates, is deterministic, and untrusted archives are read safely."""

import hashlib
import io
import json
import zipfile

import pytest

from bake.errors import InputError
from bake.scratch import sb3


def lists():
    return {"verts": [0, 1.5, -2, 3], "names": ["a", "b,c", "\"q"]}


def test_written_project_validates_and_round_trips(tmp_path):
    data, pj_bytes = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists()), sb3.Target("Mesh")])
    p = tmp_path / "x.sb3"
    p.write_bytes(data)
    project, assets = sb3.load_project(p)
    assert sb3.validate_project(project, assets) == []
    stage = project["targets"][0]
    assert {v[0]: v[1] for v in stage["lists"].values()} == lists()
    assert len(json.dumps(project, separators=(",", ":"), ensure_ascii=False).encode()) == pj_bytes
    for c in stage["costumes"]:
        assert hashlib.md5(assets[c["md5ext"]]).hexdigest() == c["assetId"]


def test_deterministic_bytes():
    a = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists())])[0]
    b = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists())])[0]
    assert a == b


def test_sprite3_validates(tmp_path):
    p = tmp_path / "m.sprite3"
    p.write_bytes(sb3.write_sprite3(sb3.Target("Mesh", lists=lists())))
    entries = sb3.read_archive(p)
    sprite = json.loads(entries.pop("sprite.json"))
    assert sb3.validate_sprite(sprite, entries) == []
    assert sprite["isStage"] is False and sprite["name"] == "Mesh"


def test_validator_reports_every_problem():
    project = sb3.project_json([sb3.Target("Stage", is_stage=True, lists={"a": [1, float("nan")]}),
                                sb3.Target("S", lists={"b": [[1]]})])
    project["targets"][1]["costumes"] = []
    project["targets"][0]["costumes"][0]["assetId"] = "xyz"
    project["meta"]["semver"] = "2.0.0"
    problems = sb3.validate_project(project, assets={})
    text = "\n".join(problems)
    assert "semver" in text and "assetId" in text and "needs at least one costume" in text
    assert "nan" in text and "[1]" in text and len(problems) >= 5


def _zip(entries, tmp_path, name="in.sb3", compress=zipfile.ZIP_DEFLATED):
    p = tmp_path / name
    with zipfile.ZipFile(p, "w", compression=compress) as z:
        for n, d in entries.items():
            z.writestr(n, d)
    return p


def test_untrusted_archives_refused_with_the_limit_named(tmp_path):
    with pytest.raises(InputError, match="outside the archive root"):
        sb3.read_archive(_zip({"../evil.txt": b"x", "project.json": b"{}"}, tmp_path))
    bomb = _zip({"project.json": b"{}", "big.bin": b"\0" * (8 << 20)}, tmp_path, "bomb.sb3")
    with pytest.raises(InputError, match="compression ratio"):
        sb3.read_archive(bomb)
    with pytest.raises(InputError, match="entries"):
        sb3.read_archive(_zip({f"{i}.txt": b"" for i in range(20)}, tmp_path, "many.sb3"), max_entries=10)
    notzip = tmp_path / "no.sb3"
    notzip.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a Scratch project archive"):
        sb3.read_archive(notzip)
    with pytest.raises(InputError, match="uncompresses"):
        sb3.read_archive(_zip({"a": b"1" * 1000, "b": b"2" * 1000}, tmp_path, "t.sb3"), max_total=1500)


def test_project_in_subfolder_is_found(tmp_path):
    p = _zip({"proj/project.json": json.dumps(sb3.project_json([sb3.Target("Stage", is_stage=True)])),
              "proj/" + sb3.Asset(sb3.BACKDROP_SVG, "svg").md5ext: sb3.BACKDROP_SVG}, tmp_path)
    project, assets = sb3.load_project(p)
    assert sb3.validate_project(project, assets) == []


# --------------------------------------------------------------------------- more untrusted input
def test_more_untrusted_archives(tmp_path):
    def raw_zip(name, infos):
        p = tmp_path / name
        with zipfile.ZipFile(p, "w") as z:
            for info, data in infos:
                z.writestr(info, data)
        return p

    link = zipfile.ZipInfo("project.json")
    link.external_attr = 0o120777 << 16
    with pytest.raises(InputError, match="symbolic link"):
        sb3.read_archive(raw_zip("link.sb3", [(link, b"/etc/passwd")]))
    with pytest.warns(UserWarning):  # zipfile warns about the duplicate name
        dup = raw_zip("dup.sb3", [(zipfile.ZipInfo("project.json"), b"{}"), (zipfile.ZipInfo("project.json"), b"{}")])
    with pytest.raises(InputError, match="two entries named"):
        sb3.read_archive(dup)
    # the "encrypted" flag (zipfile cannot write one: set bit 0 in both headers by hand)
    enc = bytearray(raw_zip("enc.sb3", [(zipfile.ZipInfo("project.json"), b"{}")]).read_bytes())
    for sig, off in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        i = enc.index(sig) + off
        enc[i] |= 0x1
    with pytest.raises(InputError, match="encrypted"):
        sb3.read_archive(bytes(enc))
    for bad in ("/abs/project.json", "C:/x.json", "a\\..\\b", "a/../../b"):
        with pytest.raises(InputError, match="outside the archive root"):
            sb3.read_archive(raw_zip("p.sb3", [(zipfile.ZipInfo(bad), b"x")]))
    # corrupt data: flip bytes inside the stored entry so the CRC check fails
    good = raw_zip("good.sb3", [(zipfile.ZipInfo("project.json"), b"A" * 64)])
    data = bytearray(good.read_bytes())
    data[data.index(b"A" * 8):data.index(b"A" * 8) + 8] = b"B" * 8
    with pytest.raises(InputError, match="cannot be read"):
        sb3.read_archive(bytes(data))
    # bytes work like paths; the limits are named
    ok = _zip({"project.json": b"{}"}, tmp_path, "ok.sb3")
    assert sb3.read_archive(ok.read_bytes()) == {"project.json": b"{}"}
    with pytest.raises(InputError, match=r"limit 10\)"):
        sb3.read_archive(_zip({"a": b"1" * 11}, tmp_path, "big.sb3"), max_entry=10)
    # two project.json files at the same depth: ambiguous, refused
    two = _zip({"a/project.json": b"{}", "b/project.json": b"{}"}, tmp_path, "two.sb3")
    with pytest.raises(InputError, match="several project.json"):
        sb3.load_project(two)
    with pytest.raises(InputError, match="not valid JSON"):
        sb3.load_project(_zip({"project.json": b"{nope"}, tmp_path, "bad.sb3"))
    with pytest.raises(InputError, match="no targets"):
        sb3.load_project(_zip({"project.json": b"[]"}, tmp_path, "arr.sb3"))


def test_extensions_come_from_the_blocks():
    pen = {"a": {"opcode": "pen_clear"}, "b": {"opcode": "operator_add"}, "c": [12, "v", "id"]}
    t = sb3.Target("S", blocks=pen)
    project = sb3.project_json([sb3.Target("Stage", is_stage=True), t])
    assert project["extensions"] == ["pen"]
    assert sb3.project_json([sb3.Target("Stage", is_stage=True)])["extensions"] == []


def test_archive_sizes_are_the_written_bytes():
    data, pj = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists()), sb3.Target("Mesh")])
    sizes = sb3.archive_sizes(data)
    assert sizes["project_json_bytes"] == pj
    assert sizes["assets"] == {sb3.Asset(sb3.BACKDROP_SVG, "svg").md5ext: len(sb3.BACKDROP_SVG),
                               sb3.Asset(sb3.SPRITE_SVG, "svg").md5ext: len(sb3.SPRITE_SVG)}


# --------------------------------------------------------------------------- merging into a project
def _engine(tmp_path, *, subfolder=""):
    """An author's project: global 'verts' with a visible monitor, sprite 'Engine' with its own
    'tris' and a costume, another sprite, a sound file we never touch."""
    stage = sb3.Target("Stage", is_stage=True, lists={"verts": [9, 9, 9]}, variables={"score": 3})
    engine = sb3.Target("Engine", lists={"tris": [1, 1, 1, 1]}, layer_order=1,
                        costumes=[sb3.Costume("c1", sb3.Asset(b"<svg xmlns='http://www.w3.org/2000/svg'/>", "svg"))])
    other = sb3.Target("Other", lists={"own": ["x"]}, layer_order=2)
    project = sb3.project_json([stage, engine, other])
    vid = next(iter(project["targets"][0]["lists"]))
    project["monitors"] = [{"id": vid, "mode": "list", "opcode": "data_listcontents", "params": {"LIST": "verts"},
                            "spriteName": None, "value": [9, 9, 9], "width": 100, "height": 100, "x": 5, "y": 5,
                            "visible": True}]
    entries = {subfolder + "project.json": sb3.dumps(project).encode(), subfolder + "beep.wav": b"RIFFxxxx"}
    for t in (stage, engine, other):
        for a in t.assets():
            entries[subfolder + a.md5ext] = a.data
    p = tmp_path / "engine.sb3"
    with zipfile.ZipFile(p, "w") as z:
        for n, d in entries.items():
            z.writestr(n, d)
    return p, project


def test_merge_replaces_adds_hides_and_keeps_the_rest(tmp_path):
    path, before = _engine(tmp_path)
    original = path.read_bytes()
    new_costume = sb3.Costume("c1", sb3.Asset(b"<svg xmlns='http://www.w3.org/2000/svg' width='3'/>", "svg"))
    extra = sb3.Costume("tex", sb3.Asset(b"<svg xmlns='http://www.w3.org/2000/svg' width='4'/>", "svg"))
    out = sb3.merge_into(path, "Engine", {"verts": [1, 2.5, -3], "tris": [1, 2, 3, 1], "fresh": ["a,b", 7]},
                         [new_costume, extra])
    assert path.read_bytes() == original  # the input is only read
    p2 = tmp_path / "out.sb3"
    p2.write_bytes(out)
    after, assets = sb3.load_project(p2)
    assert sb3.validate_project(after, assets) == []
    stage, engine, other = after["targets"]
    (vid, verts), = stage["lists"].items()
    assert verts == ["verts", [1, 2.5, -3]] and vid == next(iter(before["targets"][0]["lists"]))
    assert {v[0]: v[1] for v in engine["lists"].values()} == {"tris": [1, 2, 3, 1], "fresh": ["a,b", 7]}
    assert next(iter(engine["lists"])) == next(iter(before["targets"][1]["lists"]))  # tris kept its id
    assert after["monitors"][0]["visible"] is False and after["monitors"][0]["value"] == []
    assert [c["name"] for c in engine["costumes"]] == ["c1", "tex"]
    assert engine["costumes"][0]["assetId"] == new_costume.asset.md5
    assert assets[extra.asset.md5ext] == extra.asset.data
    # everything else untouched
    assert other == before["targets"][2] and stage["variables"] == before["targets"][0]["variables"]
    assert assets["beep.wav"] == b"RIFFxxxx" and after["meta"] == before["meta"]
    assert sb3.merge_into(path, "Engine", {"verts": [1, 2.5, -3], "tris": [1, 2, 3, 1], "fresh": ["a,b", 7]},
                          [new_costume, extra]) == out  # deterministic


def test_merge_into_stage_keeps_a_subfolder_layout_and_bare_json_works(tmp_path):
    path, _ = _engine(tmp_path, subfolder="proj/")
    out = sb3.merge_into(path.read_bytes(), "Stage", {"verts": [0], "new": [1]})
    with zipfile.ZipFile(io.BytesIO(out)) as z:
        names = z.namelist()
    assert "proj/project.json" in names and "proj/beep.wav" in names and names == sorted(names)
    project, _ = sb3.load_project(out)
    assert {v[0] for v in project["targets"][0]["lists"].values()} == {"verts", "new"}
    bare = sb3.dumps(sb3.project_json([sb3.Target("Stage", is_stage=True)])).encode()
    project, _ = sb3.load_project(sb3.merge_into(bare, "Stage", {"l": [1]}))
    assert list(project["targets"][0]["lists"].values()) == [["l", [1]]]


def test_merge_refuses_conflicts_with_a_clear_reason(tmp_path):
    path, _ = _engine(tmp_path)
    with pytest.raises(InputError, match="no sprite named 'Nope'.*Stage, Engine, Other"):
        sb3.merge_into(path, "Nope", {"a": [1]})
    with pytest.raises(InputError, match="sprite 'Other' has its own list 'own'"):
        sb3.merge_into(path, "Stage", {"own": [1]})
    with pytest.raises(InputError, match="nan"):
        sb3.merge_into(path, "Stage", {"bad": [1, float("nan")]})
    with pytest.raises(InputError, match="already has a sprite named 'Engine'"):
        sb3.merge_into(path, "Stage", {"a": [1]}, sprites=[sb3.Target("Engine")])
    with pytest.raises(InputError, match="variable 'score' that the stage also has"):
        sb3.merge_into(path, "Stage", {"a": [1]}, sprites=[sb3.Target("R", variables={"score": 0})])
    with pytest.raises(InputError, match="not a Scratch project archive"):
        sb3.merge_into(b"junk", "Stage", {})


def test_merged_sprites_point_at_the_stage_lists(tmp_path):
    path, before = _engine(tmp_path)
    reader = sb3.Target("Reader", layer_order=5, blocks={
        "a": {"opcode": "data_addtolist", "next": None, "parent": None, "inputs": {"ITEM": [3, [13, "verts", "WRONG"],
              [10, ""]]}, "fields": {"LIST": ["verts", "WRONG"]}, "shadow": False, "topLevel": True, "x": 0, "y": 0},
        "b": [13, "verts", "WRONG", 0, 0]})
    project, _ = sb3.load_project(sb3.merge_into(path, "Stage", {"verts": [5]}, sprites=[reader]))
    vid = next(iter(project["targets"][0]["lists"]))
    blocks = project["targets"][3]["blocks"]
    assert blocks["a"]["fields"]["LIST"] == ["verts", vid]
    assert blocks["a"]["inputs"]["ITEM"][1] == [13, "verts", vid] and blocks["b"][2] == vid
    assert project["targets"][3]["layerOrder"] == 3


def test_validator_checks_blocks_names_values_and_size():
    blocks = {"a": {"opcode": "motion_movesteps", "next": "gone", "parent": None, "inputs": {"S": [3, "nope", [4, ""]]},
                    "fields": {}, "shadow": False, "topLevel": True},
              "c": {"opcode": "procedures_call", "next": None, "parent": None, "inputs": {}, "fields": {},
                    "mutation": {"proccode": "undefined %s"}, "topLevel": True}}
    dup = sb3.Costume("x", sb3.Asset(sb3.SPRITE_SVG, "svg"))
    stage = sb3.Target("Stage", is_stage=True, lists={"verts": [1]})
    sprite = sb3.Target("S", variables={"v": float("inf")}, lists={"verts": [2, 3]}, blocks=blocks,
                        costumes=[dup, dup])
    project = sb3.project_json([stage, sprite])
    problems = sb3.validate_project(project, project_json_bytes=6 << 20)
    text = "\n".join(problems)
    for needle in ("next 'gone' is not a block", "missing block 'nope'", "'undefined %s', which this target",
                   "a second costume named 'x'", "value inf is not a finite", "has the name of a stage list",
                   "project.json is 6291456 bytes"):
        assert needle in text, needle
    many = sb3.project_json([sb3.Target("Stage", is_stage=True, lists={"l": [1, None, 2, None, float("nan")]})])
    (msg,) = sb3.validate_project(many)
    assert "item 2: None" in msg and "(3 such items)" in msg
