"""The ``gearjax`` command line (interface.md): info, modes, calibrate, sweep, simulate,
verify, sensitivity, optimize, study, plot.

Why this module is long: it is the one module that knows flag names and exit codes, so
the parser of every command, their handlers and the translation of library errors into
flag words stay together.

Exit codes: 0 finished; 2 bad input or usage (one line on stderr, no traceback);
3 finished but nothing converged; 1 an internal error or a problem too large for the
memory (one line; ``GEARJAX_DEBUG=1`` shows the traceback); 130 interrupted.
JAX's and XLA's own log messages stay off stderr (the console script, :func:`console`)
unless ``GEARJAX_DEBUG=1``.
``--json`` prints one JSON object on stdout and nothing else there; warnings go to
stderr, one line each.

Refuse, don't guess: every output path (``--out``, ``--out-train``, ``--plot``,
``plot --out``) is checked before any work; results are written atomically; a sweep's
journal is locked while its run is live, so a second run on the same ``--out`` is
refused instead of racing the first.

The library speaks in Python terms: an :class:`~gearjax._errors.ArgumentError` names
the Python argument and writes other arguments as ``` `name` ```; :data:`ARGUMENT_FLAGS`
translates both into flags here (``command line: --flag = VALUE: RULE``), and the
backticked names in any other refusal or warning of gearjax's.
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import os
import pathlib
import re
import sys
import warnings
from fractions import Fraction

import numpy as np

from ._errors import (
    ArgumentError,
    TrainError,
    TrainWarning,
    fail,
    field_message,
    one_line,
)
from ._config import quiet_jax_logs
from ._environment import check_environment

EXIT_OK, EXIT_INTERNAL, EXIT_INPUT, EXIT_NOT_CONVERGED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
DEBUG_ENV = "GEARJAX_DEBUG"
DEFAULT_INPUT_RPM = 1000.0
"""``info``'s input speed where neither ``--input-rpm`` nor the gear's ``input_rpm`` is
given."""

ARGUMENT_FLAGS = {
    # every command, and the sweep
    "gear": "--gear", "stage": "--stage", "linear": "--linear", "harmonics": "--harmonics",
    "from_hz": "--from", "to_hz": "--to", "eta": "--eta", "max_step_hz": "--max-step",
    "points": "--points", "max_points": "--max-points", "smoothing": "--smoothing",
    "resume": "--resume", "journal": "--out",  # the command line keeps it as --out FILE.journal
    # study, and plot of a study
    "store": "--out", "workers": "--workers", "client": "--scheduler", "merit": "--pareto",
    # info
    "input_rpm": "--input-rpm",
    # simulate, verify
    "at_hz": "--at", "tol_linear": "--tol-linear", "tol_nonlinear": "--tol-nonlinear",
    "curve": "--curve",
    # calibrate (gearjax._gear.calibrate)
    "targets_hz": "--targets-hz", "free": "--free", "out_train": "--out-train",
    # sensitivity
    "response": "--response", "mesh": "--mesh", "paths": "--vary",
    # optimize (and its OptimizeSettings fields)
    "band_hz": "--band", "vary": "--vary", "proxy_points": "--proxy-points",
    "phase_grid": "--phase-grid", "screen": "--screen", "screen_points": "--points",
    "final_points": "--final-points", "nonlinear": "--nonlinear",
    "nonlinear_harmonics": "--harmonics", "relax_iterations": "--relax-iterations",
    "passes": "--passes", "seeds": "--seeds", "recheck_band_hz": "--recheck-band",
    "recheck_harmonics": "--recheck-harmonics",
    # plot
    "what": "--what", "out": "--out",
}
"""The flag of each Python argument name the library's errors use."""


def console() -> None:
    """The ``gearjax`` console script: :func:`main` on ``sys.argv``, with JAX's and XLA's
    log messages kept off stderr (:func:`~gearjax._config.quiet_jax_logs`) unless
    ``GEARJAX_DEBUG=1``; exits with :func:`main`'s code. Callers of :func:`main` in
    Python keep their own logging."""
    if os.environ.get(DEBUG_ENV, "") in ("", "0"):
        quiet_jax_logs()
    sys.exit(main())


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as e:
        return _refuse(str(e))
    args.command_line = _command_line(argv)
    if args.command is None:
        return _refuse(f"command line: COMMAND = (missing): give one of "
                       f"{', '.join(_COMMANDS)} (gearjax --help describes them)")
    notes: list[str] = []
    try:
        check_environment()
        _check_outputs(args)
        with warnings.catch_warnings():
            warnings.simplefilter("always", TrainWarning)
            warnings.showwarning = _warning_printer(notes, warnings.showwarning)
            if not getattr(args, "needs_train", True):  # e.g. plot: a results file, no train
                return args.run(args, None, notes)
            from ._gear.toml_io import load_train

            train = load_train(args.train)
            return args.run(args, train, notes)
    except TrainError as e:
        return _refuse(cli_message(e))
    except KeyboardInterrupt:
        _stderr(_interrupted(args))
        return EXIT_INTERRUPTED
    except Exception as e:  # noqa: BLE001  no traceback reaches a user
        if os.environ.get(DEBUG_ENV, "") not in ("", "0"):
            raise
        if _out_of_memory(e):
            how = ("fewer harmonics (--harmonics K)" if hasattr(args, "harmonics")
                   else "a smaller problem")
            _stderr(f"gearjax: error: the problem did not fit in memory ({_one_line(e, 160)}): "
                    f"try {how}, fewer points or a narrower band")
            return EXIT_INTERNAL
        if isinstance(e, OSError):
            return _refuse(_os_error(e))
        _stderr(f"gearjax: internal error: {type(e).__name__}: {_one_line(e)} "
                f"(set {DEBUG_ENV}=1 for the traceback)")
        return EXIT_INTERNAL


def _refuse(message: str) -> int:
    _stderr(f"gearjax: error: {one_line(message)}")
    return EXIT_INPUT


def cli_message(e: TrainError) -> str:
    """A library refusal in the command line's words: an ``ArgumentError`` as
    ``command line: --flag = VALUE: RULE``, and in any message the backticked argument
    names of :data:`ARGUMENT_FLAGS` as their flags."""
    if isinstance(e, ArgumentError):
        flag = ARGUMENT_FLAGS.get(e.argument, e.argument)
        return field_message("command line", flag, e.value, flag_words(e.rule))
    return flag_words(str(e))


def flag_words(text: str) -> str:
    """``text`` with each backticked Python argument name of :data:`ARGUMENT_FLAGS` (e.g.
    ``` `from_hz` ```) replaced by its flag (``--from``)."""
    return re.sub(r"`(\w+)`", lambda m: ARGUMENT_FLAGS.get(m[1], m[0]), text)


def _command_line(argv: list[str] | None) -> str:
    """How this run was asked for, as the results files record it."""
    return " ".join(sys.argv if argv is None else ["gearjax", *argv])


def _warning_printer(notes: list[str], fallback):
    """A ``warnings.showwarning`` that prints each distinct :class:`TrainWarning` (and
    any other warning of gearjax's own, e.g. a truncation estimate) once, as one line
    on stderr, and keeps it in ``notes`` (the JSON ``warnings``)."""

    def show(message, category, filename, lineno, file=None, line=None):
        ours = issubclass(category, TrainWarning) or category.__module__.startswith("gearjax")
        if not ours:
            return fallback(message, category, filename, lineno, file, line)
        text = flag_words(_one_line(message, 1000))
        if text not in notes:
            notes.append(text)
            _stderr(f"warning: {text}")

    return show


def _one_line(e, limit: int = 300) -> str:
    text = one_line(" ".join(str(e).split())) or type(e).__name__
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _out_of_memory(e: BaseException) -> bool:
    if isinstance(e, MemoryError):
        return True
    text = str(e)
    return "RESOURCE_EXHAUSTED" in text or "out of memory" in text.lower()


def _os_error(e: OSError) -> str:
    """One line naming the file and the operating system's reason."""
    reason = e.strerror or _one_line(e)
    if e.filename is not None:
        where = str(e.filename) + (f" -> {e.filename2}" if e.filename2 is not None else "")
        return f"{where}: {reason}"
    return f"{type(e).__name__}: {_one_line(e)}"


