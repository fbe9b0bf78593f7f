"""Markdown tables generated from benchmark results, so the figures in the docs are the ones
``make bench`` measured and never typed by hand.

A generated table sits between two HTML comments in any ``README.md`` or ``docs/*.md``; the
opening one holds the table's spec as JSON (GitHub does not show the comments)::

    <!-- doc-table {"source": "bvh.json", "rows": "models", "keys": ["teapot", "duck"],
         "labels": {"duck": "duck (glTF)"}, "align": "lrr",
         "columns": [["model", "{label} ({triangles:,})"],
                     ["items read per ray", "{binary.reads_per_ray:.0f} / {quantised.reads_per_ray:.0f}"]]} -->
    | model | items read per ray |
    |:---|---:|
    | teapot (6,320) | 457 / 176 |
    | duck (glTF) (4,212) | 482 / 185 |
    <!-- /doc-table -->

Spec keys:

* ``source`` -- a JSON file in ``benchmarks/results/``: what ``make bench`` writes (each
  benchmark with its defaults), or a benchmark run with other options (a narrower run, another
  ``--before`` commit), whose command the doc names beside the table and the JSON records under
  ``command``; ``make bench`` does not run those again. The files are committed so the docs can
  be checked against them;
* ``rows`` -- dotted path to the rows in that file: a dict (one row per key, in file order) or a
  list (one row per element);
* ``keys`` -- (dict rows) which keys, in this order; ``labels`` -- key -> ``{label}`` text
  (default: the key itself);
* ``columns`` -- ``[header, template]`` pairs. A template is a Python format string over the
  row: ``{a.b.c:fmt}`` walks dicts (and list indices), ``{key}`` / ``{label}`` / ``{index}``
  name the row, ``{_.path}`` reads from the top of the file. ``None`` renders as ``-``.
  Derived figures (ratios, percentages of something else) belong in the benchmark's JSON;
  ``%`` and ``,`` format specs are there for scaling and thousands;
* ``align`` -- one letter per column, ``l`` / ``r`` / ``c`` (default: all ``l``).

Regenerate every table after ``make bench`` (which runs this at its end)::

    .venv/bin/python tools/doc_tables.py            # rewrites the tables in README.md and docs/*.md
    .venv/bin/python tools/doc_tables.py --check    # exit 1 and name each table that differs

``tests/test_doc_tables.py`` runs the check, so a table edited by hand, or a results file
changed without regenerating the docs, fails the suite.
"""

from __future__ import annotations

import argparse
import json
import re
import string
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "benchmarks" / "results"
BLOCK = re.compile(r"<!--\s*doc-table\s+(?P<spec>.*?)-->(?P<body>.*?)<!--\s*/doc-table\s*-->", re.S)
ALIGN = {"l": ":---", "r": "---:", "c": ":---:"}


class TableError(Exception):
    """A spec or a results file the tool cannot render: one line naming the doc and its line."""


@dataclass
class Block:
    path: Path
    line: int  # of the opening comment
    start: int  # offsets of the generated body in the text
    end: int
    spec: dict
    body: str


class _Formatter(string.Formatter):
    def __init__(self, root: Any):
        super().__init__()
        self.root = root

    def get_field(self, field_name, args, kwargs):
        parts = field_name.split(".")
        obj: Any = self.root if parts[0] == "_" else kwargs
        for p in parts[1:] if parts[0] == "_" else parts:
            if isinstance(obj, list):
                try:
                    obj = obj[int(p)]
                except (ValueError, IndexError):
                    raise KeyError(field_name) from None
            elif isinstance(obj, dict) and p in obj:
                obj = obj[p]
            else:
                raise KeyError(field_name)
        return obj, field_name

    def format_field(self, value, format_spec):
        if value is None:
            return "-"
        return super().format_field(value, format_spec)


def blocks(path: Path, text: str | None = None) -> list[Block]:
    """The generated tables of one markdown file."""
    text = path.read_text("utf-8") if text is None else text
    out = []
    for m in BLOCK.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        try:
            spec = json.loads(m.group("spec"))
        except json.JSONDecodeError as e:
            raise TableError(f"{path}:{line}: doc-table spec is not JSON: {e}") from None
        if not isinstance(spec, dict):
            raise TableError(f"{path}:{line}: doc-table spec must be a JSON object")
        out.append(Block(path, line, m.start("body"), m.end("body"), spec, m.group("body")))
    return out


def _walk(data: Any, dotted: str, where: str) -> Any:
    obj = data
    for p in [q for q in dotted.split(".") if q]:
        if isinstance(obj, dict) and p in obj:
            obj = obj[p]
        elif isinstance(obj, list) and p.isdigit() and int(p) < len(obj):
            obj = obj[int(p)]
        else:
            raise TableError(f"{where}: no '{dotted}' in the results (stops at '{p}')")
    return obj


