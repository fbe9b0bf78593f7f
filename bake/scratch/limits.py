"""Scratch's limits (shared/docs/scratch.md, section 2), in one place for every check and report."""

from __future__ import annotations

LIST_ITEM_LIMIT = 200_000  # vanilla `add to list` stops here (loading is not limited)
PROJECT_JSON_LIMIT = 5 * 1024 * 1024  # 5 MiB upload limit on scratch.mit.edu
ASSET_LIMIT = 10_000_000  # each costume/sound must be under 10 MB to save on scratch.mit.edu
# An empty project.json (stage, one sprite, backdrop and costume entries, meta) is about this size.
PROJECT_BASE_BYTES = 1_500


def fmt_bytes(n: int) -> str:
    """A size as the reports print it: bytes, KiB (one decimal) or MiB (two)."""
    if n >= 1024 * 1024:
        return f"{n / 1024 / 1024:.2f} MiB"
    if n >= 1024:
        return f"{n / 1024:.1f} KiB"
    return f"{n} B"
