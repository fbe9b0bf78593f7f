"""Every input in fuzz/corpus/<target>/ (hand-made seeds plus what ``make fuzz`` found interesting)
fed to its reader: the answer is a result (a scene that passes ``Scene.validate()`` with finite
colours, or a project that reads back) or a one-line :class:`BakeError` -- nothing else.

Inputs that reproduce bugs reported but not yet fixed (``fuzz_targets.KNOWN_BUGS``, in modules
that are in progress) are strict xfails: the test fails once the bug is fixed, as a reminder to
drop the entry."""

from __future__ import annotations

import sys
import warnings

import pytest

from rel_util import REPO

sys.path.insert(0, str(REPO / "fuzz"))
import fuzz_targets  # noqa: E402

CASES = []
for target in sorted(fuzz_targets.TARGETS):
    folder = fuzz_targets.corpus_dir(target)
    for f in sorted(folder.iterdir()) if folder.is_dir() else []:
        CASES.append((target, f))


def test_corpus_is_small_and_covers_every_reader():
    assert {t for t, _ in CASES} == set(fuzz_targets.TARGETS)
    total = sum(f.stat().st_size for _, f in CASES)
    assert all(f.stat().st_size <= 16 * 1024 for _, f in CASES), "keep checked-in fuzz inputs small"
    assert total <= 512 * 1024, total


def _case(target, f):
    marks = ()
    if f.name in fuzz_targets.known_files(target):
        marks = pytest.mark.xfail(strict=True, reason="reported bug, see fuzz_targets.KNOWN_BUGS")
    return pytest.param(target, f, id=f"{target}/{f.name}", marks=marks)


@pytest.mark.parametrize("target,path", [_case(t, f) for t, f in CASES])
def test_fuzz_input_gives_a_result_or_a_bake_error(target, path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numpy / zipfile warnings are not the subject here
        outcome = fuzz_targets.run_one(target, path.read_bytes())
    assert outcome == "ok" or outcome.startswith("error: ")