def render(spec: dict, results: Path = RESULTS, where: str = "doc-table") -> str:
    """The markdown table (no trailing newline) a spec asks for."""
    for k in ("source", "rows", "columns"):
        if k not in spec:
            raise TableError(f"{where}: doc-table spec needs '{k}'")
    unknown = set(spec) - {"source", "rows", "keys", "labels", "columns", "align"}
    if unknown:
        raise TableError(f"{where}: unknown doc-table spec key(s) {sorted(unknown)}")
    src = Path(results) / spec["source"]
    try:
        data = json.loads(src.read_text("utf-8"))
    except FileNotFoundError:
        raise TableError(f"{where}: {src} not found (run `make bench`, and commit the JSON)") from None
    except json.JSONDecodeError as e:
        raise TableError(f"{where}: {src} is not JSON: {e}") from None
    rows_at = _walk(data, spec["rows"], f"{where} ({spec['source']})")
    labels = spec.get("labels", {})
    rows: list[dict] = []
    if isinstance(rows_at, dict):
        keys = spec.get("keys", list(rows_at))
        for k in keys:
            if k not in rows_at:
                raise TableError(f"{where}: no row '{k}' under '{spec['rows']}' in {spec['source']}")
            r = rows_at[k]
            rows.append({**(r if isinstance(r, dict) else {"value": r}), "key": k, "label": labels.get(k, k)})
    elif isinstance(rows_at, list):
        if "keys" in spec:
            raise TableError(f"{where}: 'keys' needs rows that are a dict, '{spec['rows']}' is a list")
        for i, r in enumerate(rows_at):
            rows.append({**(r if isinstance(r, dict) else {"value": r}), "index": i})
    else:
        raise TableError(f"{where}: '{spec['rows']}' in {spec['source']} is neither a dict nor a list")
    cols = spec["columns"]
    if not cols or not all(isinstance(c, list) and len(c) == 2 for c in cols):
        raise TableError(f"{where}: 'columns' must be a list of [header, template] pairs")
    align = spec.get("align", "l" * len(cols))
    if len(align) != len(cols) or set(align) - set(ALIGN):
        raise TableError(f"{where}: 'align' needs one of l, r, c per column ({len(cols)})")
    fmt = _Formatter(data)
    lines = ["| " + " | ".join(h for h, _ in cols) + " |", "|" + "|".join(ALIGN[a] for a in align) + "|"]
    for r in rows:
        cells = []
        for h, tpl in cols:
            try:
                cells.append(fmt.vformat(tpl, (), r))
            except KeyError as e:
                name = r.get("key", r.get("index"))
                raise TableError(f"{where}: column '{h}': row '{name}' has no {e}") from None
            except (ValueError, TypeError) as e:
                raise TableError(f"{where}: column '{h}': {e}") from None
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines)


def regenerate(text: str, path: Path, results: Path = RESULTS) -> str:
    """``text`` with every generated table re-rendered."""
    out, pos = [], 0
    for b in blocks(path, text):
        out.append(text[pos:b.start])
        out.append("\n" + render(b.spec, results, f"{path}:{b.line}") + "\n")
        pos = b.end
    out.append(text[pos:])
    return "".join(out)


def doc_files(root: Path = REPO) -> list[Path]:
    return [p for p in [root / "README.md", *sorted((root / "docs").glob("*.md"))] if p.is_file()]


def stale(paths: list[Path], results: Path = RESULTS) -> list[str]:
    """One line per generated table whose text differs from what the results render."""
    bad = []
    for p in paths:
        text = p.read_text("utf-8")
        for b in blocks(p, text):
            want = "\n" + render(b.spec, results, f"{p}:{b.line}") + "\n"
            if b.body != want:
                bad.append(f"{p}:{b.line}: table from {b.spec.get('source')} differs from the results")
    return bad


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Render the docs' tables from benchmarks/results/*.json.")
    ap.add_argument("files", nargs="*", type=Path, help="markdown files (default: README.md, docs/*.md)")
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if a table differs")
    ap.add_argument("--results", type=Path, default=RESULTS, help="folder of the results JSON")
    a = ap.parse_args(argv)
    paths = a.files or doc_files()
    try:
        if a.check:
            bad = stale(paths, a.results)
            for line in bad:
                print(line, file=sys.stderr)
            if bad:
                print("regenerate with: .venv/bin/python tools/doc_tables.py", file=sys.stderr)
            return 1 if bad else 0
        for p in paths:
            text = p.read_text("utf-8")
            new = regenerate(text, p, a.results)
            if new != text:
                tmp = p.with_name(p.name + ".tmp")
                tmp.write_text(new, "utf-8")
                tmp.replace(p)
                print(f"updated {p}")
    except TableError as e:
        print(f"doc_tables: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
