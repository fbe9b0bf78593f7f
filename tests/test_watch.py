"""``bake watch`` for real (a subprocess, files edited on disk, SIGINT), the reload of report.html
in a real browser (headless Chromium, skipped without it), and the progress bar (a real pty)."""

from __future__ import annotations

import io
import json
import os
import queue
import re
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from bake.outputs import html
from bake.progress import StageProgress

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_cache import CONFIG_B, write_model  # noqa: E402
from conftest import sigint_default

TIMEOUT = 180.0  # a loaded 2-core machine


class Proc:
    """A subprocess whose stdout and stderr lines arrive on one queue."""

    def __init__(self, args: list[str], cwd: Path, env: dict | None = None):
        self.p = subprocess.Popen(args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  env=env, preexec_fn=sigint_default)
        self.q: queue.Queue = queue.Queue()
        self.lines: list[tuple[str, str]] = []
        self.seen: dict[str, int] = {}  # per stream: lines up to here were matched or passed over
        self.threads = [threading.Thread(target=self._pump, args=(name, stream), daemon=True)
                        for name, stream in (("out", self.p.stdout), ("err", self.p.stderr))]
        for t in self.threads:
            t.start()

    def _pump(self, name, stream):
        for line in stream:
            self.q.put((name, line.rstrip("\n")))

    def expect(self, pattern: str, stream: str = "out", timeout: float = TIMEOUT) -> str:
        """The next line of ``stream`` that matches, after the last one this returned for that
        stream (stdout and stderr interleave freely: a line of one that arrived while waiting for
        the other is still found)."""
        seen = self.seen.get(stream, 0)
        for k in range(seen, len(self.lines)):
            name, line = self.lines[k]
            if name == stream and re.search(pattern, line):
                self.seen[stream] = k + 1
                return line
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                name, line = self.q.get(timeout=0.2)
            except queue.Empty:
                assert self.p.poll() is None, f"bake watch exited ({self.p.returncode}): {self.lines}"
                continue
            self.lines.append((name, line))
            if name == stream and re.search(pattern, line):
                self.seen[stream] = len(self.lines)
                return line
        raise AssertionError(f"no {pattern!r} on {stream} within {timeout} s: {self.lines}")

    def stop(self):
        if self.p.poll() is None:
            self.p.kill()
            self.p.wait()


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


@pytest.mark.slow
def test_watch_rebakes_on_changes_survives_errors_and_stops_on_sigint(tmp_path):
    model = write_model(tmp_path / "m")
    cfg = tmp_path / "m" / "b.toml"
    cfg.write_text(CONFIG_B.replace("html = false", "html = true"))
    out = tmp_path / "out"
    w = Proc([sys.executable, "-m", "bake.cli", "watch", str(cfg), "--out", str(out)], cwd=tmp_path)
    try:
        first = w.expect(r"triangles.* -> ")
        assert "from the cache" not in first
        w.expect(r"watching \d+ file", "err")
        page = (out / "report.html").read_text()
        stamp = re.search(r"var s='([0-9a-f]{16})'", page).group(1)
        assert (out / html.LIVE_NAME).read_text() == f"window.bakeReportStamp&&window.bakeReportStamp('{stamp}');\n"
        lists0 = json.loads((out / "lists.json").read_text())["lists"]

        # a lighting key: re-baked from the lighting stage on
        _edit(cfg, "ambient = [0.2, 0.2, 0.2]", "ambient = [0.5, 0.4, 0.3]")
        line = w.expect(r"triangles.* -> ")
        assert "from the cache: import..textures" in line, line
        rep = json.loads((out / "report.json").read_text())
        assert rep["config"]["lighting"]["ambient"] == [0.5, 0.4, 0.3]
        assert json.loads((out / "lists.json").read_text())["lists"]["tri colors"] != lists0["tri colors"]
        page2 = (out / "report.html").read_text()
        stamp2 = re.search(r"var s='([0-9a-f]{16})'", page2).group(1)
        assert stamp2 != stamp and stamp2 in (out / html.LIVE_NAME).read_text()

        # the .mtl (a file the config does not name): everything again
        _edit(model.with_suffix(".mtl"), "Kd 0.8 0.3 0.2", "Kd 0.1 0.8 0.2")
        line = w.expect(r"triangles.* -> ")
        assert "from the cache" not in line, line
        assert json.loads((out / "lists.json").read_text())["lists"]["mat colors"] != lists0["mat colors"]

        # a broken config: one error line, the watch goes on, the outputs stay
        before = (out / "lists.json").read_bytes()
        _edit(cfg, "[lighting]\n", "[lighting]\nambiant = 1\n")
        err = w.expect(r"bake: error: ", "err")
        assert "ambiant" in err and "did you mean" in err and str(cfg) in err
        assert (out / "lists.json").read_bytes() == before
        _edit(cfg, "ambiant = 1\n", "")
        line = w.expect(r"triangles.* -> ")
        assert "from the cache: " in line  # back to a config that was baked: all from the cache

        # a model file that is deleted and comes back
        text = model.read_bytes()
        model.unlink()
        w.expect(r"bake: error: .*scene\.obj", "err")
        model.write_bytes(text)
        w.expect(r"triangles.* -> ")

        w.p.send_signal(signal.SIGINT)
        assert w.p.wait(timeout=30) == 0
        for t in w.threads:
            t.join(timeout=10)
        while not w.q.empty():
            w.lines.append(w.q.get())
        errs = "\n".join(line for name, line in w.lines if name == "err")
        assert "bake watch: stopped" in errs and "Traceback" not in errs
        assert not (out / html.LIVE_NAME).exists()
    finally:
        w.stop()


