"""Atomic writes, change-only rewrites, stale-file cleanup, input protection, depfiles."""

import os

import pytest

from bake.errors import BakeError, ConfigError
from bake.files import write_atomic
from bake.outputs.write import depfile_text, write_outputs


def test_unchanged_bytes_keep_timestamp(tmp_path):
    p = tmp_path / "a.txt"
    assert write_atomic(p, b"1\n2") is True
    os.utime(p, (1, 1))
    assert write_atomic(p, b"1\n2") is False
    assert p.stat().st_mtime == 1
    assert write_atomic(p, b"1\n3") is True and p.read_bytes() == b"1\n3"
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".bake-tmp")]


def test_stale_outputs_removed_user_files_kept(tmp_path):
    (tmp_path / "mine.txt").write_text("user file")
    s1 = write_outputs(tmp_path, {"lists/a.txt": b"1", "lists/b.txt": b"2"})
    assert s1 == {"lists/a.txt": "written", "lists/b.txt": "written"}
    s2 = write_outputs(tmp_path, {"lists/a.txt": b"1"})
    assert s2 == {"lists/a.txt": "unchanged", "lists/b.txt": "removed"}
    assert (tmp_path / "mine.txt").read_text() == "user file"
    assert not (tmp_path / "lists/b.txt").exists()


def test_refuses_to_overwrite_inputs_or_escape(tmp_path):
    model = tmp_path / "lists" / "a.txt"
    model.parent.mkdir()
    model.write_text("input")
    with pytest.raises(BakeError, match="refusing to overwrite the input"):
        write_outputs(tmp_path, {"lists/a.txt": b"x"}, protect={model})
    assert model.read_text() == "input"
    with pytest.raises(BakeError, match="outside the output folder"):
        write_outputs(tmp_path / "out", {"../evil.txt": b"x"})


def test_failed_write_leaves_previous_file(tmp_path, monkeypatch):
    p = tmp_path / "a.txt"
    write_atomic(p, b"old")

    def boom(*a, **k):
        raise OSError("disk full")
    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        write_atomic(p, b"new")
    assert p.read_bytes() == b"old"
    assert sorted(os.listdir(tmp_path)) == ["a.txt"]


def test_depfile_escapes_spaces(tmp_path):
    text = depfile_text([tmp_path / "out dir/lists.json"], [tmp_path / "my model.obj", tmp_path / "a.mtl"])
    first = text.splitlines()[0]
    assert first.endswith(": \\") and "out\\ dir/lists.json" in first
    assert "my\\ model.obj" in text and f"{tmp_path}/a.mtl:" in text


def test_orphan_temps_from_a_killed_bake_are_removed(tmp_path):
    (tmp_path / "lists").mkdir()
    orphan = tmp_path / "lists" / ".verts.txt.abc.bake-tmp"
    orphan.write_text("half")
    write_outputs(tmp_path, {"lists/verts.txt": b"1"})
    assert not orphan.exists() and (tmp_path / "lists/verts.txt").read_bytes() == b"1"


def test_a_failure_in_phase_one_changes_nothing(tmp_path, monkeypatch):
    write_outputs(tmp_path, {"a.txt": b"old a", "b.txt": b"old b"})
    import bake.outputs.write as w
    real = w.stage_temp
    calls = []

    def flaky(path, data):
        calls.append(path.name)
        if path.name == "b.txt":
            raise OSError("disk full")
        return real(path, data)
    monkeypatch.setattr(w, "stage_temp", flaky)
    with pytest.raises(ConfigError, match=r"b\.txt: cannot write: disk full"):  # exit 2, the path named
        write_outputs(tmp_path, {"a.txt": b"new a", "b.txt": b"new b"})
    assert (tmp_path / "a.txt").read_bytes() == b"old a" and (tmp_path / "b.txt").read_bytes() == b"old b"
    assert not list(tmp_path.glob(".*bake-tmp"))
