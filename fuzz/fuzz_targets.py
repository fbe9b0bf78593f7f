"""The reader entry points the fuzzers drive, shared by the atheris harnesses (``fuzz/fuzz_*.py``)
and the regression test (``tests/reliability/test_rel_fuzz_regressions.py``).

Each target takes the raw bytes of one input and either returns a result or raises
:class:`bake.errors.BakeError`. Anything else (another exception, a scene that fails
``Scene.validate()``, NaN in a result) is a bug. Inputs are plain files, so a corpus entry
can be opened in an editor:

* ``obj``: the bytes are an OBJ file. If they contain a line ``#MTL`` the rest (after that line)
  is written to ``m.mtl`` beside it (so ``mtllib m.mtl`` in the OBJ part reads it) -- one input
  fuzzes both the OBJ and the MTL reader.
* ``gltf``: the bytes are a ``.gltf`` (JSON) file, or a ``.glb`` when they start with ``glTF``.
* ``sb3``: the bytes are an ``.sb3`` archive, read the way ``export.into`` reads the author's
  project (``read_archive`` with its limits, ``load_project``, then ``merge_into`` a small list).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

MTL_MARK = b"\n#MTL\n"

_WORKDIR: Path | None = None


def _workdir() -> Path:
    """One private folder per process, reused by every input (writes are cheap; mkdtemp is not)."""
    global _WORKDIR
    if _WORKDIR is None:
        _WORKDIR = Path(tempfile.mkdtemp(prefix="bake-fuzz-"))
    return _WORKDIR


def _clear(folder: Path) -> None:
    for p in folder.iterdir():
        if p.is_file():
            p.unlink()


def _check_scene(scene: Any) -> None:
    """What a successful import must hand on: a consistent scene with finite numbers."""
    scene.validate()
    for m in scene.materials:
        assert all(np.isfinite(c) and 0.0 <= c <= 1.0 for c in m.color), f"material colour {m.color}"
    for lt in scene.lights:
        for v in (lt.position, lt.direction):
            assert v is None or all(np.isfinite(v)), f"light {lt}"


def read_obj(data: bytes, folder: Path | None = None, strict: bool = True) -> Any:
    from bake.config import ImportJob
    from bake.importers import obj

    folder = folder or _workdir()
    _clear(folder)
    obj_part, mark, mtl_part = data.partition(MTL_MARK)
    (folder / "model.obj").write_bytes(obj_part)
    if mark:
        (folder / "m.mtl").write_bytes(mtl_part)
    scene, _ = obj.load(ImportJob(path=folder / "model.obj", strict=strict))
    _check_scene(scene)
    return scene


def read_gltf(data: bytes, folder: Path | None = None, strict: bool = True) -> Any:
    from bake.config import ImportJob
    from bake.importers import gltf

    folder = folder or _workdir()
    _clear(folder)
    name = "model.glb" if data[:4] == b"glTF" else "model.gltf"
    (folder / name).write_bytes(data)
    scene, _ = gltf.load(ImportJob(path=folder / name, strict=strict))
    _check_scene(scene)
    return scene


def read_sb3(data: bytes, folder: Path | None = None, strict: bool = True) -> Any:
    from bake.scratch import sb3

    entries = sb3.read_archive(data)
    assert all(isinstance(k, str) and isinstance(v, bytes) for k, v in entries.items())
    project, assets = sb3.load_project(data)
    assert isinstance(project, dict) and isinstance(project.get("targets"), list)
    # the engine check export.into runs on the author's project (bake/scratch/engine.py)
    from bake.scratch import engine
    found = engine.check(project, "Stage", {"fuzz verts": 3}, reader_added=False)
    assert set(found["lists"]) == {"fuzz verts"} and all(isinstance(w, str) for w in found["warnings"])
    merged = sb3.merge_into(data, "Stage", {"fuzz verts": [1, 2.5, -3]})
    # what merge_into returns is itself a project bake can read back, with the list in it
    project2, _ = sb3.load_project(merged)
    stage = next(t for t in project2["targets"] if isinstance(t, dict) and t.get("isStage"))
    assert any(v[0] == "fuzz verts" for v in stage.get("lists", {}).values())
    return project2


TARGETS: dict[str, Callable[..., Any]] = {"obj": read_obj, "gltf": read_gltf, "sb3": read_sb3}

# Findings reported but not yet fixed (their owners' modules are in progress): exception type name,
# text in its message, and the corpus file that reproduces it. ``make fuzz`` steps over them so a
# session is not stopped by what is already known; the regression test marks those files xfail
# (strict), so it fails once the bug is fixed and the entry is due for removal.
# (The three .sb3 crashes fuzzing found — zlib.error, NotImplementedError, IndexError escaping
# read_archive — are fixed; their inputs stay in fuzz/corpus/sb3 as regressions.)
KNOWN_BUGS: dict[str, list[tuple[str, str, str]]] = {}


def is_known(target: str, exc: BaseException) -> bool:
    return any(type(exc).__name__ == name and text in str(exc) for name, text, _ in KNOWN_BUGS.get(target, []))


def known_files(target: str) -> set[str]:
    return {f for _, _, f in KNOWN_BUGS.get(target, [])}


def corpus_dir(target: str) -> Path:
    return Path(__file__).resolve().parent / "corpus" / target


def run_one(target: str, data: bytes) -> str:
    """Feed one input; return "ok" or "error: <message>" for a BakeError; raise anything else."""
    from bake.errors import BakeError

    try:
        TARGETS[target](data)
    except BakeError as e:
        msg = str(e)
        assert msg and "\n" not in msg, f"error message is not one line: {msg!r}"
        return f"error: {msg}"
    return "ok"


if __name__ == "__main__":  # feed files by hand: python fuzz/fuzz_targets.py obj file...
    import sys

    for f in sys.argv[2:]:
        print(f, run_one(sys.argv[1], Path(f).read_bytes()), sep=": ")
    os._exit(0)