def test_watch_debounces_a_burst_of_saves_into_one_bake(tmp_path):
    from bake import watch as watch_mod

    h = watch_mod._Changes()
    f = str(tmp_path / "a.toml")
    h.watch({f})

    class E:
        is_directory = False
        event_type = "modified"

        def __init__(self, p):
            self.src_path = p

    def burst():
        for _ in range(5):
            h.dispatch(E(f))
            time.sleep(0.03)
        h.dispatch(E(str(tmp_path / "other.txt")))  # not watched

    t = threading.Thread(target=burst)
    t0 = time.monotonic()
    t.start()
    changed = watch_mod._wait_for_change(h, 0.1)
    t.join()
    assert changed == {f}
    assert time.monotonic() - t0 >= 0.1 + 4 * 0.03 - 0.01  # waited for the burst to end
    assert not h.event.is_set()


# --------------------------------------------------------------------------- the browser
def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        p = shutil.which(name)
        if p:
            return p
    return None


class CDP:
    """The DevTools protocol over --remote-debugging-pipe (fds 3 and 4: JSON messages ending in NUL)."""

    def __init__(self, exe: str, url: str, profile: Path):
        r_in, w_in = os.pipe()  # we write, chromium reads fd 3
        r_out, w_out = os.pipe()  # chromium writes fd 4, we read
        os.set_inheritable(r_in, True)
        os.set_inheritable(w_out, True)

        def fds():
            os.dup2(r_in, 3)
            os.dup2(w_out, 4)

        # the player suite's flags (vm/player.js): nothing reaches for the network at start-up
        self.log = profile.parent / "chromium.log"
        with open(self.log, "wb") as log:
            self.p = subprocess.Popen([exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                       "--disable-background-networking", "--disable-component-update",
                                       "--disable-sync", "--host-resolver-rules=MAP * ~NOTFOUND",
                                       "--remote-debugging-pipe", f"--user-data-dir={profile}", url],
                                      preexec_fn=fds, pass_fds=(3, 4), stdout=log, stderr=log)
        os.close(r_in)
        os.close(w_out)
        self.w, self.r = w_in, r_out
        self.buf = b""
        self.n = 0
        # a cold first start (a fresh machine, a just-installed browser) took over 20 s once in CI
        try:
            self.call("Target.getTargets", timeout=120)
        except BaseException:
            self.close()
            raise

    def call(self, method: str, params: dict | None = None, session: str | None = None, timeout: float = 20):
        self.n += 1
        msg = {"id": self.n, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.w, json.dumps(msg).encode() + b"\0")
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            while b"\0" in self.buf:
                raw, self.buf = self.buf.split(b"\0", 1)
                m = json.loads(raw)
                if m.get("id") == self.n:
                    if "error" in m:
                        raise RuntimeError(m["error"])
                    return m["result"]
            ready, _, _ = select.select([self.r], [], [], 0.5)
            if ready:
                chunk = os.read(self.r, 1 << 16)
                if not chunk:
                    raise RuntimeError("chromium closed the pipe")
                self.buf += chunk
        tail = self.log.read_bytes()[-2000:].decode("utf-8", "replace")
        state = "running" if self.p.poll() is None else f"exited with {self.p.returncode}"
        raise TimeoutError(f"{method}: no answer in {timeout} s (chromium {state}); its log ends:\n{tail}")

    def close(self):
        try:
            self.call("Browser.close", timeout=5)
        except (RuntimeError, TimeoutError, OSError):
            pass
        try:
            self.p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.p.kill()
            self.p.wait()
        for fd in (self.w, self.r):
            try:
                os.close(fd)
            except OSError:
                pass


