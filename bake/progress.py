"""Stage progress: a bar on a terminal, a line now and then elsewhere, for bakes that take a while.

On a terminal, a bar advances stage by stage, and within a stage its text follows the steps the
stage reports (:func:`step`: the simplify stage's library runs, repair rounds, measures and
probes). Nothing is shown for a bake that ends within ``after`` seconds (2 s; the environment
variable ``BAKE_PROGRESS_AFTER`` overrides it, which the tests use). The bar is transient: when
the bake ends it disappears and the summary is printed in its place. Stages that come from the
stage cache count as done at once.

When stderr is not a terminal (a Makefile, a pipe, CI), a stage that runs past ``every``
seconds (10 s; ``BAKE_PROGRESS_EVERY``) prints one line, and another at most every ``every``
seconds while it runs: ``bake: simplify 20 s: repair round 2 (library run)``, the stage, its
elapsed seconds and its last step. So a long bake in a Makefile is not silent for minutes. With
``--quiet``, nothing.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager
from typing import Any, Callable, Iterator

DEFAULT_AFTER = 2.0
DEFAULT_EVERY = 10.0

# the running stage's step callback (set by the pipeline around each stage; None: nobody listens)
_reporter: Callable[[str], None] | None = None


def step(text: str) -> None:
    """What the running stage is doing now (a few words: "measure", "repair round 2"), for the
    progress display. Cheap when nobody listens; stages call it between their phases."""
    r = _reporter
    if r is not None:
        r(text)


@contextmanager
def reporting(callback: Callable[[str], None] | None) -> Iterator[None]:
    """Route :func:`step` to ``callback`` while the block runs (the pipeline, around a stage)."""
    global _reporter
    before, _reporter = _reporter, callback
    try:
        yield
    finally:
        _reporter = before


def _env_seconds(name: str, default: float) -> float:
    try:
        return max(0.0, float(os.environ.get(name, default)))
    except ValueError:
        return default


def _after_default() -> float:
    return _env_seconds("BAKE_PROGRESS_AFTER", DEFAULT_AFTER)


class _Lines:
    """Without a terminal: a line on ``stream`` when a stage has run ``every`` seconds, and at most
    every ``every`` seconds after, from a thread that wakes while a stage runs."""

    def __init__(self, every: float, stream: Any):
        self.every = every
        self.stream = stream
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stage = ""
        self._step = ""
        self._started = 0.0
        self._thread: threading.Thread | None = None
        self._stopped = False

    def __call__(self, stage: str, event: str, detail: str = "") -> None:
        with self._lock:
            if event == "start":
                self._stage, self._step, self._started = stage, "", time.monotonic()
                if self._thread is None:
                    self._thread = threading.Thread(target=self._run, name="bake-progress", daemon=True)
                    self._thread.start()
            elif event == "step" and stage == self._stage:
                self._step = detail
            elif event in ("done", "cached", "skipped") and stage == self._stage:
                self._stage = ""

    def _run(self) -> None:
        last = None
        while not self._wake.wait(min(1.0, self.every / 4) if self.every > 0 else 0.25):
            with self._lock:
                if self._stopped:
                    return
                stage, step_, started = self._stage, self._step, self._started
            now = time.monotonic()
            if not stage or now - started < self.every:
                continue
            if last is not None and last[0] == (stage, started) and now - last[1] < self.every:
                continue
            el = now - started
            line = f"bake: {stage} {el:.0f} s" if el >= 10 else f"bake: {stage} {el:.1f} s"
            line += f": {step_}" if step_ else ""
            try:
                print(line, file=self.stream, flush=True)
            except (OSError, ValueError):  # the stream went away (a closed pipe)
                return
            last = ((stage, started), now)

    def stop(self) -> None:
        with self._lock:
            self._stopped = True
        self._wake.set()


class StageProgress:
    """The ``progress`` callback of :func:`bake.pipeline.run`: ``(stage, "start" | "done" |
    "cached" | "skipped")`` and ``(stage, "step", text)`` for a step within a stage ("skipped": the
    stage found nothing to do, so the bar counts one stage fewer)."""

    def __init__(self, quiet: bool = False, total: int | None = None, *, after: float | None = None,
                 console: Any = None, every: float | None = None, stream: Any = None):
        if console is None and not quiet and sys.stderr.isatty():
            from rich.console import Console

            console = Console(stderr=True)
        self.enabled = not quiet and console is not None and console.is_terminal
        self.console = console
        self.total = total
        self.after = _after_default() if after is None else after
        # without a terminal: a line now and then for long stages
        self.lines = None if quiet or self.enabled else _Lines(
            _env_seconds("BAKE_PROGRESS_EVERY", DEFAULT_EVERY) if every is None else every,
            sys.stderr if stream is None else stream)
        self._lock = threading.Lock()
        self._timer: threading.Timer | None = None
        self._bar: Any = None
        self._task: Any = None
        self._done = 0
        self._current = ""
        self._stage = ""
        self._stopped = False

    def __call__(self, stage: str, event: str, detail: str = "") -> None:
        if self.lines is not None:
            self.lines(stage, event, detail)
        if not self.enabled:
            return
        with self._lock:
            if self._stopped:
                return
            if event == "step":
                if stage == self._stage:
                    self._current = f"{stage}: {detail}" if detail else stage
                    self._update_locked()
                return
            if self._timer is None and self._bar is None:
                if self.after <= 0:
                    self._show_locked()
                else:
                    self._timer = threading.Timer(self.after, self._show)
                    self._timer.daemon = True
                    self._timer.start()
            if event == "start":
                self._current = self._stage = stage
            elif event in ("done", "cached"):
                self._done += 1
                self._current = f"{stage} (cached)" if event == "cached" else stage
            elif event == "skipped" and self.total:
                self.total -= 1
            self._update_locked()

    def _show(self) -> None:
        with self._lock:
            if not self._stopped and self._bar is None:
                self._show_locked()

    def _show_locked(self) -> None:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, \
            TimeElapsedColumn

        self._bar = Progress(SpinnerColumn(), TextColumn("bake: [bold]{task.description:<34}"), BarColumn(),
                             MofNCompleteColumn(), TextColumn("stages"), TimeElapsedColumn(),
                             console=self.console, transient=True)
        self._task = self._bar.add_task(self._current or "starting", total=self.total, completed=self._done)
        self._bar.start()

    def _update_locked(self) -> None:
        if self._bar is not None:
            self._bar.update(self._task, description=self._current, completed=self._done, total=self.total)

    def stop(self) -> None:
        if self.lines is not None:
            self.lines.stop()
        with self._lock:
            self._stopped = True
            if self._timer is not None:
                self._timer.cancel()
            if self._bar is not None:
                self._bar.stop()
                self._bar = None


__all__ = ["StageProgress", "step", "reporting", "DEFAULT_AFTER", "DEFAULT_EVERY"]
