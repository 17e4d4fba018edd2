"""The one enumeration of outcomes: of a point (harmonic balance, time integration,
derivative), of a continuation and of a sweep's segment.

:class:`RESULTS` extends ``optimistix.RESULTS`` (itself extending ``lineax.RESULTS``),
as ``diffrax.RESULTS`` does, so a root finder's result promotes into it
(``RESULTS.promote``). Results files and JSON keep the words of the interface
(``converged``, ``max_steps``, ``not_periodic``, ``reached_end``, ...):
:func:`result_word` names an item, :func:`result_from_word` reads a word back, the
words of files written by every earlier version included.
"""

from __future__ import annotations

import numpy as np
import optimistix as optx


class RESULTS(optx.RESULTS):  # type: ignore[misc]
    """Outcomes: ``optimistix.RESULTS`` (``successful``, ``nonlinear_max_steps_reached``,
    ``nonfinite``, ...; ``max_steps_reached`` for a time integration's step limit, as in
    diffrax) and the items below. Compare with ``==`` (a boolean array, batched where
    the item is); ``RESULTS[item]`` is the message."""

    not_periodic = ("The time integration ran its periods without settling onto a "
                    "periodic orbit.")
    quasi_periodic = ("The windowed time integration reached statistics that agree between "
                      "consecutive windows (for a quasi-periodic train, which has no period, "
                      "these statistics are its result).")
    not_stationary = ("The time integration ran its windows without consecutive windows' "
                      "statistics agreeing within tolerance.")
    solver_failed = "The ODE solver failed (its step size collapsed)."
    reached_end = "The continuation reached the end of its parameter range."
    max_points = "The continuation used its budget of points."
    step_too_small = ("The continuation's step fell below its minimum without the "
                      "corrector converging.")
    closed_loop = "The branch came back onto a stretch it had traced, in the same direction."
    detour = "The branch stopped advancing in the parameter (it turned back or wandered)."
    runaway = ("The branch's alternating mesh deflection exceeded its runaway bound (five "
               "times the static deflection plus the backlash: inside or at the edge of a "
               "parametric instability, or a resonance beyond what the model describes).")
    no_converged_start = "No converged point was found where the segment starts."
    fold = "The point lies at a fold of the branch: its derivative is unbounded there."
    unstable = "The periodic state is unstable: no test rig settles onto it."
    not_converged = "The point did not converge: it has no derivative."
    lightly_damped_mode = ("A Floquet multiplier of the linear response lies near +1 through "
                           "a lightly damped mode (near-rigid, or in resonance with a "
                           "harmonic of the response), not a fold (a linear system has "
                           "none): its derivative is ill-conditioned there.")


_WORDS = {"successful": "converged", "nonlinear_max_steps_reached": "max_steps",
          "max_steps_reached": "max_steps"}
"""Item names whose word in files differs (the interface's words since version 1)."""

_NAMES = ("successful", "max_steps_reached", "singular", "breakdown", "stagnation", "conlim",
          "nonfinite_input", "nonlinear_max_steps_reached", "nonlinear_divergence",
          "nonfinite", "not_periodic", "quasi_periodic", "not_stationary", "solver_failed", "reached_end", "max_points",
          "step_too_small", "closed_loop", "detour", "runaway", "no_converged_start",
          "fold", "unstable", "not_converged", "lightly_damped_mode")
"""Every item's name (an equinox enumeration lists none)."""
_LEGACY_CODES = {"hb": ("converged", "max_steps", "nonfinite"),
                 "time_domain": ("converged", "not_periodic", "max_steps", "solver_failed",
                                 "nonfinite")}
"""Integer result codes of earlier versions (journals stored them) by kind."""


def result_word(result):
    """The interface word of ``result`` (a ``RESULTS`` item, concrete): a ``str``, or an
    array of ``str`` with the item's shape where it is batched."""
    words = np.full(np.shape(result == RESULTS.successful), "", dtype=object)
    for name in _NAMES:
        words[np.asarray(result == getattr(RESULTS, name))] = _WORDS.get(name, name)
    return words.item() if words.ndim == 0 else words.astype(str)


def result_from_word(word: str, *, time_domain: bool = False) -> RESULTS:
    """The ``RESULTS`` item of an interface word (:func:`result_word`); ``max_steps`` is a
    time integration's step limit with ``time_domain``, Newton's otherwise. A sweep
    stop "no converged start at ..." (its detail included) is ``no_converged_start``.

    **Raises:** ``ValueError`` for a word no version wrote."""
    if word.startswith("no converged start"):
        return RESULTS.no_converged_start
    if word == "converged":
        return RESULTS.successful
    if word == "max_steps":
        return RESULTS.max_steps_reached if time_domain else RESULTS.nonlinear_max_steps_reached
    if word in _NAMES and word not in _WORDS:
        return getattr(RESULTS, word)
    raise ValueError(f"unknown result {word!r}")


def legacy_words(codes, kind: str) -> np.ndarray:
    """Words of the integer result codes ``codes`` that earlier versions stored (``kind``
    ``"hb"`` or ``"time_domain"``); an array of words passes through unchanged."""
    codes = np.asarray(codes)
    if codes.dtype.kind in "US":
        return codes.astype(str)
    return np.asarray(_LEGACY_CODES[kind], dtype=str)[codes]
