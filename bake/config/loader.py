"""TOML -> typed config.

The loader checks every key against the schema (``bake.config.schema``). An unknown key is an
error that names the file, the line and the nearest known key. Types are checked (an ``int`` is
accepted where a ``float`` is expected), ``Literal`` choices are enforced, and nested sections
and arrays of tables (``[[lighting.lights]]``) are typed too. Then every section's own range
check runs (``check``), and the stages' (the registry's ``StageSpec.check``).

``--set section.key=value`` overrides go through the same checks (the value is parsed as a TOML
value, falling back to a bare string).
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import sys
import types
import typing
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from ..errors import ConfigError
from .keys import (FILE_RELATIVE_KEYS, PATH_KEYS, _closest_field, _fields, _hints, _set_key, _toml_name,
                   _suggest, all_keys, get_key)
from .origins import _Where, error_at
from .schema import _ALIASES, _STAGE_CHECKS, Config


_PLURAL = {"int": "integers", "float": "numbers", "str": "strings", "bool": "true or false values"}


def _type_name(t: Any) -> str:
    if get_origin(t) in (Union, types.UnionType):
        words: list[str] = []
        for a in get_args(t):
            if a is bool:
                words += ["true", "false"]
            elif get_origin(a) is Literal:
                words += [repr(c) for c in get_args(a)]
            elif a is not type(None):
                words.append(_type_name(a))
        return ", ".join(words[:-1]) + " or " + words[-1] if len(words) > 1 else "".join(words)
    if get_origin(t) is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(t))
    if get_origin(t) in (list, typing.List):
        (inner,) = get_args(t) or (Any,)
        if get_origin(inner) is Literal:
            return "a list of values from " + ", ".join(repr(a) for a in get_args(inner))
        if isinstance(inner, type) and inner.__name__ in _PLURAL:
            return f"a list of {_PLURAL[inner.__name__]}"
        return f"a list of {_type_name(inner)}"
    if isinstance(t, type):
        return {"int": "an integer", "float": "a number", "str": "a string", "bool": "true or false"}.get(
            t.__name__, t.__name__)
    return str(t)


def _list_expected(t: Any, key: str, value: Any, example: Any) -> str:
    """What a list-typed key expects, said so a reader can write it: an array of tables as its
    double-bracket headers, a list of numbers with an example in the shape of its default."""
    (inner,) = get_args(t) or (Any,)
    if dataclasses.is_dataclass(inner):
        one = key.rsplit(".", 1)[-1].rstrip("s") or "entry"
        got = f"a single [{key}] table" if isinstance(value, dict) else f"{value!r}"
        return (f"an array of tables: each {one} is written under its own [[{key}]] header (double brackets); "
                f"got {got}")
    such = ""
    numbers = inner in (int, float)
    if not isinstance(value, (list, dict)):  # one value where a list goes: the list it may have meant
        such = f" such as {[value] * len(example) if numbers and isinstance(example, list) and example else [value]!r}"
    elif isinstance(example, list) and example:
        such = f" such as {example!r}"
    return f"{_type_name(t)}{such}, got {value!r}"


def _convert(value: Any, t: Any, key: str, where: _Where, example: Any = None) -> Any:
    origin = get_origin(t)
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(t) if a is not type(None)]
        if value is None:
            return None
        if len(args) == 1:
            return _convert(value, args[0], key, where)
        for a in args:  # (bool | Literal["auto"]: the first that takes the value)
            try:
                return _convert(value, a, key, where)
            except ConfigError:
                continue
        raise where.error(key, f"expected {_type_name(t)}, got {value!r}")
    if origin is Literal:
        choices = get_args(t)
        if value not in choices:
            sugg = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1)
            hint = f"; did you mean {sugg[0]!r}?" if sugg else ""
            raise where.error(key, f"expected {_type_name(t)}, got {value!r}{hint}")
        return value
    if origin in (list, typing.List):
        (inner,) = get_args(t) or (Any,)
        if not isinstance(value, list):
            raise where.error(key, "expected " + _list_expected(t, key, value, example))
        return [_convert(v, inner, f"{key}[{i}]", where) for i, v in enumerate(value)]
    if dataclasses.is_dataclass(t):
        if not isinstance(value, dict):
            raise where.error(key, f"expected a table [{key}], got {value!r}")
        return _build(t, value, key + ".", where)
    if t is bool:
        if not isinstance(value, bool):
            raise where.error(key, f"expected true or false, got {value!r}")
        return value
    if t is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise where.error(key, f"expected an integer, got {value!r}")
        return value
    if t is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise where.error(key, f"expected a number, got {value!r}")
        f = float(value)
        if f != f or f in (float("inf"), float("-inf")):
            raise where.error(key, f"expected a finite number, got {value!r}")
        return f
    if t is str:
        if not isinstance(value, str):
            raise where.error(key, f"expected a string, got {value!r}")
        return value
    return value


def _leaves(value: dict, prefix: str) -> list[str]:
    out = []
    for k, v in value.items():
        out.extend(_leaves(v, f"{prefix}.{k}") if isinstance(v, dict) and v else [f"{prefix}.{k}"])
    return out


def _build(cls: type, data: dict, prefix: str, where: _Where, base: Any = None) -> Any:
    fields = _fields(cls)
    hints = _hints(cls)
    obj = base if base is not None else cls()
    for raw_key, value in data.items():
        attr = _ALIASES.get(raw_key, raw_key)
        key = prefix + raw_key
        if attr not in fields:
            if re.search(r"\[\d+\]\.$", prefix):  # inside [[...]]: the element's own fields, by name
                close = _closest_field(raw_key, all_keys(cls))
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise where.error(key, f"unknown key{hint} (an entry of [[{prefix.split('[')[0]}]] has "
                                  + ", ".join(all_keys(cls)) + ")")
            known = all_keys(Config)
            sub = [k for k in known if k.startswith(prefix)] if prefix else known
            leaves = _leaves(value, key) if isinstance(value, dict) else [key]
            # a [table] header in the file, or a table of several keys: mend the table's name;
            # a dotted key (--set lightning.enabled=true): mend the whole key
            if len(leaves) != 1 or (isinstance(value, dict) and where.is_header(key)):
                raise where.error(key, f"unknown table [{key}]" + _suggest(key, sub or known, table=True))
            raise where.error(leaves[0], "unknown key" + _suggest(leaves[0], known))
        t = hints[attr]
        if dataclasses.is_dataclass(t) and isinstance(value, dict):
            setattr(obj, attr, _build(t, value, key + ".", where, base=getattr(obj, attr)))
        else:
            setattr(obj, attr, _convert(value, t, key, where, example=getattr(obj, attr, None)))
            where.given[key] = where.origin
    return obj


def load(path: str | Path | None = None, overrides: list[str] | None = None,
         data: dict | None = None) -> Config:
    """Load a config file (or none: defaults), then apply ``key=value`` overrides."""
    text = None
    src = None
    if path is not None:
        src = Path(path)
        try:
            raw = src.read_bytes()
        except OSError as e:
            raise ConfigError(f"cannot read config: {e.strerror}", path=src) from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise ConfigError(f"config is not UTF-8 text (byte {e.start})", path=src) from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            m = re.search(r"line (\d+)", str(e))
            raise ConfigError(f"not valid TOML: {e}", path=src,
                              line=int(m.group(1)) if m else None) from None
    where = _Where(text, src)
    cfg = _build(Config, data or {}, "", where)
    cfg.given.update(where.given)
    if src is not None:
        cfg.base_dir = src.resolve().parent
        cfg.source = src.resolve()
    for key in FILE_RELATIVE_KEYS:  # paths in a config are relative to it (input.path: see pipeline)
        val = get_key(cfg, key)
        if val and val.strip().lower() != "none" and not Path(val).expanduser().is_absolute():
            _set_key(cfg, key, str(cfg.base_dir / Path(val).expanduser()))
    for ov in overrides or []:
        apply_override(cfg, ov)
    validate(cfg)
    return cfg


def parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_override(cfg: Config, assignment: str) -> None:
    """Apply ``section.key=value`` (value parsed as TOML, else a string)."""
    if "=" not in assignment:
        raise ConfigError(f"--set expects section.key=value, got {assignment!r}")
    key, text = assignment.split("=", 1)
    key = key.strip()
    m = re.match(r"^(?P<head>[\w.]+)\[(?P<n>\d+)\]\.(?P<rest>[\w.]+)$", key)
    if m:  # a field of one element of an array of tables: lighting.lights[0].angle=2
        where = _Where(None, None, origin=f"--set {key}={text.strip()}")
        _override_element(cfg, m.group("head"), int(m.group("n")), m.group("rest"), parse_value(text.strip()),
                          where)
        cfg.given.update(where.given)
        return
    parts = key.split(".")
    nested: dict = {}
    cur = nested
    for p in parts[:-1]:
        cur = cur.setdefault(p, {})
    value = parse_value(text.strip())
    if key in PATH_KEYS and isinstance(value, str) and value and value.strip().lower() != "none":
        # a path typed on the command line is relative to the current folder
        value = str((Path.cwd() / Path(value).expanduser()).absolute())
    cur[parts[-1]] = value
    where = _Where(None, None, origin=f"--set {key}={text.strip()}")
    _build(Config, nested, "", where, base=cfg)
    cfg.given.update(where.given)


def _element_class(obj: Any, attr: str, key: str) -> type:
    """The dataclass of the elements of the list field ``attr`` (e.g. LightConfig)."""
    t = _hints(type(obj)).get(attr) if dataclasses.is_dataclass(obj) else None
    args = get_args(t) if t is not None and get_origin(t) in (list, typing.List) else ()
    if not args or not dataclasses.is_dataclass(args[0]):
        raise ConfigError("unknown key" + _suggest(key, all_keys()), key=key)
    return args[0]


def _override_element(cfg: Config, head: str, n: int, rest: str, value: Any, where: "_Where | None" = None) -> None:
    """``--set lighting.lights[n].field=value``: set a field of element ``n``; ``n`` equal to
    the number of elements adds one with the defaults."""
    parts = head.split(".")
    obj: Any = get_key(cfg, ".".join(parts[:-1])) if len(parts) > 1 else cfg
    attr = _ALIASES.get(parts[-1], parts[-1])
    cls = _element_class(obj, attr, f"{head}[{n}].{rest}")
    items = getattr(obj, attr)
    if n > len(items):
        raise ConfigError(f"there are {len(items)} element(s); [{len(items)}] adds one", key=f"{head}[{n}]")
    elem = items[n] if n < len(items) else cls()
    nested: dict = {}
    cur = nested
    rparts = rest.split(".")
    for p in rparts[:-1]:
        cur = cur.setdefault(p, {})
    cur[rparts[-1]] = value
    _build(cls, nested, f"{head}[{n}].", where or _Where(None, None), base=elem)
    if n == len(items):
        items.append(elem)


def validate(cfg: Config) -> None:
    """Range checks that types alone cannot express: each section's own (``check``, next to its
    schema), then the stages' (an error placed where its value came from: the config file and the
    key's line, or the --set on the command line)."""
    _check_tree(cfg, "", cfg)
    for check in _STAGE_CHECKS:
        try:
            check(cfg)
        except ConfigError as e:
            raise (e if e.path is not None or e.origin is not None or e.key is None
                   else error_at(cfg, e.key, e.message)) from None


def _check_tree(section: Any, prefix: str, cfg: Config) -> None:
    """Run ``check`` of ``section`` and of every section and array-of-tables element under it,
    in the schema's order; the first key out of range is an error placed by :func:`error_at`."""
    def need(ok: bool, key: str, msg: str) -> None:
        if not ok:
            raise error_at(cfg, prefix + key, msg)

    check = getattr(section, "check", None)
    if check is not None:
        check(need)
    for attr in _fields(type(section)):
        value = getattr(section, attr)
        key = prefix + _toml_name(attr)
        if dataclasses.is_dataclass(value):
            _check_tree(value, key + ".", cfg)
        elif isinstance(value, list):
            for i, item in enumerate(value):
                if dataclasses.is_dataclass(item):
                    _check_tree(item, f"{key}[{i}].", cfg)
