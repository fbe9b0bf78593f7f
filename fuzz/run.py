"""``make fuzz``: run each atheris harness for a while, then fold what it found into the corpus.

    python fuzz/run.py [--seconds 120] [--targets obj,gltf,sb3] [--no-merge] [--strict]

For each target: libFuzzer starts from ``fuzz/corpus/<target>`` (read, never written while
fuzzing), writes new interesting inputs to ``fuzz/.work/<target>`` and crashes to
``fuzz/.work/artifacts/``. Then (unless ``--no-merge``) ``-merge=1`` copies into
``fuzz/corpus/<target>`` only the new inputs that reach code the corpus did not (inputs over
``--max-len`` bytes are never produced), so the checked-in corpus stays small; review and commit it.
``make test`` feeds every corpus file to its reader (tests/reliability/test_rel_fuzz_regressions.py).

Exit status 1 if any harness found a crash (the input is in fuzz/.work/artifacts/). Known,
reported bugs (``fuzz_targets.KNOWN_BUGS``) are stepped over unless ``--strict``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=int, default=int(os.environ.get("FUZZ_SECONDS", "120")),
                    help="fuzzing time per target (default 120, or $FUZZ_SECONDS)")
    ap.add_argument("--targets", default="obj,gltf,sb3")
    ap.add_argument("--max-len", type=int, default=8192)
    ap.add_argument("--rss-limit-mb", type=int, default=3072)
    ap.add_argument("--no-merge", action="store_true")
    ap.add_argument("--strict", action="store_true", help="stop at known, reported bugs too")
    args = ap.parse_args(argv)
    try:
        import atheris  # noqa: F401
    except ImportError:
        print("atheris is not installed: pip install -c constraints.txt -e '.[fuzz]'", file=sys.stderr)
        return 2
    work = HERE / ".work"
    art = work / "artifacts"
    art.mkdir(parents=True, exist_ok=True)
    # libFuzzer's merge re-runs argv[0] through the shell: the harnesses are executable scripts
    # (#!/usr/bin/env python3), so this interpreter's folder goes first on PATH
    env = dict(os.environ, BAKE_FUZZ_STRICT="1" if args.strict else "0",
               PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    crashed = []
    for t in args.targets.split(","):
        corpus = HERE / "corpus" / t
        new = work / t
        new.mkdir(parents=True, exist_ok=True)
        before = set(art.iterdir())
        common = [f"-max_len={args.max_len}", f"-rss_limit_mb={args.rss_limit_mb}", "-timeout=30",
                  f"-artifact_prefix={art}/{t}-"]
        print(f"== fuzz {t}: {args.seconds} s from {corpus.relative_to(HERE.parent)}", flush=True)
        r = subprocess.run([str(HERE / f"fuzz_{t}.py"), str(new), str(corpus),
                            f"-max_total_time={args.seconds}", "-print_final_stats=1", *common], env=env)
        found = sorted(set(art.iterdir()) - before)
        if r.returncode != 0 or found:
            crashed.append((t, found))
            print(f"!! {t}: crash, input(s): {', '.join(str(f) for f in found) or '(see the log above)'}")
        if not args.no_merge:
            n0 = len(list(corpus.iterdir()))
            # edges only (no hit counters): the fewest inputs that reach the new code
            subprocess.run([str(HERE / f"fuzz_{t}.py"), "-merge=1", "-use_counters=0", str(corpus), str(new),
                            *common], env=env, capture_output=True)
            print(f"== {t}: corpus {n0} -> {len(list(corpus.iterdir()))} inputs")
    return 1 if crashed else 0


if __name__ == "__main__":
    sys.exit(main())
