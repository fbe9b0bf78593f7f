"""``bake watch MODEL|CONFIG``: bake, then bake again whenever an input changes.

The inputs are the config (if one is given), the model and every file the last bake read
(``Scene.source.files_read``: .mtl, textures, glTF buffers, ``textures.texture``, the project of
``export.into``). Their folders are watched with watchdog (inotify on Linux, FSEvents on macOS,
ReadDirectoryChangesW on Windows): no polling loop of ours. Editors save in bursts (write, rename,
chmod), so a bake starts once the inputs have been quiet for ``debounce`` seconds; a change during
a bake starts another one right after it. The stage cache (bake/cache/) makes the re-bake start
at the first stage whose inputs changed.

Every bake prints one line (time, model, triangles, vertices, list bytes, seconds, which stages
came from the cache, exceeded limits); a bake that fails prints its one-line error and the watch
goes on with the last good outputs left in place. report.html is written with a reload script
(``bake.outputs.html.live_script``) so a browser showing it reloads after each bake. Ctrl-C (or
SIGTERM) ends the watch: the bake under way stops (outputs are written atomically, so the folder
keeps the last complete bake), report-live.js is removed, the exit status is 0.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import traceback
from pathlib import Path
from typing import Any, TextIO

from .errors import BakeError


class _Changes:
    """watchdog's handler: remembers that one of the watched files changed."""

    def __init__(self) -> None:
        self.files: set[str] = set()
        self.lock = threading.Lock()
        self.event = threading.Event()
        self.last = 0.0
        self.changed: set[str] = set()

    def watch(self, files: set[str]) -> None:
        with self.lock:
            self.files = set(files)

    def dispatch(self, event: Any) -> None:  # watchdog calls this from its thread
        if getattr(event, "is_directory", False) or getattr(event, "event_type", "") in ("opened", "closed_no_write"):
            return
        paths = [getattr(event, "src_path", ""), getattr(event, "dest_path", "")]
        with self.lock:
            hit = [os.path.abspath(os.fsdecode(p)) for p in paths if p]
            hit = [p for p in hit if p in self.files]
            if hit:
                self.changed.update(hit)
                self.last = time.monotonic()
                self.event.set()

    def take(self) -> set[str]:
        with self.lock:
            out, self.changed = self.changed, set()
            self.event.clear()
            return out


class Watcher:
    """The folders of the watched files, scheduled on one watchdog observer."""

    def __init__(self, handler: _Changes):
        from watchdog.observers import Observer

        self.handler = handler
        self.observer = Observer()
        self.observer.daemon = True
        self.watches: dict[str, Any] = {}
        self.observer.start()

    def update(self, files: set[str]) -> None:
        self.handler.watch(files)
        want = set()
        for f in files:
            d = os.path.dirname(f)
            while d and not os.path.isdir(d):  # a folder that is gone: watch the nearest one there is
                up = os.path.dirname(d)
                d = "" if up == d else up
            if d:
                want.add(d)
        for d in set(self.watches) - want:
            try:
                self.observer.unschedule(self.watches.pop(d))
            except (KeyError, ValueError, OSError):
                pass
        for d in sorted(want - set(self.watches)):
            try:
                self.watches[d] = self.observer.schedule(self.handler, d, recursive=False)
            except OSError:
                pass

    def stop(self) -> None:
        self.observer.stop()
        self.observer.join(timeout=5)


def _stamp() -> str:
    return time.strftime("%H:%M:%S")


def fmt_bytes(n: int) -> str:
    return f"{n / 1024:.1f} KiB" if n < 1024 * 1024 else f"{n / 1024 / 1024:.2f} MiB"


def one_line(rep: dict, out: Path, seconds: float) -> str:
    """The summary of one bake in one line."""
    s = rep["scene"]
    name = Path(rep["input"]["path"] or "model").name
    total = sum(v["bytes"] for v in rep["lists"].values())
    parts = [f"{name}: {s['triangles']:,} triangles, {s['vertices']:,} vertices, {len(rep['lists'])} lists "
             f"{fmt_bytes(total)}, in {seconds:.2f} s"]
    cached = (rep.get("cache") or {}).get("from_cache") or []
    if cached:
        parts.append("from the cache: " + (cached[0] if len(cached) == 1 else f"{cached[0]}..{cached[-1]}"))
    warnings = sum(len(st["warnings"]) for st in rep["stages"])
    if warnings:
        parts.append(f"{warnings} warning{'s' if warnings > 1 else ''}")
    bad = [lim for lim in rep["limits"] if not lim["ok"]]
    if bad:
        parts.append(f"LIMIT EXCEEDED: {bad[0]['name']} = {bad[0]['value']} > {bad[0]['limit']}")
    return f"{_stamp()} " + "; ".join(parts) + f" -> {out}/"


