"""Bearing forces of a translational sweep against frequency (a figure)."""

from __future__ import annotations

import numpy as np

from .._errors import bad_argument
from .units import frequency_unit

MEMBER_COLORS = {"sun": "tab:blue", "ring": "tab:orange", "carrier": "tab:green"}


def bearing_figure(ds, title: str = ""):
    """One panel per stage: the peak magnitude (solid) and the mean magnitude (dotted)
    of each bearing's force (N) against reference-stage mesh frequency; sun, ring and
    carrier in colour, planet pins grey; the peak of unstable states thin and dashed.

    **Raises:** ``TrainError`` (a ``bad_argument`` naming ``what``) where ``ds`` has no
    bearing forces (a torsional train). **Returns:** the Figure.
    """
    import matplotlib.pyplot as plt

    if "bearing_max_force" not in ds:
        raise bad_argument("what", "bearings", "these results have no bearing forces: the "
                                               'train file needs model = "translational"')
    scale, unit = frequency_unit(ds)
    f = np.asarray(ds["mesh_frequency_hz"], float) / scale
    stable = np.asarray(ds["stable"]) if "stable" in ds else np.full(f.shape, -1)
    keep = stable != 0
    order = np.argsort(f)
    stages = list(dict.fromkeys(ds["bearing_stage"].values.tolist()))
    fig, axes = plt.subplots(len(stages), 1, figsize=(10.0, 3.0 * len(stages)), sharex=True,
                             squeeze=False, constrained_layout=True)
    for ax, stage in zip(axes[:, 0], stages):
        for j, name in enumerate(ds["bearing"].values.tolist()):
            if ds["bearing_stage"].values[j] != stage:
                continue
            member = name.rsplit(".", 1)[1]
            pin = member.startswith("pin")
            color = "0.55" if pin else MEMBER_COLORS[member]
            label = "planet pins" if member == "pin1" else (None if pin else member)
            peak = np.asarray(ds["bearing_max_force"].values[:, j], float)
            mean = np.asarray(ds["bearing_mean_force"].values[:, j], float)
            for y, style, lw, tag in ((np.where(keep, peak, np.nan), "-", 1.2, label),
                                      (np.where(keep, np.nan, peak), "--", 0.7, None),
                                      (np.where(keep, mean, np.nan), ":", 0.9, None)):
                ax.plot(f[order], y[order], style, color=color, lw=lw, label=tag)
        ax.set_title(f"stage {stage} bearings: peak (solid; unstable states dashed) and mean "
                     "(dotted) force", fontsize=9)
        ax.set_ylabel("bearing force (N)", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=4)
    axes[-1, 0].set_xlabel(f"stage {ds.attrs.get('reference_stage', '')} mesh frequency "
                           f"({unit})")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
