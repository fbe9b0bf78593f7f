"""What a stage cache key hashes: the tool, config sections, files and folder listings.

The *tool fingerprint* (:func:`tool_fingerprint`) hashes the bytes of every ``bake/**/*.py`` file,
the versions of the libraries that compute results (numpy, scipy, embreex, meshoptimizer, xatlas,
...), the Python version and the machine type: a code change invalidates everything, a version
number alone would not. A stage's files are hashed by their bytes (:func:`file_digest`; a missing
one is ``"missing"`` until it appears), the folders they came from by the names of the files a
model could name in them (:func:`listing_digest`), its config section as canonical JSON
(:func:`canonical`). :func:`digest` chains such parts into a key (``session.py`` builds the chain,
``memo.py`` the keys of memos).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import sys
from pathlib import Path
from typing import Any

from .. import __version__

# folder listings that are part of a key: the files a model may name (case-insensitively)
LISTED_SUFFIXES = frozenset({".mtl", ".bin", ".png", ".jpg", ".jpeg", ".gif", ".bmp", ".tga", ".webp",
                             ".tif", ".tiff", ".ktx2", ".dds", ".obj", ".gltf", ".glb"})
# libraries whose results end up in a scene
_LIBRARIES = ("numpy", "scipy", "pillow", "embreex", "fast-simplification", "pymeshlab", "libigl",
              "meshoptimizer", "xatlas", "DracoPy", "mapbox-earcut")


def digest(*parts: Any) -> str:
    """SHA-256 (hex) of JSON values and bytes, each length-prefixed: the parts of a key."""
    h = hashlib.sha256()
    for p in parts:
        b = p if isinstance(p, bytes) else json.dumps(p, sort_keys=True, separators=(",", ":"),
                                                       ensure_ascii=False).encode("utf-8")
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def tool_fingerprint() -> str:
    """What the code that computes a scene is: the bake package's source bytes, the libraries'
    versions, Python and the machine type (computed once per process). The cache's modules call
    it as ``keys.tool_fingerprint()``, so a test that replaces it here stands for another version."""
    return fingerprint_of(Path(__file__).resolve().parents[1])


def fingerprint_of(root: Path) -> str:
    """:func:`tool_fingerprint` of the package in ``root``."""
    from importlib import metadata

    h = hashlib.sha256()
    h.update(f"scratch-bake {__version__}; python {sys.version_info[0]}.{sys.version_info[1]}; "
             f"{platform.machine()}; {sys.byteorder}\n".encode())
    for name in _LIBRARIES:
        try:
            v = metadata.version(name)
        except metadata.PackageNotFoundError:
            v = "-"
        h.update(f"{name}=={v}\n".encode())
    for p in sorted(Path(root).rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode() + b"\n")
        h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def canonical(section: Any) -> Any:
    """A config section as plain JSON data (TOML names; internal fields such as the output folder
    left out): what a stage's key hashes."""
    from ..config import to_dict

    return to_dict(section)


def file_digest(path: str | Path) -> str:
    try:
        with open(path, "rb") as f:
            return hashlib.file_digest(f, "sha256").hexdigest() if hasattr(hashlib, "file_digest") \
                else hashlib.sha256(f.read()).hexdigest()
    except FileNotFoundError:
        return "missing"
    except OSError as e:
        return f"unreadable ({e.errno})"


def listing_digest(folder: str | Path) -> str:
    """The names (as written) of the files in ``folder`` that a model could name."""
    try:
        names = sorted(n for n in os.listdir(folder) if os.path.splitext(n)[1].lower() in LISTED_SUFFIXES)
    except OSError as e:
        return f"unlistable ({e.errno})"
    return digest(names)
