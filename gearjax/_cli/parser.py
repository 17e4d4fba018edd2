"""The argument parser of every command: flags, defaults, help, and usage errors as
one line."""

from __future__ import annotations

import argparse
import re

from .design import optimize_command, sensitivity_command
from .info import DEFAULT_INPUT_RPM, info_command, mesh_command
from .modes import calibrate_command, modes_command
from .plot import plot_command
from .points import simulate_command, verify_command
from .study import study_command
from .sweep import sweep_command


class UsageError(Exception):
    """argparse's refusal, made one line (:class:`Parser`)."""


class Parser(argparse.ArgumentParser):
    """``ArgumentParser`` whose usage errors are one line in the form of every other
    refusal (``command line: FLAG = VALUE: RULE``) instead of a usage dump."""

    def error(self, message: str):
        raise UsageError(usage_message(self.prog, message))


def usage_message(prog: str, message: str) -> str:
    """argparse's refusal ``message`` as one line in the form of every other refusal:
    the flag, its value (or ``(missing)``) and the rule, and where ``--help`` helps."""
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


# the flags several commands share, declared once


def reference_stage_flag(c: argparse.ArgumentParser) -> None:
    c.add_argument("--stage", help="reference stage id (default: first turning stage)")


def linear_flag(c: argparse.ArgumentParser) -> None:
    c.add_argument("--linear", action="store_true", help="no backlash")


def results_flags(c: argparse.ArgumentParser) -> None:
    """``--out`` and ``--plot`` of sweep and simulate."""
    c.add_argument("--out", metavar="FILE.nc|.csv", help="write the results")
    c.add_argument("--plot", metavar="FIG", help="write the RMS mesh forces")


def point_flags(c: argparse.ArgumentParser) -> None:
    """The frequency flags of simulate and verify."""
    c.add_argument("--at", type=float, nargs="+", metavar="HZ",
                   help="independent points, reference-stage mesh frequency (Hz)")
    c.add_argument("--from", dest="from_hz", type=float, metavar="HZ",
                   help="sweep start (Hz); each point continues from the previous")
    c.add_argument("--to", dest="to_hz", type=float, metavar="HZ", help="sweep end (Hz)")
    c.add_argument("--points", type=int, metavar="N", help="sweep points (default 20)")
    reference_stage_flag(c)
    linear_flag(c)


