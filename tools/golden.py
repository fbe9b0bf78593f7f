"""Bakes a fixed set of configs with a checkout's ``bake`` and prints a digest of every output,
so a refactor can show that it writes byte-identical lists and projects (issue 38).

    .venv/bin/python tools/golden.py --tree /path/to/other/checkout > before.json
    .venv/bin/python tools/golden.py > after.json
    .venv/bin/python tools/golden.py --compare before.json after.json

What is compared: every file a bake writes except the ones that hold times (report.json,
report.md, report.html, the manifest), with the .sb3/.sprite3 archives compared by their
members' bytes (a zip's dates are its own). The cases cover every stage and every output format
on models of the corpus (../shared beside the repository).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CORPUS = REPO.parent / "shared" / "corpus"

# (name, target relative to the repository or the corpus, --set overrides)
CASES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("house", "configs/house.toml", ()),
    ("bunny", "configs/bunny.toml", ()),
    ("example", "configs/example.toml", ()),
    ("box_textured", "corpus:box_textured_glb", ("textures.enabled=true",)),
    ("box_textimage", "corpus:box_textured_glb", ("textures.encodings=[\"textimage\"]",)),
    ("box_costume", "corpus:box_textured_glb", ("textures.encodings=[\"costume\"]",)),
    ("duck_bvh", "corpus:duck_glb", ("bvh.enabled=true", "export.faces=\"triangles\"")),
    ("cornell_lightmap", "corpus:cornell_box_multimaterial",
     ("lighting.enabled=true", "lighting.target=\"lightmap\"", "textures.enabled=true", "textures.lightmap.enabled=true",
      "textures.lightmap.resolution=64",
      "lighting.ao.enabled=true", "lighting.ao.samples=8")),
    ("cornell_bsp_bvh", "corpus:cornell_box_tinyobj",
     ("bsp.enabled=true", "bvh.enabled=true", "lighting.enabled=true")),
    ("suzanne_simplify", "corpus:suzanne_obj",
     ("mesh.simplify.enabled=true", "mesh.simplify.target_triangles=300", "bsp.enabled=true")),
    ("quads", "corpus:cube_quads_mtl", ("export.faces=\"quads\"",)),
    ("sprite", "corpus:ico4_mtl", ("export.sprite3=true", "lighting.enabled=true")),
)

SKIP = {"report.json", "report.md", "report.html", ".bake-manifest.json"}


def corpus_model(folder: str) -> Path:
    d = CORPUS / folder
    for ext in (".glb", ".gltf", ".obj"):
        found = sorted(d.rglob(f"*{ext}"))
        if found:
            return found[0]
    raise SystemExit(f"golden: no model in {d}")


def digest(out: Path) -> dict[str, str]:
    files: dict[str, str] = {}
    for p in sorted(out.rglob("*")):
        if not p.is_file() or p.name in SKIP or ".bake-cache" in p.parts:
            continue
        rel = p.relative_to(out).as_posix()
        if p.suffix in (".sb3", ".sprite3"):
            with zipfile.ZipFile(p) as z:
                for name in sorted(z.namelist()):
                    files[f"{rel}!{name}"] = hashlib.sha256(z.read(name)).hexdigest()
        else:
            files[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return files


def bake_all(tree: Path, only: list[str]) -> dict[str, dict[str, str]]:
    result: dict[str, dict[str, str]] = {}
    env = dict(os.environ, PYTHONPATH=str(tree))
    for name, target, sets in CASES:
        if only and name not in only:
            continue
        t = corpus_model(target.split(":", 1)[1]) if target.startswith("corpus:") else REPO / target
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / name
            cmd = [sys.executable, "-c", "import sys; from bake.cli import main; sys.exit(main())",
                   "run", str(t), "--out", str(out), "--quiet"]
            for s in sets:
                cmd += ["--set", s]
            p = subprocess.run(cmd, env=env, cwd=str(tree), capture_output=True, text=True)  # (python -c puts its cwd first on sys.path)
            if p.returncode != 0:
                result[name] = {"exit": str(p.returncode), "stderr": p.stderr[-400:]}
            else:
                result[name] = digest(out)
        print(f"golden: {name}: {len(result[name])} file(s)", file=sys.stderr)
    return result


def compare(a: dict, b: dict) -> list[str]:
    bad = []
    for name in sorted(set(a) | set(b)):
        fa, fb = a.get(name, {}), b.get(name, {})
        if "exit" in fa or "exit" in fb:
            if fa != fb:
                bad.append(f"{name}: exit {fa.get('exit', 0)} / {fb.get('exit', 0)} {fb.get('stderr', fa.get('stderr', ''))}")
            continue
        for f in sorted(set(fa) | set(fb)):
            if fa.get(f) != fb.get(f):
                bad.append(f"{name}: {f} differs ({fa.get(f, 'missing')[:12]} / {fb.get(f, 'missing')[:12]})")
    return bad


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", type=Path, default=REPO, help="checkout whose bake to run (default: this one)")
    ap.add_argument("--only", nargs="*", default=[], help="case names")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    args = ap.parse_args(argv)
    if args.compare:
        bad = compare(*(json.loads(p.read_text()) for p in args.compare))
        print("\n".join(bad) or "golden: every output is byte-identical")
        return 1 if bad else 0
    print(json.dumps(bake_all(args.tree.resolve(), args.only), indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
