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
