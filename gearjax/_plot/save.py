"""Figures: mode shapes, sweeps, solution points, verification; and redrawing a saved
results file (:func:`plot_results`, ``gearjax plot``). Matplotlib, no screen needed."""

from __future__ import annotations

import json
import math
import pathlib
import textwrap
import tomllib
from collections.abc import Callable

import numpy as np

from .._errors import TrainError, bad_argument
from .._io.results import read_netcdf
from .._io.verify_file import load_verify
from .._engine.modal import ModalResult
from .bearing_figure import bearing_figure
from .units import frequency_unit

WHAT = {"rms": ("rms_force", "RMS mesh force (N)"), "dlf": ("dlf", "dynamic load factor"),
        "separation": ("separation", "share of period in separation"),
        "torque": ("mean_torque", "mean transmitted torque (N m)")}
"""``what`` of the response plots: the Dataset variable and its axis label."""


def plot_mode_shapes(result: ModalResult, path: str, title: str = "", classes=("elastic",)):
    """Bar chart of each distinct mode's shape (one panel per frequency), saved to ``path``.

    Bars: each coordinate's rotation (rad) scaled so the largest is 1, central members
    blue and planets (rotation relative to their carrier) orange, as the legend below
    says. Repeated modes get one panel (the solver's first basis vector) marked ``xN``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    chosen, k = [], 0
    modes = [m for m in result.modes if m.cls in classes]
    while k < len(modes):
        chosen.append(modes[k])
        k += modes[k].multiplicity
    cols = min(4, max(1, len(chosen)))
    rows = math.ceil(len(chosen) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 0.5 + 2.9 * rows),
                             squeeze=False, sharey=True, layout="constrained")
    for ax, m in zip(axes.flat, chosen):
        labels = list(m.shape)
        values = np.array([m.shape[l] for l in labels])
        colors = ["tab:blue" if ".planet" not in l else "tab:orange" for l in labels]
        ax.bar(range(len(labels)), values, color=colors)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=90, fontsize=6)
        tag = f" x{m.multiplicity}" if m.multiplicity > 1 else ""
        fam = f"planet {m.stage}" if m.family == "planet" else m.family
        ax.set_title(f"{m.hz / 1e3:.3f} kHz{tag} ({fam})", fontsize=8)
        ax.set_xlabel("coordinate", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("rotation (largest = 1)", fontsize=8)
    for ax in list(axes.flat)[len(chosen):]:
        ax.set_visible(False)
    fig.legend(handles=[Patch(color="tab:blue", label="central member (sun, ring, carrier)"),
                        Patch(color="tab:orange", label="planet, relative to its carrier")],
               loc="outside lower center", ncol=2, fontsize=7, frameon=False)
    fig.suptitle(title or "mode shapes (largest coordinate = 1)", fontsize=9)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_sweep(ds, path: str, what: str = "rms", title: str = ""):
    """Response of every stage's meshes against reference-stage mesh frequency.

    ``what``: ``rms`` (RMS alternating force, N), ``dlf``, ``separation`` (share of the
    period) or ``torque`` (mean transmitted torque, N m). One panel per stage and mesh
    side, the planets' curves overlaid; stable solid, unstable dashed, unknown dotted; a
    sweep that used its budget of points before the band's end is marked where it
    stopped.
    """
    from matplotlib.lines import Line2D

    var, label = WHAT[what]
    f = np.asarray(ds["mesh_frequency_hz"]) / frequency_unit(ds)[0]
    stable = np.asarray(ds["stable"]) if "stable" in ds else np.full(f.shape, -1)
    branch = np.asarray(ds["branch"]) if "branch" in ds else np.zeros(f.shape, int)
    fig, axes, panels = _mesh_panels(ds, label)
    for ax, first, meshes in panels:
        for j in meshes:
            planet = int(ds["planet"][j])
            _branch_lines(ax, f, np.asarray(ds[var])[:, j], stable, branch,
                          color=f"C{(planet - 1) % 10}",  # one colour per planet
                          label=f"planet {planet}" if first else None)
        values = np.asarray(ds[var])[:, meshes]
        clip_to_stable(ax, values, values[stable == 1])
    styles = [Line2D([], [], ls=ls, color="0.3", lw=1.0, label=name)
              for flag, ls, name in ((1, "-", "stable"), (0, "--", "unstable"),
                                     (-1, ":", "stability unknown")) if np.any(stable == flag)]
    if ds.attrs.get("stop") == "max_points" and f.size:  # ended before the band's end
        for ax in axes.ravel():
            ax.axvline(f[-1], color="tab:red", ls="-.", lw=1.0)
        styles.append(Line2D([], [], ls="-.", color="tab:red", lw=1.0,
                             label="stopped here: its budget of points used"))
    _finish(fig, axes, ds, path, title or "frequency response (solid stable, dashed unstable)",
            styles)


def _branch_lines(ax, f, y, stable, branch, color, label=None) -> None:
    """A response ``y`` against ``f`` in the order swept, one line per ``branch`` number
    (branches are not joined to each other), solid where ``stable`` is 1, dashed where 0,
    dotted where -1 (unknown); ``label`` on the first line drawn."""
    for b in dict.fromkeys(branch.tolist()):
        sel = branch == b
        for flag, style in ((1, "-"), (0, "--"), (-1, ":")):
            on = stable[sel] == flag
            if not np.any(on):
                continue
            on[1:] |= stable[sel][:-1] == flag  # each run reaches the next point
            ax.plot(f[sel], np.where(on, y[sel], np.nan), style, lw=1.0, color=color,
                    label=label)
            label = None


def clip_to_stable(ax, values, stable_values, factor: float = 1.5, corner: str = "right"
                    ) -> None:
    """Keep the stable response readable: where unstable branches reach more than
    ``factor`` times the largest stable value (inside a parametric instability the
    periodic orbits of the paper case reach meganewtons, all unstable), the y-axis stops
    at ``factor`` times it and a note in the upper ``corner`` (``"left"`` or ``"right"``,
    the one without a legend) gives how far the unstable branches go."""
    top = np.nanmax(stable_values) if np.any(np.isfinite(stable_values)) else np.nan
    high = np.nanmax(values) if np.any(np.isfinite(values)) else np.nan
    if not (np.isfinite(top) and top > 0 and high > factor * top):
        return
    low = min(0.0, float(np.nanmin(values)))
    ax.set_ylim(low, factor * top)
    x = 0.01 if corner == "left" else 0.99
    ax.text(x, 0.97, f"unstable branches up to {high:.3g}, off scale", fontsize=7,
            ha=corner, va="top", transform=ax.transAxes, color="0.3")


def _mesh_panels(ds, ylabel: str):
    """A figure with one panel per stage (rows) and mesh side (sun, ring: columns).

    **Returns:** ``(fig, axes, panels)``, ``panels`` a list of ``(ax, first, meshes)``:
    the panel, whether it is the first (it carries the legend) and the indices of its
    meshes in ``ds``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = list(dict.fromkeys(np.asarray(ds["stage"]).tolist()))
    fig, axes = plt.subplots(len(stages), 2, figsize=(10, 0.6 + 3.2 * len(stages)),
                             squeeze=False, sharex=True, layout="constrained")
    panels = []
    for r, stage in enumerate(stages):
        for c, side in enumerate(("sun", "ring")):
            ax = axes[r, c]
            sel = (np.asarray(ds["stage"]) == stage) & (np.asarray(ds["side"]) == side)
            ax.set_title(f"stage {stage}, {side}-planet meshes", fontsize=9)
            ax.set_ylabel(ylabel, fontsize=8)
            ax.ticklabel_format(axis="y", useOffset=False)
            ax.grid(alpha=0.3)
            panels.append((ax, r == 0 and c == 0, np.where(sel)[0]))
    return fig, axes, panels


