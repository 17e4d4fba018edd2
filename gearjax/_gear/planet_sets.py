"""Admissible planet sets of a stage and the designs the torsional model can tell apart.

**Admissible sets** (model.md, Geometry; :mod:`gearjax._gear.validate`): planet ``i``
sits at ``psi_i`` with ``(Z_s + Z_r) psi_i / 360`` an integer (the assembly rule:
``Z_s + Z_r`` slots around the carrier) and no two planets overlap,
``2 r_c sin(dpsi / 2) > m (Z_p + 2)``, i.e. neighbours are at least ``k_min`` slots
apart. Planet 1 is at 0 and the angles increase (canonical order: relabelling planets
changes nothing), so a set is a composition of ``Z_s + Z_r`` into ``N`` gaps
``>= k_min``: 4495 sets for the paper's stage 1 (4 planets, 100 slots, ``k_min`` = 18),
out of ``C(99, 3)`` = 156849 without the overlap rule.

**Distinct designs** (:func:`phasing_classes`): the torsional model sees a planet only
through its mesh phases ``Z_s psi_i`` and ``Z_r psi_i`` modulo 360 deg, so sets with the
same multiset of slot residues ``Z_s k_i mod (Z_s + Z_r)`` are one design (relabelled):
the paper's 4495 stage-1 sets are 220 designs (``Z_s = 30`` on 100 slots: 10 residues),
its 67525 stage-2 sets 5456. With ``phasing = "physical"`` rotating a set by a slot
multiple and relabelling shifts every mesh phase of the stage by the same angle (the
assembly rule makes ``Z_r dpsi = -Z_s dpsi`` mod 360): the same set with another stage
phase, so where the stage phase is varied too, sets that differ by a rotation are one
class (73 and 1496 for the paper's stages).

Angles are in degrees throughout; a set is a row ``(N,)``, a list of sets ``(S, N)``.
"""

from __future__ import annotations

import math

import numpy as np

from .validate import assembly_ok, assembly_slots, overlapping_planets

MAX_SETS = 2_000_000
"""Largest number of admissible planet sets enumerated (more: refused with a message)."""


