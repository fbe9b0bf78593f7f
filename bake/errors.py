"""Errors that reach the user as one line: where (file, line or key) and what was expected.

Exit statuses (documented in README.md):
  0  success
  1  internal error (a bug; rerun with --debug for the traceback)
  2  bad command line or config (unknown key, wrong type, bad value)
  3  bad input file (unreadable, malformed, out of range, NaN/Inf, unsafe archive)
  4  under --strict: a Scratch limit was exceeded, or the report lists a problem (all-black lighting)
  5  a stage failed on valid input (e.g. an external tool crashed or timed out)
"""

from __future__ import annotations

import os
from pathlib import Path


class BakeError(Exception):
    """An error with a place. ``str(err)`` is the one-line message shown to the user."""

    exit_code = 1
    # the model cannot be baked whatever its files come to hold (a format bake does not read, a
    # path that is no file): `bake watch` stops on such an error in its first bake
    unwatchable = False

    def __init__(self, message: str, *, path: str | Path | None = None, line: int | None = None,
                 key: str | None = None, origin: str | None = None, unwatchable: bool = False):
        self.unwatchable = unwatchable
        self.message = message  # what was wrong, without the place
        # files are named by their absolute paths, whichever way the command or a config gave them
        self.path = Path(os.path.abspath(path)) if path is not None else None
        self.line = line
        self.key = key
        self.origin = origin  # the command-line option that gave the value (e.g. "--set k=v")
        super().__init__(self.format())

    def format(self) -> str:
        where = ""
        if self.path is not None:
            where = str(self.path)
            if self.line is not None:
                where += f":{self.line}"
        if self.key is not None:
            where = f"{where}: key '{self.key}'" if where else f"key '{self.key}'"
        text = self.message if self.origin is None else f"{self.message} (from {self.origin} on the command line)"
        return f"{where}: {text}" if where else text


class ConfigError(BakeError):
    exit_code = 2


class InputError(BakeError):
    exit_code = 3


class LimitError(BakeError):
    exit_code = 4


class StageError(BakeError):
    exit_code = 5
