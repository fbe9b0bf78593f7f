"""The import stage: a model file (OBJ + MTL, glTF, GLB) into a new :class:`~bake.scene.Scene`."""

from __future__ import annotations

from pathlib import Path

from ..config import Config, ImportJob
from ..errors import InputError
from ..record import StageRecord
from ..scene import Scene, coordinate_problem

FORMATS = {".obj": "obj", ".gltf": "gltf", ".glb": "glb"}


def job(cfg: Config) -> ImportJob:
    """The stage's section: the model's path (relative to the config's folder) and how to read it."""
    p = Path(cfg.input.path)
    if not p.is_absolute():
        p = cfg.base_dir / p
    return ImportJob(path=p, format=cfg.input.format, strict=cfg.import_.strict, scene=cfg.import_.scene)


def detect_format(job: ImportJob) -> str:
    if job.format != "auto":
        return job.format
    fmt = FORMATS.get(job.path.suffix.lower())
    if fmt is None:
        raise InputError(f"unknown model format '{job.path.suffix}' (expected .obj, .gltf or .glb; "
                         f"or set input.format)", path=job.path, unwatchable=True)
    return fmt


def stage(_: Scene, job: ImportJob) -> tuple[Scene, StageRecord]:
    """The import stage: read ``job.path`` into a new scene."""
    if not job.path.exists():
        raise InputError("file not found", path=job.path, unwatchable=True)
    if job.path.is_dir():
        raise InputError("is a folder, expected a model file", path=job.path, unwatchable=True)
    fmt = detect_format(job)
    if fmt == "obj":
        from .obj import load
    else:
        from .gltf import load
    scene, rec = load(job)
    problem = coordinate_problem(scene)
    if problem is not None:
        raise InputError(problem, path=scene.source.path)
    return scene, rec