def min_gap_slots(stage) -> int:
    """Smallest number of assembly slots between two planets that do not overlap."""
    S = assembly_slots(stage)
    for k in range(1, S // 2 + 1):
        if overlapping_planets(stage, [0.0, 360.0 * k / S]) is None:
            return k
    return S  # even opposite planets overlap


def _compositions(total: int, parts: int, low: int) -> np.ndarray:
    """Every row of ``parts`` integers ``>= low`` summing to ``total`` (lexicographic)."""
    if parts == 1:
        return np.array([[total]], dtype=np.int64) if total >= low else np.zeros((0, 1), int)
    rows = []
    for first in range(low, total - low * (parts - 1) + 1):
        sub = _compositions(total - first, parts - 1, low)
        rows.append(np.column_stack([np.full(len(sub), first, dtype=np.int64), sub]))
    return np.concatenate(rows) if rows else np.zeros((0, parts), dtype=np.int64)


def count_planet_sets(stage, n_planets: int | None = None) -> int:
    """How many admissible sets :func:`admissible_planet_sets` would list (all rotations)."""
    N = stage.n_planets if n_planets is None else int(n_planets)
    S, k = assembly_slots(stage), min_gap_slots(stage)
    free = S - N * k
    if N == 1:
        return 1
    return math.comb(free + N - 1, N - 1) if free >= 0 else 0


def admissible_planet_sets(stage, n_planets: int | None = None, *,
                           modulo_rotation: bool = False) -> np.ndarray:
    """Every admissible placement of ``n_planets`` (default: the stage's count) planets.

    Planet 1 at 0 deg, angles increasing; each on an assembly slot (``(Z_s + Z_r) psi /
    360`` integer) and no two overlapping (module docstring). ``modulo_rotation``: one
    set per class of sets that differ by a rotation and relabelling (the one whose gap
    sequence, read from planet 1, is lexicographically smallest).

    **Returns:** ``(S, N)`` angles in degrees, in lexicographic order of the gaps.
    **Raises:** ``ValueError`` when there are more than :data:`MAX_SETS`.
    """
    N = stage.n_planets if n_planets is None else int(n_planets)
    S, k = assembly_slots(stage), min_gap_slots(stage)
    if N < 1:
        raise ValueError("a planet set needs at least one planet")
    if N == 1:
        return np.zeros((1, 1))
    count = count_planet_sets(stage, N)
    if count > MAX_SETS:
        raise ValueError(f"stage {stage.id!r}: {count} admissible sets of {N} planets on "
                         f"{S} slots is more than {MAX_SETS} to enumerate")
    gaps = _compositions(S, N, k)
    if modulo_rotation and len(gaps):
        keep = np.ones(len(gaps), dtype=bool)
        for r in range(1, N):
            rolled = np.roll(gaps, -r, axis=1)
            diff = rolled - gaps
            first = np.argmax(diff != 0, axis=1)
            smaller = diff[np.arange(len(gaps)), first] < 0  # the rotation is smaller
            keep &= ~smaller
        gaps = gaps[keep]
    slots = np.concatenate([np.zeros((len(gaps), 1), np.int64),
                            np.cumsum(gaps[:, :-1], axis=1)], axis=1)
    return 360.0 * slots / S


def planet_set_ok(stage, angles_deg) -> bool:
    """Planet 1 at 0, strictly increasing below 360, the assembly rule and no overlap."""
    a = np.asarray(angles_deg, dtype=float)
    return bool(a.size == stage.n_planets and a[0] == 0 and np.all(np.diff(a) > 0)
                and a[-1] < 360 and assembly_ok(stage, a)
                and overlapping_planets(stage, a) is None)


def phasing_classes(stage, sets, *, modulo_shift: bool = False) -> tuple[np.ndarray,
                                                                           np.ndarray]:
    """Group planet sets ``(S, N)`` (deg) of ``stage`` that the model cannot tell apart.

    Planet positions enter the (torsional) model only through the mesh phases
    ``Z_s psi_i`` and ``Z_r psi_i`` modulo 360 deg (model.md, phasing), and relabelling
    identical planets changes nothing: two sets with the same multiset of slot residues
    ``(Z_s k_i mod S, Z_r k_i mod S)`` (``k_i`` the slot of planet ``i``, ``S = Z_s + Z_r``)
    are the same design. The paper's stage 1 (``Z_s = 30``, 100 slots) has only 10
    residues: its 4495 admissible sets are 220 designs. ``modulo_shift``: also one class
    for residue multisets that differ by a common shift (a rotated set: the same design
    with another stage phase, when that stage phase is screened too).

    **Returns:** ``(representatives, sizes)``: the index into ``sets`` of one set per
    class (the best-balanced one, smallest ``|sum_i exp(i psi_i)|``: the planets'
    centre of mass nearest the carrier axis, then the widest smallest gap, then the
    first), in order of first appearance, and how many sets each class holds.
    """
    sets = np.asarray(sets, dtype=float)
    S = assembly_slots(stage)
    k = np.rint(sets * S / 360.0).astype(np.int64)
    sun = (stage.teeth.sun * k) % S
    ring = (stage.teeth.ring * k) % S
    shifts = [0]
    classes: dict[tuple, list[int]] = {}
    for i in range(len(sets)):
        pairs = list(zip(sun[i].tolist(), ring[i].tolist()))
        if modulo_shift:
            shifts = pairs
        key = min(tuple(sorted(((a - da) % S, (b - db) % S) for a, b in pairs))
                  for da, db in (shifts if modulo_shift else [(0, 0)]))
        classes.setdefault(key, []).append(i)
    psi = np.deg2rad(sets)
    imbalance = np.abs(np.sum(np.exp(1j * psi), axis=1))
    gaps = np.diff(np.concatenate([sets, np.full((len(sets), 1), 360.0)], axis=1), axis=1)
    reps, sizes = [], []
    for members in classes.values():
        m = np.asarray(members)
        order = np.lexsort((m, -np.round(gaps[m].min(axis=1), 9), np.round(imbalance[m], 9)))
        reps.append(int(m[order[0]]))
        sizes.append(len(members))
    return np.asarray(reps, dtype=np.int64), np.asarray(sizes, dtype=np.int64)


def planet_imbalance(angles_deg) -> float:
    """``|sum_i exp(i psi_i)| / N``: the planets' centre of mass off the carrier axis, as a
    share of the carrier radius (0 for a balanced set such as equal spacing)."""
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))
    return float(np.abs(np.sum(np.exp(1j * a))) / max(a.size, 1))