def test_report_html_reloads_itself_in_a_browser_when_the_watch_writes_a_new_one(tmp_path):
    exe = _chromium()
    if exe is None:
        pytest.skip("no Chromium on this machine (the reload is checked in a real browser)")
    from bake import cli

    model = write_model(tmp_path / "m", n=4)
    out = tmp_path / "out"
    assert cli.main(["run", str(model), "--out", str(out), "--quiet", "--set", "report.preview_width=64"]) == 0
    info = html.write(out, width=64, height=48, live=True)
    cdp = CDP(exe, (out / "report.html").as_uri(), tmp_path / "profile")
    try:
        def evaluate(expression):
            targets = cdp.call("Target.getTargets")["targetInfos"]
            page = next(t for t in targets if t["type"] == "page")
            sid = cdp.call("Target.attachToTarget", {"targetId": page["targetId"], "flatten": True})["sessionId"]
            r = cdp.call("Runtime.evaluate", {"expression": expression, "returnByValue": True}, session=sid)
            return r["result"].get("value", "")

        def page_state():
            return evaluate("document.readyState + ' ' + performance.timeOrigin + ' ' + "
                            "(document.documentElement.outerHTML.match(/var s='(\\w+)'/)||[])[1]")

        def wait_for(pred, what):
            end = time.monotonic() + 60
            while time.monotonic() < end:
                v = page_state()
                if pred(v):
                    return v
                time.sleep(0.2)
            raise AssertionError(f"{what}: {v}")

        state = wait_for(lambda v: v.startswith("complete") and v.endswith(info["live_stamp"]), "first page")
        origin = state.split()[1]
        time.sleep(1.5)  # polls report-live.js several times: the same stamp, no reload
        assert page_state().split()[1] == origin
        evaluate("window.scrollTo(0, 300); window.scrollY")  # the author was reading further down
        # a new bake's report (here: the same folder with another preview size)
        info2 = html.write(out, width=80, height=60, live=True)
        assert info2["live_stamp"] != info["live_stamp"]
        state = wait_for(lambda v: v.startswith("complete") and v.endswith(info2["live_stamp"]), "reloaded page")
        assert state.split()[1] != origin  # a new document, not the old one patched
        end = time.monotonic() + 20  # the reload keeps the place on the page (restored after the load)
        while evaluate("window.scrollY") != 300 and time.monotonic() < end:
            time.sleep(0.2)
        assert evaluate("window.scrollY") == 300
    finally:
        cdp.close()


# --------------------------------------------------------------------------- progress
def test_progress_bar_on_a_terminal_and_silence_elsewhere():
    from rich.console import Console

    buf = io.StringIO()
    prog = StageProgress(total=5, after=0, console=Console(file=buf, force_terminal=True, width=100))
    assert prog.enabled
    prog("import", "cached")
    prog("transform", "cached")
    prog("lighting", "start")
    time.sleep(0.3)
    prog.stop()
    text = buf.getvalue()
    assert "lighting" in text and "2/5" in text and "stages" in text
    quiet = io.StringIO()
    prog = StageProgress(total=5, after=0, console=Console(file=quiet, force_terminal=False))
    assert not prog.enabled
    prog("lighting", "start")
    prog.stop()
    assert quiet.getvalue() == ""
    # a bake shorter than the delay shows nothing on a terminal either
    buf = io.StringIO()
    prog = StageProgress(total=3, after=5.0, console=Console(file=buf, force_terminal=True))
    prog("import", "start")
    prog("import", "done")
    prog.stop()
    assert buf.getvalue() == ""


def test_bake_run_shows_the_bar_on_a_pty_and_nothing_on_a_pipe(tmp_path):
    import pty

    model = write_model(tmp_path / "m", n=4)
    env = dict(os.environ, BAKE_PROGRESS_AFTER="0", COLUMNS="100")
    args = [sys.executable, "-m", "bake.cli", "run", str(model), "--set", "report.html=false"]
    master, slave = pty.openpty()
    p = subprocess.Popen(args + ["--out", str(tmp_path / "a")], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=slave, env=env)
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        seen += chunk
    assert p.wait(timeout=120) == 0
    os.close(master)
    text = seen.decode("utf-8", "replace")
    assert "stages" in text and "/6" in text, text  # the model is textured: the textures stage runs (auto)
    piped = subprocess.run(args + ["--out", str(tmp_path / "b")], capture_output=True, text=True, env=env,
                           timeout=120)
    assert piped.returncode == 0 and piped.stderr == ""
