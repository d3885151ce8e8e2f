"""Command line: ``flexctl run``, ``flexctl export``, ``flexctl scenes``, ``flexctl demo``,
``flexctl bench``.

::

    flexctl run SCENE [--set key=value ...] [--out DIR]
    flexctl export SCENE [--set key=value ...] [--out DIR] [--sample-time S] [--no-compile]
                   [--precision double|float] [--loop-check]
                   [--target host|cortex-m4|cortex-m7]
    flexctl scenes
    flexctl demo [--out DIR] [--workers N]
    flexctl bench [--quick] [--scene SCENE ...] [--modes 1-12] [--out DIR]
                  [--store FILE] [--resume] (see --help)
    flexctl --version

``SCENE`` is a TOML file or the name of a built-in scene; ``--set`` overrides one value by its
dotted path (``--set maneuver.spin_rate=10 --set model.variant=zero_order``), the value read as
TOML. ``run`` writes ``timeseries.csv``, ``summary.json`` and ``response.png`` into ``DIR``
(default ``flexctl-out/<scene name>``), see :mod:`flexctl.app.report`.

Exit status: 0 when every run reached its final time (for ``demo``: when every run ended as
expected), 3 when a run stopped early (diverged or singular; its files are still written), 2 on
bad input (one line on stderr starting ``flexctl: error:`` naming the key, the rule and the
value, and nothing else on stderr), 1 for a bug (with its traceback).

Every output is written whole or not at all (:mod:`flexctl.sim.atomic_files`): a run's files,
an export, a bench scene's pages and the demo folder are written into a temporary folder and
moved into ``DIR`` only once all of them are complete; a command that fails leaves ``DIR`` as
it was, and files of other names in ``DIR`` are kept. ``flexctl export`` holds what the design
and the compiler print, like a run: when it fails (a compiler that refuses the code is named
with its exit status and messages), its error line is alone on stderr.

Examples
--------
>>> from flexctl.app.cli import main
>>> main(["--version"])
flexctl 0.1.0
0
"""

from __future__ import annotations

import argparse
import ctypes
import os
import sys
import tempfile
import textwrap
import time
import traceback
import warnings
from dataclasses import fields
from pathlib import Path

from controllers.spec import CONTROLLER_KINDS

from .. import __version__
from ..model.errors import InputError, InputValueError
from .bench import BenchConfig, run_bench, summary_line
from .demo import DEMO_WORKERS, run_demo
from .report import format_summary
from ..sim.blas_threads import DEFAULT_THREADS, threads_from_environment
from ..sim.progress import progress_printer
from .runner import execute, write_complete
from .scenes import SceneError, builtin_scenes, load_scene
from .spatial_scene import SpatialScene

__all__ = ["main", "parse_overrides", "EXIT_OK", "EXIT_BUG", "EXIT_BAD_INPUT", "EXIT_STOPPED"]

EXIT_OK = 0
EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_STOPPED = 3
PROG = "flexctl"
DEFAULT_RUN_DIR = Path("flexctl-out")
DEFAULT_DEMO_DIR = Path("flexctl-demo")
#: The bench's store in its output directory when ``--resume`` names none.
BENCH_STORE = "bench-runs.sqlite"
#: Errors of loading or running a scene that are the user's input, reported in one line: the
#: checks of parameters, scenes, controller settings and simulate raise these; any other
#: exception is a bug and ends with its traceback (exit 1).
INPUT_ERRORS = (InputError,)