MIN_SPAN = 0.02
"""Least height of a panel's y axis relative to the largest magnitude it shows: a
variation of 0.1% of the values then fills a twentieth of the panel, not all of it."""


def _not_a_trend(ax) -> None:
    """Widen ``ax``'s y range to :data:`MIN_SPAN` of its values' magnitude where it is
    narrower, about its middle, so a flat curve is drawn flat."""
    lo, hi = ax.get_ylim()
    size = max(abs(lo), abs(hi))
    if size > 0 and hi - lo < MIN_SPAN * size:
        mid = (lo + hi) / 2
        ax.set_ylim(mid - MIN_SPAN * size / 2, mid + MIN_SPAN * size / 2)


TITLE_WIDTH = 100
"""Characters of a figure title's line (a longer title is wrapped, not clipped)."""


def rpm_per_unit(ds, scale: float) -> float | None:
    """Input speed (rpm) per unit of the frequency axis (``scale`` Hz, :func:`frequency_unit`)
    of the points of ``ds``: mesh frequency and input speed are proportional for one gear;
    ``None`` where ``ds`` has no ``input_rpm`` or no point gives a finite positive ratio."""
    if "input_rpm" not in ds:
        return None
    f = np.asarray(ds["mesh_frequency_hz"], dtype=float).reshape(-1)
    n = np.asarray(ds["input_rpm"], dtype=float).reshape(-1)
    ok = np.isfinite(f) & np.isfinite(n) & (f > 0) & (n > 0)
    return float(np.median(n[ok] / f[ok]) * scale) if np.any(ok) else None


