"""The ``bake`` command.

    bake run MODEL|CONFIG.toml [--set key=value ...] [--out DIR] [--depfile FILE] [--strict] [--quiet]
    bake demo [--out DIR]
    bake inspect MODEL [--set key=value ...] [--json]
    bake report OUT_DIR [--width N]
    bake check PROJECT.sb3 [--json] [--strict]
    bake sweep MODEL|CONFIG --vary KEY=V1,V2,... [--out DIR]
    bake watch MODEL|CONFIG [--set key=value ...] [--out DIR]
    bake keys

Exit statuses: see bake/errors.py (0 ok, 1 internal error, 2 config/usage, 3 bad input,
4 limit exceeded under --strict, 5 stage failure).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Callable

# the command's start, as early as the process can say (its imports so far are the standard library's)
_STARTED = time.perf_counter()

from . import __version__  # noqa: E402
from . import config as config_mod
from .errors import BakeError, ConfigError, InputError, LimitError, StageError


# --------------------------------------------------------------------------- progress
# A bar on stderr for bakes longer than 2 s on a terminal, a line every 10 s of a long stage elsewhere
# (bake/progress.py).
from .progress import StageProgress as _Progress  # noqa: E402


def _default_out(target: Path) -> Path:
    return Path("bake-out") / target.stem


def _wrote_lines(out: Path, rep: dict[str, Any], cfg: config_mod.Config) -> list[str]:
    """What the bake left in ``out``: the projects by name first, then lists and reports."""
    done = [k for k, v in rep.get("outputs", {}).items() if v != "removed"]
    export = next((s for s in rep.get("stages", []) if s["name"] == "export"), {})
    into = (export.get("details") or {}).get("into") or {}
    projects = [k for k in done if k.endswith((".sb3", ".sprite3")) and k != into.get("file")]
    n_lists = sum(1 for k in done if k.startswith("lists/"))
    n_assets = sum(1 for k in done if k.startswith("assets/"))
    parts = projects[:]
    if cfg.export.json_name in done:
        parts.append(cfg.export.json_name)
    if n_lists:
        parts.append(f"lists/ ({n_lists} files)")
    if n_assets:
        parts.append(f"assets/ ({n_assets} PNG)")
    parts += ["report.md", "report.json"] + (["report.html"] if cfg.report.html else [])
    lines = [f"  wrote {out}/: {', '.join(parts)}"]
    if into.get("file"):
        lines.append(f"  wrote {out / into['file']}: {into.get('project')} with these lists in "
                     f"'{into.get('target', 'Stage')}'")
    return lines


def _bake(cfg: config_mod.Config, out: Path, *, quiet: bool, strict: bool, depfile: Path | None) -> dict[str, Any]:
    from . import pipeline
    from .outputs import output, report

    _check_output_names(cfg)
    output.check_paths(out, depfile=depfile, inputs=_known_inputs(cfg), names=_known_outputs(cfg))
    _check_into(cfg)
    prog = _Progress(quiet, total=pipeline.stage_count(cfg))
    cfg.out_dir = out  # the default xatlas cache and stage cache live in the output folder
    try:
        result = pipeline.run(cfg, progress=prog)
        if prog.enabled:
            prog("writing outputs", "start")
        rep = output.finish(result, out, depfile=depfile)
    finally:
        prog.stop()
    if not quiet:
        for line in report.summary_lines(rep, command_seconds=time.perf_counter() - _STARTED):
            print(line)
        for line in _wrote_lines(out, rep, cfg):
            print(line)
    if strict or cfg.report.strict:
        bad = [lim for lim in rep["limits"] if not lim["ok"]]
        problems = rep.get("problems", [])
        what = []
        if bad:
            what.append(f"{len(bad)} limit(s) exceeded, first: {bad[0]['name']} = {bad[0]['value']} > "
                        f"{bad[0]['limit']}")
        if problems:
            what.append(f"{len(problems)} problem(s) under --strict, first: {problems[0]['stage']}: "
                        f"{problems[0]['message']}")
        failed = [p for p in problems if p.get("failed")]
        if failed:  # a part of a stage failed on valid input: exit 5, as a stage that stops the bake
            raise StageError(f"{len(failed)} part(s) of a stage failed under --strict, first: {failed[0]['stage']}: "
                             f"{failed[0]['message']}; see {out / 'report.md'}")
        if what:
            raise LimitError("; ".join(what) + f"; see {out / 'report.md'}")
    return rep


def _model_path(cfg: config_mod.Config) -> Path | None:
    if not cfg.input.path:
        return None
    p = Path(cfg.input.path)
    return p if p.is_absolute() else cfg.base_dir / p


def _known_inputs(cfg: config_mod.Config) -> list[Path]:
    """Files the bake will read, known before it starts (the importers find the rest)."""
    out = [p for p in (_model_path(cfg), cfg.source) if p is not None]
    if cfg.export.into:
        out.append(Path(cfg.export.into))
    return out


def _output_names(cfg: config_mod.Config) -> list[tuple[str, str, str]]:
    """(key that names it, name, what it is) of each output known before the bake starts."""
    ex = cfg.export
    model = _model_path(cfg)
    stem = model.stem if model is not None else "model"
    out = [("export.json_name", ex.json_name, "the lists' JSON")] if ex.json else []
    sb3_name = ex.sb3_name or f"{stem}.sb3"
    if ex.sb3:
        out.append(("export.sb3_name", sb3_name, "the .sb3"))
    if ex.sprite3:
        out.append(("export.sb3_name", f"{Path(sb3_name).stem}.sprite3", "the .sprite3 (named after the .sb3)"))
    if ex.into:
        out.append(("export.into_name", ex.into_name or f"{Path(ex.into).stem}-{stem}.sb3",
                    "the export.into project"))
    return out


def _known_outputs(cfg: config_mod.Config) -> list[str]:
    """Output names known before the bake starts."""
    return [name for _, name, _ in _output_names(cfg)]


def _check_output_names(cfg: config_mod.Config) -> None:
    """Two outputs with one name would leave only one of them (a file system that ignores case
    counts too): exit 2 before baking, naming the key."""
    if not cfg.export.enabled:
        return
    seen: dict[str, tuple[str, str]] = {}
    for key, name, what in _output_names(cfg):
        other = seen.get(name.lower())
        if other is not None:
            # blame the key the user set (a default name clashing with a chosen one)
            blame = other[0] if other[0] in cfg.given and key not in cfg.given else key
            raise config_mod.error_at(cfg, blame, f"'{name}' would name both {other[1]} ({other[0]}) and "
                                                  f"{what} ({key}); choose another name")
        seen[name.lower()] = (key, what)


def _check_into(cfg: config_mod.Config) -> None:
    """``export.into``: the project must be there and readable, with the target sprite, before the
    bake starts (not found out after it)."""
    if not cfg.export.into or not cfg.export.enabled:
        return
    from .scratch.sb3 import merge_into

    src = Path(cfg.export.into)
    if not src.is_file():
        raise InputError("export.into: project not found" if not src.exists() else
                         "export.into: not a file", path=src)
    merge_into(src, cfg.export.into_target or "Stage", {})


def cmd_run(args: argparse.Namespace) -> int:
    from .pipeline import load_config_for

    target = Path(args.target)
    if not target.exists():
        raise InputError("file not found", path=target)
    cfg = load_config_for(target, args.set)
    out = Path(args.out) if args.out else _default_out(target)
    _bake(cfg, out, quiet=args.quiet, strict=args.strict, depfile=Path(args.depfile) if args.depfile else None)
    return 0


def sample_config_path() -> Path:
    return Path(__file__).resolve().parent / "samples" / "demo.toml"


def cmd_demo(args: argparse.Namespace) -> int:
    cfg = config_mod.load(sample_config_path(), args.set)
    _bake(cfg, Path(args.out), quiet=args.quiet, strict=False, depfile=None)
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    import numpy as np

    from . import pipeline

    cfg = pipeline.load_config_for(Path(args.target), args.set)
    result = pipeline.run(cfg, until="clean")
    scene = result.scene
    sizes: dict[str, int] = {}
    if scene.poly_sizes is not None and len(scene.poly_sizes):
        u, c = np.unique(scene.poly_sizes, return_counts=True)
        sizes = {str(int(k)): int(v) for k, v in zip(u, c)}
    b = scene.bounds()
    exported, _ = pipeline.run_stage("export", scene, cfg)
    info = exported.artefacts.list_info
    data = {
        "file": str(scene.source.path),
        "format": scene.source.format,
        "polygons_by_size": sizes,
        "triangles": scene.n_triangles,
        "vertices": scene.n_vertices,
        "materials": [{"name": m.name, "color": [round(c, 4) for c in m.color],
                       "texture": str(m.texture) if m.texture else ("embedded" if m.texture_data else None)}
                      for m in scene.materials],
        "lights": len(scene.lights),
        "bounds": {"min": b[0].tolist(), "max": b[1].tolist(), "diagonal": scene.diagonal()},
        "lists": {k: {"items": v["items"], "project_json_bytes": v["project_json_bytes"]} for k, v in info.items()},
        "warnings": [w for r in result.records for w in r.warnings],
    }
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    print(f"{data['file']} ({data['format']})")
    print("  polygons by size: " + (", ".join(f"{k}-gon x{v}" for k, v in sizes.items()) or "none"))
    print(f"  triangles {data['triangles']}, vertices {data['vertices']}, lights {data['lights']}")
    print(f"  bounds min {np.round(b[0], 4).tolist()} max {np.round(b[1], 4).tolist()}, "
          f"diagonal {data['bounds']['diagonal']:.6g}")
    print(f"  materials ({len(data['materials'])}):")
    for m in data["materials"]:
        tex = f", texture {m['texture']}" if m["texture"] else ""
        print(f"    {m['name']}: rgba {m['color']}{tex}")
    print("  lists of the mesh as imported and cleaned, with the current export settings (the stages after\n"
          "  clean -- simplify, BSP, BVH, lighting, textures -- change or add lists; `bake run` reports those):")
    for k, v in data["lists"].items():
        print(f"    {k:<14} {v['items']:>8} items  {v['project_json_bytes']:>9} bytes")
    for w in data["warnings"]:
        print(f"  warning: {w}")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from . import sweep as sweep_mod
    from .pipeline import load_config_for

    target = Path(args.target)
    if not target.exists():
        raise InputError("file not found", path=target)
    cfg = load_config_for(target, args.set)
    key, values = sweep_mod.parse_vary(args.vary)
    reference = None
    if args.reference is not None:
        rkey, rvals = sweep_mod.parse_vary(f"{key}={args.reference}", "--reference")
        reference = rvals[0]
    out_dir = Path(args.out) if args.out else _default_out(target)
    cfg.out_dir = out_dir  # the sweep reuses (and fills) the bake's stage cache
    out = out_dir / "sweeps" / key
    from .outputs import output

    output.check_paths(out_dir)
    if out_dir.is_dir() and (out_dir / "sweeps").exists():
        output.check_paths(out_dir / "sweeps", label="--out (sweeps/)")
    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        if not args.quiet:
            print(f"bake sweep [{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    table = sweep_mod.sweep(cfg, key, values, reference=reference, out=out, progress=progress)
    html_written = False
    if (out_dir / "report.json").is_file() and cfg.report.html:  # show it in the bake's report
        from .outputs import html

        w = cfg.report.preview_width
        html.write(out_dir, width=w, height=max(1, w * 3 // 4))
        html_written = True
    if not args.quiet:
        for line in sweep_mod.summary_lines(table):
            print(line)
        print(f"  wrote {out}.json and {out}.svg" + (f"; updated {out_dir / 'report.html'}" if html_written else
                                                     f" (bake into {out_dir} and its report.html shows them)"))
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    from .scratch import check as check_mod

    target = Path(args.target)
    if not target.exists():
        raise InputError("file not found", path=target)
    rep = check_mod.check(target)
    if args.with_lists:
        rep["engine"] = _engine_check(target, Path(args.with_lists), args.into_target)
        rep["problems"] = list(rep["problems"]) + rep["engine"]["warnings"]
    if args.json:
        print(json.dumps(rep, indent=2))
    else:
        for line in check_mod.summary_lines(rep):
            print(line)
        for name, e in (rep.get("engine") or {}).get("lists", {}).items():
            who = ", ".join(f"{u['sprite']} ({u['blocks']})" for u in e["read_by"]) or "no block"
            print(f"engine: '{name}' read by {who}")
    if args.strict and any(not lim["ok"] for lim in rep["limits"]):
        bad = [lim for lim in rep["limits"] if not lim["ok"]][0]
        raise LimitError(f"limit exceeded: {bad['name']} = {bad['value']} > {bad['limit']}", path=target)
    if args.strict and rep["problems"]:  # (as `bake run --strict` fails on a stage's problems)
        raise LimitError(f"{len(rep['problems'])} problem(s) under --strict, first: {rep['problems'][0]}",
                         path=target)
    return 0


def _engine_check(project: Path, lists_json: Path, target: str) -> dict:
    """``bake check ENGINE --with lists.json``: the engine check of ``export.into`` for lists a
    bake wrote earlier (their names and lengths), without merging anything."""
    from .scratch import engine, sb3

    try:
        doc = json.loads(lists_json.read_text("utf-8"))
    except OSError as e:
        raise InputError(f"cannot read: {e.strerror}", path=lists_json) from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"is not a bake's lists.json ({e})", path=lists_json) from None
    lists = doc.get("lists") if isinstance(doc, dict) else None
    if not isinstance(lists, dict) or not all(isinstance(v, list) for v in lists.values()):
        raise InputError("is not a bake's lists.json (expected a \"lists\" object of arrays)", path=lists_json)
    proj = sb3.load_project(project)[0]
    names = {t.get("name") for t in proj.get("targets", []) if isinstance(t, dict)}
    if target not in ("Stage", "_stage_") and target not in names:
        raise ConfigError(f"--into-target: no sprite '{target}' in {project.name}")
    from .scratch.project import all_numbers

    return engine.check(proj, target, {n: len(v) for n, v in lists.items()}, reader_added=False,
                        numbers={n for n, v in lists.items() if all_numbers(v)})


def cmd_report(args: argparse.Namespace) -> int:
    from .outputs import html

    out = Path(args.out_dir)
    if not out.is_dir():
        raise InputError("not a folder (give the output folder of a bake)", path=out)
    w = args.width
    if not 16 <= w <= 2048:
        raise ConfigError(f"--width must be between 16 and 2048, got {w}")
    info = html.write(out, width=w, height=max(1, w * 3 // 4))
    if not args.quiet:
        for v in info["views"]:
            print(f"  {v['name']:<12} {v['wrong_pixels']:>7} wrong pixels of {v['covered_pixels']:>7} "
                  f"({v['order']})")
        for t in info["textures"]:
            print(f"  texture {t['name']}: {', '.join(t['encodings'])} "
                  f"({'identical' if t['agree'] else 'DIFFERENT'})")
        print(f"  wrote {out / html.HTML_NAME} ({info['images']} images, {len(info['sweeps'])} sweeps)")
    return 0


def cmd_keys(args: argparse.Namespace) -> int:
    from . import stages  # noqa: F401  (the registry hands the loader the sections stages bring)

    # arrays of tables list their fields too: lighting.lights[].kind = "sun", ...
    for key, val in config_mod.key_defaults():
        print(f"{key} = {json.dumps(val)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bake", description="Bake 3D models into Scratch-ready lists.")
    p.add_argument("--version", action="version", version=f"scratch-bake {__version__}")
    p.add_argument("--debug", action="store_true", help="show Python tracebacks")
    sub = p.add_subparsers(dest="command", required=True)

    def common(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config key (repeatable), e.g. --set bsp.enabled=true")
        sp.add_argument("--quiet", action="store_true", help="print nothing but errors")
        # SUPPRESS: when absent here, `bake --debug run ...` (the top-level flag) still counts
        sp.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                        help="show Python tracebacks")

    r = sub.add_parser("run", help="bake a model file or a config")
    r.add_argument("target", help="a model (.obj/.gltf/.glb) or a config (.toml)")
    r.add_argument("--out", help="output folder (default: bake-out/<name>)")
    r.add_argument("--depfile", help="write Make-style dependencies to this file")
    r.add_argument("--strict", action="store_true",
                   help="exit 4 if a Scratch limit is exceeded or the bake has a problem (e.g. all-black lighting)")
    common(r)
    r.set_defaults(func=cmd_run)

    d = sub.add_parser("demo", help="bake the bundled sample into ./bake-demo/")
    d.add_argument("--out", default="bake-demo")
    common(d)
    d.set_defaults(func=cmd_demo)

    i = sub.add_parser("inspect", help="print counts, materials, bounds and list sizes of a model")
    i.add_argument("target")
    i.add_argument("--json", action="store_true")
    common(i)
    i.set_defaults(func=cmd_inspect)

    sw = sub.add_parser("sweep", help="bake at several values of any numeric key: error and bytes against seconds")
    sw.add_argument("target", help="a model or a config (.toml)")
    sw.add_argument("--vary", required=True, metavar="KEY=V1,V2,...",
                    help="e.g. lighting.ao.samples=16,64,256,1024")
    sw.add_argument("--reference", metavar="VALUE", help="compare against a bake at this value "
                    "(default: the highest value swept)")
    sw.add_argument("--out", help="the bake's output folder (default: bake-out/<name>); writes "
                    "OUT/sweeps/KEY.json and .svg, shown by OUT/report.html")
    common(sw)
    sw.set_defaults(func=cmd_sweep)

    ck = sub.add_parser("check", help="where a project's bytes go: lists, blocks, assets against Scratch's limits")
    ck.add_argument("target", help="an .sb3 (or a project.json)")
    ck.add_argument("--json", action="store_true")
    ck.add_argument("--with", dest="with_lists", metavar="LISTS_JSON",
                    help="a bake's lists.json: check the project as the engine those lists would go into "
                         "(which blocks read each list; lists no block reads, parallel lists, a green-flag "
                         "delete all)")
    ck.add_argument("--into-target", default="Stage", metavar="NAME",
                    help="with --with: the sprite the lists would go into (default: the stage)")
    ck.add_argument("--strict", action="store_true", help="exit 4 if a limit is exceeded or the project has a problem")
    ck.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show Python tracebacks")
    ck.set_defaults(func=cmd_check)

    rp = sub.add_parser("report", help="re-render report.html of a finished bake (no baking)")
    rp.add_argument("out_dir", help="the output folder of a bake (has report.json and lists.json)")
    rp.add_argument("--width", type=int, default=320, help="preview width in pixels (default 320)")
    rp.add_argument("--quiet", action="store_true", help="print nothing but errors")
    rp.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show Python tracebacks")
    rp.set_defaults(func=cmd_report)

    k = sub.add_parser("keys", help="list every config key with its default")
    k.set_defaults(func=cmd_keys, set=[], quiet=False)

    for extra in _EXTRA_COMMANDS:
        extra(sub, common)
    return p


# Commands contributed by other modules: functions (subparsers, common) -> None.
_EXTRA_COMMANDS: list[Callable[[Any, Callable], None]] = []


# --------------------------------------------------------------------------- watch
def cmd_watch(args: argparse.Namespace) -> int:
    from . import watch

    target = Path(args.target)
    if not target.exists():
        raise InputError("file not found", path=target)
    if not (args.debounce >= 0 and args.debounce != float("inf")):  # (NaN fails both)
        raise ConfigError(f"--debounce expects seconds >= 0, got {args.debounce}")
    out = Path(args.out) if args.out else _default_out(target)
    return watch.watch(target, args.set, out, quiet=args.quiet, debug=getattr(args, "debug", False),
                       debounce=args.debounce)


def _add_watch(sub: Any, common: Callable) -> None:
    w = sub.add_parser("watch", help="bake, then bake again whenever the model, its files or the config change")
    w.add_argument("target", help="a model (.obj/.gltf/.glb) or a config (.toml)")
    w.add_argument("--out", help="output folder (default: bake-out/<name>)")
    w.add_argument("--debounce", type=float, default=0.1, metavar="SECONDS",
                   help="wait this long after the last change before baking (default 0.1)")
    common(w)
    w.set_defaults(func=cmd_watch)


_EXTRA_COMMANDS.append(_add_watch)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised like Ctrl-C so every temporary file is cleaned up on the way out."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _terminate(signum: int, _frame: Any) -> None:
    raise Terminated(signum)


def _catch_termination() -> None:
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for name in ("SIGTERM", "SIGHUP"):
        s = getattr(signal, name, None)
        if s is not None and signal.getsignal(s) in (signal.SIG_DFL, None):
            signal.signal(s, _terminate)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = getattr(args, "debug", False)
    _catch_termination()
    try:
        return int(args.func(args) or 0)
    except BakeError as e:
        if debug:
            traceback.print_exc()
        print(f"bake: error: {e}", file=sys.stderr)
        return e.exit_code
    except BrokenPipeError:  # e.g. `bake keys | head`
        sys.stderr.close()
        return 0
    except KeyboardInterrupt as e:
        from .outputs import write

        what = "terminated" if isinstance(e, Terminated) else "interrupted"
        state = ("after the outputs were written (the output folder is the new bake's)" if write.COMMITTED else
                 "before any output was written (the output folder is as it was)")
        print(f"bake: {what} {state}", file=sys.stderr)
        return 128 + e.signum if isinstance(e, Terminated) else 130
    except Exception as e:  # a bug: one line, traceback with --debug
        if debug:
            traceback.print_exc()
        print(f"bake: internal error: {type(e).__name__}: {e} (rerun with --debug for the traceback)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
