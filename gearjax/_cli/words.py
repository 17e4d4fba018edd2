"""The flag of each Python argument name: the library's refusals in the command
line's words."""

from __future__ import annotations

import re

from .._errors import ArgumentError, TrainError, field_message


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
