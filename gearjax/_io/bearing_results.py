"""Bearing forces of the translational model from a results Dataset's displacements.

A bearing's force is a vector of two rows, ``F = k R x + c R x'`` (``x, y`` of a
central member; radial and tangential of a planet pin, in the frame turning with the
carrier), so its Fourier coefficients follow from the member displacement
coefficients that :func:`gearjax._io.results.add_displacement_harmonics` (or
``add_displacement_waves`` on a torus) stored. Per point and bearing:

- ``bearing_mean_force``: magnitude of the mean force vector (N);
- ``bearing_rms_force``: RMS of the alternating vector ``sqrt(mean |F - Fbar|^2)``
  (N), exact (Parseval);
- ``bearing_max_force``: peak magnitude ``max |F|`` (N), sampled on a uniform grid of
  the period (or the torus) fine enough for the stored harmonics.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

BEARING_FIELDS = ("mean_force", "rms_force", "max_force")
"""The per-bearing outputs; Dataset variables ``bearing_<field>``."""

_NAMES = {"mean_force": "magnitude of the mean bearing force vector",
          "rms_force": "RMS of the alternating bearing force vector",
          "max_force": "peak magnitude of the bearing force"}


def add_bearing_forces(ds: xr.Dataset, names: Sequence[str], stages: Sequence[str], rows,
                       offsets, stiffness, damping) -> xr.Dataset:
    """``ds`` with ``bearing_mean_force``, ``bearing_rms_force``, ``bearing_max_force``
    ``(point, bearing)`` (N) and the coordinates ``bearing`` (``names``) and
    ``bearing_stage``.

    **Arguments:** ``rows`` ``(b, 2, n)``: each bearing's two deflection rows over the
    ``n`` coordinates of ``ds``'s ``dof``, ``offsets`` ``(b, 2)`` their rest offsets (m:
    the deflection is ``r x + e``); ``stiffness``, ``damping`` ``(b,)`` (N/m, N s/m).
    ``ds`` needs ``omega`` and the displacement coefficients (``harmonic`` with ``eta``,
    or ``wave`` with ``wave_vector`` and ``wave_frequency``).
    """
    rows = np.asarray(rows, dtype=float)
    e = np.asarray(offsets, dtype=float)
    k = np.asarray(stiffness, dtype=float)[:, None, None]
    c = np.asarray(damping, dtype=float)[:, None, None]
    cos = np.asarray(ds["displacement_cos"].values, dtype=float)  # (P, n, W)
    sin = np.asarray(ds["displacement_sin"].values, dtype=float)
    P = cos.shape[0]
    if "wave" in ds.dims:
        vectors = np.asarray(ds["wave_vector"].values, dtype=np.int64)  # (W, G)
        rates = np.broadcast_to(np.asarray(ds["wave_frequency"].values, float), (P, len(vectors)))
    else:
        orders = np.arange(cos.shape[2])
        vectors = orders[:, None]
        eta = np.asarray(ds["eta"].values, float) if "eta" in ds else np.ones(P)
        rates = orders[None, :] / eta[:, None]
    angles = _grid(vectors)  # (T, G)
    phase = angles @ vectors.T  # (T, W)
    cos_t, sin_t = np.cos(phase), np.sin(phase)
    omega = np.asarray(ds["omega"].values, dtype=float)
    out = {f: np.zeros((P, len(names))) for f in BEARING_FIELDS}
    for p in range(P):
        a = np.einsum("bdn,nw->bdw", rows, cos[p])
        b = np.einsum("bdn,nw->bdw", rows, sin[p])
        w = omega[p] * rates[p][None, None, :]
        fc = k * a + c * w * b
        fs = k * b - c * w * a
        mean = fc[:, :, 0] + k[:, :, 0] * e
        out["mean_force"][p] = np.linalg.norm(mean, axis=1)
        out["rms_force"][p] = np.sqrt(0.5 * np.sum(fc[:, :, 1:] ** 2 + fs[:, :, 1:] ** 2,
                                                   axis=(1, 2)))
        F = (np.einsum("bdw,tw->bdt", fc, cos_t) + np.einsum("bdw,tw->bdt", fs, sin_t)
             + (k[:, :, 0] * e)[:, :, None])
        out["max_force"][p] = np.linalg.norm(F, axis=1).max(axis=1)
    return _assign(ds, names, stages, out)


def add_bearing_samples(ds: xr.Dataset, names: Sequence[str], stages: Sequence[str], rows,
                        offsets, stiffness, damping, x, v) -> xr.Dataset:
    """:func:`add_bearing_forces` from time samples instead of harmonics (a time
    integration's last periods): ``x``, ``v`` ``(P, n, T)`` coordinates and rates,
    uniform over whole periods; NaN where ``x`` is (a failed point)."""
    rows = np.asarray(rows, dtype=float)
    k = np.asarray(stiffness, dtype=float)[:, None, None]
    c = np.asarray(damping, dtype=float)[:, None, None]
    e = np.asarray(offsets, dtype=float)[:, :, None]
    F = (k * (np.einsum("bdn,pnt->pbdt", rows, np.asarray(x, float)) + e)
         + c * np.einsum("bdn,pnt->pbdt", rows, np.asarray(v, float)))
    mean = F.mean(axis=3)
    out = {"mean_force": np.linalg.norm(mean, axis=2),
           "rms_force": np.sqrt(np.mean(np.sum((F - mean[..., None]) ** 2, axis=2), axis=2)),
           "max_force": np.linalg.norm(F, axis=2).max(axis=2)}
    return _assign(ds, names, stages, out)


def _assign(ds: xr.Dataset, names, stages, out: dict) -> xr.Dataset:
    ds = ds.assign_coords(bearing=("bearing", np.asarray(list(names), dtype=str)),
                          bearing_stage=("bearing", np.asarray(list(stages), dtype=str)))
    for field in BEARING_FIELDS:
        ds[f"bearing_{field}"] = (("point", "bearing"), out[field],
                                  {"units": "N", "long_name": _NAMES[field]})
    return ds


def bearings_json(ds: xr.Dataset, k: int, number) -> list[dict]:
    """interface.md's ``bearings`` of point ``k``: ``{name, stage, mean_force,
    rms_force, max_force}`` per bearing (N), each value through ``number`` (the JSON
    number rule: ``None`` for NaN); ``[]`` where ``ds`` has none."""
    if "bearing_mean_force" not in ds:
        return []
    names = ds["bearing"].values.tolist()
    stages = ds["bearing_stage"].values.tolist()
    return [{"name": str(name), "stage": str(stages[j]),
             **{f: number(ds[f"bearing_{f}"].values[k, j]) for f in BEARING_FIELDS}}
            for j, name in enumerate(names)]


def _grid(vectors: np.ndarray) -> np.ndarray:
    """Uniform samples ``(T, G)`` of the torus angles: ``4 max|k_g| + 4`` per angle (at
    least 64 for one angle, 16 per angle for more), enough to resolve every wave
    several times over."""
    G = vectors.shape[1]
    top = np.abs(vectors).max(axis=0) if len(vectors) else np.zeros(G, int)
    counts = [max(64 if G == 1 else 16, 4 * int(t) + 4) for t in top]
    axes = [2 * np.pi * np.arange(m) / m for m in counts]
    return np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
