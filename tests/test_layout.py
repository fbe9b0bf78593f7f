"""The package layout (shared/docs/layout.md): no import circles, and Scratch-format knowledge in
one room (``bake/scratch/``) that the stages hand data to, never the other way round.

Every ``import`` counts, including those inside functions (a lazy import is still a circle), and
so does every ``"bake.module:function"`` string (the stage registry loads stages by such names)."""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "bake"


def _modules() -> dict[str, Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = p.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


def import_graph() -> dict[str, set[str]]:
    """module -> the bake modules it imports (anywhere in the file)."""
    mods = _modules()
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text("utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in node.names]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                m = LOADED.fullmatch(node.value)
                targets = [m.group(1)] if m else []
            for t in targets:
                if t in mods and t != name:
                    graph[name].add(t)
    return graph


LOADED = re.compile(r"(bake(?:\.\w+)+):\w+")  # a function loaded by name


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _package(mod: str) -> str:
    """The room of a module: its package under bake/, or itself for a module at bake/'s root."""
    return ".".join(mod.split(".")[:2])


def test_the_graph_sees_lazy_imports():
    g = import_graph()
    # bake.lighting.lightmap imports the textures' lightmap machinery, and bake.cli imports
    # bake.scratch.check inside a function: both must be edges
    assert "bake.textures.lightmap" in g["bake.lighting.lightmap"]
    assert "bake.scratch.check" in g["bake.cli"]
    # the registry's names are arrows: the pipeline reaches every stage through it
    assert {"bake.importers.stage", "bake.export.stage", "bake.bsp.report", "bake.lighting.plan"} <= g["bake.stages"]
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]


def test_no_module_import_circles():
    assert _cycles(import_graph()) == []


def test_no_package_import_circles():
    pg: dict[str, set[str]] = defaultdict(set)
    for a, bs in import_graph().items():
        for b in bs:
            if _package(a) != _package(b) and _package(b) != "bake":
                pg[_package(a)].add(_package(b))
    assert _cycles(pg) == []


def test_only_what_runs_after_the_bake_imports_the_runner():
    """The pipeline runs the stages; the commands and the outputs (reports, HTML, files) run it.
    Nothing it runs may import it back."""
    above = {"bake.cli", "bake.sweep", "bake.watch"}
    bad = {a for a, bs in import_graph().items() if "bake.pipeline" in bs
           and a not in above and _package(a) != "bake.outputs"}
    assert bad == set()


def test_the_export_stage_is_apart_from_the_outputs():
    """bake/export/ holds the export stage; writing files, reports and previews is bake/outputs/,
    which no stage imports."""
    stage_rooms = {_package(s.entry.split(":")[0]) for s in _registry()}
    bad = {(a, b) for a, bs in import_graph().items() if _package(a) in stage_rooms - {"bake.outputs"}
           for b in bs if _package(b) == "bake.outputs"}
    assert bad == set() and "bake.outputs" not in stage_rooms


def _registry():
    from bake.stages import STAGES
    return STAGES


def test_scratch_room_depends_on_no_stage():
    """bake/scratch/ owns number text, colour numbers, TextImage, .sb3, blocks, readers and
    packers; the stages call it. It may read the data model and the BVH format's constants."""
    allowed = {"bake.scratch", "bake.errors", "bake.scene", "bake.colorspace", "bake.bvh", "bake"}
    bad = {(a, b) for a, bs in import_graph().items() if a.startswith("bake.scratch")
           for b in bs if _package(b) not in allowed}
    assert bad == set()


def test_moved_modules_are_gone():
    # (export/report.py is the export stage's report.html section now; the report writer moved to outputs/)
    assert "def section(" in (ROOT / "export/report.py").read_text()
    for old in ("export/sb3.py", "export/numbers.py", "export/check.py", "textures/colors.py",
                "textures/textimage.py", "mesh/simplify.py", "config.py", "cache.py",
                *(f"export/{m}.py" for m in ("write", "output", "html", "preview")),
                *(f"mesh/simplify_{m}.py" for m in ("error", "measure", "repair", "fit", "meshopt", "parts",
                                                    "report"))):
        assert not (ROOT / old).exists(), old
