"""Scratch projects: write .sb3 / .sprite3, validate what we write, read untrusted ones safely,
and bake lists into an author's project.

Facts this follows are in shared/docs/scratch.md, section 1: an .sb3 is a ZIP of
``project.json`` plus assets named ``<md5>.<ext>``; a .sprite3 holds ``sprite.json`` (one target)
and its assets; list values are ``["name", [items]]`` with items string/number/boolean only;
a visible list monitor stores a second copy of the list, so we write monitors hidden.

* :func:`write_sb3` / :func:`write_sprite3`: from :class:`Target` objects (lists, variables,
  costumes, blocks, e.g. from ``bake.scratch.blocks``); ``extensions`` follow the blocks.
* :func:`validate_project` / :func:`validate_sprite`: every problem, not just the first.
* :func:`read_archive`, :func:`load_project`, :func:`load_sprite`: untrusted input, with limits
  on entries, sizes and compression ratio, and no entry outside the archive root.
* :func:`merge_into`: a new .sb3 with our lists (and costumes, and extra sprites) put into an
  existing project; the input is only read.
* :func:`archive_sizes`: the real project.json and asset sizes of a written archive.

Archives are written deterministically: entries sorted, fixed timestamps, fixed compression
level, so the same lists give byte-identical files.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import struct
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Sequence

from ..errors import InputError
from .limits import ASSET_LIMIT, PROJECT_JSON_LIMIT

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


def data_ids(target: str, variables: Sequence[str], lists: Sequence[str], *, length: int = 20,
             taken: Sequence[str] = ()) -> tuple[dict[str, str], dict[str, str]]:
    """The ids of a target's variables and lists, derived from the names (:func:`stable_id`) and
    unique within the target: Scratch keeps variables and lists in one table keyed by id, so a
    short id that collides with one already given is derived again with a salt. ``taken``: ids
    of another target to keep clear of too (a sprite's lookup falls back to the stage's ids)."""
    taken = set(taken)

    def one(kind: str, name: str) -> str:
        vid, salt = stable_id(target, kind, name, length=length), 0
        while vid in taken:
            salt += 1
            vid = stable_id(target, kind, name, str(salt), length=length)
        taken.add(vid)
        return vid

    var_ids = {n: one("var", n) for n in variables}
    return var_ids, {n: one("list", n) for n in lists}


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
    # only what the loaders need (a lighter project, issue 41): the name, the asset and its
    # format. scratch-parser requires no more; scratch-vm and TurboWarp derive md5ext from the
    # asset id and format, take a bitmap resolution of 1, and centre an SVG without a rotation
    # centre on its view box (the alphabet's costumes are empty and never shown)
    minimal: bool = False

    def to_json(self) -> dict[str, Any]:
        if self.minimal:
            return {"name": self.name, "assetId": self.asset.md5, "dataFormat": self.asset.ext}
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
    visible: bool = True
    current_costume: int = 0
    id_length: int = 20  # characters of the variable and list ids (derived from the names)
    comments: dict[str, Any] = field(default_factory=dict)  # workspace comments (id -> comment JSON)

    def to_json(self) -> dict[str, Any]:
        costumes = self.costumes or [Costume("backdrop1" if self.is_stage else "costume1",
                                             Asset(BACKDROP_SVG if self.is_stage else SPRITE_SVG, "svg"),
                                             1, (240.0, 180.0) if self.is_stage else (1.0, 1.0))]
        var_ids, list_ids = data_ids(self.name, list(self.variables), list(self.lists), length=self.id_length)
        t: dict[str, Any] = {
            "isStage": self.is_stage, "name": self.name,
            "variables": {var_ids[k]: [k, v] for k, v in self.variables.items()},
            "lists": {list_ids[k]: [k, v] for k, v in self.lists.items()},
            "broadcasts": {}, "blocks": self.blocks, "comments": dict(self.comments),
            "currentCostume": self.current_costume, "costumes": [c.to_json() for c in costumes], "sounds": [],
            "volume": 100, "layerOrder": self.layer_order,
        }
        if self.is_stage:
            t.update({"tempo": 60, "videoTransparency": 50, "videoState": "on", "textToSpeechLanguage": None})
        else:
            t.update({"visible": self.visible, "x": 0, "y": 0, "size": 100, "direction": 90, "draggable": False,
                      "rotationStyle": "all around"})
        return t

    def assets(self) -> list[Asset]:
        if self.costumes:
            seen: dict[str, Asset] = {}
            for c in self.costumes:
                seen.setdefault(c.asset.md5ext, c.asset)
            return list(seen.values())
        return [Asset(BACKDROP_SVG if self.is_stage else SPRITE_SVG, "svg")]


#: TurboWarp's project settings live in a workspace comment of the stage whose text has a line
#: ending in this marker, the settings' JSON before it (TurboWarp's scratch-vm,
#: ``Runtime.parseProjectOptions``, applies it when it loads the project; Scratch shows a comment)
TW_CONFIG_MARKER = " // _twconfig_"
TW_CONFIG_COMMENT_ID = "twconfig"


def turbowarp_settings_comment(settings: dict[str, Any]) -> dict[str, Any]:
    """The stage comment that stores ``settings`` (e.g. ``{"runtimeOptions": {"fencing":
    False}}``: only the keys to change; TurboWarp keeps its defaults for the rest) as TurboWarp's
    project settings."""
    text = ("TurboWarp settings, written by scratch-bake (export.turbowarp_fencing). TurboWarp applies "
            "the last line when it loads the project; Scratch ignores it. Delete this comment to go "
            "back to TurboWarp's defaults.\n"
            + json.dumps(settings, separators=(",", ":"), sort_keys=True, allow_nan=False) + TW_CONFIG_MARKER)
    return {"blockId": None, "x": 0, "y": 0, "width": 350, "height": 170, "minimized": False, "text": text}


def turbowarp_settings(comments: dict[str, Any]) -> dict[str, Any] | None:
    """The TurboWarp settings a target's comments store (parsed the way TurboWarp parses them:
    the first line ending in the marker), or None."""
    for c in comments.values():
        for line in str((c or {}).get("text", "")).split("\n"):
            if line.endswith(TW_CONFIG_MARKER):
                try:
                    out = json.loads(line[:-len(TW_CONFIG_MARKER)])
                except ValueError:
                    return None
                return out if isinstance(out, dict) else None
    return None


def dumps(obj: Any) -> str:
    """Compact JSON as Scratch stores it; refuses NaN/Infinity."""
    return json.dumps(obj, ensure_ascii=False, separators=(",", ":"), allow_nan=False)


# Opcode prefixes of the extensions the VM loads from a project's blocks (sb3.js getExtensionIdForOpcode:
# the part of the opcode before the first "_"); core categories are not extensions.
CORE_CATEGORIES = {"argument", "colour", "control", "data", "event", "looks", "math", "motion", "operator",
                   "procedures", "sensing", "sound"}


def extensions_used(targets: list[dict[str, Any]]) -> list[str]:
    """Extension ids used by the blocks of these (JSON) targets, sorted (informational in sb3)."""
    found: set[str] = set()
    for t in targets:
        for b in (t.get("blocks") or {}).values():
            if isinstance(b, dict) and isinstance(b.get("opcode"), str) and "_" in b["opcode"]:
                prefix = b["opcode"].split("_", 1)[0]
                if prefix not in CORE_CATEGORIES:
                    found.add(prefix)
    return sorted(found)


def project_json(targets: list[Target], extensions: list[str] | None = None) -> dict[str, Any]:
    tj = [t.to_json() for t in targets]
    return {"targets": tj, "monitors": [],
            "extensions": extensions if extensions is not None else extensions_used(tj),
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


def _bad_value(v: Any) -> bool:
    if isinstance(v, (bool, str)):
        return False
    return not (isinstance(v, (int, float)) and math.isfinite(v))


def _check_asset(w: str, md5ext: str, assets: dict[str, bytes] | None, problems: list[str]) -> None:
    if assets is None:
        return
    data = assets.get(md5ext)
    if data is None:
        problems.append(f"{w}: asset {md5ext} is not in the archive")
    elif hashlib.md5(data).hexdigest() != md5ext.split(".")[0]:
        problems.append(f"{w}: asset {md5ext} has md5 {hashlib.md5(data).hexdigest()}")
    elif len(data) >= ASSET_LIMIT:
        problems.append(f"{w}: asset {md5ext} is {len(data)} bytes (limit: under 10 MB)")


def _check_blocks(blocks: Any, where: str, problems: list[str]) -> None:
    """Links between blocks point at blocks that exist (a dangling one stops the VM loading)."""
    if not isinstance(blocks, dict):
        problems.append(f"{where}.blocks: not an object")
        return
    protos = {b.get("mutation", {}).get("proccode") for b in blocks.values()
              if isinstance(b, dict) and b.get("opcode") == "procedures_prototype"}
    for bid, b in blocks.items():
        w = f"{where}.blocks[{bid!r}]"
        if isinstance(b, list):  # a top-level variable/list reporter [12|13, name, id, x, y]
            if len(b) < 3 or b[0] not in (12, 13):
                problems.append(f"{w}: malformed top-level reporter")
            continue
        if not isinstance(b, dict) or not isinstance(b.get("opcode"), str):
            problems.append(f"{w}: not a block (no opcode)")
            continue
        for key in ("next", "parent"):
            ref = b.get(key)
            if ref is not None and ref not in blocks:
                problems.append(f"{w}: {key} {ref!r} is not a block of this target")
        for name, inp in (b.get("inputs") or {}).items():
            if not isinstance(inp, list) or not inp or inp[0] not in (1, 2, 3):
                problems.append(f"{w}: input {name} is malformed")
                continue
            for ref in inp[1:]:
                if isinstance(ref, str) and ref not in blocks:
                    problems.append(f"{w}: input {name} refers to missing block {ref!r}")
        if b.get("opcode") == "procedures_call":
            code = (b.get("mutation") or {}).get("proccode")
            if code not in protos:
                problems.append(f"{w}: calls custom block {code!r}, which this target does not define")


def _check_target(t: Any, where: str, assets: dict[str, bytes] | None, problems: list[str],
                  ids: dict[str, str]) -> None:
    if not isinstance(t, dict):
        problems.append(f"{where}: not an object")
        return
    for k in ("name", "isStage", "variables", "costumes", "sounds", "blocks"):
        if k not in t:
            problems.append(f"{where}: missing '{k}'")
    for kind in ("variables", "lists"):
        seen_names: set[str] = set()
        for vid, val in (t.get(kind) or {}).items():
            w = f"{where}.{kind}[{vid!r}]"
            if vid in ids:
                problems.append(f"{w}: id also used by {ids[vid]}")
            ids[vid] = w
            if not isinstance(val, list) or len(val) < 2 or not isinstance(val[0], str):
                problems.append(f"{w}: expected [name, value]")
                continue
            if val[0] in seen_names:
                problems.append(f"{w}: a second {kind[:-1]} named {val[0]!r} in this target")
            seen_names.add(val[0])
            if kind == "variables":
                if _bad_value(val[1]):
                    problems.append(f"{w}: value {val[1]!r} is not a finite number, string or boolean")
                continue
            items = val[1]
            if not isinstance(items, list):
                problems.append(f"{w}: list value is not an array")
                continue
            bad = [i for i, it in enumerate(items) if _bad_value(it)]
            if bad:
                more = f" ({len(bad)} such items)" if len(bad) > 1 else ""
                problems.append(f"{w} item {bad[0] + 1}: {items[bad[0]]!r} is not a finite number, string or "
                                f"boolean{more}")
    costumes = t.get("costumes")
    if not isinstance(costumes, list) or not costumes:
        problems.append(f"{where}: needs at least one costume")
        costumes = []
    names: set[str] = set()
    for ci, c in enumerate(costumes):
        w = f"{where}.costumes[{ci}]"
        if not isinstance(c, dict):
            problems.append(f"{w}: not an object")
            continue
        if not isinstance(c.get("name"), str):
            problems.append(f"{w}: name must be a string")
        elif c["name"] in names:
            # Scratch renames a duplicate on load ("x2"), which breaks lookups by name
            problems.append(f"{w}: a second costume named {c['name']!r}")
        else:
            names.add(c["name"])
        if not _HEX32.match(str(c.get("assetId", ""))):
            problems.append(f"{w}: assetId must be 32 hex digits")
        if c.get("dataFormat") not in _FORMATS:
            problems.append(f"{w}: dataFormat {c.get('dataFormat')!r} is not one of {sorted(_FORMATS)}")
        md5ext = c.get("md5ext") or f"{c.get('assetId')}.{c.get('dataFormat')}"
        if not _MD5EXT.match(md5ext):
            problems.append(f"{w}: md5ext {md5ext!r} is malformed")
        if c.get("dataFormat") != "svg" and c.get("bitmapResolution") not in (1, 2):
            problems.append(f"{w}: bitmapResolution should be 2 for bitmaps")
        for k in ("rotationCenterX", "rotationCenterY"):
            if k in c and (isinstance(c[k], bool) or not isinstance(c[k], (int, float)) or not math.isfinite(c[k])):
                problems.append(f"{w}: {k} must be a finite number")
        _check_asset(w, md5ext, assets, problems)
    for si, snd in enumerate(t.get("sounds") or []):
        w = f"{where}.sounds[{si}]"
        if not isinstance(snd, dict) or snd.get("dataFormat") not in ("wav", "wave", "mp3"):
            problems.append(f"{w}: dataFormat must be wav or mp3")
            continue
        _check_asset(w, snd.get("md5ext") or f"{snd.get('assetId')}.{snd.get('dataFormat')}", assets, problems)
    _check_blocks(t.get("blocks", {}), where, problems)


def validate_project(project: Any, assets: dict[str, bytes] | None = None, *,
                     project_json_bytes: int | None = None) -> list[str]:
    """Every problem found in a project.json (not just the first): required fields, list items
    and variable values (finite numbers, strings or booleans only), unique ids and names,
    costume/sound fields, asset md5s and sizes (when ``assets`` is given), links between blocks,
    visible list monitors, and the 5 MiB project.json limit (when its size is given)."""
    problems: list[str] = []
    if project_json_bytes is not None and project_json_bytes > PROJECT_JSON_LIMIT:
        problems.append(f"project.json is {project_json_bytes} bytes (scratch.mit.edu accepts {PROJECT_JSON_LIMIT})")
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
    stage = next((t for t in targets if isinstance(t, dict) and t.get("isStage")), None)
    if stage is not None:
        for kind in ("variables", "lists"):
            glob = {v[0] for v in (stage.get(kind) or {}).values() if isinstance(v, list) and v}
            for i, t in enumerate(targets):
                if t is stage or not isinstance(t, dict):
                    continue
                for v in (t.get(kind) or {}).values():
                    if isinstance(v, list) and v and v[0] in glob:
                        problems.append(f"targets[{i}] ({t.get('name')}): {kind[:-1]} {v[0]!r} has the name of "
                                        f"a stage {kind[:-1]} (scripts would not know which one they mean)")
    for m in project.get("monitors", []) or []:
        if isinstance(m, dict) and m.get("mode") == "list" and m.get("visible"):
            problems.append(f"monitors[{m.get('id')}]: a visible list monitor stores a second copy of the list")
    return problems


def validate_sprite(sprite: Any, assets: dict[str, bytes] | None = None) -> list[str]:
    problems: list[str] = []
    _check_target(sprite, "sprite", assets, problems, {})
    if isinstance(sprite, dict) and sprite.get("isStage"):
        problems.append("sprite: isStage must be false")
    return problems


# --------------------------------------------------------------------------- reading
_S_IFMT, _S_IFLNK = 0o170000, 0o120000


# Everything zipfile/zlib raise on malformed archives (fuzzing found zlib.error for a corrupt
# deflate stream, NotImplementedError for a bad version field, IndexError for an empty name).
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, ValueError, EOFError, NotImplementedError,
               IndexError, RuntimeError, struct.error, UnicodeDecodeError)


def _open_zip(source: Path | bytes, path: Path | None) -> zipfile.ZipFile:
    try:
        if isinstance(source, (bytes, bytearray, memoryview)):
            return zipfile.ZipFile(io.BytesIO(bytes(source)))
        return zipfile.ZipFile(source)
    except _ZIP_ERRORS as e:
        raise InputError(f"not a Scratch project archive (zip): {e}", path=path) from None


def read_archive(source: Path | str | bytes, *, max_entries: int = MAX_ENTRIES,
                 max_total: int = MAX_TOTAL_UNCOMPRESSED, max_entry: int = MAX_ENTRY_UNCOMPRESSED,
                 max_ratio: float = MAX_RATIO) -> dict[str, bytes]:
    """Read an untrusted .sb3/.sprite3 (a path or its bytes) and return entry name -> bytes.

    Refused, with the limit named: entries outside the archive root (absolute, ``..``, drive
    letters, backslashes), symbolic links, duplicate names, encrypted entries, more than
    ``max_entries`` entries, an entry over ``max_entry`` bytes or a total over ``max_total``
    bytes uncompressed, a compression ratio over ``max_ratio`` (entries over 1 MiB), entries
    larger than their header says, and corrupt data. Sizes are checked against the headers
    before anything is decompressed, and again while reading."""
    path = None if isinstance(source, (bytes, bytearray, memoryview)) else Path(source)
    try:
        return _read_archive(_open_zip(path if path is not None else source, path), path, max_entries,
                             max_total, max_entry, max_ratio)
    except _ZIP_ERRORS as e:  # anything the checks below did not name
        raise InputError(f"archive cannot be read: {type(e).__name__}: {e}", path=path) from None


def _read_archive(zf: zipfile.ZipFile, path: Path | None, max_entries: int, max_total: int,
                  max_entry: int, max_ratio: float) -> dict[str, bytes]:
    with zf:
        infos = zf.infolist()
        if len(infos) > max_entries:
            raise InputError(f"archive has {len(infos)} entries (limit {max_entries})", path=path)
        total = 0
        seen: set[str] = set()
        for info in infos:
            name = info.filename
            pp = PurePosixPath(name)
            if (name.startswith(("/", "\\")) or ".." in pp.parts or ":" in name or "\\" in name
                    or "\x00" in name):
                raise InputError(f"archive entry {name!r} points outside the archive root", path=path)
            if (info.external_attr >> 16) & _S_IFMT == _S_IFLNK:
                raise InputError(f"archive entry {name!r} is a symbolic link", path=path)
            if name in seen:
                raise InputError(f"archive has two entries named {name!r}", path=path)
            seen.add(name)
            if info.flag_bits & 0x1:
                raise InputError(f"archive entry {name!r} is encrypted", path=path)
            if info.file_size > max_entry:
                raise InputError(f"archive entry {name!r} is {info.file_size} bytes uncompressed "
                                 f"(limit {max_entry})", path=path)
            total += info.file_size
            if total > max_total:
                raise InputError(f"archive uncompresses to more than {max_total} bytes (limit {max_total})",
                                 path=path)
            if info.file_size > 1 << 20 and info.file_size > max_ratio * max(info.compress_size, 1):
                raise InputError(f"archive entry {name!r} has compression ratio "
                                 f"{info.file_size / max(info.compress_size, 1):.0f}:1 (limit {max_ratio:.0f}:1)",
                                 path=path)
        out: dict[str, bytes] = {}
        for info in infos:
            if info.is_dir():
                continue
            try:
                with zf.open(info) as f:
                    data = f.read(info.file_size + 1)
            except _ZIP_ERRORS as e:
                raise InputError(f"archive entry {info.filename!r} cannot be read: {e}", path=path) from None
            if len(data) > info.file_size:  # the header lied about the size
                raise InputError(f"archive entry {info.filename!r} is larger than its header says", path=path)
            out[info.filename] = data
    return out


_PROJECT_RE = re.compile(r"^([^/]*/)?project\.json$")


def _find_json(entries: dict[str, bytes], name: str, path: Path | None) -> str:
    names = sorted((n for n in entries if re.match(rf"^([^/]*/)?{re.escape(name)}$", n)),
                   key=lambda n: (n.count("/"), n))
    if not names:
        raise InputError(f"archive has no {name}", path=path)
    if len(names) > 1 and names[1].count("/") == names[0].count("/"):
        raise InputError(f"archive has several {name} files ({', '.join(names[:3])})", path=path)
    return names[0]


def _json_entry(entries: dict[str, bytes], key: str, path: Path | None) -> Any:
    try:
        return json.loads(entries[key].decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise InputError(f"{key} is not valid JSON: {e}", path=path) from None


def load_project(source: Path | str | bytes) -> tuple[dict[str, Any], dict[str, bytes]]:
    """project.json (from the root or one sub-folder, as Scratch accepts) and the other entries
    (named relative to that folder). ``source`` is a path or the archive's bytes; a bare
    project.json (first byte ``{``) is accepted too, as scratch-parser does."""
    path = None if isinstance(source, (bytes, bytearray, memoryview)) else Path(source)
    raw = bytes(source) if path is None else None
    if raw is None and path.suffix.lower() == ".json":
        raw = path.read_bytes()
    if raw is not None and raw.lstrip()[:1] == b"{":
        project = _json_entry({"project.json": raw}, "project.json", path)
        assets: dict[str, bytes] = {}
    else:
        entries = read_archive(path if path is not None else raw)
        key = _find_json(entries, "project.json", path)
        prefix = key[: -len("project.json")]
        project = _json_entry(entries, key, path)
        assets = {n[len(prefix):]: d for n, d in entries.items() if n.startswith(prefix) and n != key}
    if not isinstance(project, dict) or not isinstance(project.get("targets"), list):
        raise InputError("project.json is not a Scratch 3 project (no targets)", path=path)
    return project, assets


def load_sprite(source: Path | str | bytes) -> tuple[dict[str, Any], dict[str, bytes]]:
    """sprite.json and the other entries of a .sprite3."""
    path = None if isinstance(source, (bytes, bytearray, memoryview)) else Path(source)
    entries = read_archive(source)
    key = _find_json(entries, "sprite.json", path)
    prefix = key[: -len("sprite.json")]
    sprite = _json_entry(entries, key, path)
    if not isinstance(sprite, dict):
        raise InputError("sprite.json is not an object", path=path)
    return sprite, {n[len(prefix):]: d for n, d in entries.items() if n.startswith(prefix) and n != key}


def archive_sizes(data: bytes) -> dict[str, Any]:
    """The real sizes in a written archive: project.json (or sprite.json) bytes and each asset's."""
    out: dict[str, Any] = {"project_json_bytes": None, "assets": {}}
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        for info in z.infolist():
            base = info.filename.rsplit("/", 1)[-1]
            if base in ("project.json", "sprite.json"):
                out["project_json_bytes"] = info.file_size
            elif not info.is_dir():
                out["assets"][base] = info.file_size
    return out


# --------------------------------------------------------------------------- merging
def _unique_id(seed: tuple[str, ...], used: set[str]) -> str:
    n = 0
    while True:
        vid = stable_id(*seed, *(("#", str(n)) if n else ()))
        if vid not in used:
            used.add(vid)
            return vid
        n += 1


def _all_ids(project: dict[str, Any]) -> set[str]:
    ids: set[str] = set()
    for t in project["targets"]:
        for kind in ("variables", "lists", "broadcasts"):
            ids.update((t.get(kind) or {}).keys())
    return ids


def _names(t: dict[str, Any], kind: str) -> dict[str, str]:
    """name -> id of a target's variables or lists."""
    out: dict[str, str] = {}
    for vid, val in (t.get(kind) or {}).items():
        if isinstance(val, list) and val and isinstance(val[0], str):
            out.setdefault(val[0], vid)
    return out


def relink(sprite: dict[str, Any], stage: dict[str, Any]) -> int:
    """Point a sprite's references to global variables and lists at the stage's actual ids
    (matched by name, as Scratch itself falls back to when an id is unknown). Returns the number
    of references changed."""
    own = set((sprite.get("variables") or {}).keys()) | set((sprite.get("lists") or {}).keys())
    gv, gl = _names(stage, "variables"), _names(stage, "lists")
    changed = 0
    for b in (sprite.get("blocks") or {}).values():
        if isinstance(b, list) and len(b) >= 3 and b[0] in (12, 13) and b[2] not in own:
            table = gv if b[0] == 12 else gl
            if b[1] in table and b[2] != table[b[1]]:
                b[2] = table[b[1]]
                changed += 1
            continue
        if not isinstance(b, dict):
            continue
        for fname, table in (("VARIABLE", gv), ("LIST", gl)):
            f = (b.get("fields") or {}).get(fname)
            if isinstance(f, list) and len(f) >= 2 and f[1] not in own and f[0] in table and f[1] != table[f[0]]:
                f[1] = table[f[0]]
                changed += 1
        for inp in (b.get("inputs") or {}).values():
            if not isinstance(inp, list):
                continue
            for prim in inp[1:]:
                if isinstance(prim, list) and len(prim) >= 3 and prim[0] in (12, 13) and prim[2] not in own:
                    table = gv if prim[0] == 12 else gl
                    if prim[1] in table and prim[2] != table[prim[1]]:
                        prim[2] = table[prim[1]]
                        changed += 1
    return changed


def merge_into(project: Path | str | bytes, target_name: str, lists: dict[str, list],
               costumes: list[Costume] | tuple[Costume, ...] = (), *,
               sprites: list[Target] | tuple[Target, ...] = ()) -> bytes:
    """A new .sb3 (bytes): ``project`` (an .sb3 path or bytes) with our lists and costumes put
    into the target named ``target_name`` ("Stage" or a sprite), everything else untouched.

    * A list with the same name visible from the target (its own, or the stage's when the
      target is a sprite) gets our items and keeps its id, so the project's scripts read the new
      data; other lists are added to the target. A list monitor of a list we write is hidden
      (a visible one stores a second copy of the list).
    * A costume with the same name in the target is replaced (same position); others are added.
    * ``sprites`` (e.g. the reader sprite) are added as new sprites; a name already in use is an
      error, as are their local variables or lists clashing with the stage's.
    * Every other entry of the archive (assets, other targets, monitors, extensions, comments,
      meta) is kept as it was. The input is only read, never written.

    Raises :class:`InputError` for an unreadable project, an unknown target, a name conflict, or
    a result that breaks a validation rule the input did not already break."""
    path = None if isinstance(project, (bytes, bytearray, memoryview)) else Path(project)
    data = bytes(project) if path is None else path.read_bytes()
    if data.lstrip()[:1] == b"{":
        entries = {"project.json": data}
        key = "project.json"
    else:
        entries = read_archive(path if path is not None else data)  # errors name the file
        key = _find_json(entries, "project.json", path)
    prefix = key[: -len("project.json")]
    proj = _json_entry(entries, key, path)
    if not isinstance(proj, dict) or not isinstance(proj.get("targets"), list) or not proj["targets"]:
        raise InputError("project.json is not a Scratch 3 project (no targets)", path=path)
    assets = {n[len(prefix):]: d for n, d in entries.items() if n.startswith(prefix) and n != key}
    before = set(validate_project(proj, assets))

    targets = proj["targets"]
    stage = next((t for t in targets if isinstance(t, dict) and t.get("isStage")), None)
    if stage is None:
        raise InputError("project has no stage", path=path)
    if target_name in ("Stage", "_stage_"):
        target = stage
    else:
        target = next((t for t in targets if isinstance(t, dict) and not t.get("isStage")
                       and t.get("name") == target_name), None)
    if target is None:
        names = ["Stage"] + [t.get("name") for t in targets if isinstance(t, dict) and not t.get("isStage")]
        raise InputError(f"no sprite named {target_name!r} in the project (targets: {', '.join(map(str, names))})",
                         path=path)

    problems: list[str] = []
    probe = {"isStage": False, "name": "lists", "variables": {}, "costumes": [{}], "sounds": [], "blocks": {},
             "lists": {f"l{i}": [n, v] for i, (n, v) in enumerate(lists.items())}}
    for msg in validate_sprite(probe, None):
        if "lists[" in msg:
            problems.append(msg.replace("sprite.lists", "list"))
    if problems:
        raise InputError("lists cannot be stored in Scratch: " + "; ".join(problems), path=path)

    used = _all_ids(proj)
    written_ids: set[str] = set()
    for name, items in lists.items():
        own = _names(target, "lists")
        if name in own:
            vid, owner = own[name], target
        elif target is not stage and name in _names(stage, "lists"):
            vid, owner = _names(stage, "lists")[name], stage
        else:
            if target is stage:
                clash = [t.get("name") for t in targets if t is not stage and name in _names(t, "lists")]
                if clash:
                    raise InputError(f"sprite {clash[0]!r} has its own list {name!r}; a stage list of the same "
                                     "name would be hidden from its scripts (rename one, or bake into that sprite)",
                                     path=path)
            vid, owner = _unique_id((str(target.get("name")), "list", name), used), target
            owner.setdefault("lists", {})
        owner["lists"][vid] = [name, list(items)]
        written_ids.add(vid)
    for mon in proj.get("monitors") or []:
        if isinstance(mon, dict) and mon.get("id") in written_ids:
            mon["visible"] = False
            mon["value"] = []

    new_assets: dict[str, bytes] = {}
    if costumes:
        existing = target.setdefault("costumes", [])
        for c in costumes:
            cj = c.to_json()
            new_assets[c.asset.md5ext] = c.asset.data
            idx = next((i for i, e in enumerate(existing) if isinstance(e, dict) and e.get("name") == c.name), None)
            if idx is None:
                existing.append(cj)
            else:
                existing[idx] = cj

    if sprites:
        taken = {t.get("name") for t in targets if isinstance(t, dict)}
        stage_vars, stage_lists = _names(stage, "variables"), _names(stage, "lists")
        layer = max((t.get("layerOrder", 0) for t in targets if isinstance(t, dict)), default=0)
        for sp in sprites:
            if sp.name in taken or sp.name == "Stage":
                raise InputError(f"the project already has a sprite named {sp.name!r}", path=path)
            for kind, glob in (("variables", stage_vars), ("lists", stage_lists)):
                for n in getattr(sp, kind):
                    if n in glob:
                        raise InputError(f"sprite {sp.name!r} has a {kind[:-1]} {n!r} that the stage also has",
                                         path=path)
            layer += 1
            sj = sp.to_json()
            sj["layerOrder"] = layer
            relink(sj, stage)
            targets.append(sj)
            taken.add(sp.name)
            for a in sp.assets():
                new_assets[a.md5ext] = a.data
        if any(op.startswith("pen_") for sp in sprites for op in
               (b.get("opcode", "") for b in sp.blocks.values() if isinstance(b, dict))):
            ext = proj.setdefault("extensions", [])
            if "pen" not in ext:
                ext.append("pen")

    merged_assets = dict(assets)
    merged_assets.update(new_assets)
    after = validate_project(proj, merged_assets)
    fresh = [p for p in after if p not in before]
    if fresh:
        raise InputError("the merged project would be invalid: " + "; ".join(fresh), path=path)

    out = {n: d for n, d in entries.items() if n != key}
    out[key] = dumps(proj).encode("utf-8")
    for name, d in new_assets.items():
        out[prefix + name] = d
    return _zip(out)
