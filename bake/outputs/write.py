"""Putting outputs on disk: atomically, only when their bytes change, nothing half-written.

Every file is written to a temporary name in its own folder, flushed, and renamed over the
target (``os.replace`` is atomic on POSIX). A file whose bytes are unchanged is not touched,
so ``make`` sees an unchanged timestamp. A manifest (``.bake-manifest.json``) remembers what the
last bake wrote, so files a previous bake wrote and this one no longer produces are removed —
files the user put in the folder are never touched — and a folder of ours left empty by that
(``assets/`` after a rebake without textures) goes too.

A bake's outputs go out as one :class:`Outputs` set: every check first (a target that is a
folder, an input file in the way, a path outside the output folder), then every changed file
staged under a temporary name (interruptible: an interrupt removes the temporaries and leaves
the folder as it was), then :meth:`Outputs.commit` does only renames, removals and the manifest
with SIGINT, SIGTERM and SIGHUP held until it is done. So an interrupted bake leaves every file
as the previous bake left it, or the whole folder new. (SIGKILL cannot be held: killed during
the few microseconds of the commit, each file is still complete, old or new.)
"""

from __future__ import annotations

import glob
import json
import os
from pathlib import Path

from ..errors import BakeError, ConfigError
from ..files import TMP_SUFFIX, remove_orphan_temps, same_bytes, signals_held, stage_temp, unlink_quietly

MANIFEST = ".bake-manifest.json"
COMMITTED: list[Path] = []  # output folders whose commit finished in this process (for messages)


def _safe_join(root: Path, rel: str) -> Path:
    p = (root / rel).resolve()
    if root.resolve() not in p.parents and p != root.resolve():
        raise BakeError(f"refusing to write outside the output folder: {rel}")
    return p


# --------------------------------------------------------------------------- output errors
def output_error(e: OSError, path: Path, what: str = "cannot write") -> ConfigError:
    """An OSError on an output path as a one-line error naming the path (exit 2)."""
    return ConfigError(f"{what}: {e.strerror or e or type(e).__name__}", path=path)


