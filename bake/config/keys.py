"""The config's keys by name: every dotted key and its type, reading and setting one, the
defaults (``bake keys``), the config as plain data, and the "did you mean" of an unknown key."""

from __future__ import annotations

import dataclasses
import difflib
import re
import typing
from pathlib import Path
from typing import Any, get_args, get_origin, get_type_hints

from ..errors import ConfigError
from .schema import _ALIASES, _REVERSE, Config, stage_sections


def _toml_name(attr: str) -> str:
    return _REVERSE.get(attr, attr)


def _fields(cls: type) -> list[str]:
    """The attribute names of a section's keys, in order (the config's own sections, then those
    the stages bring)."""
    names = [f.name for f in dataclasses.fields(cls) if not f.metadata.get("internal")]
    return names + [n for n in stage_sections() if n not in names] if cls is Config else names


def _hints(cls: type) -> dict[str, Any]:
    """The type of each attribute of a section (with the stages' sections for the config)."""
    hints = get_type_hints(cls)
    return {**stage_sections(), **hints} if cls is Config else hints


def all_keys(cls: type = Config, prefix: str = "") -> list[str]:
    """Every dotted key the config accepts (for suggestions and docs)."""
    hints = _hints(cls)
    out = []
    for name in _fields(cls):
        key = prefix + _toml_name(name)
        t = hints[name]
        if dataclasses.is_dataclass(t):
            out.extend(all_keys(t, key + "."))
        else:
            out.append(key)
    return out


# Words authors reach for, and the key bake calls that thing (matched per dotted component).
_SYNONYMS = {"occlusion": "ao", "ambient_occlusion": "ao", "ambientocclusion": "ao", "ssao": "ao",
             "shadow": "shadows", "bounce": "bounces", "gi": "bounces", "indirect": "bounces",
             "light": "lights", "lamp": "lights", "lamps": "lights", "simplification": "simplify",
             "decimate": "simplify", "decimation": "simplify", "texture": "textures", "uv": "uvs",
             "lightmaps": "lightmap", "colour": "color", "colours": "colors", "centre": "center",
             "triangulation": "triangulate", "cleanup": "clean", "output": "export", "model": "input"}


def _children(cls: Any) -> dict[str, Any]:
    """TOML name -> type of each key of a section (list[Section] as Section)."""
    hints = _hints(cls)
    out = {}
    for name in _fields(cls):
        t = hints[name]
        if get_origin(t) in (list, typing.List) and get_args(t) and dataclasses.is_dataclass(get_args(t)[0]):
            t = get_args(t)[0]
        out[_toml_name(name)] = t
    return out


def _walk_suggestion(parts: list[str], *, table: bool) -> str | None:
    """Mend a dotted key one component at a time, from the top: a known name stays, a synonym
    or the closest name at that level replaces an unknown one (``lightning.enabled`` ->
    ``lighting.enabled``, ``lighting.occlusion`` -> ``lighting.ao``)."""
    cls: Any = Config
    out = []
    for i, raw in enumerate(parts):
        if not dataclasses.is_dataclass(cls):
            return None
        name, _, index = raw.partition("[")
        kids = _children(cls)
        last = i == len(parts) - 1
        # at the last component of a table, or on the way down, only sections fit; else keys
        fits = [k for k, t in kids.items() if dataclasses.is_dataclass(t) == (table or not last)]
        if name not in kids or (last and name not in fits):
            syn = _SYNONYMS.get(name.lower())
            if syn in fits:
                name = syn
            else:
                close = difflib.get_close_matches(name, fits, n=1, cutoff=0.6)
                if not close:
                    return None
                name = close[0]
        out.append(name + (f"[{index}" if index else ""))
        cls = kids[name]
    return ".".join(out)


def _suggest(key: str, candidates: list[str], *, table: bool = False) -> str:
    """``; did you mean 'x'?`` for an unknown ``key`` (a table: ``table=True``), or ""."""
    mended = _walk_suggestion(key.split("."), table=table)
    if mended and mended != key:
        return f"; did you mean [{mended}]?" if table else f"; did you mean '{mended}'?"
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.5)
    if not close:
        # try the last component against the last components
        last = key.rsplit(".", 1)[-1]
        by_last = {c.rsplit(".", 1)[-1]: c for c in candidates}
        m = difflib.get_close_matches(last, list(by_last), n=1, cutoff=0.6)
        close = [by_last[m[0]]] if m else []
    return f"; did you mean '{close[0]}'?" if close else ""