class _Parser(argparse.ArgumentParser):
    """argparse with errors in one line, like the rest of the command line."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{PROG}: error: {message} (see '{self.prog} --help')\n")


def _error(message) -> int:
    text = " ".join(str(message).split()) or type(message).__name__
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return EXIT_BAD_INPUT


def parse_overrides(settings) -> dict:
    """``["a.b=1", ...]`` from ``--set`` to ``{"a.b": "1"}`` (values stay text for load_scene).

    Parameters
    ----------
    settings : sequence of str or None
        The ``--set`` values, each ``key=value`` (spaces around either are dropped); None
        for none.

    Raises
    ------
    flexctl.model.errors.InputValueError
        If a setting has no ``=``.

    Examples
    --------
    >>> parse_overrides(["model.variant=zero_order", "maneuver.spin_rate = 10"])
    {'model.variant': 'zero_order', 'maneuver.spin_rate': '10'}
    """
    out = {}
    for item in settings or ():
        key, sep, value = item.partition("=")
        if not sep:
            raise InputValueError(f"--set expects key=value, e.g. --set "
                                  f"maneuver.spin_rate=10; got {item!r}")
        out[key.strip()] = value.strip()
    return out


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Simulate rigid-flexible hub-beam-mass scenes.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="simulate one scene and write its files",
                              description=textwrap.fill(
                                  "Simulate a scene; write timeseries.csv, summary.json and "
                                  "response.png. Exit 0 when the run reached its final time, "
                                  "3 when it stopped (diverged or singular), 2 on bad input.",
                                  width=80), epilog=controller_help(),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("scene", metavar="SCENE", help="TOML file, a run's summary.json (runs "
                     "that scene again) or built-in scene name (see 'flexctl scenes')")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a scene value by its dotted path, value read as TOML, "
                     "e.g. --set model.variant=zero_order (repeatable)")
    run.add_argument("--out", metavar="DIR", type=_out_dir,
                     help=f"output directory (default {DEFAULT_RUN_DIR}/<scene name>)")
    run.add_argument("--animate", action="store_true",
                     help="also write animation.gif: the structure turning and bending "
                     "(spatial scenes)")
    run.set_defaults(func=_cmd_run)

    export = commands.add_parser(
        "export", help="write a slew scene's controller as C99, compile and check it",
        description=textwrap.fill(
            "Design the scene's controller and write it as self-contained C99 "
            "(flexctl_ctrl.h, flexctl_ctrl.c, an example main.c and a Makefile) in DIR; "
            "where a C compiler is present, compile it at -std=c99 -Wall -Wextra -Werror and "
            "check it against the law's CasADi form. The files are written whole or not at "
            "all: a failure leaves DIR as it was, files of other names in it are kept. Exit 0 "
            "on success, 2 on bad input, a compiler that fails or a law that has no C form "
            "(the reason is printed).", width=80))
    export.add_argument("scene", metavar="SCENE", help="TOML file or built-in scene name")
    export.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a scene value, as for 'flexctl run' (repeatable)")
    export.add_argument("--out", metavar="DIR", type=_out_dir,
                        help=f"output directory (default {DEFAULT_RUN_DIR}/<scene name>/c)")
    export.add_argument("--sample-time", metavar="S", type=_positive_seconds, default=None,
                        help="s: the rate an LQG's estimator is discretised at (default the "
                        "sensors', else 0.01), or a continuous law is sampled at")
    _flight_options(export)
    export.add_argument("--no-compile", action="store_true",
                        help="write the files only")
    export.set_defaults(func=_cmd_export)

    scenes = commands.add_parser("scenes", help="list the built-in scenes")
    scenes.set_defaults(func=_cmd_scenes)

    demo = commands.add_parser("demo", help="run every built-in scene and write a report",
                               description="Run every built-in scene and the Kane spin-up "
                               "with the zero_order model; reproduce the papers' figures "
                               "(paper 001 Figs. 4 and 5, paper 000 Figs. 5 to 8 with their "
                               "sweeps) and compare every controller kind on slew-90; write "
                               "each run's files, the figures and report.md.")
    demo.add_argument("--out", metavar="DIR", type=_out_dir, default=DEFAULT_DEMO_DIR,
                      help=f"output directory (default {DEFAULT_DEMO_DIR})")
    demo.add_argument("--workers", metavar="N", type=_worker_count, default=DEMO_WORKERS,
                      help="processes for the sweeps and the controller comparison "
                      f"(default {DEMO_WORKERS}; 1 runs everything in this process)")
    demo.set_defaults(func=_cmd_demo)

    _add_bench_command(commands)
    cache = commands.add_parser(
        "cache", help="list or clear the compiled-function cache and the remembered runs",
        description="CasADi functions compiled to machine code are kept in a cache directory "
        "($FLEXCTL_CACHE_DIR, else $XDG_CACHE_HOME/flexctl or ~/.cache/flexctl) and reused by "
        "later runs; the demo's runs are remembered by their inputs and the code's version "
        "in its runs/ folder ($FLEXCTL_RUN_CACHE_DIR; FLEXCTL_RUN_CACHE=0 turns it off), so "
        "that a second 'flexctl demo' replays them. 'info' shows the directory, its entries, "
        "their size and the compiler, and the remembered runs; 'clear' removes both.")
    cache.add_argument("action", choices=("info", "clear"), help="what to do")
    cache.set_defaults(func=_cmd_cache)
    return parser


def controller_help() -> str:
    """The controller kinds and their settings with defaults, from the registry
    (:data:`controllers.spec.CONTROLLER_KINDS`), for ``flexctl run --help``."""
    lines = textwrap.wrap("controller kinds of a slew scene's [controller] table, and their "
                          "settings (default; -: off or chosen by the design; rules and units "
                          "in controllers.factory):", width=92)
    for kind in CONTROLLER_KINDS.values():
        items = ", ".join(f"{item.name}={item.default_text or '-'}"
                          for item in kind.settings)
        lines.append(textwrap.fill(f"{kind.name}: {items}", width=92, initial_indent="  ",
                                   subsequent_indent="      "))
    return "\n".join(lines)


def _list(kind):
    """argparse type: comma-separated values; integers may be ranges like 1-12."""
    def parse(text):
        parts = [p.strip() for p in str(text).split(",") if p.strip()]
        return tuple(v for p in parts for v in (
            range(int(p.split("-", 1)[0]), int(p.split("-", 1)[1]) + 1)
            if kind is int and "-" in p[1:] else (kind(p),)))
    parse.__name__ = f"list of {kind.__name__}"
    return parse


def _add_bench_command(commands) -> None:
    """``flexctl bench``: speed against error sweeps of :mod:`flexctl.app.bench`."""
    p = commands.add_parser(
        "bench", help="sweep modes, variants and integrators: speed against error",
        description="For every built-in scene driven by a torque or a hub motion (or the "
        "scenes named), sweep the number of modes, the model variants, the integrators and "
        "their tolerances; write per scene a CSV, a Markdown table and a speed-against-error "
        "plot, and report.md. Exit 0 when done, 2 on bad input.")
    p.add_argument("--scene", action="append", default=[], help="scene name or TOML file "
                   "(repeatable; default every built-in scene with an input manoeuvre)")
    p.add_argument("--quick", action="store_true", help="a small sweep (BenchConfig.quick); "
                   "the options below still apply")
    for flag, kind, text in (
            ("--modes", _list(int), "numbers of modes, e.g. 1-12 or 1,2,4 (default 1-12)"),
            ("--variants", _list(str), "default first_order,zero_order,consistent,exact"),
            ("--methods", _list(str), "default cvodes,DOP853,LSODA"),
            ("--rtols", _list(float), "default 1e-4,1e-6,1e-8"),
            ("--reference-modes", int, "modes of the reference (default 20)"),
            ("--reference-rtol", float, "rtol of the reference (default 1e-10)"),
            ("--time-limit", float, "s before a SciPy run is stopped (default 30)"),
            ("--tolerance", float, "relative tip error of the mode choice (default 1e-2)"),
            ("--t-final", float, "horizon in s instead of each scene's")):
        p.add_argument(flag, type=kind, help=text)
    p.add_argument("--out", type=_out_dir, default=Path("flexctl-bench"), metavar="DIR",
                   help="output directory (default flexctl-bench)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--store", type=_out_dir, metavar="FILE",
                   help="SQLite file that every run is committed to as it finishes (default "
                   f"none; DIR/{BENCH_STORE} with --resume)")
    p.add_argument("--resume", action="store_true", help="take the runs already in the "
                   "store (after a crash or a Ctrl-C) and run only the others")
    p.set_defaults(func=_cmd_bench)


class _InputError(Exception):
    """Bad input or an unwritable output directory, reported in one line."""


def _out_dir(text: str) -> Path:
    """argparse type of ``--out``: a non-empty path (``''`` would mean the current directory)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must name a directory; got {text!r}")
    return Path(text)


