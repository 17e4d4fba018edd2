"""Axis units of the figures."""

from __future__ import annotations

import numpy as np


def frequency_unit(ds) -> tuple[float, str]:
    """``(scale, unit)`` of a frequency axis that fits the points of ``ds``: kHz from
    1 kHz up, Hz below (a wind turbine's meshes run at tens of Hz)."""
    f = np.asarray(ds["mesh_frequency_hz"], dtype=float)
    top = float(np.nanmax(np.abs(f))) if f.size and np.isfinite(f).any() else 0.0
    return (1e3, "kHz") if top >= 1e3 else (1.0, "Hz")
