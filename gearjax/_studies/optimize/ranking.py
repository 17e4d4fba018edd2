"""Ranking candidates by their band profiles: the peak, then the next largest peaks.

A stage's phasing cannot lower a peak that another stage's excitation sets (a torsional
mode driven by the other stage loads every ring mesh alike); the peak then ties across
the stage's candidates and the rest of the band decides (:func:`leximax_order`).
"""

from __future__ import annotations

import numpy as np

TIE_DEPTH = 8
"""How many of the band's largest values break ties (:func:`leximax_order`)."""
RANK_RTOL = 1e-3
"""Candidates whose band profiles (:func:`leximax_order`) agree within this (relative)
count as equal on the proxy and the linear model; the better-balanced planet set
(:func:`gearjax._gear.planet_sets.planet_imbalance`) goes first, then the earlier one
(the incumbent before any candidate: a change must lower the objective by more than
this)."""


def band_profile(rms, depth: int = TIE_DEPTH) -> np.ndarray:
    """``(B, depth)``: the ``depth`` largest values, descending, of the per-frequency peak
    over meshes of ``rms`` ``(B, F, m)`` (N; NaN where a point failed sorts last)."""
    per_f = np.max(np.where(np.isfinite(rms), rms, -np.inf), axis=-1)
    out = -np.sort(-per_f, axis=-1)[:, :depth]
    return np.where(np.isfinite(out), out, np.nan)


def leximax_order(profiles, rtol: float = 1e-6, tie=None) -> np.ndarray:
    """Indices of the rows of ``profiles`` ``(B, k)`` (each descending: the largest
    values of a response over the band) from best to worst: by the peak, ties (within
    ``rtol`` of the largest value) broken by the next largest value, and so on; rows
    still tied go by ``tie`` ``(B,)`` (smaller first), then by index. Rows with a NaN
    peak go last (module docstring)."""
    p = np.asarray(profiles, dtype=float)
    p = p.reshape(p.shape[0], -1)
    scale = np.nanmax(np.abs(p)) if np.any(np.isfinite(p)) else 1.0
    q = np.where(np.isfinite(p), np.round(p / (rtol * (scale or 1.0))), np.inf)
    keys = [q[:, k] for k in range(q.shape[1] - 1, -1, -1)]
    if tie is not None:
        keys.insert(0, np.asarray(tie, dtype=float))
    return np.lexsort(tuple(keys))
