"""Figures returned as ``matplotlib.figure.Figure`` objects (not saved, no pyplot state),
for notebooks and interactive use: the Campbell diagram, the paper's frequency-response
figures (RMS force or mean torque per stage, a sweep over a reference sweep, time
integration points on top) and the tooth-separation map.

The saving, command-line figures are in ``_plot``; these draw the same Datasets
(``_results`` layout) and :class:`~gearjax._gear.campbell.Campbell` data.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from .._gear.campbell import Campbell
from .._gear.mesh_stiffness import mesh_cycle, rectangular_cycle
from .save import clip_to_stable

WHAT = {"rms": ("rms_force", "RMS mesh force (N)"), "dlf": ("dlf", "dynamic load factor"),
        "separation": ("separation", "share of period in separation"),
        "torque": ("mean_torque", "mean transmitted torque (N m)"),
        "max": ("max_force", "peak mesh force (N)")}
"""``what`` of :func:`response_figure`: the Dataset variable and its axis label."""

SIDE_COLORS = {"sun": "tab:blue", "ring": "tab:orange"}


def _figure(width: float, height: float, rows: int = 1, cols: int = 1, **kw):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, **kw)
    return fig, axes


# ------------------------------------------------------------------ Campbell


def campbell_figure(diagrams: Campbell | Sequence[Campbell], max_hz: float | None = None,
                    cols: int = 2):
    """Campbell diagram(s): one panel per :class:`~gearjax._gear.campbell.Campbell`.

    Rays ``h x`` per turning stage (colour per stage; dotted for an unloaded stage),
    elastic natural frequencies as horizontal lines (grey; planet modes dashed, with
    their multiplicity), crossings as circles: filled where the stiffness excitation
    drives the mode at first order, open where the planet phasing cancels it (or the
    stage is unloaded). ``max_hz``: top of the frequency axis (default: a little above
    the highest ray or mode shown). **Returns:** the Figure.
    """
    diagrams = [diagrams] if isinstance(diagrams, Campbell) else list(diagrams)
    cols = max(1, min(cols, len(diagrams)))
    rows = -(-len(diagrams) // cols)
    fig, axes = _figure(5.0 * cols, 3.5 * rows, rows, cols)
    for ax, d in zip(axes.flat, diagrams):
        top = max_hz or 1.05 * max([float(d.mode_hz.max()) if d.mode_hz.size else 0.0]
                                   + [float(d.excitation_hz.max()) if d.excitation_hz.size
                                      else 0.0] + [1.0])
        label_y = -np.inf  # mode labels in the right margin, kept apart
        for k, hz in enumerate(d.mode_hz):
            if hz > top:
                continue
            planet = d.mode_family[k] == "planet"
            ax.axhline(hz / 1e3, color="0.55", lw=0.8, ls="--" if planet else "-", zorder=1)
            tag = f"planet {d.mode_stage[k]} x{d.mode_multiplicity[k]}" if planet else ""
            label_y = max(hz / 1e3, label_y + 0.045 * top / 1e3)
            ax.annotate(f"{hz / 1e3:.2f} kHz {tag}".strip(), (1.0, label_y),
                        xycoords=("axes fraction", "data"), xytext=(3, 0),
                        textcoords="offset points", va="center", fontsize=7, color="0.35",
                        annotation_clip=False)
        for i, sid in enumerate(d.stages):
            color = f"C{i}"
            style = "-" if d.loaded[i] else ":"
            for j, h in enumerate(d.harmonics):
                y = d.excitation_hz[i, j] / 1e3
                ax.plot(d.rpm, y, style, color=color, lw=1.6 - 0.25 * min(j, 4),
                        label=f"stage {sid}" + ("" if d.loaded[i] else " (unloaded)")
                        if j == 0 else None, zorder=2)
                # label the ray just inside the point where it leaves the plot
                x_end = min(d.rpm[-1], 0.97 * top / (h * d.mesh_hz_per_rpm[i]))
                ax.annotate(f"{h}x", (x_end, h * d.mesh_hz_per_rpm[i] * x_end / 1e3),
                            fontsize=7, color=color, xytext=(2, -8),
                            textcoords="offset points")
        for c in d.crossings:
            if c.hz > top:
                continue
            color = f"C{d.stages.index(c.stage)}"
            ax.plot([c.rpm], [c.hz / 1e3], "o", ms=5, color=color,
                    mfc=color if c.excited else "white", zorder=3)
        if not d.stages:
            ax.text(0.5, 0.25, "no mesh turns in this gear", transform=ax.transAxes,
                    ha="center", fontsize=9, color="0.3",
                    bbox={"facecolor": "white", "edgecolor": "none"})
        ax.set_xlim(d.rpm[0], d.rpm[-1])
        ax.set_ylim(0.0, top / 1e3)
        ax.set_xlabel(f"input speed ({d.input}), rpm")
        ax.set_ylabel("frequency (kHz)")
        ax.set_title(f"gear {d.gear}: filled crossings = modes the mesh stiffness drives",
                     fontsize=9)
        ax.grid(alpha=0.25)
        if d.stages:
            ax.legend(fontsize=7, loc="lower right")
    for ax in list(axes.flat)[len(diagrams):]:
        ax.set_visible(False)
    return fig


# ------------------------------------------------------------------ responses


def response_figure(sweep=None, reference=None, points=None, what: str = "rms",
                    xlim: tuple[float, float] | None = None, title: str = "",
                    labels: tuple[str, str, str] = ("harmonic balance", "reference",
                                                    "time integration")):
    """The paper's Figs 4-6: a response of every mesh against reference-stage mesh
    frequency (kHz), one panel per stage, sun meshes blue and ring meshes orange (every
    planet drawn; by cyclic symmetry they usually coincide).

    **Arguments:** ``sweep``: results Dataset drawn solid where stable, dashed where
    unstable, dotted where unknown; ``reference``: another sweep (e.g. the linear one)
    drawn as a thin dotted line; ``points``: a Dataset of single points (time
    integration) drawn as open circles (converged) or crosses (not); ``what``: a key of
    :data:`WHAT`; ``xlim``: kHz (default: the range of ``sweep``, else of all data);
    ``labels``: legend names of the three. **Returns:** the Figure.
    """
    var, ylabel = WHAT[what]
    first = next(ds for ds in (sweep, reference, points) if ds is not None)
    stages = list(dict.fromkeys(np.asarray(first["stage"]).tolist()))
    fig, axes = _figure(10.0, 3.0 * len(stages), len(stages), 1, sharex=True)
    shown = [[] for _ in stages]  # per panel: (f kHz, value, not unstable) of every point
    for r, stage in enumerate(stages):
        ax = axes[r, 0]
        for role, ds in (("reference", reference), ("sweep", sweep), ("points", points)):
            if ds is None:
                continue
            f = np.asarray(ds["mesh_frequency_hz"]) / 1e3
            sel = np.where(np.asarray(ds["stage"]) == stage)[0]
            for j in sel:
                side = str(ds["side"].values[j])
                color = SIDE_COLORS.get(side, "k")
                first_of_side = j == next(k for k in sel if str(ds["side"].values[k]) == side)
                y = np.asarray(ds[var])[:, j]
                not_unstable = (np.asarray(ds["stable"]) != 0 if role == "sweep"
                                and "stable" in ds else np.ones(f.shape, bool))
                shown[r].append((f, y, not_unstable))
                tag = f"{side}, " if first_of_side else None
                if role == "reference":
                    order = np.argsort(f)
                    ax.plot(f[order], y[order], ":", lw=0.9, color=color,
                            label=tag and tag + labels[1])
                elif role == "sweep":
                    stable = np.asarray(ds["stable"]) if "stable" in ds else np.full(f.shape, -1)
                    # one line per branch: a break (NaN) where the branch number changes
                    number = np.asarray(ds["branch"]) if "branch" in ds else np.zeros(f.size, int)
                    cut = np.flatnonzero(np.diff(number) != 0) + 1
                    fb, yb, sb = (np.insert(np.asarray(v, float), cut, np.nan)
                                  for v in (f, y, stable))
                    for flag, style in ((1, "-"), (0, "--"), (-1, ":")):
                        if not np.any(stable == flag):
                            continue
                        # keep a segment's neighbours so solid and dashed parts join
                        keep = (sb == flag) | np.r_[sb[1:] == flag, False] | \
                            np.r_[False, sb[:-1] == flag]
                        yy = np.where(keep, yb, np.nan)
                        ax.plot(fb, yy, style, lw=1.2, color=color,
                                label=tag and tag + labels[0] + {1: "", 0: " (unstable)",
                                                                 -1: " (stability unknown)"}[flag])
                else:
                    ok = np.asarray(ds["converged"])
                    ax.plot(f[ok], y[ok], "o", mfc="none", ms=6, mew=1.2, color=color,
                            label=tag and tag + labels[2])
                    if np.any(~ok):
                        ax.plot(f[~ok], y[~ok], "x", ms=6, color=color,
                                label=tag and tag + labels[2] + " (not settled)")
        ax.set_title(f"stage {stage} meshes", fontsize=9)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    ref_stage = first.attrs.get("reference_stage", "")
    axes[-1, 0].set_xlabel(f"stage {ref_stage} mesh frequency (kHz)")
    if xlim is None:
        src = [sweep] if sweep is not None else [d for d in (reference, points) if d is not None]
        f_all = np.concatenate([np.asarray(d["mesh_frequency_hz"]) for d in src]) / 1e3
        xlim = (float(f_all.min()), float(f_all.max()))
        if xlim[0] == xlim[1]:
            xlim = (xlim[0] - 0.1, xlim[1] + 0.1)
    axes[0, 0].set_xlim(*xlim)
    for ax, data in zip(axes[:, 0], shown):
        _fit_y(ax, xlim)
        if data:  # unstable branches far above the rest (parametric instability): off scale
            f = np.concatenate([d[0] for d in data])
            y = np.concatenate([d[1] for d in data])
            ok = np.concatenate([d[2] for d in data])
            inside = (f >= xlim[0]) & (f <= xlim[1])
            clip_to_stable(ax, y[inside], y[inside & ok], corner="left")  # legend: right
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def _fit_y(ax, xlim) -> None:
    """Y limits from the data drawn inside ``xlim`` (a reference sweep may span more)."""
    ys = []
    for line in ax.get_lines():
        x, y = (np.asarray(v, dtype=float) for v in line.get_data())
        inside = (x >= xlim[0]) & (x <= xlim[1]) & np.isfinite(y)
        ys.append(y[inside])
    y = np.concatenate(ys) if ys else np.empty(0)
    if y.size:
        lo, hi = min(0.0, float(y.min())), max(0.0, float(y.max()))
        pad = 0.06 * (hi - lo) or 1.0
        ax.set_ylim(lo - (pad if lo < 0 else 0.0), hi + pad)


# ------------------------------------------------------------------ separation


@dataclasses.dataclass(frozen=True)
class SeparationBranch:
    """A run of consecutive sweep points whose frequency moves one way.

    **Fields:** ``points``: their indices in the Dataset; ``frequency_hz`` ``(P,)``
    (reference stage, ascending or descending as swept); ``separation`` ``(P, m)``:
    share of the period with the teeth apart, per mesh; ``stable`` ``(P,)`` int8 (1, 0,
    -1 unknown); ``meshes``: mesh names.
    """

    points: np.ndarray
    frequency_hz: np.ndarray
    separation: np.ndarray
    stable: np.ndarray
    meshes: tuple[str, ...]


def separation_branches(ds) -> list[SeparationBranch]:
    """Split a sweep Dataset into branches between folds (where the frequency turns)
    and branch restarts (where the ``branch`` number changes, a jump), so each can be
    drawn against frequency; a sweep without either is one branch.

    Points where the frequency turns belong to both neighbouring branches; a restart
    shares no point.
    """
    f = np.asarray(ds["mesh_frequency_hz"], dtype=float)
    sep = np.asarray(ds["separation"], dtype=float)
    stable = np.asarray(ds["stable"]) if "stable" in ds else np.full(f.shape, -1, np.int8)
    number = np.asarray(ds["branch"]) if "branch" in ds else np.zeros(f.shape, int)
    meshes = tuple(str(m) for m in np.asarray(ds["mesh"]).tolist())
    out = []
    starts = [0] + [i for i in range(1, f.size) if number[i] != number[i - 1]] + [f.size]
    for first, stop in zip(starts[:-1], starts[1:]):
        d = np.sign(np.diff(f[first:stop]))
        cuts = [first]
        for i in range(1, d.size):
            if d[i] != 0 and d[i - 1] != 0 and d[i] != d[i - 1]:
                cuts.append(first + i)
        cuts.append(stop - 1)
        for a, b in zip(cuts[:-1], cuts[1:]):
            idx = np.arange(a, b + 1)
            out.append(SeparationBranch(points=idx, frequency_hz=f[idx],
                                        separation=sep[idx], stable=stable[idx],
                                        meshes=meshes))
    return out


@dataclasses.dataclass(frozen=True)
class _SeparationMap:
    """The separation map on a frequency grid: ``edges_hz`` ``(G + 1,)``; ``values``
    ``(G, L, m)`` the separation of up to ``L`` states per grid cell, smallest response
    first (NaN past the ``count`` ``(G,)`` states there); ``unstable`` ``(G,)``: no
    state there is stable or of unknown stability (the one shown is unstable)."""

    edges_hz: np.ndarray
    values: np.ndarray
    count: np.ndarray
    unstable: np.ndarray


def _separation_map(ds, branches: list[SeparationBranch]) -> _SeparationMap:
    """The states :func:`separation_figure` shows in each cell of a grid over the
    swept frequencies: every branch covering the cell's centre gives one state (its
    separation interpolated linearly in frequency between the two points around it,
    unstable where either is); the states not unstable are kept, or where all are
    unstable the one with the smallest response; kept states are ordered by response (largest RMS force over
    the meshes; the mean separation where the Dataset has no ``rms_force``)."""
    f_all = np.asarray(ds["mesh_frequency_hz"], dtype=float)
    size = int(np.clip(2 * f_all.size, 200, 2000))
    lo, hi = float(np.min(f_all)), float(np.max(f_all))
    if hi == lo:
        lo, hi = lo - 0.5, hi + 0.5
    edges = np.linspace(lo, hi, size + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    response = (np.max(np.asarray(ds["rms_force"], dtype=float), axis=1) if "rms_force" in ds
                else np.mean(np.asarray(ds["separation"], dtype=float), axis=1))
    states = [[] for _ in range(size)]  # per cell: (response, separation (m,), stable flag)
    for br in branches:
        order = np.argsort(br.frequency_hz, kind="stable")
        f = br.frequency_hz[order]
        if f.size == 1:
            cells = np.array([min(int(np.searchsorted(edges, f[0], "right")) - 1, size - 1)])
        else:
            cells = np.where((centres >= f[0]) & (centres <= f[-1]))[0]
        if cells.size == 0:
            continue
        x = centres[cells]
        sep = np.stack([np.interp(x, f, br.separation[order, j])
                        for j in range(br.separation.shape[1])], axis=1)
        resp = np.interp(x, f, response[br.points[order]])
        right = np.clip(np.searchsorted(f, x), 0, f.size - 1)
        a, b = br.stable[order][np.clip(right - 1, 0, f.size - 1)], br.stable[order][right]
        flags = np.where((a == 0) | (b == 0), 0, np.where((a == -1) | (b == -1), -1, 1))
        for k, g in enumerate(cells):
            states[g].append((float(resp[k]), sep[k], int(flags[k])))
    m = len(branches[0].meshes) if branches else 0
    unstable = np.zeros(size, bool)
    kept = []
    for g, here in enumerate(states):
        shown = [s for s in here if s[2] != 0]
        if here and not shown:
            shown, unstable[g] = [min(here, key=lambda s: s[0])], True
        kept.append(sorted(shown, key=lambda s: s[0]))
    count = np.array([len(k) for k in kept])
    values = np.full((size, max(1, int(count.max(initial=0))), m), np.nan)
    for g, shown in enumerate(kept):
        for k, s in enumerate(shown):
            values[g, k] = s[1]
    return _SeparationMap(edges_hz=edges, values=values, count=count, unstable=unstable)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(first, stop)`` of each run of True in ``mask``."""
    d = np.diff(np.r_[0, mask.astype(int), 0])
    return list(zip(np.where(d == 1)[0], np.where(d == -1)[0]))