def _positive_seconds(text: str) -> float:
    """argparse type of ``--sample-time``: a positive, finite number of seconds."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds; got {text!r}") from None
    if not (value > 0.0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be positive and finite, s; got {text!r}")
    return value


def _flush_c_stdio() -> None:
    """Flush the C library's buffered streams (IPOPT writes through printf)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # pragma: no cover - no C library to flush
        pass


class _HeldOutput:
    """Hold what a run writes to the process's stdout and stderr, and its Python warnings.

    CasADi and IPOPT print from C++, numpy and the simulation warn: a run that ends in bad
    input must leave only its one error line on stderr, so the output is held at the file
    descriptors and either dropped (bad input) or replayed (any other end).
    """

    def __init__(self):
        self.streams = {}
        self.caught = []
        self._saved, self._files, self._catcher = {}, {}, None

    def __enter__(self):
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        _flush_c_stdio()
        try:
            for fd in (1, 2):
                self._files[fd] = tempfile.TemporaryFile()
                self._saved[fd] = os.dup(fd)
                os.dup2(self._files[fd].fileno(), fd)
        except OSError:     # no such descriptor: nothing to hold there
            pass
        self._catcher = warnings.catch_warnings(record=True)
        self.caught = self._catcher.__enter__()
        warnings.simplefilter("always")
        return self

    def __exit__(self, *exc_info):
        self._catcher.__exit__(*exc_info)
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        _flush_c_stdio()
        for fd, saved in self._saved.items():
            os.dup2(saved, fd)
            os.close(saved)
        for fd, file in self._files.items():
            file.seek(0)
            self.streams[fd] = file.read().decode("utf-8", "replace")
            file.close()
        return False

    def write_through(self, line: str) -> None:
        """Write ``line`` to the real stderr now, past the hold (progress of a long run)."""
        saved = self._saved.get(2)
        if saved is None:
            print(line, file=sys.stderr, flush=True)
            return
        os.write(saved, (line + "\n").encode("utf-8", "replace"))

    def replay(self) -> None:
        """Write the held output where it was going, and each warning as one line."""
        for fd, stream in ((1, sys.stdout), (2, sys.stderr)):
            if self.streams.get(fd):
                stream.write(self.streams[fd])
                stream.flush()
        seen = set()
        for w in self.caught:
            line = _warning_line(w.message, w.category)
            if line not in seen:            # each warning once per run
                seen.add(line)
                print(line, file=sys.stderr)


