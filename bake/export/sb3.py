"""Scratch projects: write .sb3 / .sprite3, validate what we write, read untrusted ones safely.

Facts this follows are in shared/docs/scratch.md, section 1: an .sb3 is a ZIP of
``project.json`` plus assets named ``<md5>.<ext>``; a .sprite3 holds ``sprite.json`` (one target)
and its assets; list values are ``["name", [items]]`` with items string/number/boolean only;
a visible list monitor stores a second copy of the list, so we write monitors hidden.

Archives are written deterministically: entries sorted, fixed timestamps, fixed compression
level, so the same lists give byte-identical files.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from ..errors import InputError

ZIP_TIME = (1980, 1, 1, 0, 0, 0)
ID_ALPHABET = "!#%()*+,-./:;=?@[]^_`{|}~ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"

# An empty backdrop and a small marker costume (SVG, bitmapResolution 1).
BACKDROP_SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" width="480" height="360" viewBox="0 0 480 360">'
                b'<rect width="480" height="360" fill="#ffffff"/></svg>')
SPRITE_SVG = (b'<svg xmlns="http://www.w3.org/2000/svg" width="2" height="2" viewBox="0 0 2 2">'
              b'<rect width="2" height="2" fill="#000000" fill-opacity="0"/></svg>')

# Limits for reading untrusted archives.
MAX_ENTRIES = 10_000
MAX_TOTAL_UNCOMPRESSED = 512 * 1024 * 1024
MAX_ENTRY_UNCOMPRESSED = 128 * 1024 * 1024
MAX_RATIO = 200.0


def stable_id(*parts: str, length: int = 20) -> str:
    """A Scratch-style 20-character id derived from names (deterministic, unlike Scratch's random ids)."""
    h = hashlib.sha256("\x00".join(parts).encode("utf-8")).digest()
    n = int.from_bytes(h, "big")
    out = []
    for _ in range(length):
        n, r = divmod(n, len(ID_ALPHABET))
        out.append(ID_ALPHABET[r])
    return "".join(out)


@dataclass(frozen=True)
class Asset:
    data: bytes
    ext: str  # svg | png | jpg | wav ...

    @property
    def md5(self) -> str:
        return hashlib.md5(self.data).hexdigest()

    @property
    def md5ext(self) -> str:
        return f"{self.md5}.{self.ext}"


@dataclass
class Costume:
    name: str
    asset: Asset
    bitmap_resolution: int = 1
    rotation_center: tuple[float, float] = (0.0, 0.0)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "bitmapResolution": self.bitmap_resolution, "dataFormat": self.asset.ext,
                "assetId": self.asset.md5, "md5ext": self.asset.md5ext,
                "rotationCenterX": self.rotation_center[0], "rotationCenterY": self.rotation_center[1]}


@dataclass
class Target:
    name: str
    is_stage: bool = False
    lists: dict[str, list] = field(default_factory=dict)  # name -> items
    variables: dict[str, Any] = field(default_factory=dict)  # name -> value
    costumes: list[Costume] = field(default_factory=list)
    blocks: dict[str, Any] = field(default_factory=dict)
    layer_order: int = 0

    def to_json(self) -> dict[str, Any]:
        costumes = self.costumes or [Costume("backdrop1" if self.is_stage else "costume1",
                                             Asset(BACKDROP_SVG if self.is_stage else SPRITE_SVG, "svg"),
                                             1, (240.0, 180.0) if self.is_stage else (1.0, 1.0))]
        t: dict[str, Any] = {
            "isStage": self.is_stage, "name": self.name,
            "variables": {stable_id(self.name, "var", k): [k, v] for k, v in self.variables.items()},
            "lists": {stable_id(self.name, "list", k): [k, v] for k, v in self.lists.items()},
            "broadcasts": {}, "blocks": self.blocks, "comments": {},
            "currentCostume": 0, "costumes": [c.to_json() for c in costumes], "sounds": [],
            "volume": 100, "layerOrder": self.layer_order,
        }
        if self.is_stage:
            t.update({"tempo": 60, "videoTransparency": 50, "videoState": "on", "textToSpeechLanguage": None})
        else:
            t.update({"visible": True, "x": 0, "y": 0, "size": 100, "direction": 90, "draggable": False,
                      "rotationStyle": "all around"})
        return t

    def assets(self) -> list[Asset]:
        if self.costumes:
            return [c.asset for c in self.costumes]
        return [Asset(BACKDROP_SVG if self.is_stage else SPRITE_SVG, "svg")]