def build_parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="gearjax",
        description="Dynamics of compound planetary gear trains. TRAIN defaults to the bundled "
                    "Al-shyyab et al. (2009) case.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)

    def command(name: str, run, help: str, description: str | None = None,
                input: tuple[str, str, str] | None = None) -> argparse.ArgumentParser:
        """A command, its ``--json`` and its input: a train file and ``--gear`` (the
        default), or ``input = (name, metavar, help)``, a file that is not a train."""
        c = sub.add_parser(name, help=help, description=description or help)
        if input is None:
            c.add_argument("train", nargs="?", default=None, metavar="TRAIN",
                           help="train file (TOML); default: the bundled paper case")
            c.add_argument("--gear", default=None,
                           help="gear name (default: first in the file)")
        else:
            c.add_argument(input[0], metavar=input[1], help=input[2])
        c.add_argument("--json", action="store_true", help="one JSON object on stdout")
        c.set_defaults(run=run, needs_train=input is None)
        return c

    c = command("info", info_command, "kinematics, phasing and static loads of a gear")
    c.add_argument("--input-rpm", type=float, default=None,
                   help=f"input speed (rpm); default: the gear's input_rpm in the train file, "
                        f"else {DEFAULT_INPUT_RPM:g}")
    c = command("modes", modes_command, "natural frequencies, shapes and classes of a gear")
    c.add_argument("--plot", metavar="FIG", help="write the elastic mode shapes to FIG")
    c = command("calibrate", calibrate_command, "fit parameters to target natural frequencies")
    c.add_argument("--targets-hz", type=float, nargs="+", required=True, metavar="F",
                   help="target elastic frequencies (Hz), ascending, repeated modes repeated")
    c.add_argument("--free", nargs="+", required=True, metavar="PATH",
                   help="TOML paths to fit, e.g. 1.inertia.sun 2.planet_mass")
    c.add_argument("--out-train", metavar="FILE.toml", help="write the calibrated train")
    c = command("mesh", mesh_command, "contact, stiffness and transmission error of a stage's "
                "meshes over one mesh cycle")
    c.add_argument("--stage", default=None, metavar="ID", help="stage id (default: every stage)")
    c.add_argument("--plot", metavar="FIG", help="write the mesh cycle of the stage to FIG")
    c = command("sweep", sweep_command, "frequency response by harmonic balance and continuation")
    c.add_argument("--from", dest="from_hz", type=float, default=None, metavar="HZ",
                   help="start, reference-stage mesh frequency (Hz); direction = order; "
                        "without --from and --to, a band chosen from the gear's modes")
    c.add_argument("--to", dest="to_hz", type=float, default=None, metavar="HZ")
    reference_stage_flag(c)
    linear_flag(c)
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
    results_flags(c)
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
    c = command("simulate", simulate_command, "steady states by time integration")
    point_flags(c)
    results_flags(c)
    c = command("verify", verify_command,
                "harmonic balance against time integration at the same points")
    point_flags(c)
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
    c = command("sensitivity", sensitivity_command,
                "derivatives of a mesh response at one frequency w.r.t. train parameters")
    c.add_argument("--at", type=float, required=True, metavar="HZ",
                   help="reference-stage mesh frequency (Hz)")
    c.add_argument("--response", choices=("rms", "max", "dlf"), default="rms",
                   help="RMS alternating force, peak force or dynamic load factor")
    c.add_argument("--mesh", metavar="NAME", help="mesh such as 1.sp1 (default: largest)")
    c.add_argument("--vary", nargs="+", metavar="PATH",
                   help="TOML paths (default: every continuous parameter that affects the "
                        "gear)")
    reference_stage_flag(c)
    linear_flag(c)
    c.add_argument("--harmonics", type=int, metavar="K",
                   help="solution harmonics (default: frequency-dependent; on a quasi-"
                        "periodic gear, K on every torus angle)")
    c = command("optimize", optimize_command,
                "planet positions, sun-ring and stage phases that minimise the peak RMS "
                "mesh force over a band")
    c.add_argument("--band", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="reference-stage mesh frequencies (Hz); default: a band chosen "
                        "from the gear's modes and excitation orders (said on stderr)")
    c.add_argument("--vary", nargs="+", metavar="PATH",
                   help="STAGE.planet_angles_deg, STAGE.sun_ring_phase_deg, "
                        "STAGE.stage_phase_deg (default: all of the turning stages)")
    reference_stage_flag(c)
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
    c = command("study", study_command,
                "a design study: candidate trains varied from a base train, each analysed "
                "on a Dask cluster (a study file, TOML)",
                "a design study: candidate trains varied from a base train, each analysed "
                "on a Dask cluster", input=("study", "STUDY.toml", "the study file"))
    c.add_argument("--out", metavar="DIR", help="the study store: one result file per "
                   "candidate (default: STUDY with .study)")
    c.add_argument("--resume", action="store_true",
                   help="run only the candidates the store has no result for")
    c.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local cluster (default: this machine's "
                        "cores; 0: every candidate in this process)")
    c.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tcp://host:8786)")
    c = command("plot", plot_command,
                "redraw a saved result (sweep, simulate, verify, optimize, study)",
                "redraw a saved result (sweep, simulate, verify, optimize, study) without "
                "recomputing", input=("results", "RESULTS.nc", "a results file written with "
                                      "--out, or a study store (directory)"))
    c.add_argument("--pareto", nargs=2, metavar=("MERIT", "MERIT"),
                   help="a study's Pareto set of these two figures of merit (default: the "
                        "first two it has)")
    c.add_argument("--what", choices=("rms", "dlf", "separation", "torque", "bearings"),
                   default="rms",
                   help="RMS mesh force, dynamic load factor, separation share, mean torque, "
                        "or the bearing forces (translational model)")
    c.add_argument("--out", metavar="FIG", help="figure file (default: RESULTS with .png)")
    p.set_defaults(commands=tuple(sub.choices))  # named where none is given
    return p
