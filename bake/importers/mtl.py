"""The OBJ's material libraries: finding the ``mtllib`` and ``map_Kd`` files (inside the OBJ's
folder only) and reading MTL files (small: line by line). The rules (which statements are read,
how names and options are taken) are listed in :mod:`bake.importers.obj`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..record import StageRecord
from ..scene import Material
from .obj_lines import _BOM, _decode, _lines_list

# MTL statements we read or knowingly ignore
_MTL_KNOWN = {"newmtl", "kd", "d", "tr", "map_kd", "ka", "ks", "ke", "ns", "ni", "illum", "tf",
              "sharpness", "map_ka", "map_ks", "map_ns", "map_d", "map_bump", "bump", "disp",
              "decal", "refl", "norm", "pr", "pm", "ps", "pc", "pcr", "aniso", "anisor", "map_pr",
              "map_pm", "map_ps", "map_ke", "map_refl", "map_norm"}
# map_* options and how many arguments they take (-o/-s/-t take 1 to 3 numbers)
_MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-boost": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3,
                "-texres": 1, "-clamp": 1, "-bm": 1, "-imfchan": 1, "-type": 1, "-cc": 1}
_VAR_OPTIONS = {"-o", "-s", "-t"}


def materials_from(obj_path: Path, mtllibs: list[tuple[int, str]], rec: StageRecord,
                   files: list[Path], missing: list[Path]) -> dict[str, Material]:
    """The materials of the ``mtllib`` lines (line, file names) of the OBJ at ``obj_path``, by
    name (the first definition wins). Each MTL file read is appended to ``files``; a file not
    found, to ``missing`` (where it was looked for)."""
    base = Path(os.path.abspath(obj_path)).parent
    mats: dict[str, Material] = {}
    seen: set[Path] = set()
    for ln, text in mtllibs:
        if not text:
            rec.warn(f"{obj_path}:{ln}: 'mtllib' without a file name")
            continue
        whole: list[Path] = []
        found = _find_file(base, text, outside=whole)
        cands = [(text, found, whole)] if found or len(text.split()) == 1 else []
        for n in ([] if cands else text.split()):
            outside: list[Path] = []
            cands.append((n, _find_file(base, n, outside=outside), outside or whole))
        for name, p, outside in cands:
            if p is None:
                if not outside:
                    missing.extend(_looked_for(base, name))
                why = (f"outside the model's folder ({outside[0]}), not read" if outside else
                       "not found")
                rec.warn(f"material library {why}: '{name}' ({obj_path}:{ln}); "
                         f"default colours used")
                continue
            if p in seen:
                continue
            seen.add(p)
            files.append(p)
            for nm, m in _parse_mtl(p, rec, root=base, missing=missing).items():
                if nm in mats:
                    rec.warn(f"material '{nm}' is defined again in {p}; the first "
                             f"definition is kept")
                else:
                    mats[nm] = m
    return mats


def _is_file(p: Path) -> bool:
    """``Path.is_file`` that is False, not an exception, for names the OS refuses (too long...)."""
    try:
        return p.is_file()
    except (OSError, ValueError):
        return False


def _inside(path: Path, root: Path) -> bool:
    """``path`` (symbolic links followed) lies in ``root`` or below it."""
    try:
        return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(root))
    except (OSError, ValueError):
        return False


def _find_file(base: Path, name: str, root: Path | None = None,
               outside: list[Path] | None = None) -> Path | None:
    """Find ``name`` (relative to ``base``, backslashes accepted): as written, then its base name
    next to ``base``, then a case-insensitive match there. Only files inside ``root`` (the OBJ's
    folder; default ``base``) count, as for glTF URIs: a path that leaves it (``..``, absolute, a
    symbolic link pointing out) is not read, and is appended to ``outside`` when it exists."""
    name = name.strip().strip('"').replace("\\", "/")
    if not name:
        return None
    root = base if root is None else root
    p = Path(name)
    cands = [p if p.is_absolute() else base / p, base / p.name]
    for c in cands:
        if _is_file(c):
            if _inside(c, root):
                return Path(os.path.normpath(c))
            if outside is not None:
                outside.append(Path(os.path.normpath(c)))
    low = p.name.lower()
    try:
        for entry in sorted(os.listdir(base)):
            if entry.lower() == low and _is_file(base / entry) and _inside(base / entry, root):
                return Path(os.path.normpath(base / entry))
    except OSError:
        pass
    return None


def _looked_for(base: Path, name: str) -> list[Path]:
    """Where :func:`_find_file` looked for ``name``: as written, and its base name next to ``base``."""
    p = Path(name.strip().strip('"').replace("\\", "/"))
    if not p.name:
        return []
    return list(dict.fromkeys([Path(os.path.normpath(p if p.is_absolute() else base / p)), base / p.name]))


def _parse_mtl(path: Path, rec: StageRecord, root: Path | None = None,
               missing: list[Path] | None = None) -> dict[str, Material]:
    """Read one MTL file: newmtl, Kd, d, Tr, map_Kd (the rules are in :mod:`bake.importers.obj`).
    Textures must lie in ``root`` (the OBJ's folder; default the MTL's). A texture not found is
    appended to ``missing`` (where it was looked for)."""
    try:
        raw = path.read_bytes()
    except OSError as e:
        rec.warn(f"cannot read material library {path}: {e.strerror or e}")
        return {}
    if b"\x00" in raw:
        rec.warn(f"material library {path} is not a text file; default colours used")
        return {}
    if raw.startswith(_BOM):
        raw = raw[3:]
    order, latin1 = _statements(raw, path, rec)
    out: dict[str, Material] = {}
    for m in order:
        name = m["name"]
        if name in out:
            rec.warn(f"{path}:{m['line']}: material '{name}' is defined twice; the first is kept")
            continue
        out[name] = _material(m, path, rec, root, missing)
    if latin1:
        rec.warn(f"names on {len(latin1)} line(s) of {path} are not UTF-8 and were decoded as "
                 f"Latin-1 (lines {_lines_list(np.array(latin1))})")
    return out


def _statements(raw: bytes, path: Path, rec: StageRecord) -> tuple[list[dict], list[int]]:
    """The statements of an MTL file that matter, per ``newmtl`` in file order: its name and line,
    and ``kd``, ``d``, ``tr``, ``map_kd`` as (value, line); and the lines whose names are not
    UTF-8. A malformed statement is a warning naming its line and is left out."""
    cur: dict | None = None
    latin1: list[int] = []
    order: list[dict] = []

    def bad(ln: int, msg: str) -> None:
        rec.warn(f"{path}:{ln}: {msg}; statement ignored")

    def nums(ln: int, toks: list[str], kw: str) -> list[float] | None:
        try:
            v = [float(x) for x in toks]
        except ValueError:
            bad(ln, f"malformed number in '{kw}'")
            return None
        if not all(np.isfinite(v)):
            bad(ln, f"non-finite value in '{kw}'")
            return None
        return v

    text_lines = raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")
    for i, bline in enumerate(text_lines, 1):
        line, fb = _decode(bline)
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split(None, 1)
        kw = parts[0].lower()
        rest = parts[1].strip() if len(parts) > 1 else ""
        if kw not in ("newmtl", "map_kd") and "#" in rest:
            rest = rest.split("#", 1)[0].strip()
        if kw == "newmtl":
            if fb:
                latin1.append(i)
            if not rest:
                bad(i, "'newmtl' without a name")
                cur = None
                continue
            cur = {"name": rest, "line": i}
            order.append(cur)
            continue
        if kw not in _MTL_KNOWN:
            continue
        if cur is None:
            if kw in ("kd", "d", "tr", "map_kd"):
                bad(i, f"'{parts[0]}' before any 'newmtl'")
            continue
        toks = rest.split()
        if kw == "kd":
            if toks and toks[0].lower() in ("spectral", "xyz"):
                bad(i, f"'Kd {toks[0]}' colours are not supported")
                continue
            v = nums(i, toks, "Kd")
            if v is None:
                continue
            if len(v) == 1:
                v = v * 3
            if len(v) != 3:
                bad(i, f"'Kd' needs 1 or 3 numbers, got {len(v)}")
                continue
            cur["kd"] = (v, i)
        elif kw in ("d", "tr"):
            toks = [x for x in toks if x.lower() != "-halo"]
            v = nums(i, toks, parts[0])
            if v is None:
                continue
            if len(v) != 1:
                bad(i, f"'{parts[0]}' needs 1 number, got {len(v)}")
                continue
            cur[kw] = (v[0], i)
        elif kw == "map_kd":
            if fb:
                latin1.append(i)
            cur["map_kd"] = (_map_file_name(rest), i)
    return order, latin1


def _material(m: dict, path: Path, rec: StageRecord, root: Path | None,
              missing: list[Path] | None) -> Material:
    """The material of one ``newmtl`` (from :func:`_statements`): Kd and alpha clipped to [0, 1],
    ``Tr 1`` read as opaque, the ``map_Kd`` texture found (warnings name the MTL line)."""
    name, base = m["name"], path.parent
    r, g, b = 0.8, 0.8, 0.8
    if "kd" in m:
        v, ln = m["kd"]
        if min(v) < 0 or max(v) > 1:
            rec.warn(f"{path}:{ln}: Kd of '{name}' outside [0, 1] was clipped")
        r, g, b = (float(np.clip(x, 0.0, 1.0)) for x in v)
    a = 1.0
    if "d" in m:
        a, ln = m["d"]
    elif "tr" in m:
        tr, ln = m["tr"]
        if tr == 1.0:
            rec.warn(f"{path}:{ln}: 'Tr 1' in '{name}' read as opaque (MeshLab and others write Tr "
                     f"as opacity; by the MTL spec it would make the material invisible)")
            a = 1.0
        else:
            a = 1.0 - tr
    if not 0.0 <= a <= 1.0:
        rec.warn(f"{path}:{ln}: alpha of '{name}' outside [0, 1] was clipped")
        a = float(np.clip(a, 0.0, 1.0))
    tex = None
    if "map_kd" in m:
        fname, ln = m["map_kd"]
        if not fname:
            rec.warn(f"{path}:{ln}: 'map_Kd' without a file name in '{name}'")
        else:
            outside: list[Path] = []
            tex = _find_file(base, fname, root=root or base, outside=outside)
            if tex is None and not outside and missing is not None:
                missing.extend(_looked_for(base, fname))
            if tex is None:
                why = f"outside the model's folder ({outside[0]}), not read" if outside else "not found"
                rec.warn(f"texture {why}: '{fname}' (material '{name}', {path}:{ln}); "
                         f"material colour used")
    return Material(name=name, color=(r, g, b, float(a)), texture=tex)


def _map_file_name(rest: str) -> str:
    """The file name of a ``map_*`` statement: options skipped, spaces inside the name kept."""
    toks = list(re.finditer(r"\S+", rest))
    i = 0
    while i < len(toks):
        opt = toks[i].group().lower()
        if not opt.startswith("-") or _is_number(opt):
            break
        nargs = _MAP_OPTIONS.get(opt, 0)
        i += 1
        if opt in _VAR_OPTIONS:
            taken = 0
            while taken < nargs and i < len(toks) - 1 and _is_number(toks[i].group()):
                i += 1
                taken += 1
        else:
            i += min(nargs, max(len(toks) - 1 - i, 0))
    if i >= len(toks):
        return ""
    name = rest[toks[i].start():].strip()
    if len(name) >= 2 and name[0] == name[-1] == '"':
        name = name[1:-1]
    return name


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
