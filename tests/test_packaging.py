"""pyproject.toml installs without setuptools' deprecation noise (issue 17, item 8)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"


def test_license_is_an_spdx_string_and_the_build_backend_reads_it():
    data = tomllib.loads(PYPROJECT.read_text("utf-8"))
    lic = data["project"]["license"]
    # a table ({text = ...}) makes setuptools >= 77 warn "project.license as a TOML table is
    # deprecated" on every install; PEP 639 wants an SPDX expression
    assert isinstance(lic, str) and re.fullmatch(r"[A-Za-z0-9.+-]+( (AND|OR|WITH) [A-Za-z0-9.+-]+)*", lic), lic
    # License :: classifiers next to an SPDX expression are an error for setuptools >= 77
    assert not [c for c in data["project"].get("classifiers", []) if c.startswith("License ::")]
    # setuptools reads the string form from 77.0.0 on: the build must not get an older one
    req = [r for r in data["build-system"]["requires"] if r.startswith("setuptools")]
    m = re.fullmatch(r"setuptools>=(\d+)(\.\d+)*", req[0].replace(" ", "")) if req else None
    assert m and int(m.group(1)) >= 77, req


def test_runtime_dependencies_are_what_bake_imports():
    """trimesh and pygltflib were runtime dependencies that only the tests import (issue 37): they
    belong to the test extras, and no module of bake/ imports them."""
    import ast

    data = tomllib.loads(PYPROJECT.read_text())
    runtime = {d.split(">")[0].split("=")[0].split("<")[0].split(";")[0].strip().lower()
               for d in data["project"]["dependencies"]}
    dev = " ".join(data["project"]["optional-dependencies"]["dev"])
    assert not {"trimesh", "pygltflib"} & runtime
    assert "trimesh" in dev and "pygltflib" in dev
    imported = set()
    for path in (PYPROJECT.parent / "bake").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text("utf-8"))):
            if isinstance(node, ast.Import):
                imported |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                imported.add(node.module.split(".")[0])
    assert not {"trimesh", "pygltflib"} & imported
