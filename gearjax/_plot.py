"""Figures: mode shapes (more plots join as solvers land). Matplotlib, no screen needed."""

from __future__ import annotations

import math

import numpy as np

from ._modal import ModalResult


def plot_mode_shapes(result: ModalResult, path: str, title: str = "", classes=("elastic",)):
    """Bar chart of each distinct mode's shape (one panel per frequency), saved to ``path``.

    Repeated modes get one panel (the solver's first basis vector) marked ``xN``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    chosen, k = [], 0
    modes = [m for m in result.modes if m.cls in classes]
    while k < len(modes):
        chosen.append(modes[k])
        k += modes[k].multiplicity
    cols = min(4, max(1, len(chosen)))
    rows = math.ceil(len(chosen) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.8 * rows), squeeze=False,
                             sharey=True)
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
    for ax in list(axes.flat)[len(chosen):]:
        ax.set_visible(False)
    fig.suptitle(title or "mode shapes (largest coordinate = 1)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_sweep(ds, path: str, what: str = "rms", title: str = ""):
    """Response of every stage's meshes against reference-stage mesh frequency.

    ``what``: ``rms`` (RMS alternating force, N), ``dlf``, ``separation`` (share of the
    period) or ``torque`` (mean transmitted torque, N m). One panel per stage and mesh
    side, the planets' curves overlaid; stable solid, unstable dashed, unknown dotted.
    """
    var, label = {"rms": ("rms_force", "RMS mesh force (N)"), "dlf": ("dlf", "dynamic load factor"),
                  "separation": ("separation", "share of period in separation"),
                  "torque": ("mean_torque", "mean transmitted torque (N m)")}[what]
    f = np.asarray(ds["mesh_frequency_hz"]) / 1e3
    stable = np.asarray(ds["stable"]) if "stable" in ds else np.full(f.shape, -1)
    fig, axes, panels = _mesh_panels(ds, label)
    for ax, first, meshes in panels:
        for j in meshes:
            y = np.asarray(ds[var])[:, j]
            for flag, style in ((1, "-"), (0, "--"), (-1, ":")):
                yy = np.where(stable == flag, y, np.nan)
                ax.plot(f, yy, style, lw=1.0, color=f"C{j % 10}",
                        label=(f"planet {int(ds['planet'][j])}" if flag == 1 and first else None))
    _finish(fig, axes, ds, path, title or "frequency response (solid stable, dashed unstable)")


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
    fig, axes = plt.subplots(len(stages), 2, figsize=(10, 3.2 * len(stages)), squeeze=False,
                             sharex=True)
    panels = []
    for r, stage in enumerate(stages):
        for c, side in enumerate(("sun", "ring")):
            ax = axes[r, c]
            sel = (np.asarray(ds["stage"]) == stage) & (np.asarray(ds["side"]) == side)
            ax.set_title(f"stage {stage}, {side}-planet meshes", fontsize=9)
            ax.set_ylabel(ylabel, fontsize=8)
            ax.grid(alpha=0.3)
            panels.append((ax, r == 0 and c == 0, np.where(sel)[0]))
    return fig, axes, panels


def _finish(fig, axes, ds, path, title: str) -> None:
    """Frequency labels, legend and title; save to ``path`` and close."""
    import matplotlib.pyplot as plt

    for ax in axes[-1]:
        ax.set_xlabel(f"stage {ds.attrs.get('reference_stage', '')} mesh frequency (kHz)")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_verify(hb, ni, path: str, curve=None, title: str = ""):
    """Integration points (markers) over the harmonic-balance RMS mesh forces, as the
    paper's Figs 4 and 5.

    ``hb``, ``ni``: results Datasets at the same points (``VerifyResult.hb``, ``.ni``);
    ``curve``: an optional sweep Dataset drawn as the harmonic-balance line (otherwise
    the line joins the ``hb`` points in frequency order). See :func:`plot_points`.
    """
    plot_points(ni, path, line=curve if curve is not None else hb,
                title=title or "harmonic balance (lines) and time integration (markers)")


def plot_points(ds, path: str, line=None, title: str = ""):
    """RMS mesh forces of solution points as markers against reference-stage mesh
    frequency, optionally over the lines of another results Dataset ``line``.

    One panel per stage and mesh side, one colour per planet; open circles are
    converged points, crosses points that did not converge (e.g. an integration that
    did not settle to the base period). Meshes are matched by name.
    """
    f_pts = np.asarray(ds["mesh_frequency_hz"]) / 1e3
    settled = np.asarray(ds["converged"])
    names = np.asarray(ds["mesh"]).tolist()
    fig, axes, panels = _mesh_panels(ds, "RMS mesh force (N)")
    for ax, first, meshes in panels:
        for j in meshes:
            color = f"C{(int(ds['planet'][j]) - 1) % 10}"  # one colour per planet
            label = f"planet {int(ds['planet'][j])}" if first else None
            if line is not None:
                f_line = np.asarray(line["mesh_frequency_hz"]) / 1e3
                order = np.argsort(f_line)
                k = np.asarray(line["mesh"]).tolist().index(names[j])
                ax.plot(f_line[order], np.asarray(line["rms_force"])[order, k], "-", lw=1.0,
                        color=color, label=label)
                label = None
            y = np.asarray(ds["rms_force"])[:, j]
            ax.plot(f_pts[settled], y[settled], "o", mfc="none", ms=6, color=color, label=label)
            ax.plot(f_pts[~settled], y[~settled], "x", ms=6, color=color)
    _finish(fig, axes, ds, path, title or "RMS mesh forces (open circles converged, crosses not)")
