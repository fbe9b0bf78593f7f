"""Numbers as short as they can be, for Scratch lists and project.json.

Floats are rounded to a number of decimals and written in the shortest text that reads back
as the rounded value (Python's ``repr`` of the rounded double, which is what JSON and
JavaScript's ``Number()`` agree on). Whole numbers lose their ``.0``; ``-0`` becomes ``0``.
NaN and Infinity are refused: Scratch's parser rejects ``null`` items, which is what
``JSON.stringify`` turns them into (shared/docs/scratch.md, section 1).
"""

from __future__ import annotations

import json
import math

import numpy as np

from ..errors import StageError
from ..scene import ScratchList

# A list entry in project.json is  "<20-char id>":["<name>",[items]],  — the id is 20
# characters in projects saved by Scratch; the rest is punctuation: the id's quotes and colon,
# the entry's brackets, the comma after the name, and the comma before the next entry (the name's
# quotes and the items' brackets are counted with them).
LIST_ENTRY_OVERHEAD = 20 + 2 + 1 + 2 + 1 + 1


def decimals_for(step: float) -> int:
    """Decimals needed to resolve ``step`` (e.g. 0.002 -> 3)."""
    if not (step > 0) or not math.isfinite(step):
        return 6
    return max(0, int(math.ceil(-math.log10(step) - 1e-9)))


def position_decimals(diagonal: float, precision: int) -> int:
    """Decimals of the grid vertex positions are written on.

    The grid step is ``10 ** -decimals``: the largest power of ten not above
    ``diagonal * 10 ** -precision`` (never coarser than 1), and a position ``x`` is written as
    ``round(x, decimals)`` (numpy's ``np.round``: nearest multiple of the step, ties to even).
    Every stage that builds on the positions as they will be written (the BSP) and every list
    that stores positions uses this one grid."""
    return decimals_for(diagonal * 10.0 ** (-precision))


def round_positions(positions: np.ndarray, decimals: int) -> np.ndarray:
    """Positions snapped to the grid exactly as :func:`format_numbers` rounds them."""
    a = np.asarray(positions, np.float64)
    return np.where(np.abs(a) < 1e15, np.round(a, decimals), a) + 0.0


def format_numbers(values: np.ndarray | list, decimals: int | None = None, *, name: str = "") -> list[str]:
    """Format a 1-D array as short decimal strings.

    ``decimals=None`` writes integers as integers and floats in their shortest round-trip
    form. Raises StageError (naming the list) if any value is NaN or infinite.
    """
    a = np.asarray(values)
    if a.ndim != 1:
        a = a.ravel()
    if a.size == 0:
        return []
    if a.dtype.kind in "iub":
        return list(map(str, a.astype(np.int64).tolist()))
    a = a.astype(np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise StageError(f"list '{name}' has a non-finite value at item {first + 1}; refusing to write "
                         f"NaN/Infinity into a Scratch list")
    if decimals is not None:
        # np.round scales by 10**decimals; leave magnitudes where that would lose digits
        a = np.where(np.abs(a) < 1e15, np.round(a, decimals), a)
    a = a + 0.0  # turns -0.0 into 0.0
    whole = (a == np.floor(a)) & (np.abs(a) < 2.0 ** 53)
    out = np.empty(a.size, dtype=object)
    out[:] = list(map(repr, a.tolist()))
    if whole.any():
        out[whole] = list(map(str, a[whole].astype(np.int64).tolist()))
    return out.tolist()


def json_array(items: list[str], kind: str = "number") -> str:
    """A JSON array from preformatted items (numbers unquoted, strings quoted)."""
    if kind == "string":
        return json.dumps(items, ensure_ascii=False, separators=(",", ":"))
    return "[" + ",".join(items) + "]"


def render_items(lst: ScratchList) -> list[str]:
    """A list's items as the text written into project.json and the list files."""
    if lst.kind == "string":
        return [str(v) for v in lst.values]
    return format_numbers(np.asarray(lst.values), lst.decimals, name=lst.name)


def project_json_bytes(name: str, items_json: str) -> int:
    """Bytes this list adds to a project.json (hidden monitor, so stored once)."""
    return len(json.dumps(name, ensure_ascii=False).encode()) + len(items_json.encode()) + LIST_ENTRY_OVERHEAD