def _interrupted(args) -> str:
    from ._io.journal import journal_path

    out = getattr(args, "out", None)
    if getattr(args, "command", None) == "study":
        store = _study_store(args)
        if pathlib.Path(store).is_dir():
            return (f"gearjax: interrupted; the finished candidates are in {store}: run the "
                    "same command with --resume to go on")
    if getattr(args, "command", None) == "sweep" and out and journal_path(out).exists():
        return (f"gearjax: interrupted; the points found so far are in {journal_path(out)}: "
                "run the same command with --resume to go on")
    return "gearjax: interrupted"


# ------------------------------------------------------------------ usage errors


class _UsageError(Exception):
    """argparse's refusal, made one line (:class:`_Parser`)."""


class _Parser(argparse.ArgumentParser):
    """``ArgumentParser`` whose usage errors are one line in the form of every other
    refusal (``command line: FLAG = VALUE: RULE``) instead of a usage dump."""

    def error(self, message: str):
        raise _UsageError(_usage_message(self.prog, message))


_COMMANDS = ("info", "modes", "calibrate", "sweep", "simulate", "verify", "sensitivity",
             "optimize", "study", "plot")


def _usage_message(prog: str, message: str) -> str:
    message = " ".join(message.split())
    hint = f" (see {prog} --help)"
    m = re.fullmatch(r"argument (\S+?)(?:/\S+)?: invalid choice: (.*?) \(choose from (.*)\)",
                     message)
    if m:
        choices = ", ".join(c.strip().strip("'") for c in m[3].split(","))
        return f"command line: {m[1]} = {m[2]}: must be one of {choices}{hint}"
    m = re.fullmatch(r"argument (\S+?)(?:/\S+)?: invalid (\w+) value: (.*)", message)
    if m:
        rule = {"float": "must be a number", "int": "must be a whole number"}.get(
            m[2], f"must be a valid {m[2]}")
        return f"command line: {m[1]} = {m[3]}: {rule}{hint}"
    m = re.fullmatch(r"the following arguments are required: (.*)", message)
    if m:
        flags = m[1]
        return f"command line: {flags} = (missing): {prog} needs it{hint}"
    m = re.fullmatch(r"argument (\S+?)(?:/\S+)?: (expected .*)", message)
    if m:
        return f"command line: {m[1]} = (missing): {m[2]}{hint}"
    m = re.fullmatch(r"unrecognized arguments: (.*)", message)
    if m:
        return f"command line: {m[1]}: not a flag or argument of this command{hint}"
    return f"command line: {prog}: {message}{hint}"


# ------------------------------------------------------------------ output paths


RESULT_SUFFIXES = {"sweep": (".nc", ".csv"), "simulate": (".nc", ".csv"),
                   "verify": (".nc",), "optimize": (".nc",)}
SUFFIX_RULES = {(".nc", ".csv"): "must end in .nc or .csv",
                (".nc",): "must end in .nc (NetCDF)"}


def _check_outputs(args) -> None:
    """Refuse, before any work, an output path that cannot be written: a directory, a
    missing or read-only directory, an unknown extension (one line, ``TrainError``)."""
    cmd = args.command
    out = getattr(args, "out", None)
    if cmd == "plot":
        results = pathlib.Path(args.results)
        fig = pathlib.Path(out) if out else results.with_suffix(".png")
        if os.path.abspath(fig) == os.path.abspath(results):
            raise fail("command line", "--out", str(fig), "would overwrite the results file")
        if results.exists():  # else plot_results says there is no such results file
            _check_figure("--out" if out else "--out (default: RESULTS with .png)", str(fig))
    elif cmd == "study":
        if out is not None:
            _check_store(out)
    elif out is not None:
        rule = SUFFIX_RULES[RESULT_SUFFIXES[cmd]]
        if cmd == "verify":
            rule = "must end in .nc (NetCDF, groups hb and ni)"
        _check_output("--out", out, RESULT_SUFFIXES[cmd], rule)
    if getattr(args, "out_train", None) is not None:
        _check_output("--out-train", args.out_train, (".toml",), "must end in .toml")
    if cmd != "plot" and getattr(args, "plot", None) is not None:
        _check_figure("--plot", args.plot)
    if cmd == "sweep" and args.resume and not args.out:
        raise fail("command line", "--resume", True, "needs --out FILE: the run to resume "
                   "is the one whose journal FILE.journal is there")