def _finish(fig, axes, ds, path, title: str, styles=()) -> None:
    """Frequency labels (and the input speed, rpm, on the top panels where ``ds`` has
    it), the title wrapped at :data:`TITLE_WIDTH`, and one legend below the panels (one
    entry per planet number of any stage, in its colour, then ``styles``: proxy artists
    of the line and marker styles); save to ``path`` and close."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    scale, unit = frequency_unit(ds)
    for ax in axes[-1]:
        ax.set_xlabel(f"stage {ds.attrs.get('reference_stage', '')} mesh frequency ({unit})")
    rpm = rpm_per_unit(ds, scale)
    if rpm is not None:  # the drivetrain engineer's axis: input speed, on the top panels
        for ax in axes[0]:
            top = ax.secondary_xaxis("top", functions=(lambda x: x * rpm, lambda n: n / rpm))
            top.set_xlabel("input speed (rpm)", fontsize=8)
            top.tick_params(labelsize=7)
    for ax in axes.ravel():
        _not_a_trend(ax)
    planets = sorted({int(p) for p in np.asarray(ds["planet"]).tolist()})
    handles = [Line2D([], [], color=f"C{(p - 1) % 10}", lw=1.0, label=f"planet {p}")
               for p in planets] + list(styles)
    if handles:
        fig.legend(handles=handles, loc="outside lower center",
                   ncol=len(handles) if len(handles) <= 5 else -(-len(handles) // 2),
                   fontsize=7, frameon=False)
    fig.suptitle("\n".join(line for part in title.split("\n")
                            for line in textwrap.wrap(part, TITLE_WIDTH) or [""]), fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_verify(hb, ni, path: str, curve=None, title: str = "", what: str = "rms"):
    """Integration points (markers) over the harmonic-balance RMS mesh forces, as the
    paper's Figs 4 and 5.

    ``hb``, ``ni``: results Datasets at the same points (``VerifyResult.hb``, ``.ni``);
    ``curve``: an optional sweep Dataset drawn as the harmonic-balance line (otherwise
    the ``hb`` points are drawn as markers, not joined); ``what`` as
    :func:`plot_sweep`. See :func:`plot_points`.
    """
    plot_points(ni, path, line=curve if curve is not None else hb, what=what,
                title=title or ("harmonic balance (lines) and time integration (circles)"
                                if curve is not None else
                                "harmonic balance (+) and time integration (circles)"))


def plot_points(ds, path: str, line=None, title: str = "", what: str = "rms"):
    """A response of solution points as markers against reference-stage mesh
    frequency, optionally over the lines of another results Dataset ``line``.

    ``what`` as :func:`plot_sweep` (default RMS mesh force). One panel per stage and
    mesh side, one colour per planet; open circles are converged points, crosses
    points that did not converge (e.g. an integration that did not settle to the base
    period). Meshes are matched by name. ``line``: a sweep (a ``branch`` variable) is
    drawn per branch in the order swept, solid stable and dashed unstable; other points
    as markers, not joined. The legend is below the panels.
    """
    from matplotlib.lines import Line2D

    var, ylabel = WHAT[what]
    scale = frequency_unit(ds if line is None else line)[0]
    f_pts = np.asarray(ds["mesh_frequency_hz"]) / scale
    settled = np.asarray(ds["converged"])
    names = np.asarray(ds["mesh"]).tolist()
    fig, axes, panels = _mesh_panels(ds, ylabel)
    for ax, first, meshes in panels:
        for j in meshes:
            color = f"C{(int(ds['planet'][j]) - 1) % 10}"  # one colour per planet
            label = f"planet {int(ds['planet'][j])}" if first else None
            if line is not None:
                k = np.asarray(line["mesh"]).tolist().index(names[j])
                _line_of(ax, line, np.asarray(line[var])[:, k], color, label, scale)
                label = None
            y = np.asarray(ds[var])[:, j]
            ax.plot(f_pts[settled], y[settled], "o", mfc="none", ms=6, color=color, label=label)
            ax.plot(f_pts[~settled], y[~settled], "x", ms=6, color=color)
    swept = line is not None and "branch" in line
    unstable = (swept and "stable" in line
                and bool(np.any(np.asarray(line["stable"]) == 0)))
    styles = ([Line2D([], [], color="0.3", lw=1.0, label="harmonic balance"
                      + (", stable" if unstable else ""))] if swept else [])
    if line is not None and not swept:
        styles.append(Line2D([], [], ls="", marker=POINT_MARKER, color="0.3",
                             label="harmonic balance"))
    if unstable:
        styles.append(Line2D([], [], ls="--", color="0.3", lw=1.0,
                             label="harmonic balance, unstable"))
    styles.append(Line2D([], [], ls="", marker="o", mfc="none", color="0.3", label="converged"))
    if np.any(~settled):
        styles.append(Line2D([], [], ls="", marker="x", color="0.3", label="not converged"))
    _finish(fig, axes, ds, path,
            title or f"{ylabel} (open circles converged, crosses not)", styles)


POINT_MARKER = "+"
"""The marker of harmonic-balance points that are not a sweep (no line is drawn between
solutions that are not neighbours on a branch)."""


def _line_of(ax, line, y, color, label, scale: float) -> None:
    """The harmonic-balance response of :func:`plot_points` against frequency in units of
    ``scale`` Hz: a sweep (a ``branch`` variable) as lines in the order swept, per branch
    and by stability as :func:`plot_sweep`; other points as markers
    (:data:`POINT_MARKER`), not joined: the response between them is not known."""
    f = np.asarray(line["mesh_frequency_hz"]) / scale
    if "branch" in line:
        stable = np.asarray(line["stable"]) if "stable" in line else np.full(f.shape, -1)
        _branch_lines(ax, f, y, stable, np.asarray(line["branch"]), color, label)
    else:
        ax.plot(f, y, POINT_MARKER, ms=8, color=color, label=label)


# ------------------------------------------------------------------ saved results


def plot_results(results, out=None, what: str = "rms") -> tuple[str, pathlib.Path]:
    """Redraw a results file (NetCDF, :func:`gearjax._io.results.save_results`) without
    recomputing.

    The figure depends on the kind of result, the file's ``kind`` attribute (files
    without one: ``simulate`` when they hold integration statistics, else ``sweep``):
    :data:`RESULT_PLOTS` maps each kind to its drawing function (new kinds register
    there). ``what``: ``rms``, ``dlf``, ``separation`` or ``torque`` (:func:`plot_sweep`),
    or ``bearings`` (:func:`~gearjax._plot.bearing_figure.bearing_figure`, translational);
    ``out``: the figure (default: ``results`` with the suffix ``.png``).

    **Returns:** ``(kind, figure path)``. **Raises:** ``TrainError`` (one line naming the
    file) for a missing, unreadable or non-gearjax file, or a kind with no figure.
    """
    path = pathlib.Path(results)
    if what not in WHAT and what != "bearings":
        raise bad_argument("what", what, f"must be one of {', '.join(WHAT)}, bearings")
    ds = _open_results(path)
    kind = result_kind(ds)
    if kind not in RESULT_PLOTS:
        raise TrainError(f"{path}: kind = {kind!r}: gearjax plot cannot draw this kind of "
                         f"result; it draws {', '.join(RESULT_PLOTS)}")
    fig = pathlib.Path(out) if out else path.with_suffix(".png")
    if fig.resolve() == path.resolve():
        raise bad_argument("out", str(fig), "would overwrite the results file")
    if what == "bearings":  # any kind with bearing forces (sweep, simulate)
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        figure = bearing_figure(ds, title=f"{path.name}: bearing forces")
        figure.savefig(fig, dpi=120)
        plt.close(figure)
    else:
        RESULT_PLOTS[kind](path, ds, fig, what)
    return kind, fig


def result_kind(ds) -> str | None:
    """The kind of a results Dataset: its ``kind`` attribute, or for files written
    before it existed ``simulate`` (integration statistics present) or ``sweep``."""
    kind = ds.attrs.get("kind")
    if kind is None and "mesh_frequency_hz" in ds:
        kind = "simulate" if "num_steps" in ds else "sweep"
    return None if kind is None else str(kind)


def _open_results(path: pathlib.Path):
    if not path.is_file():
        raise TrainError(f"{path}: no such results file")
    if path.suffix.lower() != ".nc":
        raise TrainError(f"{path}: only NetCDF results (.nc) can be redrawn; write them as "
                         "NetCDF (FILE.nc)")
    ds = read_netcdf(path)
    if "gearjax_version" not in ds.attrs:
        raise TrainError(f"{path}: not a gearjax results file (no gearjax_version attribute)")
    return ds


def _title(ds, what: str, kind: str) -> str:
    try:
        name = tomllib.loads(ds.attrs.get("train_toml", "")).get("name", "")
    except tomllib.TOMLDecodeError:
        name = ""
    try:
        linear = json.loads(ds.attrs.get("solver", "{}")).get("linear")
    except ValueError:
        linear = None
    model = {True: ", linear", False: ", backlash"}.get(linear, "")
    head = f"{name}\n" if name else ""
    return f"{head}gear {ds.attrs.get('gear', '?')}{model}, {kind}: {WHAT[what][1]}"


def _redraw_sweep(path, ds, fig, what):
    plot_sweep(ds, fig, what=what,
               title=_title(ds, what, "sweep") + " (solid stable, dashed unstable)")


def _redraw_simulate(path, ds, fig, what):
    plot_points(ds, fig, what=what, title=_title(ds, what, "time integration")
                + " (circles converged, crosses not)")


def _redraw_verify(path, ds, fig, what):
    _, hb, ni = load_verify(path)
    plot_verify(hb, ni, fig, what=what, title=_title(hb, what, "verification")
                + "\n+: harmonic balance, circles: time integration")


def plot_optimize(ds, path: str, title: str = ""):
    """A phasing optimisation (``optimize_dataset``): per stage, the largest RMS force of
    its meshes against reference-stage mesh frequency for the baseline, the optimum and
    the continuous relaxation (lines, linear time-varying harmonic balance on the common
    grid) and, where they were swept, the stable points with backlash (markers)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = list(dict.fromkeys(np.asarray(ds["stage"]).tolist()))
    fig, axes = plt.subplots(len(stages), 1, figsize=(9, 0.8 + 3.0 * len(stages)),
                             squeeze=False, sharex=True, layout="constrained")
    f = np.asarray(ds["frequency"]) / 1e3
    order = np.argsort(f)
    styles = {"baseline": ("k", "-"), "optimum": ("C3", "-"), "relaxed": ("C0", ":")}
    for ax, stage in zip(axes[:, 0], stages):
        cols = np.asarray(ds["stage"]) == stage
        for d, design in enumerate(np.asarray(ds["design"]).tolist()):
            color, ls = styles.get(design, ("C2", "--"))
            peak = np.nanmax(np.asarray(ds["linear_rms"])[d][:, cols], axis=1)
            ax.plot(f[order], peak[order], ls, color=color, lw=1.0,
                    label=f"{design} (linear)" if design != "relaxed"
                    else "relaxed (linear, cannot be assembled)")
        for design in ("baseline", "optimum"):
            if f"{design}_nonlinear_rms" in ds:
                color = styles[design][0]
                y = np.nanmax(np.asarray(ds[f"{design}_nonlinear_rms"])[:, cols], axis=1)
                ax.plot(np.asarray(ds[f"{design}_nonlinear_frequency_hz"]) / 1e3, y, ".",
                        ms=2.5, color=color, alpha=0.6, label=f"{design} (backlash, stable)")
        ax.set_yscale("log")
        ax.set_ylabel("largest RMS mesh force (N)", fontsize=8)
        ax.set_title(f"stage {stage} meshes", fontsize=9)
        ax.grid(alpha=0.3, which="both")
    fig.legend(handles=axes[0, 0].get_legend_handles_labels()[0], loc="outside lower center",
               ncol=3, fontsize=7, frameon=False)
    axes[-1, 0].set_xlabel(f"stage {ds.attrs.get('reference_stage', '')} mesh frequency (kHz)")
    fig.suptitle(title or "phasing optimisation: baseline and optimum", fontsize=10)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _redraw_optimize(path, ds, fig, what):
    peaks = (f"peak {ds.attrs.get('baseline_peak_linear', math.nan):.0f} N -> "
             f"{ds.attrs.get('optimum_peak_linear', math.nan):.0f} N (linear)")
    plot_optimize(ds, fig, title=_title(ds, "rms", "optimisation") + f"\n{peaks}")


RESULT_PLOTS: dict[str, Callable] = {
    "sweep": _redraw_sweep,
    "simulate": _redraw_simulate,
    "verify": _redraw_verify,
    "optimize": _redraw_optimize,
}
"""Drawing function per result kind: ``f(results_path, dataset, figure_path, what)``."""