def check_writable_folder(folder: Path, label: str) -> None:
    """``folder`` (which may not exist yet) can be created and written: every existing part of the
    path is a folder, and the nearest existing one lets us add files (``access(2)``: permission
    bits, and a read-only file system even for root; nothing is created, so no folder's time
    changes). Raises :class:`ConfigError` (exit 2) naming the path."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{label} names a file, not a folder", path=folder)
    probe = folder
    while not os.path.lexists(probe):
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise ConfigError(f"{label} cannot be created: {probe} is a file, not a folder", path=folder)
    if not os.access(probe, os.W_OK | os.X_OK):
        try:
            read_only = bool(os.statvfs(probe).f_flag & os.ST_RDONLY)
        except (OSError, AttributeError):
            read_only = False
        why = "on a read-only file system" if read_only else "not writable (permission denied)"
        where = "" if probe == folder else f": {probe}, where it would be created, is {why}"
        raise ConfigError(f"{label} is {why}" if not where else f"{label} cannot be created{where}", path=folder)


# --------------------------------------------------------------------------- one bake's outputs
class Outputs:
    """A bake's files under ``out_dir``, staged and then committed together.

    ``add(rel, data)`` checks the target and stages the bytes under a temporary name (nothing is
    renamed yet); ``add_file(path, data)`` does the same for a file outside the folder (the
    depfile); ``commit()`` renames, removes what the previous bake wrote and this one did not,
    and writes the manifest, with signals held; ``abort()`` (or leaving a ``with`` block by an
    exception) removes the temporaries. ``status``: rel path -> "written" | "unchanged" |
    "removed" (removals are known from the start, before commit)."""

    def __init__(self, out_dir: Path, *, protect: set[Path] | None = None, keep: tuple[str, ...] = ()):
        self.out_dir = Path(out_dir)
        self.protect = {Path(p).resolve() for p in (protect or set())}
        self.keep = tuple(keep)
        self.status: dict[str, str] = {}
        self._rels: set[str] = set()
        self._staged: list[tuple[Path, Path]] = []  # (temporary, target)
        self._attempted: list[Path] = []
        self._touch: list[Path] = []
        self._done = False
        try:
            previous = json.loads((self.out_dir / MANIFEST).read_text("utf-8")).get("files", [])
        except (OSError, ValueError, AttributeError):
            previous = []
        self._previous = [r for r in previous if isinstance(r, str)] if isinstance(previous, list) else []

    # -- checks, before anything is created
    def check(self, rels: list[str]) -> None:
        """Refuse targets that would overwrite an input, leave the folder, or are folders."""
        for rel in rels:
            target = _safe_join(self.out_dir, rel)
            if target in self.protect:
                raise ConfigError(f"refusing to overwrite the input file {target} (choose another --out)",
                                  path=self.out_dir)
            if target.is_dir():
                raise ConfigError(f"output {rel} is a folder in the way; remove it or choose another --out",
                                  path=target)

    def start(self, files: dict[str, bytes], also: list[str] = ()) -> None:
        """Check every target (``files`` and ``also``, written later), create the folder, clear
        temporaries a killed bake left, and stage ``files``."""
        self.check(sorted(files) + list(also))  # before anything is created
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise output_error(e, self.out_dir, "cannot create the output folder") from None
        remove_orphan_temps(self.out_dir)
        self.add_all(files)

    def add_all(self, files: dict[str, bytes], *, always: tuple[str, ...] = ()) -> None:
        self.check(sorted(files))
        for rel in sorted(files):
            self.add(rel, files[rel], always=rel in always)

    def add(self, rel: str, data: bytes, *, always: bool = False) -> str:
        """Stage ``data`` for ``out_dir/rel``; ``always``: an unchanged file still gets a new time."""
        self.check([rel])
        target = _safe_join(self.out_dir, rel)
        self._rels.add(rel)
        if same_bytes(target, data):
            if always:
                self._touch.append(target)
            self.status[rel] = "unchanged"
        else:
            self._stage(target, data)
            self.status[rel] = "written"
        return self.status[rel]

    def add_file(self, path: Path, data: bytes) -> None:
        """A file outside the folder (the depfile), committed with the rest."""
        path = Path(path)
        if path.resolve() in self.protect:
            raise ConfigError("refusing to overwrite an input file with the depfile", path=path)
        if path.is_dir():
            raise ConfigError("--depfile names a folder, not a file", path=path)
        if not same_bytes(path, data):
            self._stage(path, data)

    def _stage(self, target: Path, data: bytes) -> None:
        self._attempted.append(target)  # before the temporary exists: abort() finds it by name
        try:
            self._staged.append((stage_temp(target, data), target))
        except OSError as e:
            raise output_error(e, target) from None

    def removals(self) -> list[str]:
        return [r for r in self._previous if r not in self._rels and r not in self.keep]

    # -- the commit: renames only, signals held
    def commit(self) -> dict[str, str]:
        stale = []
        for rel in self.removals():
            try:
                p = _safe_join(self.out_dir, rel)
            except BakeError:
                continue
            if p.is_file() and p not in self.protect:
                stale.append((rel, p))
        manifest = json.dumps({"files": sorted(self._rels | set(self.keep))}, indent=1).encode()
        man = self.out_dir / MANIFEST
        if not same_bytes(man, manifest):
            self._stage(man, manifest)
        with signals_held():
            where = self.out_dir
            try:
                for tmp, where in self._staged:
                    os.replace(tmp, where)
                for where in self._touch:
                    os.utime(where)
            except OSError as e:
                raise output_error(e, where) from None
            finally:
                self.abort()
            folders = set()
            for rel, p in stale:
                try:
                    p.unlink()
                    self.status[rel] = "removed"
                    folders.add(p.parent)
                except OSError:
                    pass
            self._prune(folders)
            COMMITTED.append(self.out_dir)
        self._done = True
        return self.status

    def _prune(self, folders: set[Path]) -> None:
        """Folders inside out_dir that held removed outputs and are now empty (assets/)."""
        root = self.out_dir.resolve()
        for f in sorted(folders, key=lambda p: -len(p.parts)):
            while f != root and root in f.parents:
                try:
                    f.rmdir()  # only succeeds when empty
                except OSError:
                    break
                f = f.parent

    def abort(self) -> None:
        """Remove every temporary this set made, including one whose name an interrupt kept from
        being recorded (found by its target's name pattern)."""
        for tmp, _ in self._staged:
            if tmp.exists():
                unlink_quietly(tmp)
        for target in self._attempted:
            try:
                for tmp in target.parent.glob(f".{glob.escape(target.name)}.*{TMP_SUFFIX}"):
                    unlink_quietly(tmp)
            except OSError:
                pass
        self._staged = []
        self._attempted = []

    def __enter__(self) -> "Outputs":
        return self

    def __exit__(self, *exc) -> None:
        self.abort()


def write_outputs(out_dir: Path, files: dict[str, bytes], *, protect: set[Path] | None = None,
                  also_ours: tuple[str, ...] = ()) -> dict[str, str]:
    """Write ``files`` (relative path -> bytes) under ``out_dir`` as one commit. Returns path ->
    "written" | "unchanged" | "removed". ``protect`` holds input files that must never be
    overwritten; ``also_ours`` names files written separately that the manifest lists and that
    must not be removed as stale."""
    out_dir = Path(out_dir)
    with Outputs(out_dir, protect=protect, keep=also_ours) as outs:
        outs.start(files)
        return outs.commit()


def make_escape(p: str | Path) -> str:
    return str(p).replace("\\", "\\\\").replace(" ", "\\ ").replace("#", "\\#").replace("$", "$$")


def depfile_text(targets: list[Path], deps: list[Path], missing: list[Path] = ()) -> str:
    """Make-style dependency rule: every target depends on every input read, and on each file in
    ``missing`` (named by the model, not there) once it exists: ``$(wildcard PATH)`` is empty
    while the file is missing, so nothing rebakes, and names it once it is there, newer than the
    target, so the bake runs again."""
    t = " ".join(make_escape(p) for p in targets)
    d = [make_escape(p) for p in deps] + [f"$(wildcard {make_escape(p)})" for p in missing]
    # empty rules for each dependency so a deleted input does not break make
    phony = "".join(f"\n{make_escape(p)}:\n" for p in deps)
    return f"{t}: \\\n  " + " \\\n  ".join(d) + f"\n{phony}"
