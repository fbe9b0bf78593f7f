"""Stage progress on a terminal: a bar that advances stage by stage, for bakes that take a while.

Nothing is shown when stderr is not a terminal (pipes, CI, tests) or with ``--quiet``, and
nothing for a bake that ends within ``after`` seconds (2 s; the environment variable
``BAKE_PROGRESS_AFTER`` overrides it, which the tests use). The bar is transient: when the
bake ends it disappears and the summary is printed in its place. Stages that come from the
stage cache count as done at once.
"""

from __future__ import annotations

import os
import sys
import threading
from typing import Any

DEFAULT_AFTER = 2.0


def _after_default() -> float:
    try:
        return max(0.0, float(os.environ.get("BAKE_PROGRESS_AFTER", DEFAULT_AFTER)))
    except ValueError:
        return DEFAULT_AFTER


class StageProgress:
    """The ``progress`` callback of :func:`bake.pipeline.run`: ``(stage, "start" | "done" | "cached")``."""

    def __init__(self, quiet: bool = False, total: int | None = None, *, after: float | None = None,
                 console: Any = None):
        if console is None and not quiet and sys.stderr.isatty():
            from rich.console import Console

            console = Console(stderr=True)
        self.enabled = not quiet and console is not None and console.is_terminal
        self.console = console
        self.total = total
        self.after = _after_default() if after is None else after
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self._bar: Any = None
        self._task: Any = None
        self._done = 0
        self._current = ""
        self._stopped = False

    def __call__(self, stage: str, event: str) -> None:
        if not self.enabled:
            return
        with self._lock:
            if self._stopped:
                return
            if self._timer is None and self._bar is None:
                if self.after <= 0:
                    self._show_locked()
                else:
                    self._timer = threading.Timer(self.after, self._show)
                    self._timer.daemon = True
                    self._timer.start()
            if event == "start":
                self._current = stage
            elif event in ("done", "cached"):
                self._done += 1
                self._current = f"{stage} (cached)" if event == "cached" else stage
            self._update_locked()

    def _show(self) -> None:
        with self._lock:
            if not self._stopped and self._bar is None:
                self._show_locked()

    def _show_locked(self) -> None:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, \
            TimeElapsedColumn

        self._bar = Progress(SpinnerColumn(), TextColumn("bake: [bold]{task.description:<22}"), BarColumn(),
                             MofNCompleteColumn(), TextColumn("stages"), TimeElapsedColumn(),
                             console=self.console, transient=True)
        self._task = self._bar.add_task(self._current or "starting", total=self.total, completed=self._done)
        self._bar.start()

    def _update_locked(self) -> None:
        if self._bar is not None:
            self._bar.update(self._task, description=self._current, completed=self._done, total=self.total)

    def stop(self) -> None:
        with self._lock:
            self._stopped = True
            if self._timer is not None:
                self._timer.cancel()
            if self._bar is not None:
                self._bar.stop()
                self._bar = None


def stage_count(cfg: Any) -> int:
    """How many stages a config runs (the bar's length)."""
    from . import pipeline

    return sum(1 for _, on, _ in pipeline.plan(cfg) if on)


__all__ = ["StageProgress", "stage_count", "DEFAULT_AFTER"]