def bake_once(target: Path, overrides: list[str], out: Path, *, quiet: bool) -> tuple[set[str], dict]:
    """One bake as ``bake run`` does it, with a live report.html. Returns the files it read (to
    watch) and the report. Raises BakeError (the files known so far are in ``err.watch``)."""
    from . import pipeline
    from .outputs import output
    from .progress import StageProgress

    files = {os.path.abspath(target)}
    try:
        cfg = pipeline.load_config_for(target, overrides)
        model = Path(cfg.input.path)
        files.add(os.path.abspath(model if model.is_absolute() else cfg.base_dir / model))
        if cfg.export.into:
            files.add(os.path.abspath(cfg.export.into))
        cfg.out_dir = out
        prog = StageProgress(quiet, total=pipeline.stage_count(cfg))
        try:
            result = pipeline.run(cfg, progress=prog)
        finally:
            prog.stop()
        files |= {os.path.abspath(p) for p in result.scene.source.files_read}
        rep = output.finish(result, out, live_report=True)
    except BakeError as e:
        e.watch = files  # type: ignore[attr-defined]
        raise
    return files, rep


def watch(target: Path, overrides: list[str], out: Path, *, quiet: bool = False, debug: bool = False,
          debounce: float = 0.1, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Bake ``target`` now and after every change of its inputs until Ctrl-C / SIGTERM (status 0)."""
    stdout = stdout or sys.stdout
    stderr = stderr or sys.stderr
    target = Path(target)
    out = Path(out)
    handler = _Changes()
    watcher = Watcher(handler)
    old_term = None
    if threading.current_thread() is threading.main_thread():
        def _term(signum, frame):  # SIGTERM ends the watch like Ctrl-C
            raise KeyboardInterrupt
        old_term = signal.signal(signal.SIGTERM, _term)
    files: set[str] = {os.path.abspath(target)}
    shown: set[str] = set()
    first = True
    try:
        while True:
            t0 = time.perf_counter()
            try:
                files, rep = bake_once(target, overrides, out, quiet=quiet)
                line = one_line(rep, out, time.perf_counter() - t0)
                if not quiet:
                    print(line, file=stdout, flush=True)
            except BakeError as e:
                files = files | getattr(e, "watch", set())
                if debug:
                    traceback.print_exc(file=stderr)
                print(f"{_stamp()} bake: error: {e}", file=stderr, flush=True)
                if first and e.unwatchable:  # no edit of the watched files can make it bake
                    return e.exit_code
            except (MemoryError, RecursionError, Exception) as e:  # a bug: say so, keep watching
                if debug:
                    traceback.print_exc(file=stderr)
                print(f"{_stamp()} bake: internal error: {type(e).__name__}: {e} (rerun with --debug for the "
                      "traceback)", file=stderr, flush=True)
            first = False
            watcher.update(files)
            if not quiet and files != shown:
                print(f"{_stamp()} watching {len(files)} file(s); Ctrl-C to stop", file=stderr, flush=True)
                shown = set(files)
            _wait_for_change(handler, debounce)
    except KeyboardInterrupt:
        pass
    finally:
        watcher.stop()
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        from .outputs.html import LIVE_NAME

        try:
            (out / LIVE_NAME).unlink()
        except OSError:
            pass
    if not quiet:
        print(f"{_stamp()} bake watch: stopped", file=stderr, flush=True)
    return 0


def _wait_for_change(handler: _Changes, debounce: float) -> set[str]:
    """Block until a watched file changed and then stayed quiet for ``debounce`` seconds (at most
    2 s after the first change, so a file written continuously still gets baked)."""
    while not handler.event.wait(0.25):  # short waits: Ctrl-C is handled between them
        pass
    first = time.monotonic()
    while True:
        quiet_for = time.monotonic() - handler.last
        if quiet_for >= debounce or time.monotonic() - first >= 2.0:
            return handler.take()
        time.sleep(min(0.02, max(0.0, debounce - quiet_for)))


__all__ = ["watch", "bake_once", "one_line"]