def _warning_line(message, category) -> str:
    """A warning as the one console line ``flexctl: warning: Category: text``."""
    text = " ".join(str(message).split())
    return f"{PROG}: warning: {category.__name__}: {text}"


class _OneLineWarnings:
    """Every warning shown outside a held run (the demo's figures and sweeps, their worker
    processes forked from this one) as one ``_warning_line``, each text once."""

    def __init__(self):
        self.seen = set()
        self._catcher = warnings.catch_warnings()

    def show(self, message, category, filename, lineno, file=None, line=None):
        text = _warning_line(message, category)
        if text not in self.seen:
            self.seen.add(text)
            print(text, file=sys.stderr if file is None else file, flush=True)

    def __enter__(self):
        self._catcher.__enter__()
        warnings.showwarning = self.show
        return self

    def __exit__(self, *exc_info):
        return self._catcher.__exit__(*exc_info)


def _worker_count(text: str) -> int:
    """argparse type of ``demo --workers``: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1; got {text!r}")
    return value


def _load_and_run(source, overrides: dict, out_dir: Path | None,
                  animate: bool = False) -> dict:
    """Load, simulate and write one scene: the shared step of ``run`` and ``demo``.

    Returns the summary of :func:`flexctl.app.report.write_run`; raises ``_InputError``
    on bad input, with nothing else written to stdout or stderr.
    """
    held = _HeldOutput()
    try:
        with held:
            scene = load_scene(source, overrides=overrides)
            if animate and not isinstance(scene, SpatialScene):
                raise InputValueError(f"--animate draws spatial scenes (a 3 x 3 hub.inertia); "
                                      f"{scene.name} is planar")
            progress = progress_printer(lambda line: held.write_through(f"{PROG}: {line}"))
            result, extra, reference = execute(scene, progress=progress)
    except INPUT_ERRORS as exc:
        raise _InputError(str(exc)) from None
    except BaseException:
        held.replay()
        raise
    held.replay()
    out = out_dir if out_dir is not None else DEFAULT_RUN_DIR / scene.name
    try:
        return write_complete(scene, result, out, overrides, extra, reference,
                              animate=animate)
    except InputError as exc:           # a folder where a file goes
        raise _InputError(str(exc)) from None
    except OSError as exc:
        raise _InputError(_cannot_write(f"the files of {scene.name}", out, exc)) from None


def _cmd_run(args) -> int:
    try:
        overrides = parse_overrides(args.set)
        summary = _load_and_run(args.scene, overrides, args.out, animate=args.animate)
    except (_InputError, InputError) as exc:
        return _error(exc)
    if summary.get("spatial"):
        from .spatial_report import format_spatial_summary
        print(format_spatial_summary(summary))
    else:
        print(format_summary(summary))
    return EXIT_OK if summary["status"] == "ok" else EXIT_STOPPED


def _flight_options(export) -> None:
    """``flexctl export``'s options of the flight computer: precision and target."""
    from controllers.codegen.precision import PRECISIONS
    from controllers.codegen.targets import TARGETS

    export.add_argument("--precision", choices=PRECISIONS, default="double",
                        help="the C type of every real of the law (default double); float "
                        "is refused, with the reason, where single precision breaks the law")
    export.add_argument("--loop-check", action="store_true",
                        help="also fly the slew with the law compiled in double and in float "
                        "and report what single precision changed")
    export.add_argument("--target", choices=tuple(TARGETS), default="host",
                        help="also build the law freestanding for this processor with "
                        "Debian's arm-none-eabi-gcc (hard float, -Werror) and report its code, "
                        "constant, RAM and stack sizes (default host: the host build only)")