def separation_figure(ds, title: str = ""):
    """Tooth-separation map of a sweep in one panel: each mesh (rows, by name) against
    reference-stage mesh frequency (kHz), coloured by the share of the period its
    teeth spend apart (colour bar, 0 to 1 of the period).

    **Branches** (:func:`separation_branches`) share the panel. At each frequency it
    shows the states a rig can be found in: those not unstable (stable, or of unknown
    stability). Where several coexist (between the folds of a jump, or where branches
    from restarts overlap) every mesh row is split into sub-rows, one per state, the
    state with the smaller response (largest RMS mesh force) on top; elsewhere the
    state fills the row. Where every state found is unstable, the one with the
    smallest response is drawn hatched. Folds (the frequency turning along a branch)
    are marked above the panel; frequencies no branch reached are grey. Everything
    else is in the legend below the panel. **Returns:** the Figure."""
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    branches = separation_branches(ds)
    smap = _separation_map(ds, branches)
    meshes = branches[0].meshes if branches else ()
    m, lanes = len(meshes), smap.values.shape[1]
    vmax = max(0.05, float(np.nanmax(np.asarray(ds["separation"], dtype=float))))
    norm = Normalize(0.0, vmax)
    fig, axes = _figure(10.0, 2.2 + 0.24 * m)
    ax = axes[0, 0]
    # image rows: mesh i, sub-row l; a cell with c states gives state k the sub-rows
    # from k L / c to (k + 1) L / c
    image = np.full((m * lanes, smap.count.size), np.nan)
    for c in np.unique(smap.count[smap.count > 0]):
        cells = np.where(smap.count == c)[0]
        for k in range(c):
            for sub in range(k * lanes // c, (k + 1) * lanes // c):
                image[sub::lanes, cells] = smap.values[cells, k].T
    f_edges = smap.edges_hz / 1e3
    ax.set_facecolor("0.85")
    img = ax.pcolormesh(f_edges, np.arange(m * lanes + 1) / lanes - 0.5,
                        np.ma.masked_invalid(image), norm=norm, cmap="magma_r",
                        shading="flat")
    for a, b in _runs(smap.unstable):
        ax.axvspan(f_edges[a], f_edges[b], facecolor="none", edgecolor="0.25",
                   hatch="///", lw=0)
    split = _runs(smap.count > 1)
    for a, b in split:
        for i in range(m):
            for sub in range(1, lanes):
                ax.plot([f_edges[a], f_edges[b]], [i - 0.5 + sub / lanes] * 2, color="white",
                        lw=0.6)
    stages = [name.split(".")[0] for name in meshes]
    for i in range(1, m):
        boundary = stages[i] != stages[i - 1]
        ax.axhline(i - 0.5, color="k" if boundary else "white", lw=1.0 if boundary else 0.4)
    folds = [br.frequency_hz[-1] for br, nxt in zip(branches[:-1], branches[1:])
             if br.points[-1] == nxt.points[0]]
    if folds:
        ax.plot(np.asarray(folds) / 1e3, np.full(len(folds), 1.0), "v", color="C0", ms=6,
                transform=ax.get_xaxis_transform(), clip_on=False)
    ax.set_yticks(range(m))
    ax.set_yticklabels(meshes, fontsize=7)
    ax.set_ylim(m - 0.5, -0.5)
    ax.set_xlim(f_edges[0], f_edges[-1])
    ax.set_ylabel("mesh")
    ax.set_xlabel(f"stage {ds.attrs.get('reference_stage', '')} mesh frequency (kHz)")
    fig.colorbar(img, ax=ax, label="time in separation (share of period)", shrink=0.95)
    handles = []
    if folds:
        handles.append(Line2D([], [], ls="", marker="v", color="C0", ms=6,
                              label="fold: the branch turns back in frequency"))
    if split:
        handles.append(Patch(facecolor="0.6", edgecolor="white",
                             label=f"row split: {lanes} states coexist, the top one with "
                                   "the smaller response"))
    if np.any(smap.unstable):
        handles.append(Patch(facecolor="none", edgecolor="0.25", hatch="///",
                             label="no stable state found: the smallest unstable one"))
    if np.any(smap.count == 0):
        handles.append(Patch(facecolor="0.85", label="no state found (between branches)"))
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=7,
                   frameon=False)
    fig.suptitle(title or "tooth separation per mesh", fontsize=10)
    return fig


