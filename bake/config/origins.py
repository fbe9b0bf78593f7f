"""Where a key's value came from: the line of a dotted key in the TOML text, or the ``--set``
on the command line, for messages that point at it."""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import ConfigError
from .schema import Config


class _Where:
    """Finds the line of a dotted key in the TOML text, for messages."""

    def __init__(self, text: str | None, path: Path | None, origin: str = "file"):
        self.lines = text.splitlines() if text else []
        self.path = path
        self.origin = origin  # "file", or the --set assignment being applied
        self.given: dict[str, str] = {}  # keys set, -> origin

    def line_of(self, key: str) -> int | None:
        if not self.lines:
            return None
        m = re.match(r"^(?P<table>[\w.]+)\[(?P<index>\d+)\](?:\.(?P<rest>.+))?$", key)
        if m:  # a field of the n-th [[table]] (e.g. lighting.lights[1].angle)
            return self._element_line(m.group("table"), int(m.group("index")), m.group("rest"))
        parts = key.split(".")
        last = re.escape(parts[-1].split("[")[0])
        section = ".".join(parts[:-1])
        current = ""
        found = None
        for i, raw in enumerate(self.lines, 1):
            s = raw.strip()
            m = re.match(r"^\[\[?\s*([^\]]+?)\s*\]?\]$", s)
            if m:
                current = m.group(1).replace(" ", "")
                if current == key:
                    return i
                continue
            if re.match(rf"^{last}\s*=", s) or re.match(rf"^[\w.]*\.{last}\s*=", s):
                if current == section or section.endswith(current) or not section or \
                        s.startswith(section.split(".", 1)[-1]):
                    return i
                if found is None:
                    found = i
        return found

    def is_header(self, key: str) -> bool:
        """Whether ``key`` is written as a ``[table]`` (or ``[[table]]``) header in the file."""
        line = self.line_of(key)
        return line is not None and self.lines[line - 1].strip().startswith("[")

    def _element_line(self, table: str, index: int, rest: str | None) -> int | None:
        """The line of ``rest`` (a field, or None for the element itself) in the ``index``-th
        ``[[table]]`` block; for an inline array (``lights = [{...}, ...]``) the line naming the
        field after the array starts, else the array's line."""
        seen = -1
        start = None
        field = None if rest is None else re.escape(rest.split(".")[0].split("[")[0])  # direction[1] -> direction
        for i, raw in enumerate(self.lines, 1):
            s = raw.strip()
            h = re.match(r"^\[\[\s*([^\]]+?)\s*\]\]$", s)
            if start is not None and re.match(r"^\[", s):
                break  # the next table header ends the block
            if h and h.group(1).replace(" ", "") == table:
                seen += 1
                if seen == index:
                    start = i
                    if rest is None:
                        return i
            elif start is not None and field is not None and re.match(rf"^{field}\s*=", s):
                return i
        if start is not None:
            return start
        name = table.rsplit(".", 1)[-1]
        for i, raw in enumerate(self.lines, 1):  # inline: lights = [{...}] or lighting.lights = [...]
            if re.match(rf"^\s*(?:[\w.]*\.)?{re.escape(name)}\s*=", raw):
                if field is not None:
                    for j in range(i, len(self.lines) + 1):
                        if re.search(rf"\b{field}\s*=", self.lines[j - 1]):
                            return j
                return i
        return None

    def error(self, key: str, msg: str) -> ConfigError:
        if self.origin != "file":
            return ConfigError(msg, key=key, origin=self.origin)
        return ConfigError(msg, path=self.path, line=self.line_of(key), key=key)


def origin(cfg: Config, key: str) -> str | None:
    """Where ``key`` was set: "file", "--set KEY=VALUE", or None (its default)."""
    return cfg.given.get(key)


def error_at(cfg: Config, key: str, msg: str) -> ConfigError:
    """A range error on ``key`` placed where the value came from: the config file and the key's
    line in it, or the --set assignment on the command line (or just the key, for a default)."""
    where = cfg.given.get(key)
    if where is None and "[" in key:  # lighting.lights[0].color: the light's table
        where = next((v for k, v in cfg.given.items() if k.startswith(key.split("]")[0] + "]")), None)
    if where is not None and where != "file":
        return ConfigError(msg, key=key, origin=where)
    if cfg.source is None:
        return ConfigError(msg, key=key)
    try:
        text = cfg.source.read_text("utf-8")
    except (OSError, UnicodeDecodeError):
        text = None
    line = _Where(text, cfg.source).line_of(key) if where == "file" or where is None else None
    return ConfigError(msg, path=cfg.source, line=line, key=key)
