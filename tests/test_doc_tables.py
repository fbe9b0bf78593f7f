"""The docs' benchmark tables are what tools/doc_tables.py renders from the committed
benchmarks/results/*.json (and the tool itself renders, checks and fails as it says)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def _tool():
    spec = importlib.util.spec_from_file_location("doc_tables", REPO / "tools" / "doc_tables.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["doc_tables"] = mod  # dataclasses look their module up while the class is made
    spec.loader.exec_module(mod)
    return mod


dt = _tool()


def test_every_generated_table_matches_the_committed_results():
    files = dt.doc_files(REPO)
    assert (REPO / "README.md") in files
    bad = dt.stale(files)
    assert not bad, "\n".join(bad) + "\nregenerate with: .venv/bin/python tools/doc_tables.py"


def test_every_source_says_how_to_make_it_again():
    """Each results file a doc table reads is either what a benchmark writes with its defaults
    (``benchmarks/bench_X.py`` -> ``X.json``, which ``make bench`` runs) or records the
    ``command`` of the run that wrote it, a benchmark script of this repo, and the doc names
    that script and the results file beside the table (within the 40 lines before it: a table
    above it that names another run of the same script is not enough)."""
    problems = []
    for doc in dt.doc_files(REPO):
        lines = doc.read_text("utf-8").splitlines()
        for b in dt.blocks(doc):
            src = b.spec["source"]
            if (REPO / "benchmarks" / f"bench_{Path(src).stem}.py").exists():
                continue
            cmd = json.loads((dt.RESULTS / src).read_text("utf-8")).get("command")
            cmds = cmd if isinstance(cmd, list) else [cmd]
            scripts = {w for c in cmds if isinstance(c, str) for w in c.split() if w.startswith("benchmarks/bench_")}
            if not scripts or not all((REPO / w).exists() for w in scripts):
                problems.append(f"{doc.name}:{b.line}: {src} records no command of a benchmark here ({cmd!r})")
            near = "\n".join(lines[max(0, b.line - 41):b.line - 1])  # (not the spec itself)
            if not any(w in near for w in scripts) or src not in near:
                problems.append(f"{doc.name}:{b.line}: {src}: the doc does not name the run beside the table")
    assert not problems, "\n".join(problems)


SPEC = {"source": "b.json", "rows": "models", "keys": ["b", "a"], "labels": {"a": "model A"},
        "align": "lrr", "columns": [["model", "{label} ({tris:,})"], ["reads", "{q.reads:.1f}"],
                                    ["share", "{share:.1%} of {_.total}"]]}
DATA = {"total": 9, "models": {"a": {"tris": 12345, "q": {"reads": 3.14159}, "share": 0.25},
                               "b": {"tris": 7, "q": {"reads": 2.0}, "share": None}}}


def _doc(tmp_path, body="| stale |"):
    (tmp_path / "b.json").write_text(json.dumps(DATA))
    doc = tmp_path / "x.md"
    doc.write_text("# x\n\ntext\n<!-- doc-table " + json.dumps(SPEC) + " -->\n" + body +
                   "\n<!-- /doc-table -->\nafter\n")
    return doc


def test_renders_rows_in_key_order_with_formats(tmp_path):
    _doc(tmp_path)
    assert dt.render(SPEC, tmp_path) == (
        "| model | reads | share |\n|:---|---:|---:|\n"
        "| b (7) | 2.0 | - of 9 |\n"
        "| model A (12,345) | 3.1 | 25.0% of 9 |")


def test_regenerate_rewrites_only_the_table_and_check_finds_edits(tmp_path, capsys):
    doc = _doc(tmp_path)
    assert dt.stale([doc], tmp_path)  # the hand-typed body differs
    assert dt.main([str(doc), "--results", str(tmp_path), "--check"]) == 1
    assert dt.main([str(doc), "--results", str(tmp_path)]) == 0
    text = doc.read_text()
    assert text.startswith("# x\n\ntext\n<!-- doc-table ") and text.endswith("<!-- /doc-table -->\nafter\n")
    assert "| model A (12,345) | 3.1 | 25.0% of 9 |" in text
    assert dt.stale([doc], tmp_path) == [] and dt.main([str(doc), "--results", str(tmp_path), "--check"]) == 0
    doc.write_text(text.replace("3.1 |", "3.2 |"))  # a typed-over figure
    assert len(dt.stale([doc], tmp_path)) == 1


@pytest.mark.parametrize("change,message", [
    ({"keys": ["a", "zz"]}, "no row 'zz'"),
    ({"rows": "model"}, "no 'model'"),
    ({"columns": [["m", "{nope:.1f}"]], "align": "l"}, "has no 'nope'"),
    ({"source": "missing.json"}, "not found"),
    ({"align": "lr"}, "one of l, r, c per column"),
    ({"colums": []}, "unknown doc-table spec key"),
])
def test_bad_specs_are_one_line_errors_naming_the_doc_line(tmp_path, change, message):
    doc = _doc(tmp_path)
    spec = {**SPEC, **change}
    doc.write_text(doc.read_text().replace(json.dumps(SPEC), json.dumps(spec)))
    with pytest.raises(dt.TableError, match=message) as e:
        dt.stale([doc], tmp_path)
    assert f"{doc}:4" in str(e.value) and "\n" not in str(e.value)
    assert dt.main([str(doc), "--results", str(tmp_path)]) == 2