def _edges(x: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres ``x`` (half-way between neighbours)."""
    if x.size == 1:
        return np.array([x[0] - 0.01, x[0] + 0.01])
    mid = 0.5 * (x[1:] + x[:-1])
    return np.concatenate([[x[0] - (mid[0] - x[0])], mid, [x[-1] + (x[-1] - mid[-1])]])


# ------------------------------------------------------------------ designs


def design_figure(result, path: str | int = 0, title: str = ""):
    """A batched design sweep (:class:`~gearjax.DesignSweep`): the peak RMS mesh force
    over the band against the value of one varied ``path`` (name or index; the other
    values as they are), and the largest RMS over the meshes against reference-stage mesh
    frequency for the best and the worst design. **Returns:** the Figure."""
    k = result.paths.index(path) if isinstance(path, str) else int(path)
    x = np.asarray(result.thetas)[:, k]
    peak = np.asarray(result.peak, dtype=float)
    fig, axes = _figure(10.0, 3.4, 1, 2)
    ax = axes[0, 0]
    order = np.argsort(x)
    ax.plot(x[order], peak[order], "o-", ms=3, lw=1.0, color="k")
    best, worst = int(np.nanargmin(peak)), int(np.nanargmax(peak))
    for i, color, name in ((best, "C3", "best"), (worst, "C0", "worst")):
        ax.plot([x[i]], [peak[i]], "o", ms=7, color=color, label=f"{name}: {peak[i]:.0f} N")
    ax.set_xlabel(result.paths[k])
    ax.set_ylabel("peak RMS mesh force over the band (N)", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[0, 1]
    f = np.asarray(result.frequencies_hz) / 1e3
    for i, color, name in ((worst, "C0", "worst"), (best, "C3", "best")):
        per_f = np.nanmax(np.asarray(result.rms_force)[i], axis=-1)
        ax.plot(f, per_f, ".-", ms=3, lw=1.0, color=color,
                label=f"{name}, {result.paths[k]} = {x[i]:.4g}")
    ax.set_yscale("log")
    ax.set_xlabel(f"stage {result.reference_stage} mesh frequency (kHz)")
    ax.set_ylabel("largest RMS mesh force (N)", fontsize=8)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    model = "linear time-varying" if result.linear else "with backlash"
    fig.suptitle(title or f"{len(x)} designs in one batched call ({model}, K = "
                 f"{result.harmonics}, {f.size} frequencies)", fontsize=10)
    return fig


def recheck_figure(recheck, title: str = ""):
    """The re-check of an optimisation (:class:`gearjax._studies.optimize.Recheck`): per stage,
    the largest RMS force of its meshes along the fresh sweeps with backlash of the
    baseline (black) and the optimum (red), stable solid (and dots: a stable point
    between unstable ones shows too) and unstable dotted (off-scale
    unstable branches clipped at 1.5 times the largest stable value); stars: time
    integration from each sweep's peak orbit; circles: the integrations of the
    verification points. **Returns:** the Figure."""
    colors = {"baseline": "k", "optimum": "C3"}
    first = next(iter(recheck.sweeps.values())).dataset
    stages = list(dict.fromkeys(np.asarray(first["stage"]).tolist()))
    fig, axes = _figure(10.0, 3.0 * len(stages), len(stages), 1, sharex=True)
    for ax, stage in zip(axes[:, 0], stages):
        top = 0.0
        for name, sw in recheck.sweeps.items():
            ds, color = sw.dataset, colors.get(name, "C2")
            cols = np.asarray(ds["stage"]) == stage
            f = np.asarray(ds["mesh_frequency_hz"]) / 1e3
            y = np.nanmax(np.asarray(ds["rms_force"])[:, cols], axis=1)
            stable = np.asarray(ds["stable"]) == 1
            branch = np.asarray(ds["branch"]) if "branch" in ds else np.zeros(f.size, int)
            for b in np.unique(branch):
                sel = branch == b
                ys, st = y[sel], stable[sel]
                on = st | np.r_[st[1:], False]  # each stable run reaches the next point
                ax.plot(f[sel], np.where(on, ys, np.nan), "-", lw=1.1, color=color,
                        label=f"{name}, sweep with backlash" if b == branch[0] else None)
                ax.plot(f[sel][st], ys[st], ".", ms=2.5, color=color)  # lone stable points
                ax.plot(f[sel], np.where(~st, ys, np.nan), ":", lw=0.8, color=color,
                        alpha=0.7, label=f"{name}, unstable" if b == branch[0]
                        and not np.all(stable) else None)
            if np.any(stable):
                top = max(top, float(np.nanmax(y[stable])))
            if name in recheck.orbits:
                ni = recheck.orbits[name]
                yi = np.nanmax(np.asarray(ni["rms_force"])[:, cols], axis=1)
                ax.plot(np.asarray(ni["mesh_frequency_hz"]) / 1e3, yi, "*", ms=11,
                        mfc="none", mew=1.3, color=color,
                        label=f"{name}, integrated from the peak orbit")
            if name in recheck.verify:
                ni = recheck.verify[name].ni
                yi = np.nanmax(np.asarray(ni["rms_force"])[:, cols], axis=1)
                ax.plot(np.asarray(ni["mesh_frequency_hz"]) / 1e3, yi, "o", ms=7,
                        mfc="none", mew=1.2, color=color,
                        label=f"{name}, verify_gear integration")
        if top > 0:
            ax.set_ylim(0.0, 1.5 * top)
        ax.set_title(f"stage {stage} meshes: largest RMS force", fontsize=9)
        ax.set_ylabel("RMS mesh force (N)", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel(f"stage {first.attrs.get('reference_stage', '')} mesh frequency "
                           "(kHz)")
    fig.suptitle(title or f"re-check {recheck.band_hz[0]:g}-{recheck.band_hz[1]:g} Hz: fresh "
                 "sweeps with backlash and time integration", fontsize=10)
    return fig


# ------------------------------------------------------------------ mesh cycle


def mesh_cycle_figure(stage, loads: dict, title: str = ""):
    """Stiffness (top) and loaded transmission error (bottom) of ``stage``'s meshes over
    one mesh cycle.

    **Arguments:** ``loads``: side (``sun`` | ``ring``) -> static normal load of one
    planet's mesh (N). Each side is drawn in its colour from its tooth geometry
    (:func:`~gearjax._gear.mesh_stiffness.mesh_cycle`), with the rectangular wave of
    the same mean and contact ratio (dashed) that it replaces; a stage without tooth
    geometry draws its rectangular wave.
    """
    cycles = {side: (mesh_cycle(stage, side, load) if stage.geometry is not None
                     else rectangular_cycle(stage, side, load))
              for side, load in loads.items()}
    fig, axes = _figure(7.0, 5.5, rows=2, sharex=True)
    top, bottom = axes[0, 0], axes[1, 0]
    for side, c in cycles.items():
        x = (np.asarray(c.tau) / (2 * np.pi) + 0.5) % 1.0 - 0.5  # the zone in the middle
        order = np.argsort(x)
        x = x[order]
        color = SIDE_COLORS[side]
        top.plot(x, np.asarray(c.stiffness)[order] / 1e6, color=color,
                 label=f"{side}-planet, geometry")
        top.plot(x, np.asarray(c.rectangular)[order] / 1e6, color=color, ls="--", lw=1,
                 label=f"{side}-planet, rectangular wave")
        bottom.plot(x, np.asarray(c.loaded_te)[order] * 1e6, color=color,
                    label=f"{side}-planet at {float(c.load):.0f} N")
    top.set_ylabel("mesh stiffness (N/um)")
    bottom.set_ylabel("loaded transmission error (um)")
    bottom.set_xlabel("mesh cycle (0 = middle of the multiple-pair zone)")
    top.legend(fontsize=8, loc="best")
    bottom.legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