def _check_output(flag: str, value: str, suffixes: tuple[str, ...], rule: str) -> None:
    path = pathlib.Path(value)
    if path.is_dir():
        raise fail("command line", flag, value, "is a directory: name a file in it")
    if not value.lower().endswith(suffixes):
        raise fail("command line", flag, value, rule)
    parent = path.parent
    if not parent.exists():
        raise fail("command line", flag, value, f"its directory {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise fail("command line", flag, value, f"{str(parent)!r} is not a directory")
    probe = parent / f".{path.name}.{os.getpid()}.probe"
    try:  # really create a file there: permissions, read-only or special file systems
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as e:
        raise fail("command line", flag, value, f"its directory {str(parent)!r} is not "
                   f"writable ({e.strerror or e})") from None


def _check_store(value: str) -> None:
    """A study store: a directory, or a name whose directory exists."""
    path = pathlib.Path(value)
    if path.exists() and not path.is_dir():
        raise fail("command line", "--out", value, "is a file: a study store is a directory")
    parent = path.parent
    if not parent.is_dir():
        raise fail("command line", "--out", value,
                   f"its directory {str(parent)!r} does not exist")


def _check_figure(flag: str, value: str) -> None:
    formats = _figure_formats()
    ext = pathlib.Path(value).suffix.lower().lstrip(".")
    rule = ("must end in a figure format matplotlib writes: "
            + ", ".join("." + f for f in formats))
    _check_output(flag, value, ("." + ext,) if ext in formats else (), rule)


def _figure_formats() -> list[str]:
    from matplotlib.figure import Figure

    return sorted(Figure().canvas.get_supported_filetypes())


def _atomic(path):
    """Write ``path`` atomically (:func:`gearjax._io.results.atomic_path`)."""
    from ._io.results import atomic_path

    return atomic_path(path)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="gearjax",
        description="Dynamics of compound planetary gear trains. TRAIN defaults to the bundled "
                    "Al-shyyab et al. (2009) case.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    def command(name: str, run, help: str) -> argparse.ArgumentParser:
        c = sub.add_parser(name, help=help, description=help)
        c.add_argument("train", nargs="?", default=None, metavar="TRAIN",
                       help="train file (TOML); default: the bundled paper case")
        c.add_argument("--gear", default=None, help="gear name (default: first in the file)")
        c.add_argument("--json", action="store_true", help="one JSON object on stdout")
        c.set_defaults(run=run)
        return c

    c = command("info", _info, "kinematics, phasing and static loads of a gear")
    c.add_argument("--input-rpm", type=float, default=None,
                   help=f"input speed (rpm); default: the gear's input_rpm in the train file, "
                        f"else {DEFAULT_INPUT_RPM:g}")
    c = command("modes", _modes, "natural frequencies, shapes and classes of a gear")
    c.add_argument("--plot", metavar="FIG", help="write the elastic mode shapes to FIG")
    c = command("calibrate", _calibrate, "fit parameters to target natural frequencies")
    c.add_argument("--targets-hz", type=float, nargs="+", required=True, metavar="F",
                   help="target elastic frequencies (Hz), ascending, repeated modes repeated")
    c.add_argument("--free", nargs="+", required=True, metavar="PATH",
                   help="TOML paths to fit, e.g. 1.inertia.sun 2.planet_mass")
    c.add_argument("--out-train", metavar="FILE.toml", help="write the calibrated train")
    c = command("mesh", _mesh_cmd, "contact, stiffness and transmission error of a stage's "
                "meshes over one mesh cycle")
    c.add_argument("--stage", default=None, metavar="ID", help="stage id (default: every stage)")
    c.add_argument("--plot", metavar="FIG", help="write the mesh cycle of the stage to FIG")
    c = command("sweep", _sweep_cmd, "frequency response by harmonic balance and continuation")
    c.add_argument("--from", dest="from_hz", type=float, default=None, metavar="HZ",
                   help="start, reference-stage mesh frequency (Hz); direction = order; "
                        "without --from and --to, a band chosen from the gear's modes")
    c.add_argument("--to", dest="to_hz", type=float, default=None, metavar="HZ")
    c.add_argument("--stage", help="reference stage id (default: first turning stage)")
    c.add_argument("--linear", action="store_true", help="no backlash")
    c.add_argument("--harmonics", type=int, metavar="K",
                   help="solution harmonics (default: frequency-dependent)")
    c.add_argument("--eta", type=int, default=1, help="sub-harmonic index")
    c.add_argument("--max-step", type=float, metavar="HZ",
                   help="largest frequency step of the continuation predictor")
    c.add_argument("--points", type=int, default=300,
                   help="points of the even grid a linear sweep starts from (refined where "
                        "the curve bends)")
    c.add_argument("--max-points", type=int, default=3000,
                   help="cap on the points of a continuation, or on the points a linear "
                        "sweep solves (its grid and the middles that refine it)")
    c.add_argument("--smoothing", type=float, default=0.0, metavar="REL",
                   help="round the backlash corners over REL x backlash (default 0: exact)")
    c.add_argument("--out", metavar="FILE.nc|.csv", help="write the results")
    c.add_argument("--plot", metavar="FIG", help="write the RMS mesh forces")
    c.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from FILE.journal, the journal --out keeps")
    c.add_argument("--no-complete", dest="complete", action="store_false",
                   help="follow only the branch the sweep walks (with its restarts); by "
                        "default a sweep with backlash also traces the branches of the "
                        "states reached from the band's far end and by the jumps where a "
                        "stable stretch ends")
    c.add_argument("--seeds", type=int, default=0, metavar="N",
                   help="also seed branches from an up and a down time-integration sweep "
                        "over N even frequencies (default 0: none)")
    c = command("simulate", _simulate_cmd, "steady states by time integration")
    _point_flags(c)
    c.add_argument("--out", metavar="FILE.nc|.csv", help="write the results")
    c.add_argument("--plot", metavar="FIG", help="write the RMS mesh forces")
    c = command("verify", _verify_cmd,
                "harmonic balance against time integration at the same points")
    _point_flags(c)
    c.add_argument("--harmonics", type=int, metavar="K",
                   help="harmonic-balance harmonics (default: frequency-dependent; on a "
                        "quasi-periodic gear the order on every torus angle)")
    c.add_argument("--tol-linear", type=float, default=0.01, metavar="REL",
                   help="tolerance on the relative RMS difference without backlash")
    c.add_argument("--tol-nonlinear", type=float, default=0.02, metavar="REL",
                   help="tolerance on the relative RMS difference with backlash")
    c.add_argument("--plot", metavar="FIG",
                   help="write integration points over the harmonic-balance curve")
    c.add_argument("--curve", metavar="RESULTS.nc",
                   help="a saved sweep to draw as the harmonic-balance curve in --plot")
    c.add_argument("--out", metavar="FILE.nc",
                   help="write both point sets (groups hb and ni) for gearjax plot")
    c = command("sensitivity", _sensitivity_cmd,
                "derivatives of a mesh response at one frequency w.r.t. train parameters")
    c.add_argument("--at", type=float, required=True, metavar="HZ",
                   help="reference-stage mesh frequency (Hz)")
    c.add_argument("--response", choices=("rms", "max", "dlf"), default="rms",
                   help="RMS alternating force, peak force or dynamic load factor")
    c.add_argument("--mesh", metavar="NAME", help="mesh such as 1.sp1 (default: largest)")
    c.add_argument("--vary", nargs="+", metavar="PATH",
                   help="TOML paths (default: every continuous parameter that affects the "
                        "gear)")
    c.add_argument("--stage", help="reference stage id (default: first turning stage)")
    c.add_argument("--linear", action="store_true", help="no backlash")
    c.add_argument("--harmonics", type=int, metavar="K",
                   help="solution harmonics (default: frequency-dependent; on a quasi-"
                        "periodic gear, K on every torus angle)")
    c = command("optimize", _optimize_cmd,
                "planet positions, sun-ring and stage phases that minimise the peak RMS "
                "mesh force over a band")
    c.add_argument("--band", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="reference-stage mesh frequencies (Hz); default: a band chosen "
                        "from the gear's modes and excitation orders (said on stderr)")
    c.add_argument("--vary", nargs="+", metavar="PATH",
                   help="STAGE.planet_angles_deg, STAGE.sun_ring_phase_deg, "
                        "STAGE.stage_phase_deg (default: all of the turning stages)")
    c.add_argument("--stage", help="reference stage id (default: first turning stage)")
    c.add_argument("--out-train", metavar="FILE.toml", help="write the optimised train")
    c.add_argument("--out", metavar="FILE.nc", help="write the baseline, optimum and every "
                   "screened candidate (NetCDF)")
    c.add_argument("--harmonics", type=int, metavar="K",
                   help="harmonics of the linear screen and the sweeps (default: the highest "
                        "excitation order; on a quasi-periodic gear, K on every torus angle)")
    c.add_argument("--points", type=int, default=32, metavar="N",
                   help="frequencies per candidate of the linear screen (default 32)")
    c.add_argument("--final-points", type=int, default=96, metavar="N",
                   help="geometric frequencies of the grid the baseline and optimum are "
                        "compared on (default 96, plus their resonance peaks)")
    c.add_argument("--proxy-points", type=int, default=256, metavar="N",
                   help="frequencies of the first-order proxy (default 256)")
    c.add_argument("--phase-grid", type=int, default=24, metavar="N",
                   help="sun-ring phases (and stage phases, where varied) tried per "
                        "planet set (default 24)")
    c.add_argument("--screen", type=int, default=24, metavar="N",
                   help="candidates per stage solved by the linear harmonic balance (default 24)")
    c.add_argument("--nonlinear", type=int, default=2, metavar="N",
                   help="best candidates per stage swept with backlash (default 2; 0: decide "
                        "on the linear model). Each sweep, the baseline's too, is complete: "
                        "its peak is over every stable state the sweep and its completion "
                        "find")
    c.add_argument("--max-step", type=float, metavar="HZ",
                   help="largest frequency step of those sweeps (default 1/100 of the band)")
    c.add_argument("--max-points", type=int, default=3000, metavar="N",
                   help="points of each of those sweeps, walk and completion together "
                        "(default 3000; a sweep that spends them is flagged not complete)")
    c.add_argument("--seeds", type=int, default=0, metavar="N",
                   help="also seed those sweeps' completion from up and down integration "
                        "sweeps over N even frequencies (default 0: none)")
    c.add_argument("--no-recheck", dest="recheck", action="store_false",
                   help="skip the re-check: by default, with --nonlinear > 0, baseline and "
                        "optimum are swept afresh (complete sweeps at the sweep's own K) and "
                        "integrated from their peak orbits, and the verdict is on those peaks")
    c.add_argument("--recheck-band", type=float, nargs=2, metavar=("LO", "HI"),
                   help="band of the re-check's sweeps (Hz; default --band)")
    c.add_argument("--recheck-harmonics", type=int, metavar="K",
                   help="fixed K of the re-check's sweeps (default: the sweep's own, "
                        "frequency-dependent)")
    c.add_argument("--relax-iterations", type=int, default=10, metavar="N",
                   help="L-BFGS iterations of the continuous relaxation (0: skip)")
    c.add_argument("--passes", type=int, default=1, metavar="N",
                   help="rounds over the stages (default 1)")
    c = sub.add_parser("study", help="a design study: candidate trains varied from a base "
                       "train, each analysed on a Dask cluster (a study file, TOML)",
                       description="a design study: candidate trains varied from a base "
                                   "train, each analysed on a Dask cluster")
    c.add_argument("study", metavar="STUDY.toml", help="the study file")
    c.add_argument("--out", metavar="DIR", help="the study store: one result file per "
                   "candidate (default: STUDY with .study)")
    c.add_argument("--resume", action="store_true",
                   help="run only the candidates the store has no result for")
    c.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local cluster (default: this machine's "
                        "cores; 0: every candidate in this process)")
    c.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tcp://host:8786)")
    c.add_argument("--json", action="store_true", help="one JSON object on stdout")
    c.set_defaults(run=_study_cmd, needs_train=False)
    c = sub.add_parser("plot", help="redraw a saved result (sweep, simulate, verify, optimize, "
                       "study)",
                       description="redraw a saved result (sweep, simulate, verify, optimize, "
                                   "study) without recomputing")
    c.add_argument("results", metavar="RESULTS.nc",
                   help="a results file written with --out, or a study store (directory)")
    c.add_argument("--pareto", nargs=2, metavar=("MERIT", "MERIT"),
                   help="a study's Pareto set of these two figures of merit (default: the "
                        "first two it has)")
    c.add_argument("--what", choices=("rms", "dlf", "separation", "torque", "bearings"),
                   default="rms",
                   help="RMS mesh force, dynamic load factor, separation share, mean torque, "
                        "or the bearing forces (translational model)")
    c.add_argument("--out", metavar="FIG", help="figure file (default: RESULTS with .png)")
    c.add_argument("--json", action="store_true", help="one JSON object on stdout")
    c.set_defaults(run=_plot_cmd, needs_train=False)
    return p


def _point_flags(c: argparse.ArgumentParser) -> None:
    """The frequency flags of simulate and verify."""
    c.add_argument("--at", type=float, nargs="+", metavar="HZ",
                   help="independent points, reference-stage mesh frequency (Hz)")
    c.add_argument("--from", dest="from_hz", type=float, metavar="HZ",
                   help="sweep start (Hz); each point continues from the previous")
    c.add_argument("--to", dest="to_hz", type=float, metavar="HZ", help="sweep end (Hz)")
    c.add_argument("--points", type=int, metavar="N", help="sweep points (default 20)")
    c.add_argument("--stage", help="reference stage id (default: first turning stage)")
    c.add_argument("--linear", action="store_true", help="no backlash")


# ----------------------------------------------------------------------------- info


def _info(args, train, notes) -> int:
    from ._gear.frequency_groups import MAX_MULTIPLIER
    from ._gear.mesh_report import mesh_report
    from ._gear.kinematics import kinematics
    from ._gear.phasing import phasing_report
    from ._gear.static_loads import static_loads

    g = train.gear(args.gear)
    if args.input_rpm is None:  # the gear's own speed where the file gives one
        args.input_rpm = g.input_rpm if g.input_rpm is not None else DEFAULT_INPUT_RPM
    if not (args.input_rpm > 0 and math.isfinite(args.input_rpm)):
        raise fail("command line", "--input-rpm", args.input_rpm, "must be a positive speed in rpm")
    kin = kinematics(train, g.name)
    loads = static_loads(train, g.name)
    phasing = {}
    for s, sk in zip(train.stages, kin.stages):
        phasing[s.id] = [
            {"h": r.h, "k": r.k, "kind": r.kind, "signs": r.signs, "sun_deg": list(r.sun_deg),
             "ring_deg": list(r.ring_deg)}
            for r in phasing_report(s, sk.sigma, train.phasing, train.stiffness_harmonics)
        ] if sk.turning else []
    out = {
        "train": train.name,
        "gear": g.name,
        "input": g.input,
        "output": g.output,
        "brakes": list(g.brakes),
        "note": g.note,
        "ratio": float(kin.ratio),
        "ratio_exact": str(kin.ratio),
        "mu": list(kin.mu) if kin.mu is not None else None,
        "dof": train.n_dof,
        "model": train.model,
        "input_rpm": args.input_rpm,
        "stages": [
            {"id": s.id, "loaded": s.loaded, "turning": s.turning, "sigma": s.sigma,
             "mesh_frequency_hz": kin.mesh_frequency_hz(s.id, args.input_rpm),
             "planet_speed": float(s.planet_speed), "planet_speed_exact": str(s.planet_speed)}
            for s in kin.stages
        ],
        "member_speeds": {p: float(w) for p, w in kin.speeds.items()},
        "member_speeds_exact": {p: str(w) for p, w in kin.speeds.items()},
        "static": {
            name: {"force": f, "torque": loads.mesh_torque[name]}
            for name, f in loads.mesh_force.items()
        },
        "brake_reactions": loads.brake_reaction,
        "load_sharing": loads.load_sharing,
        "housing_leak": loads.leak,
        "torque_balance": loads.balance,
        "phasing": phasing,
        "harmonics": _harmonics_info(train, g.name, kin),
        "meshes": [m.as_dict() for m in mesh_report(train, g.name)],
        **_groups_info(train, kin, args.input_rpm),
        "warnings": notes,
    }
    if args.json:
        return _emit(out)
    print(f"{train.name}: gear {g.name!r} (input {g.input}, output {g.output}, "
          f"brakes {', '.join(g.brakes) or 'none'})" + (f"  [{g.note}]" if g.note else ""))
    mu = "null (no mesh turns)" if kin.mu is None else str(tuple(kin.mu))
    print(f"ratio {kin.ratio} = {float(kin.ratio):.6g}   mu = {mu}   {train.n_dof} DOF "
          f"({train.model} model)")
    print(f"\n{'stage':>6} {'loaded':>7} {'mesh Hz @ %g rpm' % args.input_rpm:>20} {'sigma':>6}"
          f" {'planet/carrier':>15}")
    for s in out["stages"]:
        print(f"{s['id']:>6} {str(s['loaded']):>7} {s['mesh_frequency_hz']:>20.2f} "
              f"{s['sigma']:>6} {s['planet_speed_exact']:>15}")
    print("\nmember speeds per unit input speed:")
    print("  " + "   ".join(f"{p} {w}" for p, w in kin.speeds.items()))
    print("\nstatic mesh forces (N) and torques (N m), mean stiffness, no backlash:")
    for name, v in out["static"].items():
        print(f"  {name:>7} {v['force']:>12.1f} N {v['torque']:>10.2f} N m")
    for path, t in loads.brake_reaction.items():
        print(f"brake {path} reacts {t:.2f} N m")
    print(f"through the free housing springs: {loads.leak:.3g} N m; "
          f"torque balance residual {loads.balance:.2g} N m")
    print("static load-sharing factor (largest planet load / mean): " + ", ".join(
        f"stage {sid} {v:.4f}" if v is not None else f"stage {sid} unloaded"
        for sid, v in loads.load_sharing.items()))
    for sid, rows in phasing.items():
        if rows:
            print(f"\nstage {sid} stiffness phasing (Parker & Lin, k = h Z_s mod N):")
            for r in rows:
                print(f"  h={r['h']}  k={r['k']}  {r['kind']:<15} sun meshes {r['signs']}")
    if out["frequency_groups"]:
        print(f"\nfrequency groups (members multiples <= {MAX_MULTIPLIER} of a group base, "
              f"at {args.input_rpm:g} rpm):")
        for k, grp in enumerate(out["frequency_groups"]):
            print(f"  {k + 1}: base {grp['base_hz']:.2f} Hz: " + ", ".join(
                f"{m} x{mu}" for m, mu in zip(grp["members"], grp["multipliers"])))
    print("\nmeshes (mean stiffness at the static load; harmonics relative to the mean):")
    _print_meshes(out["meshes"])
    print(f"solver: {out['solver_plan']}")
    h = out["harmonics"]
    if h is not None:
        print(f"\nharmonic balance: at least K = {h['floor']} harmonics of the base "
              f"({h['floor_rule']}); the first choice of K reaches {h['cutoff_hz']:.0f} Hz "
              f"(5/3 of the highest mesh mode, {h['mesh_mode_hz']:.0f} Hz); a sweep checks "
              "it against 2K")
    return EXIT_OK


def _print_meshes(meshes: list[dict]) -> None:
    for m in meshes:
        amps = " ".join(f"{h['amplitude']:.3f}" for h in m["harmonics"])
        print(f"  {m['stage']}.{m['side']:<4} {m['source']:<22} contact ratio "
              f"{m['contact_ratio']:.3f}  mean {m['mean_stiffness']:.4g} N/m  "
              f"harmonics {amps or '-'} (beyond: {100 * m['truncation']:.1f}% RMS)")
        if m["iso_mesh"] is not None:
            print(f"  {'':>6} operating pressure angle {m['pressure_angle_deg']:.3f} deg, centre "
                  f"distance {m['centre_distance_mm']:.4f} mm, load {m['load']:.1f} N; "
                  f"ISO 6336-1 c_gamma_alpha b {m['iso_mesh']:.4g} N/m "
                  f"({100 * m['iso_difference']:+.1f}% from it)")
        if m["relief_te_um"]:
            print(f"  {'':>6} tip relief transmission error (um per harmonic): "
                  + " ".join(f"{a:.3f}" for a in m["relief_te_um"]))


def _mesh_cmd(args, train, notes) -> int:
    from ._gear.mesh_report import mesh_report

    g = train.gear(args.gear)
    if args.stage is not None and args.stage not in train.stage_ids:
        raise fail("command line", "--stage", args.stage,
                   f"no such stage; stages are {', '.join(train.stage_ids)}")
    if args.plot and args.stage is None and len(train.stages) > 1:
        raise fail("command line", "--plot", args.plot,
                   "name the stage to draw with --stage ID")
    meshes = [m.as_dict() for m in mesh_report(train, g.name)
              if args.stage is None or m.stage == args.stage]
    out = {"train": train.name, "gear": g.name, "meshes": meshes, "warnings": notes}
    if args.plot:
        from ._plot.figures import mesh_cycle_figure

        stage = train.stage(args.stage or train.stage_ids[0])
        loads = {m["side"]: m["load"] for m in meshes if m["stage"] == stage.id}
        with _atomic(args.plot) as fig:
            mesh_cycle_figure(stage, loads, title=f"{train.name}: stage {stage.id}, "
                              f"gear {g.name}").savefig(fig, dpi=120)
    if args.json:
        return _emit(out)
    print(f"{train.name}: gear {g.name!r}, meshes (mean stiffness at the static load):")
    _print_meshes(meshes)
    if args.plot:
        print(f"mesh cycle written to {args.plot}")
    return EXIT_OK


def _groups_info(train, kin, input_rpm: float) -> dict:
    """``frequency_groups`` (``[{members, multipliers, base_exact, base_hz}]``, base in
    cycles per input revolution and in Hz at ``input_rpm``; empty where nothing turns)
    and ``solver_plan``: what a sweep of this gear solves."""
    from ._gear.frequency_groups import gear_frequency_groups

    rev_hz = input_rpm / 60.0
    try:
        groups = gear_frequency_groups(kin, train.source).groups
    except TrainError as e:
        return {"frequency_groups": [], "solver_plan": f"refused: {e}"}
    rows = [{"members": list(g.members), "multipliers": list(g.multipliers),
             "base_exact": str(g.base), "base_hz": float(g.base) * rev_hz} for g in groups]
    if kin.mu is None:
        plan = "refused: no mesh turns in this gear (nothing to solve at a mesh frequency)"
    elif len(groups) == 1:
        plan = (f"periodic harmonic balance with one base, {rows[0]['base_hz']:.2f} Hz, "
                f"mu = {list(kin.mu)}")
    else:
        from ._engine.floquet import return_turns
        from ._studies.harmonics import TORUS_TRUNCATION

        G = len(groups)
        ratios = [g.base / groups[0].base for g in groups]
        q, d = return_turns([float(r) for r in ratios])
        common = (f"; a single common base would need mu = {list(kin.mu)}, the excitation "
                  f"alone reaching harmonic "
                  f"{max((train.stiffness_harmonics * max(kin.mu),) + kin.ripple_mu)} of it")
        plan = (f"{G} incommensurate groups: the response is quasi-periodic on a {G}-torus, "
                f"solved by the multi-frequency harmonic balance (one angle per group, "
                f"base ratios {', '.join(str(r) for r in ratios)}; {TORUS_TRUNCATION} "
                f"truncation sets of orders K_g per angle, chosen per segment and checked "
                f"by doubling each angle's order); stability from the monodromy over {q} "
                f"turns of the first group's base, after which the torus line returns within "
                f"{d:.3f} turns" + common)
    return {"frequency_groups": rows, "solver_plan": plan}


def _harmonics_info(train, gear: str, kin) -> dict | None:
    """What the harmonic balance of ``gear`` needs: the excitation floor of K and the
    response cutoff of its first choice (``None`` where no mesh turns)."""
    from ._gear.assembly import assemble
    from ._studies.harmonics import (
        CUTOFF_MARGIN,
        excitation_floor,
        floor_reason,
        response_cutoff_hz,
    )

    if kin.mu is None:
        return None
    system = assemble(train, gear, kin)
    cutoff = response_cutoff_hz(system)
    return {"floor": excitation_floor(system), "floor_rule": floor_reason(system, 1),
            "cutoff_hz": cutoff, "mesh_mode_hz": cutoff / CUTOFF_MARGIN}


# ---------------------------------------------------------------------------- modes


def _modes(args, train, notes) -> int:
    from ._gear.assembly import assemble
    from ._engine.modal import REPEATED_RTOL, modes

    g = train.gear(args.gear)
    result = modes(assemble(train, g.name))
    out = {
        "train": train.name,
        "gear": g.name,
        "elastic_hz": result.elastic_hz,
        "repeated_rtol": REPEATED_RTOL,
        "modes": [
            {"hz": m.hz, "multiplicity": m.multiplicity, "class": m.cls, "family": m.family,
             "stage": m.stage, "shape": m.shape, "energy": m.energy, "kinetic": m.kinetic}
            for m in result.modes
        ],
        "warnings": notes,
    }
    if args.plot:
        from ._plot.save import plot_mode_shapes

        with _atomic(args.plot) as fig:
            plot_mode_shapes(result, fig, title=f"{train.name}: gear {g.name}, elastic modes")
    if args.json:
        return _emit(out)
    print(f"{train.name}: gear {g.name!r}, {len(result.modes)} modes "
          f"(repeated when within {REPEATED_RTOL:g} relative)")
    print(f"{'kHz':>10} {'mult':>4} {'class':>8} {'family':>14}  "
          "coordinates with most kinetic energy (share)")
    for m in result.modes:
        fam = f"planet {m.stage}" if m.family == "planet" else m.family
        top = sorted(m.kinetic.items(), key=lambda kv: -abs(kv[1]))[:3]
        print(f"{m.hz / 1e3:>10.4f} {m.multiplicity:>4} {m.cls:>8} {fam:>14}  "
              + ", ".join(f"{k} {v:.0%}" for k, v in top))
    if train.translational:
        counts = collections.Counter(m.family for m in result.modes)
        print("mode families: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
        for s in train.stages:
            gaps = np.diff(np.r_[np.asarray(s.planet_angles_deg, float), 360.0])
            if not np.allclose(gaps, gaps[0]):
                print(f"stage {s.id}: planets unequally spaced: Lin & Parker's rotational, "
                      "translational and planet types need equal spacing; modes that keep "
                      "one of them are named so, the rest overall")
    if args.plot:
        print(f"mode shapes written to {args.plot}")
    return EXIT_OK


# ------------------------------------------------------------------------ calibrate


def _calibrate(args, train, notes) -> int:
    from ._gear.calibrate import calibrate
    from ._gear.toml_io import save_train

    g = train.gear(args.gear)
    result = calibrate(train, args.targets_hz, args.free, g.name)
    if args.out_train:
        with _atomic(args.out_train) as tmp:
            save_train(result.train, tmp)
    out = {
        "train": train.name,
        "gear": g.name,
        "free": list(result.free),
        "initial": result.initial,
        "fitted": result.fitted,
        "targets_hz": list(result.targets_hz),
        "model_hz": list(result.model_hz),
        "residual_hz": list(result.residual_hz),
        "residual_rel": list(result.residual_rel),
        "converged": result.converged,
        "message": result.message,
        "nfev": result.nfev,
        "at_bound": list(result.at_bound),
        "out_train": args.out_train,
        "warnings": notes,
    }
    code = EXIT_OK if result.converged else EXIT_NOT_CONVERGED
    if args.json:
        _emit(out)
        return code
    print(f"calibration of {', '.join(result.free)} on gear {g.name!r}: "
          f"{'converged' if result.converged else 'NOT converged'} ({result.message}, "
          f"{result.nfev} evaluations)")
    print(f"{'target Hz':>12} {'model Hz':>12} {'residual':>10}")
    for t, m, r in zip(result.targets_hz, result.model_hz, result.residual_rel):
        print(f"{t:>12.2f} {m:>12.2f} {100 * r:>9.4f}%")
    print(f"{'parameter':>20} {'initial':>12} {'fitted':>12}")
    for p in result.free:
        flag = "  (at bound)" if p in result.at_bound else ""
        print(f"{p:>20} {result.initial[p]:>12.5g} {result.fitted[p]:>12.5g}{flag}")
    if args.out_train:
        print(f"calibrated train written to {args.out_train}")
    return code


# ---------------------------------------------------------------------------- sweep


def _sweep_cmd(args, train, notes) -> int:
    from ._io.journal import journal_path, lock

    journal = journal_path(args.out) if args.out else None
    held = lock(journal) if journal else None  # refused while another run writes it
    try:
        return _sweep_run(args, train, notes, journal)
    finally:
        if held is not None:
            held.release()


def _sweep_run(args, train, notes, journal) -> int:
    from ._io.results import save_results
    from ._studies.sweep import progress_bar, summary_json, sweep
    from ._studies.sweep.default_band import resolve_band
    from ._studies.sweep.summary import bifurcation_lines, change_words

    if args.resume and journal.exists():
        _stderr(f"sweep: resuming from {journal}")
    g = train.gear(args.gear)
    args.from_hz, args.to_hz, chosen = resolve_band(train, g.name, args.stage, args.linear,
                                                    args.from_hz, args.to_hz)
    if chosen is not None:
        _stderr(f"sweep: no --from/--to: band {args.from_hz:.1f}-{args.to_hz:.1f} Hz, "
                f"chosen {chosen}")
    # a bar on a terminal; under --json or off a terminal only its final line
    with progress_bar(args.from_hz, args.to_hz, sys.stderr, quiet=args.json) as bar:
        result = sweep(train, g.name, args.from_hz, args.to_hz, stage=args.stage,
                       linear=args.linear, harmonics=args.harmonics, eta=args.eta,
                       max_step_hz=args.max_step, points=args.points,
                       max_points=args.max_points, smoothing=args.smoothing,
                       progress=bar, say=bar.note, journal=journal, resume=args.resume,
                       command=args.command_line, complete=args.complete,
                       seeds=args.seeds)
    ds = result.dataset
    if args.out:
        save_results(ds, args.out)
        journal.unlink(missing_ok=True)  # consolidated into the results file
    if args.plot:
        from ._plot.save import plot_sweep

        kind = "linear" if args.linear else "backlash"
        with _atomic(args.plot) as fig:
            plot_sweep(ds, fig, title=f"{train.name}: gear {g.name}, {kind}")
    out = summary_json(result)
    out["warnings"] = notes
    converged = bool(np.any(ds["converged"].values))
    code = EXIT_OK if converged else EXIT_NOT_CONVERGED
    if args.json:
        _emit(out)
        return code
    stable = ds["stable"].values
    print(f"sweep of gear {g.name!r}: {ds.sizes['point']} points, "
          f"{'linear' if args.linear else 'with backlash'}, stop: {result.stop}, "
          f"{result.seconds:.1f} s")
    print("segments (Hz, harmonics): " + ", ".join(
        f"{a:.0f}-{b:.0f} K={k}" for a, b, k in result.segments))
    refinement = out["solver"].get("refinement")
    if refinement:
        print(f"points: {refinement['grid']} of the even grid (--points {args.points}) and "
              f"{refinement['added']} placed where a straight line missed the RMS or peak "
              f"mesh force by more than {100 * refinement['tolerance']:g}%; "
              f"{refinement['solved']} solved with the {refinement['checked']} middles "
              f"checked, of at most {refinement['max_points']} (--max-points)")
    if result.folds_hz:
        print("folds at " + ", ".join(f"{f:.1f}" for f in result.folds_hz) + " Hz")
    if len(out["branches"]) > 1:
        print("branches: " + "; ".join(
            f"{b['branch']} {b['found']} ({b['seed_hz']:.1f} Hz)" for b in out["branches"]))
    if out["coexisting_hz"]:
        print("coexisting stable states (jumps up and down differ) over " + ", ".join(
            f"{a:.1f}-{b:.1f}" for a, b in out["coexisting_hz"]) + " Hz")
        for c in out["coexisting"]:
            print(f"  {c['from_hz']:.1f}-{c['to_hz']:.1f} Hz: {c['states']} stable states; "
                  "jumps sweeping up at " + (", ".join(f"{f:.1f}" for f in c["jump_up_hz"])
                                             or "-") + " Hz, sweeping down at "
                  + (", ".join(f"{f:.1f}" for f in c["jump_down_hz"]) or "-") + " Hz")
    for r in result.restarts:
        print(f"branch left at {r['from_hz']:.1f} Hz ({r['reason']}); new branch from "
              f"{r['at_hz']:.1f} Hz")
    print(f"unstable points: {int(np.sum(stable == 0))}")
    for b in out["bifurcations"]:
        print(f"  stability changes near {b['mesh_frequency_hz']:.1f} Hz: {change_words(b)}")
    for line in bifurcation_lines(out["bifurcation_notes"]):
        print(f"  {line}")
    lo, hi = out["band_hz"]
    for row in out["largest"]:  # stable, converged points inside the band asked for
        scope = (f"(stable points inside {lo:.1f}-{hi:.1f} Hz: {row['points']} of "
                 f"{row['of']})")
        if row["rms_force"] is None:
            print(f"stage {row['stage']}: {row['reason']}")
            continue
        share = "-" if row["separation"] is None else f"{row['separation']:.3f}"
        print(f"stage {row['stage']}: largest RMS mesh force {row['rms_force']:.1f} N at "
              f"{row['mesh_frequency_hz']:.1f} Hz ({row['mesh']}); largest separation share "
              f"{share} {scope}")
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return code


# ------------------------------------------------------------------ simulate, verify


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _simulate_cmd(args, train, notes) -> int:
    from ._io.results import json_number, points_json, save_results
    from ._studies.simulate import simulate_gear

    g = train.gear(args.gear)
    ds = simulate_gear(train, g.name, args.at, from_hz=args.from_hz, to_hz=args.to_hz,
                       points=args.points, stage=args.stage, linear=args.linear,
                       progress=_stderr, command=args.command_line)
    if args.out:
        save_results(ds, args.out)
    if args.plot:
        from ._plot.save import plot_points

        kind = "linear" if args.linear else "backlash"
        with _atomic(args.plot) as fig:
            plot_points(ds, fig, title=f"{train.name}: gear {g.name}, {kind}, time "
                                       "integration")
    converged = bool(np.any(ds["converged"].values))
    code = EXIT_OK if converged else EXIT_NOT_CONVERGED
    out = {"gear": g.name, "reference_stage": ds.attrs["reference_stage"],
           "mode": ds.attrs["mode"], "seconds": ds.attrs["seconds"],
           "points": points_json(ds), "solver": json.loads(ds.attrs["solver"]),
           "warnings": notes}
    for p, periods, steps in zip(out["points"], ds["periods"].values, ds["num_steps"].values):
        p["periods"], p["num_steps"] = int(periods), int(steps)
    windowed = "windows" in ds  # a quasi-periodic gear: statistics over windows
    if windowed:
        for k, p in enumerate(out["points"]):
            p["windows"] = int(ds["windows"].values[k])
            p["window_s"] = json_number(ds["window_s"].values[k])
            p["window_change"] = json_number(ds["window_change"].values[k])
            p["period_reason"] = ("quasi-periodic: the mesh frequencies fall in "
                                  "incommensurate groups, so the response never repeats; "
                                  "statistics of the last of the windows")
    if args.json:
        _emit(out)
        return code
    rms = ds["rms_force"].values
    print(f"simulation of gear {g.name!r}: {ds.sizes['point']} points "
          f"({ds.attrs['mode']}), {'linear' if args.linear else 'with backlash'}, "
          f"{ds.attrs['seconds']:.1f} s")
    if windowed:
        sv = out["solver"]
        print(f"quasi-periodic ({sv['torus']['G']} incommensurate frequency groups): "
              f"statistics over windows of {sv['window_periods']} base periods, "
              f"consecutive windows agreeing within {sv['tol']:g}")
    stages = list(dict.fromkeys(ds["stage"].values.tolist()))
    wide = 14 if windowed else 13  # "quasi_periodic"
    print(f"{'Hz':>9} {'result':>{wide}} {'period':>6} {'periods':>7} "
          + " ".join(f"{'max RMS ' + s + ' (N)':>14}" for s in stages))
    for k, p in enumerate(out["points"]):
        cols = [np.nanmax(rms[k, ds["stage"].values == s]) if p["converged"] or
                p["result"] in ("not_periodic", "not_stationary") else math.nan
                for s in stages]
        period = "-" if p["period"] is None else f"{p['period']:.0f}"
        print(f"{p['mesh_frequency_hz']:>9.1f} {p['result']:>{wide}} {period:>6} "
              f"{p['periods']:>7} " + " ".join(f"{c:>14.1f}" for c in cols))
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return code


def _verify_cmd(args, train, notes) -> int:
    from ._io.verify_file import save_verify
    from ._studies.verify import verify_gear, verify_json

    g = train.gear(args.gear)
    curve = None
    if args.curve:
        from ._io.results import load_results

        try:
            curve = load_results(args.curve)
        except (OSError, ValueError) as e:
            raise fail("command line", "--curve", args.curve, f"cannot be read: {e}") from None
    result = verify_gear(train, g.name, args.at, from_hz=args.from_hz, to_hz=args.to_hz,
                         points=args.points, stage=args.stage, linear=args.linear,
                         harmonics=args.harmonics, tol_linear=args.tol_linear,
                         tol_nonlinear=args.tol_nonlinear, progress=_stderr,
                         command=args.command_line)
    if args.plot:
        from ._plot.save import plot_verify

        kind = "linear" if args.linear else "backlash"
        with _atomic(args.plot) as fig:
            plot_verify(result.hb, result.ni, fig, curve=curve,
                        title=f"{train.name}: gear {g.name}, {kind}: harmonic balance "
                              f"({'line' if curve is not None else '+'}) and time "
                              "integration (circles)")
    if args.out:
        with _atomic(args.out) as tmp:
            save_verify(result, tmp)
    out = verify_json(result)
    out["warnings"] = notes
    converged = any(p["converged"] for p in out["points"])
    code = EXIT_OK if converged else EXIT_NOT_CONVERGED
    if args.json:
        _emit(out)
        return code
    n_ok, n = int(np.sum(result.ok)), result.ok.size
    print(f"verification of gear {g.name!r}: {len(out['points'])} points, "
          f"{'linear' if args.linear else 'with backlash'}, tolerance {result.tolerance:g} "
          f"(relative to the stage's largest RMS); {n_ok} of {n} meshes ok; "
          f"harmonic balance {result.seconds['harmonic_balance']:.1f} s, "
          f"integration {result.seconds['integration']:.1f} s")
    ref = out.get("reference")  # a quasi-periodic gear: windowed statistics
    if ref is not None:
        print(f"quasi-periodic ({out['torus']['G']} incommensurate frequency groups): torus "
              f"harmonic balance against {ref['method']}, windows of "
              f"{ref['window_periods']} base periods, {ref['n_agree']} consecutive windows "
              f"agreeing within {ref['agreement_tolerance']:g}")
    kw, nw = (8, 14) if ref is not None else (3, 13)  # "(12, 10)", "quasi_periodic"
    print(f"{'Hz':>9} {'K':>{kw}} {'truncation':>10} {'HB':>10} {'NI':>{nw}} {'stable':>6} "
          f"{'max rel diff':>12} "
          f"{'worst mesh':>10} {'RMS HB (N)':>10} {'RMS NI (N)':>10}")
    for k, p in enumerate(out["points"]):
        rel = result.rel_diff[k]
        if np.any(np.isfinite(rel)):
            j = int(np.nanargmax(rel))
            tail = (f"{rel[j]:>12.2e} {p['meshes'][j]['name']:>10} "
                    f"{result.rms_hb[k, j]:>10.1f} {result.rms_ni[k, j]:>10.1f}")
        else:
            tail = f"{'-':>12} {'-':>10} {'-':>10} {'-':>10}"
        stable = {None: "?", True: "yes", False: "no"}[p["stable"]]
        K = p["harmonics"]
        K = K if isinstance(K, int) else "(" + ", ".join(map(str, K)) + ")"
        flag = "" if p["ok"] else "  NOT OK" + (f" ({p['agreement']})" if "agreement" in p
                                                else "")
        print(f"{p['mesh_frequency_hz']:>9.1f} {K:>{kw}} {_last_estimate(p):>10} "
              f"{p['result_hb']:>10} "
              f"{p['result_ni']:>{nw}} {stable:>6} " + tail + flag)
        if p.get("shortfall_reason"):
            print(f"{'':>9} {p['shortfall_reason']}")
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return code


def _last_estimate(point: dict) -> str:
    """The truncation estimate of a verified point's orders (the largest over the angles
    of its last check), or ``-`` where none was made."""
    K = point["truncation"][-1]["K"] if point["truncation"] else None
    changes = [c["change"] for c in point["truncation"]
               if c["K"] == K and c["change"] is not None]
    return f"{max(changes):.1e}" if changes else "-"


# ----------------------------------------------------------------------------- plot


def _plot_cmd(args, train, notes) -> int:
    from ._plot.save import plot_results

    results = pathlib.Path(args.results)
    fig = pathlib.Path(args.out) if args.out else results.with_suffix(".png")
    if results.is_dir():
        return _plot_study(args, results, fig)
    if args.pareto is not None:
        raise fail("command line", "--pareto", " ".join(args.pareto),
                   "is for a study store; RESULTS is a file")
    with _atomic(fig) as tmp:
        kind, _ = plot_results(results, tmp, what=args.what)
    if args.json:
        return _emit({"results": args.results, "kind": kind, "what": args.what,
                      "figure": str(fig)})
    print(f"{kind} results {args.results}: figure ({args.what}) written to {fig}")
    return EXIT_OK


# ---------------------------------------------------------------------------- study


def _study_cmd(args, train, notes) -> int:
    from ._studies.study import load_study, study
    from ._studies.study.report import study_json

    spec = load_study(args.study)
    store = _study_store(args)
    client = None
    if args.scheduler is not None:
        if args.workers is not None:
            raise fail("command line", "--workers", args.workers,
                       "is for the local cluster; --scheduler names a cluster with its own "
                       "workers")
        from dask.distributed import Client

        try:
            client = Client(args.scheduler, timeout=30)
        except OSError as e:
            raise fail("command line", "--scheduler", args.scheduler,
                       f"no Dask scheduler answers there ({_one_line(e, 120)})") from None
    try:
        result = study(spec, store, client=client, workers=args.workers, resume=args.resume,
                       say=_stderr)
    finally:
        if client is not None:
            client.close()
    out = study_json(result)
    out["warnings"] = notes
    if args.json:
        return _emit(out)
    print(f"study {spec.source}: {out['candidates']} candidates ({out['design']}) in "
          f"{store}: {out['ran']} run now, {out['skipped']} before, {out['refused']} "
          f"refused, {out['failed']} failed, {out['missing']} missing "
          f"({out['seconds']:.0f} s)")
    for rec in out["results"]:
        values = "; ".join(f"{p} = {v:g}" if isinstance(v, float) else f"{p} = {v}"
                           for p, v in rec["values"].items())
        merits = [f"first mode {rec['first_elastic_hz']:.1f} Hz"
                  if rec["first_elastic_hz"] is not None else ""]
        for kind in ("linear", "backlash"):
            if rec[kind] is not None:
                peaks = ", ".join(f"{s} {_kilo(f)}" for s, f in
                                  rec[kind]["peak_rms_force"].items())
                merits.append(f"{kind} peak RMS {peaks}")
        check = rec["verify"]
        if check is not None and check["max_rel_diff"] is not None:
            merits.append(f"verify {check['max_rel_diff']:.2%} "
                          f"({'within' if check['ok'] else 'beyond'} {check['tolerance']:.0%})")
        tail = rec["reason"] if rec["status"] != "done" else "; ".join(m for m in merits if m)
        print(f"{rec['candidate']:>6} {rec['status']:<8} {values}: {tail}")
    return EXIT_OK


def _study_store(args) -> str:
    """The study store: ``--out``, else the study file with ``.study``."""
    return args.out or str(pathlib.Path(args.study).with_suffix(".study"))


def _kilo(force: float | None) -> str:
    return "-" if force is None else f"{force / 1e3:.2f} kN"


def _plot_study(args, store: pathlib.Path, fig_path: pathlib.Path) -> int:
    from ._plot.study_figure import pareto_pair, study_figure
    from ._studies.study import load_study_results
    from ._studies.study.report import pareto

    ds = load_study_results(store)
    pair = pareto_pair(ds, None if args.pareto is None else tuple(args.pareto))
    fig = study_figure(ds, pair)
    with _atomic(fig_path) as tmp:
        fig.savefig(tmp, format=fig_path.suffix.lstrip(".") or "png", dpi=120)
    best = pareto(ds, *pair) if pair is not None else None
    if args.json:
        return _emit({"results": str(store), "kind": "study", "figure": str(fig_path),
                      "pareto_merits": None if pair is None else list(pair),
                      "pareto": best})
    print(f"study results {store}: figure written to {fig_path}"
          + (f"; Pareto set of {pair[0]} and {pair[1]}: candidates "
             f"{', '.join(map(str, best))}" if pair is not None else ""))
    return EXIT_OK


# ---------------------------------------------------------------------- sensitivity


def _sensitivity_cmd(args, train, notes) -> int:
    from ._studies.sensitivity import sensitivity, sensitivity_json

    if not (args.at > 0 and math.isfinite(args.at)):
        raise fail("command line", "--at", args.at, "must be a positive mesh frequency in Hz")
    result = sensitivity(train, args.gear, args.at, response=args.response, mesh=args.mesh,
                         paths=args.vary, stage=args.stage, linear=args.linear,
                         harmonics=args.harmonics, progress=_stderr)
    out = sensitivity_json(result)
    out["warnings"] = notes
    code = EXIT_OK if result.ok else EXIT_NOT_CONVERGED
    if not result.ok:
        _stderr(f"gearjax: {result.message}")
    if args.json:
        _emit(out)
        return code
    kind = "linear" if args.linear else "with backlash"
    print(f"sensitivity of the {result.response} of mesh {result.mesh} ({result.value:.6g} "
          f"{result.unit}) at {result.mesh_frequency_hz:g} Hz, gear {result.gear!r}, {kind}, "
          f"K = {result.harmonics}: {result.result}")
    if not result.ok:
        return code
    print(f"ranked {out['ranking']}")
    print(f"{'path':>28} {'value':>12} {'dR/dp':>13} {'per':>8} {'(p/R) dR/dp':>12} "
          f"{'step s':>10} {'(s/R) dR/dp':>12}")
    for row in out["derivatives"]:
        norm = "-" if row["normalised"] is None else f"{row['normalised']:+.4e}"
        rel = "-" if row["relative"] is None else f"{row['relative']:+.4e}"
        step = ("value" if row["step_rule"] is None else f"{row['step']:.4g} {row['unit']}")
        print(f"{row['path']:>28} {row['value']:>12.5g} {row['derivative']:>+13.5e} "
              f"{row['unit']:>8} {norm:>12} {step:>10} {rel:>12}")
    return code


# ------------------------------------------------------------------------- optimize


def _optimize_cmd(args, train, notes) -> int:
    from ._errors import bad_argument
    from ._studies.optimize import (OptimizeSettings, optimize, optimize_dataset,
                                    optimize_json, recheck, recheck_json)
    from ._studies.optimize.settings import check_band
    from ._io.results import save_results
    from ._gear.toml_io import save_train

    settings = OptimizeSettings(
        proxy_points=args.proxy_points, phase_grid=args.phase_grid, screen=args.screen,
        screen_points=args.points, final_points=args.final_points, harmonics=args.harmonics,
        nonlinear=args.nonlinear,
        max_step_hz=args.max_step, max_points=args.max_points, seeds=args.seeds,
        relax_iterations=args.relax_iterations,
        passes=args.passes)
    rechecking = args.recheck and args.nonlinear > 0
    recheck_band = tuple(args.recheck_band) if args.recheck_band is not None else None
    if rechecking:  # refused before the optimisation, in the re-check flags' words
        if args.recheck_band is not None:  # (the default, --band, the optimiser checks)
            try:
                check_band(recheck_band)
            except ArgumentError as e:
                raise bad_argument("recheck_band_hz", e.value, e.rule) from None
        if args.recheck_harmonics is not None and args.recheck_harmonics < 1:
            raise bad_argument("recheck_harmonics", args.recheck_harmonics,
                               "must be an integer >= 1")
    g = train.gear(args.gear)
    result = optimize(train, g.name, None if args.band is None else tuple(args.band),
                      args.vary, stage=args.stage,
                      settings=settings, progress=_stderr)
    check = None
    if rechecking:
        check = recheck(result, recheck_band, verify_hz=[],
                        harmonics=args.recheck_harmonics, max_points=args.max_points,
                        seeds=args.seeds, progress=_stderr)
    outcome = check.verdict if check is not None else result.verdict
    recommended = check.recommended_train if check is not None else result.recommended_train
    if args.out_train:
        with _atomic(args.out_train) as tmp:
            save_train(recommended, tmp)
    attrs = {"command": args.command_line}
    if check is not None:
        attrs.update(recheck=recheck_json(check), recheck_verdict=check.verdict["text"],
                     recommended=check.recommended)
    if args.out:
        save_results(optimize_dataset(result, attrs), args.out)
    out = optimize_json(result)
    out.update(recheck=None if check is None else recheck_json(check),
               recommended=outcome["recommended"], conclusion=outcome["text"],
               out_train=args.out_train, out=args.out, warnings=notes)
    code = EXIT_OK if result.converged else EXIT_NOT_CONVERGED
    if args.json:
        _emit(out)
        return code
    b, o = result.baseline, result.optimum
    print(f"phasing optimisation of gear {g.name!r}, band {result.band_hz[0]:g}-"
          f"{result.band_hz[1]:g} Hz (stage {result.reference_stage}), varying "
          f"{', '.join(result.vary)}: {result.seconds:.0f} s")
    print(f"{'':>10} {'peak RMS, linear (N)':>22} {'with backlash (N)':>18}  "
          "planet angles, phases")
    for name, d in (("baseline", b), ("optimum", o)):
        nl = "-" if d.nonlinear is None else f"{d.nonlinear_peak:.1f}"
        print(f"{name:>10} {d.linear_peak:>22.1f} {nl:>18}  " + _values_text(d.values))
    models = result.models or {}
    print(f"models: proxy {models['proxy']['frequencies']} frequencies x "
          f"{models['proxy']['phase_grid']} phases; linear screen K = "
          f"{models['linear']['harmonics']}, {models['linear']['frequencies_per_candidate']} "
          "frequencies per candidate; with backlash: "
          + ("none (--nonlinear 0)" if models.get("backlash") is None
             else models["backlash"]["text"] + ", peak over every stable state")
          + ("" if check is None else f"; re-check: {check.settings.text()}, "
             f"{check.band_hz[0]:g}-{check.band_hz[1]:g} Hz"))
    if check is not None:
        print(f"{'re-check':>10} {'fresh peak (N)':>22} {'at (Hz)':>18}  integration from "
              "that orbit")
        for name, row in check.peaks.iterrows():
            print(f"{name:>10} {row['sweep peak (N)']:>22.1f} {row['at (Hz)']:>18.1f}  "
                  f"{row.get('integrated (N)', math.nan):.1f} N ({row['integration']}), "
                  f"branch found by {row['branch found by'] or '-'}"
                  + ("" if row["complete"] else ", sweep NOT complete"))
    print(f"optimiser: {result.verdict['text']}")
    if check is not None:
        print(f"re-check: {check.verdict['text']}")
    r = result.relaxation
    if r is not None:
        print(f"{'relaxed':>10} {r.linear_peak:>22.1f} {'-':>18}  " + _values_text(r.values)
              + "  (continuous: not assemblable)")
    for s in result.stages:
        print(f"stage {s['stage']}: {s['planet_sets']} admissible planet sets"
              + f" ({s['screened_sets']} distinct phasings"
              + (" up to a rotation" if s["modulo_rotation"] else "") + ")"
              + f", {s['linear_screened']} solved linear, {s['nonlinear_swept']} with "
              f"backlash: {s['chosen']}")
    if args.out_train:
        print(f"{'optimised' if outcome['recommended'] == 'optimum' else 'baseline'} train "
              f"(the recommended design) written to {args.out_train}")
    if args.out:
        print(f"results written to {args.out}")
    return code


def _values_text(values: dict) -> str:
    """``1.planet_angles_deg [0, 90, ...]``-style summary of design values."""
    planets: dict[str, list[float]] = {}
    rest = []
    for path, v in values.items():
        sid, key, *i = path.split(".")
        if key == "planet_angles_deg":
            planets.setdefault(sid, [0.0]).append(v)
        else:
            rest.append(f"{path} {v:.4g}")
    return ", ".join([f"{sid}.planets [" + ", ".join(f"{a:.4g}" for a in a_s) + "]"
                      for sid, a_s in planets.items()] + rest)


# ----------------------------------------------------------------------------- JSON


def _emit(obj) -> int:
    print(json.dumps(_json_safe(obj), allow_nan=False, indent=1))
    return EXIT_OK


def _json_safe(obj):
    """Replace NaN/inf with null (interface.md: JSON never holds NaN or Infinity)."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, Fraction):
        return float(obj)
    if hasattr(obj, "item") and not isinstance(obj, str):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


if __name__ == "__main__":
    console()
