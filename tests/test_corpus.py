"""Every corpus entry bakes to lists whose counts match the file, or fails with one line that
names the file and the problem (exit 3) — never a traceback."""

import json
import re

import pytest

from bake import cli
from conftest import CORPUS

ENTRIES = json.loads((CORPUS / "manifest.json").read_text()) if (CORPUS / "manifest.json").exists() else []

# Entries that are broken on purpose: they must fail cleanly with the default (strict) import.
MUST_FAIL = {
    "test_nan_inf": "nan|non-finite|NaN",
    "zero_face_index": "index 0|index",
    "invalid_face_definition": "fewer than 3|vertices",
    "notenough_indices": "fewer than 3|vertices",
    "gltf_index_out_of_range": "out of range",
    "tinygltf_bounds_checking": "out of range|bounds|past",
    "empty_obj": "no faces",
    "gltf_empty_nodes": "no faces",
    "stanford_bunny_res2_ply": "format",
}


def obj_polygon_sizes(path):
    """Independent count: vertex counts of every `f` line in an OBJ file."""
    sizes = []
    text = path.read_bytes().decode("latin-1").replace("\\\r\n", " ").replace("\\\n", " ")  # continuations
    for line in text.splitlines():
        parts = line.split()
        if parts and parts[0] == "f":
            sizes.append(len(parts) - 1)
    return sizes


@pytest.mark.corpus
@pytest.mark.parametrize("entry", ENTRIES, ids=[e["id"] for e in ENTRIES])
def test_corpus_entry(entry, tmp_path, capsys):
    path = CORPUS / entry["id"] / entry["primary"]
    out = tmp_path / "out"
    code = cli.main(["run", str(path), "--out", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    if entry["id"] in MUST_FAIL:
        assert code == 3, f"expected a clean input error, got exit {code}: {captured.err}"
    if code != 0:
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1, captured.err
        assert path.name in lines[0], lines[0]
        assert code == 3, lines[0]
        if entry["id"] in MUST_FAIL:
            assert re.search(MUST_FAIL[entry["id"]], lines[0], re.I), lines[0]
        return
    rep = json.loads((out / "report.json").read_text())
    stages = {s["name"]: s for s in rep["stages"]}
    tri = stages["triangulate"]
    clean = stages["clean"]
    # triangles = sum(n - 2) over the imported polygons ...
    polys_in = tri["counts_in"]["polygons"]
    assert tri["counts_out"]["triangles"] >= polys_in
    if path.suffix == ".obj":
        sizes = obj_polygon_sizes(path)
        assert polys_in == len(sizes)
        assert tri["counts_out"]["triangles"] == sum(n - 2 for n in sizes)
    # ... minus what cleaning reports dropping
    dropped = clean["counts_in"]["triangles"] - clean["counts_out"]["triangles"]
    # every triangle clean dropped has its reason counted, and the warning gives both
    reasons = clean["details"]["dropped_repeated_index"] + clean["details"]["dropped_zero_area"]
    assert dropped == reasons
    assert (dropped == 0) == (not any(w.startswith("dropped ") for w in clean["warnings"]))
    assert rep["scene"]["triangles"] == tri["counts_out"]["triangles"] - dropped
    lists = rep["lists"]
    assert lists["tris"]["items"] == 4 * rep["scene"]["triangles"]
    assert lists["verts"]["items"] == 3 * rep["scene"]["vertices"]
    tris_txt = (out / "lists" / "tris.txt").read_text()
    assert not tris_txt.endswith("\n")
    items = [int(x) for x in tris_txt.split("\n")] if tris_txt else []
    assert len(items) == lists["tris"]["items"]
    if items:
        assert min(items) >= 1
        assert max(items[0::4] + items[1::4] + items[2::4]) <= rep["scene"]["vertices"]
    verts = (out / "lists" / "verts.txt").read_text().split("\n")
    assert all(v not in ("nan", "inf", "-inf", "NaN", "Infinity") for v in verts)