def _typos(a: str, b: str) -> int:
    """Edits (insert, delete, substitute, swap two neighbours) from ``a`` to ``b``: ``angel`` is
    one swap from ``angle`` and two edits from ``range`` (difflib rates both alike). Names are a
    few letters long, so the quadratic table is nothing."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1]))
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


def _closest_field(name: str, fields: list[str]) -> list[str]:
    """The field a misspelt ``name`` most likely meant (fewest edits, then difflib's ratio), if
    it is within a third of the name's length; else difflib's closest (``[]`` if none)."""
    if not fields:
        return []
    best = min(fields, key=lambda f: (_typos(name, f), -difflib.SequenceMatcher(None, name, f).ratio()))
    if _typos(name, best) <= max(1, len(name) // 3):
        return [best]
    return difflib.get_close_matches(name, fields, n=1, cutoff=0.5)


# Keys that hold paths. From --set they resolve against the current folder; in a config file,
# FILE_RELATIVE_KEYS against the config's folder (input.path too, in the pipeline; textures.texture
# is relative to the model's folder, see TexturesConfig).
PATH_KEYS = ("input.path", "export.into", "textures.texture", "textures.lightmap.cache_dir")
FILE_RELATIVE_KEYS = ("export.into", "textures.lightmap.cache_dir")


def _set_key(cfg: Config, key: str, value: Any) -> None:
    obj: Any = cfg
    parts = key.split(".")
    for p in parts[:-1]:
        obj = getattr(obj, _ALIASES.get(p, p))
    setattr(obj, _ALIASES.get(parts[-1], parts[-1]), value)


def key_defaults() -> list[tuple[str, Any]]:
    """Every key with its default, for ``bake keys``: the keys of :func:`all_keys`, and for an
    array of tables (``[[lighting.lights]]``) each field of one element as ``lighting.lights[].kind``."""
    cfg = Config()
    out: list[tuple[str, Any]] = []
    for key in all_keys():
        val = get_key(cfg, key)
        out.append((key, to_dict(val)))
        *path, last = key.split(".")
        owner = get_key(cfg, ".".join(path)) if path else cfg
        t = _hints(type(owner)).get(_ALIASES.get(last, last))
        args = get_args(t) if get_origin(t) in (list, typing.List) else ()
        if args and dataclasses.is_dataclass(args[0]):
            elem = args[0]()
            out.extend((f"{key}[].{k}", to_dict(get_key(elem, k))) for k in all_keys(args[0]))
    return out


def get_key(cfg: Any, key: str) -> Any:
    """The value of a dotted key (``lighting.lights[0].angle`` reads one element)."""
    obj: Any = cfg
    for p in key.split("."):
        m = re.match(r"^(\w+)\[(\d+)\]$", p)
        if m and dataclasses.is_dataclass(obj) and m.group(1) in _fields(type(obj)):
            items = getattr(obj, m.group(1))
            if not isinstance(items, list) or int(m.group(2)) >= len(items):
                raise ConfigError(f"no element {m.group(2)} (there are {len(items)})", key=key)
            obj = items[int(m.group(2))]
            continue
        attr = _ALIASES.get(p, p)
        if not dataclasses.is_dataclass(obj) or attr not in _fields(type(obj)):
            raise ConfigError("unknown key" + _suggest(key, all_keys()), key=key)
        obj = getattr(obj, attr)
    return obj


def to_dict(obj: Any) -> Any:
    """The config as plain data (TOML names), for the report."""
    if dataclasses.is_dataclass(obj):
        return {_toml_name(f): to_dict(getattr(obj, f)) for f in _fields(type(obj))}
    if isinstance(obj, list):
        return [to_dict(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj


def numeric_keys() -> list[str]:
    """Keys whose value is an int or float (what ``bake sweep --vary`` accepts)."""
    out = []

    def walk(cls: type, prefix: str) -> None:
        hints = _hints(cls)
        for name in _fields(cls):
            t = hints[name]
            key = prefix + _toml_name(name)
            if dataclasses.is_dataclass(t):
                walk(t, key + ".")
            elif t in (int, float):
                out.append(key)

    walk(Config, "")
    return out
