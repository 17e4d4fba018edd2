"""Load-sharing factors: how evenly a stage's planets carry its load.

A planet's load is its sun-mesh force (in statics the ring-mesh force is the same: the
planet's moment balance). Per stage, the factor is the largest planet's load over the
mean of its planets' loads: 1 is perfect sharing, ``N`` one planet carrying everything
(KISSsoft's K_gamma, ISO 6336's mesh load factor). Static: on the static mesh forces.
Dynamic (Kahraman 1994): on each planet's peak sun-mesh force over the period.
"""

from __future__ import annotations

import numpy as np

from .._engine.system import System


def load_sharing(system: System, forces) -> dict[str, float | None]:
    """Per stage id: ``max_i F_i / mean_i F_i`` over the stage's sun meshes, ``forces``
    ``(m,)`` (N; one per mesh of ``system``, e.g. static forces or each mesh's peak
    force). ``None`` where the stage's mean is 0 (an unloaded stage)."""
    stages, factors = stage_load_sharing(system, np.asarray(forces)[None])
    return {sid: float(v[0]) if np.isfinite(v[0]) else None for sid, v in zip(stages, factors)}


def stage_load_sharing(system: System, forces) -> tuple[list[str], np.ndarray]:
    """The stage ids (mesh order of first appearance) and their factors ``(S, P)`` for
    ``forces`` ``(P, m)`` (N), NaN where a stage's mean load is 0."""
    forces = np.abs(np.asarray(forces, dtype=float))
    groups = np.asarray(system.mesh_group)
    sides = np.asarray(system.mesh_side)
    stages = list(dict.fromkeys(system.mesh_group))
    out = np.full((len(stages), forces.shape[0]), np.nan)
    for j, sid in enumerate(stages):
        f = forces[:, (groups == sid) & (sides == "sun")]
        mean = f.mean(axis=1)
        ok = mean > 0
        out[j, ok] = f.max(axis=1)[ok] / mean[ok]
    return stages, out