def dumps(obj: Any) -> str:
    """Compact JSON as Scratch stores it; refuses NaN/Infinity."""
    return json.dumps(obj, ensure_ascii=False, separators=(",", ":"), allow_nan=False)


def project_json(targets: list[Target], extensions: list[str] | None = None) -> dict[str, Any]:
    return {"targets": [t.to_json() for t in targets], "monitors": [], "extensions": extensions or [],
            "meta": {"semver": "3.0.0", "vm": "5.0.300", "agent": "scratch-bake"}}


def _zip(entries: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name in sorted(entries):
            info = zipfile.ZipInfo(name, ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, entries[name], compresslevel=6)
    return buf.getvalue()


def write_sb3(targets: list[Target], extensions: list[str] | None = None) -> tuple[bytes, int]:
    """The .sb3 bytes and the size of its project.json."""
    pj = dumps(project_json(targets, extensions)).encode("utf-8")
    entries = {"project.json": pj}
    for t in targets:
        for a in t.assets():
            entries[a.md5ext] = a.data
    return _zip(entries), len(pj)


def write_sprite3(target: Target) -> bytes:
    sj = dumps(target.to_json()).encode("utf-8")
    entries = {"sprite.json": sj}
    for a in target.assets():
        entries[a.md5ext] = a.data
    return _zip(entries)


# --------------------------------------------------------------------------- validation
_HEX32 = re.compile(r"^[a-fA-F0-9]{32}$")
_MD5EXT = re.compile(r"^[a-f0-9]{32}\.[a-zA-Z]+$")
_FORMATS = {"png", "svg", "jpeg", "jpg", "bmp", "gif"}


def _check_target(t: Any, where: str, assets: dict[str, bytes] | None, problems: list[str],
                  ids: dict[str, str]) -> None:
    if not isinstance(t, dict):
        problems.append(f"{where}: not an object")
        return
    for k in ("name", "isStage", "variables", "costumes", "sounds", "blocks"):
        if k not in t:
            problems.append(f"{where}: missing '{k}'")
    for kind in ("variables", "lists"):
        for vid, val in (t.get(kind) or {}).items():
            w = f"{where}.{kind}[{vid!r}]"
            if vid in ids:
                problems.append(f"{w}: id also used by {ids[vid]}")
            ids[vid] = w
            if not isinstance(val, list) or len(val) < 2 or not isinstance(val[0], str):
                problems.append(f"{w}: expected [name, value]")
                continue
            if kind == "lists":
                items = val[1]
                if not isinstance(items, list):
                    problems.append(f"{w}: list value is not an array")
                    continue
                for i, it in enumerate(items):
                    if isinstance(it, bool) or isinstance(it, str):
                        continue
                    if isinstance(it, (int, float)) and math.isfinite(it):
                        continue
                    problems.append(f"{w} item {i + 1}: {it!r} is not a finite number, string or boolean")
                    break
    costumes = t.get("costumes")
    if not isinstance(costumes, list) or not costumes:
        problems.append(f"{where}: needs at least one costume")
        costumes = []
    for ci, c in enumerate(costumes):
        w = f"{where}.costumes[{ci}]"
        if not _HEX32.match(str(c.get("assetId", ""))):
            problems.append(f"{w}: assetId must be 32 hex digits")
        if c.get("dataFormat") not in _FORMATS:
            problems.append(f"{w}: dataFormat {c.get('dataFormat')!r} is not one of {sorted(_FORMATS)}")
        md5ext = c.get("md5ext") or f"{c.get('assetId')}.{c.get('dataFormat')}"
        if not _MD5EXT.match(md5ext):
            problems.append(f"{w}: md5ext {md5ext!r} is malformed")
        if c.get("dataFormat") != "svg" and c.get("bitmapResolution") not in (1, 2):
            problems.append(f"{w}: bitmapResolution should be 2 for bitmaps")
        if assets is not None:
            data = assets.get(md5ext)
            if data is None:
                problems.append(f"{w}: asset {md5ext} is not in the archive")
            elif hashlib.md5(data).hexdigest() != md5ext.split(".")[0]:
                problems.append(f"{w}: asset {md5ext} has md5 {hashlib.md5(data).hexdigest()}")
            elif len(data) >= 10_000_000:
                problems.append(f"{w}: asset {md5ext} is {len(data)} bytes (limit: under 10 MB)")


def validate_project(project: Any, assets: dict[str, bytes] | None = None) -> list[str]:
    """Every problem found in a project.json (not just the first)."""
    problems: list[str] = []
    if not isinstance(project, dict):
        return ["project.json: not an object"]
    meta = project.get("meta")
    if not isinstance(meta, dict) or not re.match(r"^3\.[0-9]+\.[0-9]+$", str(meta.get("semver", ""))):
        problems.append("meta.semver: missing or not 3.x.y")
    targets = project.get("targets")
    if not isinstance(targets, list) or not targets:
        return problems + ["targets: missing or empty"]
    if not (isinstance(targets[0], dict) and targets[0].get("isStage") is True):
        problems.append("targets[0]: must be the stage")
    if sum(1 for t in targets if isinstance(t, dict) and t.get("isStage")) != 1:
        problems.append("targets: exactly one stage expected")
    ids: dict[str, str] = {}
    for i, t in enumerate(targets):
        _check_target(t, f"targets[{i}]", assets, problems, ids)
    for m in project.get("monitors", []) or []:
        if m.get("mode") == "list" and m.get("visible"):
            problems.append(f"monitors[{m.get('id')}]: a visible list monitor stores a second copy of the list")
    return problems


def validate_sprite(sprite: Any, assets: dict[str, bytes] | None = None) -> list[str]:
    problems: list[str] = []
    _check_target(sprite, "sprite", assets, problems, {})
    if isinstance(sprite, dict) and sprite.get("isStage"):
        problems.append("sprite: isStage must be false")
    return problems


# --------------------------------------------------------------------------- reading
def read_archive(path: Path, *, max_entries: int = MAX_ENTRIES, max_total: int = MAX_TOTAL_UNCOMPRESSED,
                 max_entry: int = MAX_ENTRY_UNCOMPRESSED, max_ratio: float = MAX_RATIO) -> dict[str, bytes]:
    """Read an untrusted .sb3/.sprite3: refuse entries outside the root, too many entries, too much
    uncompressed data or a suspicious compression ratio, and say which limit was hit."""
    path = Path(path)
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as e:
        raise InputError(f"not a Scratch project archive (zip): {e}", path=path) from None
    with zf:
        infos = zf.infolist()
        if len(infos) > max_entries:
            raise InputError(f"archive has {len(infos)} entries (limit {max_entries})", path=path)
        total = 0
        for info in infos:
            name = info.filename
            pp = PurePosixPath(name)
            if name.startswith(("/", "\\")) or ".." in pp.parts or ":" in name or "\\" in name:
                raise InputError(f"archive entry {name!r} points outside the archive root", path=path)
            if info.file_size > max_entry:
                raise InputError(f"archive entry {name!r} is {info.file_size} bytes uncompressed "
                                 f"(limit {max_entry})", path=path)
            total += info.file_size
            if total > max_total:
                raise InputError(f"archive uncompresses to more than {max_total} bytes", path=path)
            if info.compress_size and info.file_size / info.compress_size > max_ratio and info.file_size > 1 << 20:
                raise InputError(f"archive entry {name!r} has compression ratio "
                                 f"{info.file_size / info.compress_size:.0f}:1 (limit {max_ratio:.0f}:1)",
                                 path=path)
        out: dict[str, bytes] = {}
        for info in infos:
            if info.is_dir():
                continue
            with zf.open(info) as f:
                data = f.read(info.file_size + 1)
            if len(data) > info.file_size:  # the header lied about the size
                raise InputError(f"archive entry {info.filename!r} is larger than its header says", path=path)
            out[info.filename] = data
    return out


def load_project(path: Path) -> tuple[dict[str, Any], dict[str, bytes]]:
    """project.json (from the root or one sub-folder, as Scratch accepts) and the other entries."""
    entries = read_archive(path)
    names = [n for n in entries if re.match(r"^([^/]*/)?project\.json$", n)]
    if not names:
        raise InputError("archive has no project.json", path=path)
    prefix = names[0][: -len("project.json")]
    try:
        project = json.loads(entries[names[0]].decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise InputError(f"project.json is not valid JSON: {e}", path=path) from None
    assets = {n[len(prefix):]: d for n, d in entries.items() if n.startswith(prefix) and n != names[0]}
    return project, assets
