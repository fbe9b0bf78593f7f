"""Re-bake after a lighting change, each bake a new ``bake run`` process: writes
benchmarks/results/rebake.json (issue 41, item 1).

For the 2k bunny (``configs/bunny.toml`` with ``mesh.simplify.target_triangles = 2000``: centred on
its base, ``fit = 100``, ambient + one soft sun + 64-sample AO, BSP) and ``configs/house.toml``,
side by side in one run:

1. a cold bake into a fresh ``--out`` folder;
2. a re-bake into the same folder with ``lighting.ao.samples = 65``;
3. a re-bake into the same folder with the sun's direction changed (AO back to 64);

every one a new ``bake run`` process (Python's start and imports included), timed from outside
(wall seconds, and the child's CPU seconds, a figure the other processes on a shared machine
disturb less). For each: the per-stage seconds of report.json, how each stage ran (from the
cache, ran and reused the tree or the trace, ran), and ``cache.memos_reused``. Each re-bake's
lists (``lists/`` and ``lists.json``) are compared byte for byte with a cold bake of the changed
config into a fresh folder. Goal: re-bake / cold <= 15% (bunny), <= 25% (house).

Python's compiled bytecode: this machine's environment sets ``PYTHONDONTWRITEBYTECODE=1``, which
makes every new process compile scratch-bake's ~370 source files again (0.5-0.7 s per bake, more
than a tenth of a cold bake's share budget). An installed tool has its bytecode; so the bakes run
with ``PYTHONDONTWRITEBYTECODE`` unset and ``PYTHONPYCACHEPREFIX`` a temporary folder, filled by
``compileall`` before the first timed bake (the tree itself is not written to). ``--no-bytecode``
keeps the environment's setting (the figures are then recorded under ``"bytecode": false``).

``--code DIR`` runs the bakes with ``PYTHONPATH=DIR`` (e.g. an extracted older commit, to get the
figures before a change: ``git archive <commit> bake | tar -x -C DIR``); ``--label`` names the
run in the results file (runs with other labels are kept).

Run: ``.venv/bin/python benchmarks/bench_rebake.py [--repeat N] [--code DIR --label before]``.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "benchmarks" / "results" / "rebake.json"
CONFIGS = {
    "bunny_2k": (REPO / "configs" / "bunny.toml", ["mesh.simplify.target_triangles=2000"], 0.15),
    "house": (REPO / "configs" / "house.toml", [], 0.25),
}
AO = "lighting.ao.samples=65"
SUN = "lighting.lights[0].direction=[0.3, -1.0, 0.5]"  # neither config's sun points this way


def load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


ENV: dict[str, str] = {}  # the children's environment (main sets it)


def child_env(code: Path, pycache: Path | None) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=str(code))
    if pycache is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(code / "bake")], check=True, env=env,
                       stdout=subprocess.DEVNULL)
    return env


def run(cfg: Path, sets: list[str], out: Path, code: Path) -> dict:
    """One ``bake run`` in a new process: wall and CPU seconds, and what report.json says."""
    args = [sys.executable, "-m", "bake.cli", "run", str(cfg), "--out", str(out), "--quiet"]
    for s in sets:
        args += ["--set", s]
    env = ENV
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(args, check=True, env=env, cwd=code)  # (-m puts the folder first on sys.path)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    rep = json.loads((out / "report.json").read_text())
    bsp = next(s for s in rep["stages"] if s["name"] == "bsp")
    stages = {}
    for s in rep["stages"]:
        d = s.get("details") or {}
        if (d.get("cache") or {}).get("from_cache"):
            how = "from the cache"
        elif (d.get("tree_reused") or {}).get("reused"):
            how = "ran, tree reused"
        elif (d.get("trace_reused") or {}).get("reused"):
            how = "ran, trace reused"
        else:
            how = "ran"
        stages[s["name"]] = {"seconds": s["seconds"], "how": how}
    return {"wall": round(wall, 3), "cpu": round(cpu, 3), "stages": stages,
            "outside_stages": round(wall - sum(v["seconds"] for v in stages.values()), 3),
            "memos_reused": (rep.get("cache") or {}).get("memos_reused", []),
            "bsp": {**{k: bsp["details"].get(k) for k in ("merged_triangles", "remerged_fragments", "splits",
                                                            "inflation")},
                    "triangles_out": bsp["counts_out"]["triangles"], "vertices_out": bsp["counts_out"]["vertices"]}}


def same_lists(a: Path, b: Path) -> bool:
    """``lists/`` and ``lists.json`` byte for byte (``cmp``)."""
    if not filecmp.cmp(a / "lists.json", b / "lists.json", shallow=False):
        return False
    names = sorted(p.name for p in (a / "lists").iterdir())
    if names != sorted(p.name for p in (b / "lists").iterdir()):
        return False
    return all(filecmp.cmp(a / "lists" / n, b / "lists" / n, shallow=False) for n in names)


def one(name: str, tmp: Path, code: Path) -> dict:
    cfg, sets, goal = CONFIGS[name]
    out = tmp / f"{name}-out"
    shutil.rmtree(out, ignore_errors=True)
    row: dict = {"load_before": load()}
    row["cold"] = run(cfg, sets, out, code)
    row["ao"] = run(cfg, [*sets, AO], out, code)
    fresh = tmp / f"{name}-cold-ao"
    shutil.rmtree(fresh, ignore_errors=True)
    row["cold_ao"] = run(cfg, [*sets, AO], fresh, code)
    row["ao_lists_equal_cold"] = same_lists(out, fresh)
    row["sun"] = run(cfg, [*sets, SUN], out, code)
    fresh = tmp / f"{name}-cold-sun"
    shutil.rmtree(fresh, ignore_errors=True)
    row["cold_sun"] = run(cfg, [*sets, SUN], fresh, code)
    row["sun_lists_equal_cold"] = same_lists(out, fresh)
    row["load_after"] = load()
    c = row["cold"]
    row["ao_share"] = round(row["ao"]["wall"] / c["wall"], 4)
    row["sun_share"] = round(row["sun"]["wall"] / c["wall"], 4)
    row["ao_cpu_share"] = round(row["ao"]["cpu"] / c["cpu"], 4)
    row["sun_cpu_share"] = round(row["sun"]["cpu"] / c["cpu"], 4)
    print(f"{name}: cold {c['wall']:.2f} s; ao 65 {row['ao']['wall']:.2f} s ({row['ao_share']:.1%}, CPU "
          f"{row['ao_cpu_share']:.1%}) memos {row['ao']['memos_reused']}, lists = cold: {row['ao_lists_equal_cold']}; "
          f"sun {row['sun']['wall']:.2f} s ({row['sun_share']:.1%}, CPU {row['sun_cpu_share']:.1%}) memos "
          f"{row['sun']['memos_reused']}, lists = cold: {row['sun_lists_equal_cold']}; load {row['load_after']}",
          flush=True)
    return row


LABELS = {"bunny_2k": "2k bunny", "house": "house"}


def table(doc: dict) -> dict:
    """README's rows (``"table"`` in the results): per config and run label, the medians and the
    figures README shows, derived here (tools/doc_tables.py only formats)."""
    rows = {}
    for name in CONFIGS:
        for label, run_ in doc.items():
            if label in ("table", "command") or not isinstance(run_, dict) or name not in run_.get("configs", {}):
                continue
            c = run_["configs"][name]
            runs = c["runs"]

            def med(f):
                return statistics.median(f(r) for r in runs)

            first = runs[0]
            bsp = sorted({f"{first[k]['stages']['bsp']['how']} {first[k]['stages']['bsp']['seconds']:.2f} s"
                          for k in ("ao", "sun")})
            rows[f"{name} {label}"] = {
                "config": LABELS[name], "code": label.replace("_", " "), "runs": len(runs),
                "cold": med(lambda r: r["cold"]["wall"]), "ao": med(lambda r: r["ao"]["wall"]),
                "sun": med(lambda r: r["sun"]["wall"]), **c["median"],
                "bsp_how": "; ".join(bsp), "memos": json.dumps(first["ao"]["memos_reused"]),
                "triangles_cold": first["cold"]["bsp"]["triangles_out"],
                "triangles_ao": first["cold_ao"]["bsp"]["triangles_out"],
                "goal": f"≤ {c['goal']:.0%}: {'met' if c['met'] else 'not met'}",
                "lists_equal_cold": "yes" if c["lists_equal_cold"] else "NO"}
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--code", type=Path, default=REPO, help="folder holding the bake package to run")
    ap.add_argument("--label", default="after")
    ap.add_argument("--only", choices=sorted(CONFIGS), action="append")
    ap.add_argument("--no-bytecode", action="store_true", help="keep PYTHONDONTWRITEBYTECODE as it is")
    ap.add_argument("--table-only", action="store_true", help="only rebuild the README rows from the results")
    a = ap.parse_args()
    if a.table_only:
        doc = json.loads(RESULTS.read_text())
        doc["table"] = table(doc)
        RESULTS.write_text(json.dumps(doc, indent=1) + "\n")
        return
    a.code = a.code.resolve()
    names = a.only or list(CONFIGS)
    res: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench-rebake-") as d:
        ENV.update(child_env(a.code, None if a.no_bytecode else Path(d) / "pycache"))
        for name in names:
            rows = [one(name, Path(d), a.code) for _ in range(a.repeat)]
            _, _, goal = CONFIGS[name]
            med = {k: statistics.median(r[k] for r in rows) for k in ("ao_share", "sun_share", "ao_cpu_share",
                                                                    "sun_cpu_share")}
            res[name] = {"goal": goal, "median": med,
                         "met": med["ao_share"] <= goal and med["sun_share"] <= goal,
                         "lists_equal_cold": all(r["ao_lists_equal_cold"] and r["sun_lists_equal_cold"] for r in rows),
                         "runs": rows}
    doc = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    doc[a.label] = {"code": str(a.code), "bytecode": not a.no_bytecode and "PYTHONDONTWRITEBYTECODE" not in ENV,
                    "machine": platform.machine(), "python": platform.python_version(),
                    "cpus": os.cpu_count(), "when": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                    "configs": res}
    doc["command"] = "benchmarks/bench_rebake.py --code <88de006 extracted> --label before_88de006; " \
                     "benchmarks/bench_rebake.py --repeat 3"
    doc["table"] = table(doc)
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
