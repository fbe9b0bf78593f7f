"""Shared fixtures. Tests that need the shared corpus skip with a reason when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# Property tests explore new random examples on every local run; under CI (CI=true) they run a
# fixed, derandomized set, so a submission's run does not depend on luck (a generator bug they
# found once: tests/reliability/test_rel_properties.py's polygons could wind clockwise).
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

REPO = Path(__file__).resolve().parent.parent


def sigint_default() -> None:
    """``preexec_fn`` for a child a test interrupts with SIGINT: the default disposition. A shell
    starts a background job (``make test &``, nohup, some CI runners) with SIGINT ignored, the
    child would inherit that, and the bake rightly keeps an ignored SIGINT ignored."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))


def corpus_path(*parts: str) -> Path:
    """Path inside ../shared/corpus, or skip the calling test if the corpus is absent."""
    p = CORPUS.joinpath(*parts)
    if not CORPUS.is_dir():
        pytest.skip(f"../shared/corpus not found at {CORPUS} (set BAKE_CORPUS to run corpus tests)")
    if not p.exists():
        pytest.skip(f"corpus file missing: {p}")
    return p


@pytest.fixture
def corpus():
    return corpus_path