def _cmd_export(args) -> int:
    """``flexctl export``: the design, the compile cache and IPOPT are held like a run's
    (``_HeldOutput``), so that a failure leaves its one error line alone on stderr."""
    from controllers.codegen import CompileError

    from .export import export_scene, format_export
    held, out = _HeldOutput(), args.out
    try:
        with held:
            scene = load_scene(args.scene, overrides=parse_overrides(args.set))
            out = out if out is not None else DEFAULT_RUN_DIR / scene.name / "c"
            summary = export_scene(scene, out, sample_time=args.sample_time,
                                   compile=not args.no_compile, precision=args.precision,
                                   loop_check=args.loop_check, target=args.target)
    except (InputError, CompileError) as exc:
        return _error(exc)
    except OSError as exc:
        return _error(_cannot_write("the export", out, exc))
    except BaseException:
        held.replay()
        raise
    held.replay()
    print(format_export(summary))
    return EXIT_OK


def _cannot_write(what: str, out, exc: OSError) -> str:
    """The one line of an output that could not be written: where, why, and which file."""
    where = f" ({exc.filename})" if exc.filename else ""
    return f"cannot write {what} to {out}: {exc.strerror or exc}{where}"


def _cmd_scenes(args) -> int:
    scenes = builtin_scenes()
    width = max(map(len, scenes), default=0)
    for name, description in scenes.items():
        print(f"{name:<{width}}  {description}")
    return EXIT_OK


def _cmd_bench(args) -> int:
    names = [f.name for f in fields(BenchConfig) if f.name != "scenes"]
    changes = {k: getattr(args, k) for k in names if getattr(args, k) is not None}
    if args.scene:
        changes["scenes"] = tuple(args.scene)
    start = time.perf_counter()
    try:
        config = BenchConfig.quick(**changes) if args.quick else BenchConfig(**changes)
        store = args.store or (Path(args.out) / BENCH_STORE if args.resume else None)
        benches = run_bench(config, args.out, progress=not args.no_progress, store=store,
                            resume=args.resume)
    except (SceneError, ValueError, TypeError) as exc:
        return _error(exc)
    except OSError as exc:
        return _error(_cannot_write("the bench files", args.out, exc))
    for b in benches:
        print(summary_line(b))
    print(f"report: {Path(args.out) / 'report.md'} ({time.perf_counter() - start:.1f} s)")
    return EXIT_OK


def _cmd_demo(args) -> int:
    start = time.perf_counter()
    try:
        report, surprises = run_demo(args.out, _load_and_run, workers=args.workers,
                                     progress=lambda line: print(line, flush=True))
    except _InputError as exc:
        return _error(exc)
    except InputError as exc:           # a folder where a file goes
        return _error(exc)
    except OSError as exc:
        return _error(_cannot_write("the demo report", args.out, exc))
    print(f"report: {report} ({time.perf_counter() - start:.1f} s)")
    for text in surprises:
        print(f"{PROG}: unexpected: {text}", file=sys.stderr)
    return EXIT_STOPPED if surprises else EXIT_OK


def _cmd_cache(args) -> int:
    from ..sim.compile_cache import cache_dir, cache_info, clear_cache
    from .run_cache import clear_run_cache, run_cache_info
    try:
        if args.action == "clear":
            report, runs = clear_cache(), clear_run_cache()
            print(report)
            print(f"removed {runs.files} remembered runs from {runs.folder}")
            failed = report.failed + runs.failed
            if failed:
                return _error(f"could not remove {len(failed)} files from the cache "
                              f"(first: {failed[0][0]}: {failed[0][1]})")
        else:
            print(cache_info())
            print(run_cache_info())
    except OSError as exc:
        return _error(f"cannot read the cache {cache_dir()}: {exc.strerror or exc}")
    return EXIT_OK


def main(argv=None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit status.

    A bug (any exception that is not bad input) prints its traceback and returns 1.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name. Default None: ``sys.argv[1:]``.
    """
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:    # --help, --version and usage errors
        if exc.code is None:
            return EXIT_OK
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    # one BLAS thread per process (flexctl.sim.blas_threads), in the worker processes too
    os.environ.setdefault("FLEXCTL_BLAS_THREADS", str(DEFAULT_THREADS))
    threads_from_environment()
    try:
        with _OneLineWarnings():
            return args.func(args)
    except Exception:   # a bug: say where, and do not pass it off as bad input
        traceback.print_exc()
        return EXIT_BUG


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
