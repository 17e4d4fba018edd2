"""The figure of a design study: each figure of merit against each varied parameter,
and the Pareto set of two merits."""

from __future__ import annotations

import numpy as np

from .._studies.study.report import LARGER_IS_BETTER, MERITS, merit_values, pareto, varied_paths

LABELS = {"first_elastic_hz": "first elastic mode (Hz)",
          "linear_peak_rms_force": "linear: peak RMS mesh force (N)",
          "backlash_peak_rms_force": "backlash: peak RMS mesh force (N)",
          "linear_coexisting_hz": "linear: coexisting band (Hz)",
          "backlash_coexisting_hz": "backlash: coexisting bands (Hz)",
          "verify_max_rel_diff": "verify: largest relative RMS difference"}
"""Axis label of each figure of merit (a per-stage merit: its largest stage)."""


def study_merits(ds) -> list[str]:
    """The merits of :data:`~gearjax._studies.study.report.MERITS` the study ``ds``
    computed for at least one candidate (coexisting bands only where a sweep found
    one)."""
    out = []
    for merit in MERITS:
        try:
            values = merit_values(ds, merit)
        except ValueError:
            continue
        if np.isfinite(values).any() and not (merit.endswith("coexisting_hz")
                                              and np.nanmax(values) <= 0):
            out.append(merit)
    return out


def pareto_pair(ds, pareto_merits: tuple[str, str] | None = None) -> tuple[str, str] | None:
    """The two merits whose Pareto set :func:`study_figure` draws: ``pareto_merits``
    where given, else the first two :func:`study_merits` of ``ds`` (``None`` where it
    has fewer)."""
    if pareto_merits is not None:
        return tuple(pareto_merits)
    merits = study_merits(ds)
    return (merits[0], merits[1]) if len(merits) >= 2 else None


def study_figure(ds, pareto_merits: tuple[str, str] | None = None, title: str = ""):
    """A study (:func:`gearjax.load_study_results`): one row per figure of merit it has
    (:func:`study_merits`), one column per varied path (numbers on a linear axis, lists
    such as planet angles as categories), the done candidates as dots; and, where two
    merits exist, a last row with ``pareto_merits`` (default: the first two) against each
    other, the Pareto set (:func:`~gearjax._studies.study.report.pareto`) circled and
    joined. Refused and failed candidates are counted in the title, not drawn.

    **Returns:** the Figure. **Raises:** ``ArgumentError`` (``merit``) for a Pareto merit
    the study does not have."""
    from matplotlib.figure import Figure

    merits = study_merits(ds)
    paths = varied_paths(ds)
    pareto_merits = pareto_pair(ds, pareto_merits)
    rows = len(merits) + (pareto_merits is not None)
    cols = max(len(paths), 1)
    fig = Figure(figsize=(3.4 * cols + 0.6, 2.6 * max(rows, 1) + 0.6), layout="constrained")
    axes = fig.subplots(max(rows, 1), cols, squeeze=False)
    done = np.asarray(ds["status"].values) == "done"
    for r, merit in enumerate(merits):
        y = merit_values(ds, merit)
        for c, path in enumerate(paths):
            ax = axes[r, c]
            x, ticks = _positions(ds[path].values)
            ax.plot(x[done], y[done], "o", ms=4, color="k", alpha=0.7)
            if ticks is not None:
                ax.set_xticks(range(len(ticks)), ticks, fontsize=6, rotation=20)
            ax.set_xlabel(path, fontsize=8)
            ax.set_ylabel(LABELS[merit], fontsize=7)
            ax.grid(alpha=0.3)
    if pareto_merits is not None:
        a_name, b_name = pareto_merits
        a, b = merit_values(ds, a_name), merit_values(ds, b_name)
        ax = axes[-1, 0]
        ax.plot(a[done], b[done], "o", ms=4, color="0.5", label="candidates")
        best = pareto(ds, a_name, b_name)
        at = [int(np.flatnonzero(ds["candidate"].values == i)[0]) for i in best]
        order = sorted(at, key=lambda i: a[i])
        ax.plot(a[order], b[order], "o-", ms=7, mfc="none", color="C3",
                label=f"Pareto set ({len(best)})")
        for i in order:
            ax.annotate(str(int(ds["candidate"].values[i])), (a[i], b[i]), fontsize=6,
                        xytext=(3, 3), textcoords="offset points")
        ax.set_xlabel(LABELS[a_name] + _sense(a_name), fontsize=7)
        ax.set_ylabel(LABELS[b_name] + _sense(b_name), fontsize=7)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        for extra in axes[-1, 1:]:
            extra.set_visible(False)
    status = np.asarray(ds["status"].values)
    counts = ", ".join(f"{int((status == s).sum())} {s}" for s in ("done", "refused", "failed")
                       if (status == s).any())
    missing = int(ds.attrs.get("missing", 0))
    fig.suptitle(title or f"study {ds.attrs.get('study', '')}: {counts}"
                 + (f", {missing} not run yet" if missing else ""), fontsize=10)
    return fig


def _positions(values) -> tuple[np.ndarray, list[str] | None]:
    """x of each candidate: the number itself, or the index of its category (lists)."""
    values = np.asarray(values)
    if values.dtype.kind in "iuf":
        return values.astype(float), None
    labels = list(dict.fromkeys(str(v) for v in values))
    return np.array([labels.index(str(v)) for v in values], float), labels


def _sense(merit: str) -> str:
    return " (higher is better)" if merit in LARGER_IS_BETTER else " (lower is better)"
