"""Helpers for the reliability tests: running the real CLI, checking one-line errors, writing
models (OBJ with exact round-trip numbers, glTF/GLB built from numpy arrays) and the similarity
transforms of the stability tests. Independent of the code under test except for ``bake.cli``."""

from __future__ import annotations

import base64
import json
import os
import re
import struct
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bake import cli

REPO = Path(__file__).resolve().parents[2]
TRACEBACK = "Traceback (most recent call last)"


# --------------------------------------------------------------------------- running the CLI
def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    """``bake.cli.main`` in this process; returns (exit status, stdout, stderr)."""
    capsys.readouterr()
    code = cli.main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def run_subprocess(argv: list[str], cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """``python -m bake.cli`` in a fresh interpreter (what a user's shell runs)."""
    env = dict(os.environ)
    env.pop("PYTHONWARNINGS", None)
    return subprocess.run([sys.executable, "-m", "bake.cli", *map(str, argv)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def assert_clean_error(code: int, err: str, *, status: int, file: str | None, place: str | None) -> str:
    """The error contract: the documented status, exactly one line on stderr, ``bake: error:``,
    the file's name and the place (a regex: line, key or JSON path) in it, no traceback."""
    assert TRACEBACK not in err, err
    lines = err.strip("\n").splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}:\n{err}"
    line = lines[0]
    assert code == status, f"exit {code}, expected {status}: {line}"
    assert line.startswith("bake: error: "), line
    if file is not None:
        assert file in line, f"{file!r} not named in: {line}"
    if place is not None:
        assert re.search(place, line), f"place /{place}/ not in: {line}"
    return line


# --------------------------------------------------------------------------- writing models
def fmt(x: float) -> str:
    """Shortest text that reads back as exactly ``x`` (repr of a float64)."""
    return repr(float(x))


def write_obj(path: Path, positions, polygons, *, materials: list[str] | None = None,
              poly_material=None, mtllib: str | None = None) -> Path:
    """An OBJ with ``v`` lines that round-trip exactly and one ``f`` line per polygon."""
    lines = [f"mtllib {mtllib}"] if mtllib else []
    lines += ["v " + " ".join(fmt(c) for c in p) for p in np.asarray(positions, np.float64)]
    current = None
    for i, poly in enumerate(polygons):
        if materials is not None and poly_material is not None:
            m = materials[int(poly_material[i])]
            if m != current:
                lines.append(f"usemtl {m}")
                current = m
        lines.append("f " + " ".join(str(int(k) + 1) for k in poly))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def gltf_triangles(positions, triangles, *, colors=None, uvs=None) -> tuple[dict, bytes]:
    """A glTF document (one mesh, one node) and its binary buffer for float32 positions,
    uint32 indices and optional float32 COLOR_0 (VEC4) / TEXCOORD_0."""
    pos = np.asarray(positions, np.float32).reshape(-1, 3)
    idx = np.asarray(triangles, np.uint32).reshape(-1)
    parts = [pos.tobytes(), idx.tobytes()]
    acc = [{"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3",
            "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
           {"bufferView": 1, "componentType": 5125, "count": len(idx), "type": "SCALAR"}]
    attrs = {"POSITION": 0}
    if colors is not None:
        parts.append(np.asarray(colors, np.float32).reshape(-1, 4).tobytes())
        acc.append({"bufferView": len(parts) - 1, "componentType": 5126, "count": len(pos), "type": "VEC4"})
        attrs["COLOR_0"] = len(acc) - 1
    if uvs is not None:
        parts.append(np.asarray(uvs, np.float32).reshape(-1, 2).tobytes())
        acc.append({"bufferView": len(parts) - 1, "componentType": 5126, "count": len(pos), "type": "VEC2"})
        attrs["TEXCOORD_0"] = len(acc) - 1
    views, buf = [], b""
    for p in parts:
        views.append({"buffer": 0, "byteOffset": len(buf), "byteLength": len(p)})
        buf += p + b"\0" * (-len(p) % 4)
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": attrs, "indices": 1}]}], "accessors": acc,
           "bufferViews": views, "buffers": [{"byteLength": len(buf)}]}
    return doc, buf


def write_gltf(path: Path, doc: dict, buf: bytes, *, embed: bool = True, bin_name: str | None = None) -> Path:
    doc = json.loads(json.dumps(doc))
    if embed:
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
    elif bin_name:
        doc["buffers"][0]["uri"] = bin_name
        (path.parent / bin_name).write_bytes(buf)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc))
    return path


def glb_bytes(doc: dict, buf: bytes) -> bytes:
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    buf = buf + b"\0" * (-len(buf) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(buf), 0x004E4942) + buf
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


# --------------------------------------------------------------------------- similarity maps
@dataclass(frozen=True)
class Similarity:
    """``p -> s R p + t`` (R a rotation, s > 0)."""

    name: str
    s: float = 1.0
    R: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    t: tuple = (0.0, 0.0, 0.0)

    @property
    def Rm(self) -> np.ndarray:
        return np.array(self.R, np.float64)

    def apply(self, p: np.ndarray) -> np.ndarray:
        return self.s * (np.asarray(p, np.float64) @ self.Rm.T) + np.array(self.t)

    def inverse(self, p: np.ndarray) -> np.ndarray:
        return ((np.asarray(p, np.float64) - np.array(self.t)) / self.s) @ self.Rm

    def direction(self, d: np.ndarray) -> np.ndarray:
        return np.asarray(d, np.float64) @ self.Rm.T


def rotation(seed: int) -> np.ndarray:
    """A random proper rotation (QR of a Gaussian matrix, sign-fixed), deterministic per seed."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def similarities() -> list[Similarity]:
    """The maps the issue names: translation by 1e5, scale by 1e-3 and 1e3, a rotation; and all
    four at once (a 1e-3 model 1e5 away is the hard case: ~8 significant digits are left)."""
    R = tuple(map(tuple, rotation(7)))
    return [
        Similarity("translate_1e5", t=(1e5, -1e5, 0.5e5)),
        Similarity("scale_1e-3", s=1e-3),
        Similarity("scale_1e3", s=1e3),
        Similarity("rotate", R=R),
        Similarity("all_at_once", s=1e-3, R=R, t=(1e5, 1e5, -1e5)),
    ]
