"""Phasing optimisation: planet positions, sun-ring and stage phases that minimise the
largest RMS dynamic mesh force over a band of mesh frequencies.

**Variables** (``vary``, TOML paths; default: every phasing variable of the turning
stages): ``STAGE.planet_angles_deg`` (the stage's whole planet set, chosen among the
admissible sets), ``STAGE.sun_ring_phase_deg`` and ``STAGE.stage_phase_deg``
(continuous, 360 deg = one mesh cycle). The first turning stage's stage phase is the
time origin (shifting it shifts time) and is not a variable.

**Admissible planet sets** (model.md, Geometry; :mod:`gearjax._validate`): planet
``i`` sits at ``psi_i`` with ``(Z_s + Z_r) psi_i / 360`` an integer (the assembly rule:
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
its 67525 stage-2 sets 5456. One set per class is screened, the best-balanced one (the
planets' centre of mass nearest the carrier axis). With ``phasing = "physical"``
rotating a set by a slot multiple and relabelling shifts every mesh phase of the stage
by the same angle (the assembly rule makes ``Z_r dpsi = -Z_s dpsi`` mod 360): the same
set with another stage phase. Where the stage phase is varied, it is screened on the
same grid as the sun-ring phase and sets that differ by a rotation are one class
(73 and 1496 for the paper's stages).

**Objective:** the largest RMS of the alternating mesh force (N) over the band's
frequencies and the gear's meshes. Ties are broken by the next largest per-frequency
peaks (:func:`leximax_order`): a stage's phasing cannot lower a peak that another
stage's excitation sets, and then the rest of the band decides. Profiles within
:data:`RANK_RTOL` (0.1%) are equal; the better-balanced planet set wins the tie
(:func:`planet_imbalance`: an unequally spaced set puts a rotating unbalance on the
carrier), and the incumbent is kept unless a candidate beats it by more. Stages are optimised
one at a time, in file order (``passes`` times); the incumbent (the current design) is
always a candidate, so no step makes the objective worse on the model that decides it.
Three models, cheapest first:

1. *proxy*, every distinct set x a grid of sun-ring (and stage) phases: the forced
   response to first order in the stiffness variation,
   ``F_o = (I - D_o W H(o Omega) W^T) q_o`` per excitation order ``o``
   (``q_o = kbar kappa_o p_static - (kbar + i o Omega c) e_o``, ``H`` the
   mean-stiffness receptance, ``D_o = diag(kbar + i o Omega c)``): the phasing
   cancellation of every stiffness harmonic weighted by the modes it drives, with the
   transfer matrices computed once (phasing does not change them);
2. *linear*: the ``screen`` best sets by the linear, time-varying harmonic balance
   (:mod:`gearjax._design`: parametric coupling kept, no backlash), batched;
3. *non-linear*: the ``nonlinear`` best by sweeps with backlash
   (:func:`gearjax.sweep`, continuation), restarted just above the frequency where a
   sweep stops (a fold with a jump, a closed loop, its point budget) so the band is
   covered as an up-sweep covers it; the peak is over the stable points (unstable
   orbits and spurious branches with a load factor above :data:`MAX_DLF` are counted
   and left out, :class:`NonlinearBand`).

The continuous relaxation (planet angles continuous, non-overlapping through a softmax
of the gaps, phases continuous; the assembly rule dropped, so it cannot be built)
minimises the smooth peak (log-sum-exp) of the linear model by L-BFGS with
``jax.grad`` from the optimum, for comparison, at the resonance frequencies
(:func:`resonance_frequencies`: where an excitation order meets a natural frequency,
which the phasing does not move) and the optimum's screen grid. The objective
oscillates in the angles (a planet moved by ``360 / Z_s`` deg brings its phases back),
so this is a local optimum next to the discrete one. Baseline, optimum and relaxation
are compared on one grid: ``final_points`` geometric frequencies, the resonance
frequencies and each design's proxy peaks.

:func:`recheck` re-checks baseline and optimum independently: fresh sweeps with backlash
(the sweep's own harmonics), time integration from their peak orbits and
:func:`gearjax.verify_gear` at the peak frequencies.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize

from . import _harmonics, _hb
from ._design import batched_rms, peak_of
from ._errors import fail
from ._kinematics import kinematics, require_base
from ._paths import get_path, leaf_selector, set_path
from ._sensitivity import GearFamily
from ._static import static_deflection
from ._train import Train
from ._validate import assembly_ok, assembly_slots, min_planet_gap_deg, overlapping_planets

PHASING_KEYS = ("planet_angles_deg", "sun_ring_phase_deg", "stage_phase_deg")
MAX_SETS = 2_000_000
"""Largest number of admissible planet sets enumerated (more: refused with a message)."""
TIE_DEPTH = 8
"""How many of the band's largest values break ties (:func:`leximax_order`)."""
RANK_RTOL = 1e-3
"""Candidates whose band profiles (:func:`leximax_order`) agree within this (relative)
count as equal on the proxy and the linear model; the better-balanced planet set
(:func:`planet_imbalance`) goes first, then the earlier one (the incumbent before any
candidate: a change must lower the objective by more than this)."""
NONLINEAR_RTOL = 1e-3
"""Peaks of sweeps with backlash closer than this (relative) count as equal."""
MAX_DLF = 50.0
"""Sweep points with a larger dynamic load factor are spurious (:class:`NonlinearBand`)."""


# ------------------------------------------------------------------ planet sets


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


# --------------------------------------------------------------------- variables


@dataclasses.dataclass(frozen=True)
class StageVariables:
    """The varied phasing of one stage: ``planets`` (the planet set), ``sun_ring``,
    ``stage_phase``; ``paths``: the TOML paths of the continuous values it owns in a
    design vector (planet angles 2..N, then the phases)."""

    stage: str
    planets: bool
    sun_ring: bool
    stage_phase: bool
    n_planets: int

    @property
    def paths(self) -> tuple[str, ...]:
        out = []
        if self.planets:
            out += [f"{self.stage}.planet_angles_deg.{i}" for i in range(2, self.n_planets + 1)]
        if self.sun_ring:
            out.append(f"{self.stage}.sun_ring_phase_deg")
        if self.stage_phase:
            out.append(f"{self.stage}.stage_phase_deg")
        return tuple(out)

    @property
    def names(self) -> tuple[str, ...]:
        """The ``--vary`` spellings."""
        keys = [k for k, on in zip(PHASING_KEYS, (self.planets, self.sun_ring,
                                                  self.stage_phase)) if on]
        return tuple(f"{self.stage}.{k}" for k in keys)


def default_vary(train: Train, gear: str | None = None) -> list[str]:
    """Every phasing variable of the stages that turn in ``gear``: planet sets (2 or more
    planets), sun-ring phases, and the stage phases of all but the time-origin stage."""
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    require_base(kin, train.source)
    origin = next(s.id for s in kin.stages if s.turning)
    out = []
    for s, sk in zip(train.stages, kin.stages):
        if not sk.turning:
            continue
        if s.n_planets >= 2:
            out.append(f"{s.id}.planet_angles_deg")
        out.append(f"{s.id}.sun_ring_phase_deg")
        if s.id != origin:
            out.append(f"{s.id}.stage_phase_deg")
    return out


def phasing_variables(train: Train, gear: str, vary: Sequence[str] | None
                      ) -> tuple[StageVariables, ...]:
    """Parse ``vary`` (default :func:`default_vary`) into one :class:`StageVariables` per
    stage, in file order. **Raises:** ``TrainError`` naming the path and the rule."""
    kin = kinematics(train, gear)
    origin = next((s.id for s in kin.stages if s.turning), None)
    vary = default_vary(train, gear) if vary is None else (
        [vary] if isinstance(vary, str) else list(vary))
    src = train.source
    if not vary:
        raise fail(src, "--vary", [], "at least one phasing path is required")
    chosen: dict[str, set] = {}
    allowed = ("STAGE.planet_angles_deg (the planet set), STAGE.sun_ring_phase_deg, "
               "STAGE.stage_phase_deg")
    for path in vary:
        parts = str(path).split(".")
        sid = parts[0]
        if len(parts) == 3 and sid in train.stage_ids and parts[1] == "planet_angles_deg":
            leaf_selector(train, path, "--vary")  # a bad planet number says so
            raise fail(src, "--vary", path,
                       f"planet angles are placed together among the admissible sets: write "
                       f"{sid}.planet_angles_deg")
        if len(parts) != 2 or sid not in train.stage_ids or parts[1] not in PHASING_KEYS:
            if not (len(parts) == 2 and sid in train.stage_ids
                    and parts[1] == "planet_angles_deg"):
                leaf_selector(train, path, "--vary")  # names nothing: its own message
            raise fail(src, "--vary", path, f"optimize varies the phasing only: {allowed}")
        s = train.stage(sid)
        if not kin.stage(sid).turning:
            raise fail(src, "--vary", path, f"stage {sid!r} does not turn in gear {gear!r}: "
                       "its phasing has no effect")
        key = parts[1]
        if key == "planet_angles_deg" and s.n_planets < 2:
            raise fail(src, "--vary", path, f"stage {sid!r} has one planet, at 0 deg: there "
                       "is no planet set to choose")
        if key == "stage_phase_deg" and sid == origin:
            raise fail(src, "--vary", path, f"stage {sid!r} is the first turning stage: its "
                       "phase is the time origin (shifting it shifts time and changes no RMS); "
                       "vary the other stages' stage_phase_deg")
        if key in chosen.setdefault(sid, set()):
            raise fail(src, "--vary", path, "the variable is given twice; name each once")
        chosen[sid].add(key)
    return tuple(
        StageVariables(stage=s.id, planets="planet_angles_deg" in chosen[s.id],
                       sun_ring="sun_ring_phase_deg" in chosen[s.id],
                       stage_phase="stage_phase_deg" in chosen[s.id], n_planets=s.n_planets)
        for s in train.stages if s.id in chosen)


# ---------------------------------------------------------------- proxy (1st order)


class FirstOrder(eqx.Module):
    """Mesh-force transfer of a gear to first order in its stiffness variation.

    **Fields:** ``transfer`` ``(F, O, m, m)``: ``T_o(f) = I - D_o W H(o Omega_f) W^T``,
    the alternating force of every mesh per unit excitation force of every mesh at base
    order ``o`` (complex amplitudes, ``x = Re(X e^{i w t})``); ``forced`` ``(F, O, m)``:
    the external torques' share (``D_o W H g_o``); ``omegas`` ``(F,)`` (rad/s);
    ``static_p`` ``(m,)``: static mesh deflections (m); ``kbar``, ``damping``;
    ``orders`` (static): the base orders of every mesh harmonic and forcing column.
    """

    transfer: Array
    forced: Array
    omegas: Array
    static_p: Array
    kbar: Array
    damping: Array
    orders: tuple[int, ...] = eqx.field(static=True)
    mesh_mu: tuple[int, ...] = eqx.field(static=True)
    forcing_mu: tuple[int, ...] = eqx.field(static=True)


def first_order(system, omegas) -> FirstOrder:
    """:class:`FirstOrder` of ``system`` at base frequencies ``omegas`` (rad/s)."""
    s = system
    H = max(s.k_cos.shape[-1], s.te_cos.shape[-1])
    orders = sorted({h * mu for mu in s.mesh_mu if mu for h in range(1, H + 1)}
                    | {mu for mu in s.forcing_mu if mu})
    omegas = jnp.asarray(omegas, dtype=float)
    Kt = s.mean_stiffness()
    Ct = s.C + s.W.T @ (s.damping[:, None] * s.W)
    x_static, _ = static_deflection(s)
    o = jnp.asarray(orders, dtype=float)
    w = omegas[:, None] * o[None, :]  # (F, O)
    A = (Kt[None, None] - (w**2)[..., None, None] * s.M[None, None]
         + 1j * w[..., None, None] * Ct[None, None])
    D = s.kbar[None, None, :] + 1j * w[..., None] * s.damping[None, None, :]  # (F, O, m)
    HWt = jnp.linalg.solve(A, jnp.broadcast_to(s.W.T.astype(complex), A.shape[:2] + s.W.T.shape))
    transfer = jnp.eye(s.n_meshes)[None, None] - D[..., :, None] * (s.W @ HWt)
    g = _forcing_orders(s, orders)  # (O, n)
    Hg = jnp.linalg.solve(A, jnp.broadcast_to(g, A.shape[:2] + g.shape[-1:])[..., None])[..., 0]
    forced = D * jnp.einsum("mn,fon->fom", s.W, Hg)
    return FirstOrder(transfer=transfer, forced=forced, omegas=omegas,
                      static_p=s.W @ x_static, kbar=s.kbar, damping=s.damping,
                      orders=tuple(orders), mesh_mu=tuple(s.mesh_mu),
                      forcing_mu=tuple(s.forcing_mu))


def _forcing_orders(s, orders) -> Array:
    g = jnp.zeros((len(orders), s.n_dof), complex)
    for col, mu in enumerate(s.forcing_mu):
        if mu in orders:
            g = g.at[orders.index(mu)].add(s.f_cos[:, col] - 1j * s.f_sin[:, col])
    return g


def excitation(fo: FirstOrder, k_cos, k_sin, te_cos, te_sin) -> tuple[Array, Array]:
    """``(a, b)``, each ``(O, m)``: the first-order excitation force of every mesh at every
    base order is ``q_o = a_o + i o Omega b_o`` (N) (module docstring), from one design's
    stiffness and transmission-error coefficients."""
    O, m = len(fo.orders), fo.kbar.shape[0]
    a = jnp.zeros((O, m), complex)
    b = jnp.zeros((O, m), complex)
    mu = np.asarray(fo.mesh_mu)
    for h in range(1, max(k_cos.shape[-1], te_cos.shape[-1]) + 1):
        for j, o in enumerate(fo.orders):
            sel = jnp.asarray((mu * h == o) & (mu > 0))
            if not bool(np.any((mu * h == o) & (mu > 0))):
                continue
            if h <= k_cos.shape[-1]:
                kappa = k_cos[:, h - 1] - 1j * k_sin[:, h - 1]
                a = a.at[j].add(jnp.where(sel, fo.kbar * kappa * fo.static_p, 0))
            if h <= te_cos.shape[-1]:
                e = te_cos[:, h - 1] - 1j * te_sin[:, h - 1]
                a = a.at[j].add(jnp.where(sel, -fo.kbar * e, 0))
                b = b.at[j].add(jnp.where(sel, -fo.damping * e, 0))
    return a, b


def first_order_rms(fo: FirstOrder, system) -> Array:
    """RMS alternating force ``(F, m)`` (N) of every mesh of ``system`` (same structure
    as the one ``fo`` was built from, other phasing) to first order in the stiffness
    variation."""
    a, b = excitation(fo, system.k_cos, system.k_sin, system.te_cos, system.te_sin)
    o = jnp.asarray(fo.orders, dtype=float)
    q = a[None] + 1j * (fo.omegas[:, None] * o[None, :])[..., None] * b[None]  # (F, O, m)
    F = jnp.einsum("foij,foj->foi", fo.transfer, q) + fo.forced
    return jnp.sqrt(jnp.sum(jnp.abs(F) ** 2, axis=1) / 2)


@eqx.filter_jit
def _proxy_chunk(fo: FirstOrder, family, thetas, phases, idx, h, h_stage, cols_s, cols_r,
                 fixed, rest, mask, depth: int):
    """Band profiles ``(b, G, depth)`` (:func:`band_profile`) of a chunk of planet sets at
    the phase pairs ``phases`` ``(G, 2)`` (sun-ring phase gamma, stage phase Gamma; rad):
    ``F_o = fixed_o + exp(i h'_o Gamma) (A_o + exp(i h_o gamma) B_o)`` with ``A``, ``B``
    the shares of the stage's sun and ring meshes (at gamma = Gamma = 0), ``h'`` the
    stage phase's multiplier (``h``, or 1 with ``phasing = "paper"``) and ``rest`` the
    squared RMS of the orders the stage does not excite."""
    o = jnp.asarray(fo.orders, dtype=float)[idx]
    T = fo.transfer[:, idx]  # (F, On, m, m)
    io_w = 1j * fo.omegas[:, None] * o[None, :]  # (F, On)

    def one(theta):
        s = family(theta)
        a, b = excitation(fo, s.k_cos, s.k_sin, s.te_cos, s.te_sin)
        q = a[idx][None] + io_w[..., None] * b[idx][None]  # (F, On, m)
        A = jnp.einsum("foij,foj->foi", T[..., cols_s], q[..., cols_s])
        B = jnp.einsum("foij,foj->foi", T[..., cols_r], q[..., cols_r])

        def at_phase(pair):
            gamma, stage_phase = pair[0], pair[1]
            F = fixed + jnp.exp(1j * h_stage * stage_phase)[None, :, None] * (
                A + jnp.exp(1j * h * gamma)[None, :, None] * B)
            rms = jnp.sqrt(jnp.sum(jnp.abs(F) ** 2, axis=1) / 2 + rest)  # (F, m)
            per_f = jnp.max(jnp.where(mask[None, :], rms, -jnp.inf), axis=1)
            return jax.lax.top_k(per_f, depth)[0]

        return jax.lax.map(at_phase, phases)

    return jax.vmap(one)(thetas)


def proxy_screen(train: Train, gear: str, stage_id: str, sets, gammas_deg, omegas,
                 mesh_mask, chunk: int = 64, depth: int = TIE_DEPTH,
                 stage_phases_deg=None) -> np.ndarray:
    """First-order band profiles ``(S, G, depth)`` (N; :func:`band_profile`: the largest
    per-frequency peaks, descending) of planet sets ``sets`` ``(S, N)`` (deg) of
    stage ``stage_id`` at sun-ring phases ``gammas_deg`` ``(G,)``, over the base
    frequencies ``omegas`` (rad/s) and the meshes of ``mesh_mask`` ``(m,)``; with
    ``stage_phases_deg`` ``(P,)`` also at each of these stage phases of the stage:
    ``(S, G, P, depth)``. Every other value is ``train``'s. One compilation per
    ``chunk``."""
    N = train.stage(stage_id).n_planets
    base = set_path(train, f"{stage_id}.sun_ring_phase_deg", 0.0)
    if stage_phases_deg is not None:
        base = set_path(base, f"{stage_id}.stage_phase_deg", 0.0)
    paths = [f"{stage_id}.planet_angles_deg.{i}" for i in range(2, N + 1)]
    family = GearFamily.of(base, paths, gear, linear=True)
    sets = np.asarray(sets, dtype=float).reshape(-1, N)
    system = family(family.theta())
    fo = first_order(system, omegas)
    mu_n = system.mesh_mu[system.mesh_group.index(stage_id)]
    in_stage = np.asarray([grp == stage_id for grp in system.mesh_group])
    ring = in_stage & (np.asarray(system.mesh_side) == "ring")
    sun = in_stage & ~ring
    idx = np.asarray([j for j, o in enumerate(fo.orders) if o % mu_n == 0], dtype=int)
    h = jnp.asarray([fo.orders[j] // mu_n for j in idx], dtype=float)
    h_stage = h if train.phasing == "physical" else jnp.ones_like(h)
    # the fixed part: every other mesh's excitation, and the forcing
    a, b = excitation(fo, system.k_cos, system.k_sin, system.te_cos, system.te_sin)
    o = jnp.asarray(fo.orders, dtype=float)
    q = (a[None] + 1j * (fo.omegas[:, None] * o[None, :])[..., None] * b[None]) * jnp.asarray(
        ~in_stage)
    F_other = jnp.einsum("foij,foj->foi", fo.transfer, q) + fo.forced  # (F, O, m)
    others = np.setdiff1d(np.arange(len(fo.orders)), idx)
    rest = jnp.sum(jnp.abs(F_other[:, others]) ** 2, axis=1) / 2
    fixed = F_other[:, idx]
    gammas = np.asarray(gammas_deg, dtype=float).reshape(-1)
    stage_phases = np.zeros(1) if stage_phases_deg is None else np.asarray(
        stage_phases_deg, dtype=float).reshape(-1)
    pairs = np.stack(np.meshgrid(gammas, stage_phases, indexing="ij"), axis=-1).reshape(-1, 2)
    phases = jnp.deg2rad(jnp.asarray(pairs))
    mask = jnp.asarray(np.asarray(mesh_mask, dtype=bool))
    cols_s, cols_r = np.flatnonzero(sun), np.flatnonzero(ring)
    thetas = sets[:, 1:]
    out = []
    for start in range(0, len(thetas), chunk):
        part = thetas[start:start + chunk]
        n = len(part)
        if n < chunk:
            part = np.concatenate([part, np.repeat(part[-1:], chunk - n, axis=0)])
        peaks = _proxy_chunk(fo, family, jnp.asarray(part), phases, idx, h, h_stage, cols_s,
                             cols_r, fixed, rest, mask, min(depth, len(fo.omegas)))
        out.append(np.asarray(peaks)[:n])
    out = np.concatenate(out)
    shape = (len(sets), len(gammas)) + (() if stage_phases_deg is None else (len(stage_phases),))
    return out.reshape(shape + out.shape[-1:])


def assemble_at(train: Train, gear: str):
    from ._assembly import assemble

    return assemble(train, gear)


# ----------------------------------------------------------------- non-linear band


@dataclasses.dataclass(frozen=True)
class NonlinearBand:
    """Sweeps with backlash over a band, restarted above each early stop.

    **Fields:** ``frequencies_hz`` ``(P,)`` and ``rms_force`` ``(P, m)`` of the converged,
    stable points of every sweep, in solve order (an unstable periodic orbit is not
    what the gearbox shows, and branches past parametric instabilities reach absurd
    amplitudes); ``unstable``: converged points left out; ``implausible``: stable points
    left out because a mesh's dynamic load factor exceeds ``max_dlf`` (RMS forces of
    meganewtons on a mesh loaded with kilonewtons: spurious branches of the truncated
    harmonic balance, not responses); ``starts_hz``, ``stops``
    (one per sweep: where it started, why it ended); ``coverage``: share of the band
    (in log frequency) the sweeps traced; ``peak``: largest RMS (N); ``stage_peaks``:
    per stage; ``seconds``.
    """

    frequencies_hz: np.ndarray
    rms_force: np.ndarray
    starts_hz: tuple[float, ...]
    stops: tuple[str, ...]
    coverage: float
    peak: float
    stage_peaks: dict
    unstable: int
    implausible: int
    seconds: float


def nonlinear_band(train: Train, gear: str, lo: float, hi: float, *, stage: str | None = None,
                   harmonics: int | None = None, max_step_hz: float | None = None,
                   max_points: int = 3000, restarts: int = 8, jump: float = 0.01,
                   max_dlf: float = MAX_DLF,
                   progress: Callable[[str], None] | None = None) -> NonlinearBand:
    """Sweep ``gear`` with backlash from ``lo`` to ``hi`` (reference-stage Hz); where a
    sweep stops early (a fold it cannot pass, a closed loop, ``max_points`` continuation
    points, no start), start a new one ``jump`` (relative) above the highest frequency
    reached, at most ``restarts`` times.
    """
    from ._sweep import sweep

    t0 = time.perf_counter()
    f0, freqs, rms, starts, stops, spans = lo, [], [], [], [], []
    labels = stage_of = None
    unstable = implausible = 0
    for _ in range(restarts + 1):
        starts.append(f0)
        try:
            r = sweep(train, gear, f0, hi, stage=stage, harmonics=harmonics,
                      max_step_hz=max_step_hz, max_points=max_points)
        except RuntimeError as e:  # no converged start: jump further
            stops.append(f"no start ({e})")
            f0 *= 1 + 10 * jump
            if f0 >= hi:
                break
            continue
        ds = r.dataset
        traced = ds["converged"].values
        stable = traced & (ds["stable"].values == 1)  # what a gearbox shows: stable orbits
        dlf = np.nanmax(np.where(np.isfinite(ds["dlf"].values), ds["dlf"].values, 0.0), axis=1)
        ok = stable & (dlf <= max_dlf)
        implausible += int(np.sum(stable & (dlf > max_dlf)))
        f = ds["mesh_frequency_hz"].values[ok]
        labels = ds["mesh"].values.tolist()
        stage_of = ds["stage"].values.tolist()
        freqs.append(f)
        rms.append(ds["rms_force"].values[ok])
        stops.append(r.stop)
        unstable += int(traced.sum() - stable.sum())
        reached = ds["mesh_frequency_hz"].values[traced]
        top = float(np.max(reached)) if reached.size else f0
        spans.append((f0, max(top, f0)))
        if progress:
            progress(f"  sweep from {f0:.0f} Hz: {int(traced.sum())} points to {top:.0f} Hz "
                     f"({r.stop}), {int(traced.sum() - stable.sum())} unstable, "
                     f"{int(np.sum(stable & (dlf > max_dlf)))} implausible")
        if r.stop == "reached_end" or top >= hi:
            break
        f0 = max(top, f0) * (1 + jump)
        if f0 >= hi:
            break
    f = np.concatenate(freqs) if freqs else np.zeros(0)
    m = len(labels) if labels else 0
    R = np.concatenate(rms) if rms else np.zeros((0, m))
    covered = sum(math.log(b / a) for a, b in spans if b > a)
    peak = float(np.nanmax(R)) if R.size and np.any(np.isfinite(R)) else math.nan
    stage_peaks = {}
    if labels:
        for sid in dict.fromkeys(stage_of):
            cols = np.asarray(stage_of) == sid
            v = R[:, cols]
            stage_peaks[sid] = float(np.nanmax(v)) if v.size and np.any(np.isfinite(v)) else (
                math.nan)
    return NonlinearBand(frequencies_hz=f, rms_force=R, starts_hz=tuple(starts),
                         stops=tuple(stops), coverage=min(1.0, covered / math.log(hi / lo)),
                         peak=peak, stage_peaks=stage_peaks, unstable=unstable,
                         implausible=implausible,
                         seconds=time.perf_counter() - t0)


# --------------------------------------------------------------------- relaxation


class _Relaxed(eqx.Module):
    """``z -> theta``: unconstrained variables to the design vector of the relaxation.

    Per stage with a free planet set, ``N`` logits ``u``: gaps ``g = g_min + (360 - N
    g_min) softmax(u)`` (deg), so no two neighbours come closer than ``g_min``; angles
    ``cumsum(g)[:-1]`` from planet 1 at 0. Phases pass through (deg).
    """

    layout: tuple = eqx.field(static=True)  # per stage: (n_planets or 0, n_phases)
    g_min: tuple = eqx.field(static=True)

    def __call__(self, z):
        out, k = [], 0
        for (N, n_phase), gmin in zip(self.layout, self.g_min):
            if N:
                u = z[k:k + N]
                k += N
                gaps = gmin + (360.0 - N * gmin) * jax.nn.softmax(u)
                out.append(jnp.cumsum(gaps)[:-1])
            if n_phase:
                out.append(z[k:k + n_phase])
                k += n_phase
        return jnp.concatenate(out)

    def start(self, theta) -> np.ndarray:
        """``z`` for a design vector ``theta`` (gaps above ``g_min`` kept; at ``g_min``,
        nudged inside by 1e-6 of the free span)."""
        theta = np.asarray(theta, dtype=float)
        out, k = [], 0
        for (N, n_phase), gmin in zip(self.layout, self.g_min):
            if N:
                angles = np.concatenate([[0.0], theta[k:k + N - 1], [360.0]])
                k += N - 1
                free = np.maximum(np.diff(angles) - gmin, 1e-6 * (360.0 - N * gmin))
                out.append(np.log(free / free.sum()))
            if n_phase:
                out.append(theta[k:k + n_phase])
                k += n_phase
        return np.concatenate(out)


@dataclasses.dataclass(frozen=True)
class Relaxation:
    """The continuous relaxation: ``values`` (path -> value, deg); ``start_peak`` (N, the
    optimum's on the relaxation's grid), ``linear_peak`` and ``linear_rms`` ``(F, m)``
    (N, on the result's common grid), ``smooth_start``, ``smooth_end`` (the smooth peak
    it minimised), ``iterations``, ``message`` (L-BFGS; where the peak on its grid did
    not fall, the start is kept and the message says so); ``assembly_violations``:
    planets off an assembly slot (it is not assemblable); ``max_slot_offset``: the
    largest distance of a planet from its nearest slot (slots, at most 0.5)."""

    values: dict
    start_peak: float
    linear_peak: float
    smooth_start: float
    smooth_end: float
    iterations: int
    message: str
    assembly_violations: int
    max_slot_offset: float
    linear_rms: np.ndarray | None


# ------------------------------------------------------------------- the optimiser


@dataclasses.dataclass(frozen=True)
class OptimizeSettings:
    """Sizes of the optimiser's steps (the expensive parts; tests use tiny ones).

    **Fields:** ``proxy_points``: frequency grid of the first-order proxy;
    ``phase_grid``: sun-ring phases tried per planet set (``360 / phase_grid`` deg
    apart), and as many stage phases where the stage phase is varied; ``screen``: best
    proxy candidates per stage solved by the linear, time-varying harmonic balance;
    ``screen_points``: its frequencies per candidate (half geometric, half the
    candidate's highest proxy peaks); ``final_points``: geometric frequencies of the
    common grid the baseline, optimum and relaxation are compared on (plus the resonance
    frequencies and their proxy peaks);
    ``harmonics``: its K (``None``: the highest excitation order, so every stiffness
    harmonic is resolved); ``nonlinear``: best linear candidates per stage swept with
    backlash (0: decide on the linear model); ``nonlinear_harmonics``: K of those sweeps
    (``None``: ``harmonics``); ``max_step_hz``, ``max_points`` (continuation points per
    sweep), ``restarts``: of the sweeps (:func:`nonlinear_band`); ``relax_iterations``:
    L-BFGS iterations of the continuous relaxation (0: skip it); ``temperature``: of its
    smooth peak (relative); ``passes``:
    rounds over the stages (a later stage's choice can unpin an earlier one's peak);
    ``chunk``: proxy designs per compiled call; ``devices``: shard the linear screen's
    designs across these (:mod:`gearjax._design`).
    """

    proxy_points: int = 256
    phase_grid: int = 24
    screen: int = 24
    screen_points: int = 32
    final_points: int = 96
    harmonics: int | None = None
    nonlinear: int = 2
    nonlinear_harmonics: int | None = None
    max_step_hz: float | None = None
    max_points: int = 400
    restarts: int = 8
    relax_iterations: int = 10
    temperature: float = 0.01
    passes: int = 1
    chunk: int = 64
    devices: tuple | None = None


@dataclasses.dataclass(frozen=True)
class Design:
    """One design and its objective values.

    **Fields:** ``values``: path -> value of every varied path (deg); ``planet_sets``:
    stage -> angles (deg); ``linear_peak``, ``linear_stage_peaks`` (N, screen grid);
    ``linear_rms`` ``(F, m)``; ``nonlinear`` (:class:`NonlinearBand` or ``None``);
    ``admissible``: every planet set assemblable and clear.
    """

    values: dict
    planet_sets: dict
    linear_peak: float
    linear_stage_peaks: dict
    linear_rms: np.ndarray
    nonlinear: NonlinearBand | None
    admissible: bool

    @property
    def nonlinear_peak(self) -> float:
        return self.nonlinear.peak if self.nonlinear is not None else math.nan


@dataclasses.dataclass(frozen=True)
class OptimizeResult:
    """A finished phasing optimisation.

    **Fields:** ``gear``, ``reference_stage``, ``band_hz`` ``(lo, hi)``, ``vary`` (the
    ``--vary`` spellings), ``paths`` (the design vector's TOML paths);
    ``baseline``, ``optimum``: :class:`Design`; ``train``: the optimum train;
    ``relaxation``: :class:`Relaxation` or ``None``; ``candidates``: dict of columns,
    one row per candidate (``stage``, ``planet_angles_deg`` ``(C, N_max)``,
    ``sun_ring_phase_deg``, ``stage_phase_deg``, ``proxy_peak``, ``linear_stage_peak``,
    ``linear_peak``, ``nonlinear_stage_peak``, ``nonlinear_peak``,
    ``nonlinear_coverage``, ``incumbent``, ``selected``; NaN where a model was not run);
    ``stages``: per stage, what was enumerated and chosen; ``frequencies_hz``: the
    screen grid; ``meshes``, ``mesh_stage``, ``mesh_side``, ``mesh_planet``;
    ``settings``; ``seconds``; ``converged``: the optimum has converged points.
    """

    gear: str
    reference_stage: str
    band_hz: tuple[float, float]
    vary: tuple[str, ...]
    paths: tuple[str, ...]
    baseline: Design
    optimum: Design
    train: Train
    baseline_train: Train
    relaxation: Relaxation | None
    candidates: dict
    stages: list
    frequencies_hz: np.ndarray
    meshes: tuple[str, ...]
    mesh_stage: tuple[str, ...]
    mesh_side: tuple[str, ...]
    mesh_planet: tuple[int, ...]
    settings: OptimizeSettings
    seconds: float

    @property
    def converged(self) -> bool:
        ok = bool(np.any(np.isfinite(self.optimum.linear_rms)))
        if self.optimum.nonlinear is not None:
            ok = ok and self.optimum.nonlinear.frequencies_hz.size > 0
        return ok


@eqx.filter_jit
def _proxy_batch(fo: FirstOrder, family, thetas):
    return jax.vmap(lambda th: first_order_rms(fo, family(th)))(thetas)


class _Screen:
    """The models over the design vector of every varied path: the first-order proxy on
    the fine grid, and the linear, time-varying harmonic balance on a grid per design
    (a shared geometric part plus the proxy's highest peaks of that design: the modes do
    not depend on the phasing, so the resonances sit where the proxy puts them)."""

    def __init__(self, train, gear, paths, f_proxy, f_shared, n_peaks, to_omega, settings,
                 devices, batch):
        self.family = GearFamily.of(train, paths, gear, linear=True)
        self.fo = first_order(self.family(self.family.theta()), to_omega(f_proxy))
        self.f_proxy = np.asarray(f_proxy)
        self.f_shared = np.asarray(f_shared)
        self.n_peaks = n_peaks
        self.to_omega = to_omega
        self.settings = settings
        self.devices = devices
        self.batch = batch

    def proxy(self, thetas) -> np.ndarray:
        """``(B, F_proxy, m)`` first-order RMS (N)."""
        return np.asarray(_proxy_batch(self.fo, self.family, jnp.asarray(thetas, dtype=float)))

    def grids(self, thetas, n_peaks: int | None = None) -> np.ndarray:
        """``(B, F)`` Hz: the shared points and each design's ``n_peaks`` highest proxy
        peaks (local maxima over frequency of the largest mesh RMS), sorted."""
        n = self.n_peaks if n_peaks is None else n_peaks
        per_f = np.max(self.proxy(thetas), axis=-1)  # (B, Fp)
        out = []
        for row in per_f:
            out.append(np.sort(np.concatenate([self.f_shared,
                                               self.f_proxy[peak_indices(row, n)]])))
        return np.asarray(out).reshape(len(per_f), -1)

    def rms(self, thetas, freqs_hz, batch: int | None = None) -> np.ndarray:
        """``(B, F, m)`` RMS (NaN where a point failed) at ``freqs_hz`` ``(B, F)``, in
        batches of ``batch`` (default ``self.batch``; padded) so calls share one shape."""
        thetas = np.asarray(thetas, dtype=float)
        om = self.to_omega(np.asarray(freqs_hz, dtype=float))
        size = batch or self.batch
        out = []
        for start in range(0, len(thetas), size):
            part, w = thetas[start:start + size], om[start:start + size]
            n = len(part)
            if n < size:
                part = np.concatenate([part, np.repeat(part[-1:], size - n, axis=0)])
                w = np.concatenate([w, np.repeat(w[-1:], size - n, axis=0)])
            rms, code = batched_rms(self.family, part, w, self.settings, solver="linear",
                                    devices=self.devices)
            rms, code = np.asarray(rms)[:n], np.asarray(code)[:n]
            out.append(np.where((code == _hb.CONVERGED)[..., None], rms, np.nan))
        return np.concatenate(out)


def peak_indices(values, n: int) -> np.ndarray:
    """Indices of the ``n`` largest local maxima of ``values`` (1-D; the ends count),
    topped up with the next largest values when there are fewer maxima."""
    v = np.asarray(values, dtype=float)
    left = np.concatenate([[-np.inf], v[:-1]])
    right = np.concatenate([v[1:], [-np.inf]])
    maxima = np.flatnonzero((v >= left) & (v >= right))
    order = list(maxima[np.argsort(-v[maxima], kind="stable")][:n])
    if len(order) < n:
        rest = [i for i in np.argsort(-v, kind="stable") if i not in set(order)]
        order += rest[:n - len(order)]
    return np.asarray(order[:n], dtype=int)


def optimize(
    train: Train,
    gear: str | None = None,
    band_hz: tuple[float, float] = (2000.0, 15000.0),
    vary: Sequence[str] | None = None,
    *,
    stage: str | None = None,
    settings: OptimizeSettings = OptimizeSettings(),
    progress: Callable[[str], None] | None = None,
) -> OptimizeResult:
    """Planet sets and phases of ``gear`` that minimise the peak RMS mesh force over a band.

    **Arguments:** ``band_hz``: ``(lo, hi)`` reference-stage mesh frequencies (Hz);
    ``vary``: phasing paths (module docstring; default :func:`default_vary`); ``stage``:
    the reference stage of the frequencies (default: the first turning one);
    ``settings``: :class:`OptimizeSettings`; ``progress(message)``: called per step.

    **Returns:** :class:`OptimizeResult`; the baseline's, optimum's and relaxation's
    linear peaks are on one common grid (``final_points`` geometric points plus the
    proxy peaks of each), the candidates' on their screen grids. **Raises:**
    ``TrainError`` for a bad band, paths, gear or stage, or settings out of range.
    """
    from ._sweep import _check_unloaded, _reference_stage

    t_start = time.perf_counter()
    say = progress or (lambda message: None)
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    mu = require_base(kin, train.source)
    ref = _reference_stage(train, kin, stage)
    mu_ref = mu[train.stage_ids.index(ref)]
    lo, hi = _check_band(band_hz)
    _check_settings(settings)
    variables = phasing_variables(train, g.name, vary)
    paths = tuple(p for v in variables for p in v.paths)
    nominal = assemble_at(train, g.name)
    if settings.nonlinear:
        _check_unloaded(train, g, kin, nominal)
    K = settings.harmonics or _harmonics.excitation_floor(nominal)
    for k in {int(K), int(settings.nonlinear_harmonics or K)}:
        _harmonics.require_harmonics(nominal, k)
        _harmonics.require_size(nominal, k, mu=mu)
    hb_settings = _hb.HarmonicBalance(n_harmonics=int(K))
    n_peaks = settings.screen_points // 2
    f_shared = np.geomspace(lo, hi, settings.screen_points - n_peaks)
    f_proxy = np.geomspace(lo, hi, settings.proxy_points)
    to_omega = lambda f: 2 * np.pi * np.asarray(f) / mu_ref  # noqa: E731
    screen = _Screen(train, g.name, paths, f_proxy, f_shared, n_peaks, to_omega, hb_settings,
                     settings.devices, settings.screen + 1)
    labels = tuple(nominal.mesh_labels)
    groups = np.asarray(nominal.mesh_group)
    K_nl = settings.nonlinear_harmonics or int(K)

    def nonlinear(t):
        return nonlinear_band(t, g.name, lo, hi, stage=ref, harmonics=K_nl,
                              max_step_hz=settings.max_step_hz,
                              max_points=settings.max_points, restarts=settings.restarts,
                              progress=say)

    def stage_peaks(rms):
        return {sid: float(peak_of(rms[None], groups == sid)[0])
                for sid in dict.fromkeys(groups.tolist())}

    def design_of(t, rms, nl):
        values = {p: float(get_path(t, p, "--vary")) for p in paths}
        sets = {v.stage: np.asarray(t.stage(v.stage).planet_angles_deg, float)
                for v in variables if v.planets}
        adm = all(planet_set_ok(t.stage(sid), a) for sid, a in sets.items())
        return Design(values=values, planet_sets=sets, linear_peak=float(peak_of(rms[None])[0]),
                      linear_stage_peaks=stage_peaks(rms), linear_rms=rms, nonlinear=nl,
                      admissible=adm)

    say(f"optimize: gear {g.name!r}, band {lo:g}-{hi:g} Hz (stage {ref}), varying "
        f"{', '.join(n for v in variables for n in v.names)}; linear screen K = {K}, "
        f"{settings.screen_points} frequencies per candidate")
    base_nl = None
    if settings.nonlinear:
        say("optimize: baseline, sweeps with backlash")
        base_nl = nonlinear(train)
        say(f"optimize: baseline peak {base_nl.peak:.1f} N (backlash)")
    current, cur_nl = train, base_nl
    rows: list[dict] = []
    stages_info = []
    for k in range(settings.passes):
        for v in variables:
            current, cur_nl, info = _optimise_stage(
                current, g.name, v, variables, kin, paths, screen, to_omega, settings, cur_nl,
                groups, nonlinear, rows, say)
            stages_info.append({"pass": k + 1, **info})
    relaxation, relaxed_theta = None, None
    theta_opt = theta_of(current, paths)
    # where the linear peaks of any phasing sit: in the relaxation's grid and the common one
    f_res = resonance_frequencies(nominal, screen.fo.orders, mu_ref, lo, hi)
    if settings.relax_iterations:
        f_relax = np.unique(np.concatenate([f_res, screen.grids(theta_opt[None])[0]]))
        say(f"optimize: continuous relaxation (L-BFGS on the linear model at {f_relax.size} "
            "frequencies: the resonances and the optimum's screen grid)")
        t0 = time.perf_counter()
        relaxation, relaxed_theta = relax(current, variables, paths, screen, f_relax, settings)
        say(f"optimize: relaxation: {relaxation.iterations} iterations in "
            f"{time.perf_counter() - t0:.1f} s ({relaxation.message})")
    # the common grid of the reported linear peaks
    finals = [theta_of(train, paths), theta_opt] + (
        [relaxed_theta] if relaxed_theta is not None else [])
    per_f = np.max(screen.proxy(np.asarray(finals)), axis=-1)
    peaks = np.concatenate([screen.f_proxy[peak_indices(row, n_peaks)] for row in per_f])
    f_final = np.unique(np.concatenate([np.geomspace(lo, hi, settings.final_points), peaks,
                                        f_res]))
    say(f"optimize: baseline and optimum{' and relaxation' if relaxation else ''} on a "
        f"common grid of {f_final.size} frequencies")
    final_rms = screen.rms(np.asarray(finals), np.broadcast_to(f_final, (len(finals),
                                                                          f_final.size)),
                           batch=len(finals))
    baseline = design_of(train, final_rms[0], base_nl)
    optimum = design_of(current, final_rms[1], cur_nl)
    if relaxation is not None:
        relaxation = dataclasses.replace(relaxation, linear_peak=float(np.nanmax(final_rms[2])),
                                         linear_rms=final_rms[2])
        say(f"optimize: relaxed peak {relaxation.linear_peak:.1f} N (linear; not "
            f"assemblable: {relaxation.assembly_violations} planets off a slot, up to "
            f"{relaxation.max_slot_offset:.2f} slot)")
    say(f"optimize: peak {baseline.linear_peak:.1f} -> {optimum.linear_peak:.1f} N (linear)"
        + (f", {baseline.nonlinear_peak:.1f} -> {optimum.nonlinear_peak:.1f} N (backlash)"
           if base_nl is not None else ""))
    return OptimizeResult(
        gear=g.name, reference_stage=ref, band_hz=(lo, hi),
        vary=tuple(n for v in variables for n in v.names), paths=paths, baseline=baseline,
        optimum=optimum, train=current, baseline_train=train, relaxation=relaxation,
        candidates=_columns(rows, max(v.n_planets for v in variables)), stages=stages_info,
        frequencies_hz=f_final, meshes=labels, mesh_stage=tuple(nominal.mesh_group),
        mesh_side=tuple(nominal.mesh_side), mesh_planet=tuple(nominal.mesh_planet),
        settings=settings, seconds=time.perf_counter() - t_start)


def _optimise_stage(current, gear, v, variables, kin, paths, screen, to_omega, settings,
                    cur_nl, groups, nonlinear, rows, say):
    """Screen, rank and choose stage ``v.stage``'s variables. **Returns:** ``(train,
    NonlinearBand or None, summary)`` of the new incumbent."""
    sid = v.stage
    st = current.stage(sid)
    everywhere = np.ones(len(groups), dtype=bool)
    # candidates: planet sets x sun-ring phases x stage phases (the proxy picks the phases
    # per set); one set per class of sets the model cannot tell apart
    shift = bool(v.planets and v.stage_phase and current.phasing == "physical")
    if v.planets:
        every = admissible_planet_sets(st)
        reps, sizes = phasing_classes(st, every, modulo_shift=shift)
        sets = every[reps]
        n_all = len(every)
    else:
        sets = np.asarray(st.planet_angles_deg, float)[None]
        n_all = 1
    grid = 360.0 * np.arange(settings.phase_grid) / settings.phase_grid
    gamma0, phase0 = float(st.sun_ring_phase_deg), float(st.stage_phase_deg)
    gammas = (gamma0 + grid if v.sun_ring else np.array([gamma0])) % 360.0
    phases = (phase0 + grid if v.stage_phase else np.array([phase0])) % 360.0
    t0 = time.perf_counter()
    proxy = proxy_screen(current, gear, sid, sets, gammas, to_omega(screen.f_proxy),
                         everywhere, settings.chunk,
                         stage_phases_deg=phases if v.stage_phase else None)
    proxy = proxy.reshape(len(sets), len(gammas) * len(phases), -1)  # (S, G P, depth)
    best_g = np.asarray([leximax_order(p)[0] for p in proxy])
    proxy_best = proxy[np.arange(len(sets)), best_g]  # (S, depth)
    gamma_of = gammas[best_g // len(phases)]
    phase_of = phases[best_g % len(phases)]
    balance = np.asarray([planet_imbalance(a) for a in sets])
    order = leximax_order(proxy_best, RANK_RTOL, tie=np.round(balance, 6))
    say(f"optimize: stage {sid}: {n_all} planet sets, {len(sets)} distinct phasings"
        + (" up to a rotation" if shift else "") + f", x {len(gammas)} sun-ring"
        + (f" x {len(phases)} stage" if v.stage_phase else "")
        + f" phases by the first-order proxy in {time.perf_counter() - t0:.1f} s; best peak "
        f"{proxy_best[order[0], 0]:.1f} N")
    top = order[:settings.screen]
    cands = [_with_stage(current, v, sets[c], gamma_of[c], phase_of[c]) for c in top]
    t0 = time.perf_counter()
    thetas = np.asarray([theta_of(t, paths) for t in [current] + cands])
    rms = screen.rms(thetas, screen.grids(thetas))
    profile = band_profile(rms)
    lin_stage = peak_of(rms, groups == sid)
    lin_all = peak_of(rms)
    ranking = leximax_order(  # 0 is the incumbent; a tie goes to the better-balanced set
        profile, RANK_RTOL, tie=np.round([planet_imbalance(t.stage(sid).planet_angles_deg)
                                          for t in [current] + cands], 6))
    say(f"optimize: stage {sid}: {len(top)} candidates by the linear harmonic balance in "
        f"{time.perf_counter() - t0:.1f} s; best peak {lin_all[ranking[0]]:.1f} N "
        f"(incumbent {lin_all[0]:.1f} N)")
    rows.append(_row(sid, st.planet_angles_deg, gamma0, phase0, math.nan,
                     lin_stage[0], lin_all[0], incumbent=True))
    row_of = [len(rows) - 1]
    for rank, c in enumerate(order):
        lin = (lin_stage[1 + rank], lin_all[1 + rank]) if rank < len(top) else (math.nan,) * 2
        rows.append(_row(sid, sets[c], gamma_of[c], phase_of[c], proxy_best[c, 0], *lin))
        if rank < len(top):
            row_of.append(len(rows) - 1)
    better = [int(i) for i in ranking[:int(np.flatnonzero(ranking == 0)[0])]
              if np.isfinite(lin_all[i])]  # candidates ranked above the incumbent
    pick = 0
    swept = 0
    if settings.nonlinear and cur_nl is not None and better:
        rows[row_of[0]].update(nonlinear_stage_peak=cur_nl.stage_peaks.get(sid, math.nan),
                               nonlinear_peak=cur_nl.peak, nonlinear_coverage=cur_nl.coverage)
        results = {0: cur_nl}
        for i in better[:settings.nonlinear]:
            t = cands[i - 1]
            say(f"optimize: stage {sid}: candidate {_show_set(t.stage(sid).planet_angles_deg)}"
                f", sun-ring {float(t.stage(sid).sun_ring_phase_deg):.1f} deg, sweeps with "
                "backlash")
            nl = nonlinear(t)
            swept += 1
            results[i] = nl
            rows[row_of[i]].update(nonlinear_stage_peak=nl.stage_peaks.get(sid, math.nan),
                                   nonlinear_peak=nl.peak, nonlinear_coverage=nl.coverage)
            say(f"optimize: stage {sid}: peak {nl.peak:.1f} N with backlash (incumbent "
                f"{cur_nl.peak:.1f} N), band coverage {nl.coverage:.3f}")
        rank_of = {int(i): k for k, i in enumerate(ranking)}
        fair = [i for i, nl in results.items()
                if np.isfinite(nl.peak) and nl.coverage >= min(0.95, cur_nl.coverage)]
        scale = max(results[i].peak for i in fair)
        pick = min(fair, key=lambda i: (round(results[i].peak / (NONLINEAR_RTOL * scale)),
                                        rank_of[i]))
        new_nl = results[pick]
    else:
        pick = int(ranking[0]) if np.isfinite(lin_all[ranking[0]]) else 0
        new_nl = cur_nl if pick == 0 else None
    rows[row_of[pick]]["selected"] = True
    if pick == 0:
        chosen = "incumbent kept"
        new = (current, cur_nl)
    else:
        t = cands[pick - 1]
        chosen = (f"{_show_set(t.stage(sid).planet_angles_deg)}, sun-ring "
                  f"{float(t.stage(sid).sun_ring_phase_deg):.1f} deg"
                  + (f", stage phase {float(t.stage(sid).stage_phase_deg):.1f} deg"
                     if v.stage_phase else ""))
        new = (t, new_nl)
    say(f"optimize: stage {sid}: {chosen}")
    info = {"stage": sid, "planet_sets": int(n_all), "screened_sets": int(len(sets)),
            "modulo_rotation": shift, "sun_ring_phases": int(len(gammas)),
            "stage_phases": int(len(phases)),
            "linear_screened": int(len(top)), "nonlinear_swept": swept, "chosen": chosen}
    return (*new, info)


def band_profile(rms, depth: int = TIE_DEPTH) -> np.ndarray:
    """``(B, depth)``: the ``depth`` largest values, descending, of the per-frequency peak
    over meshes of ``rms`` ``(B, F, m)`` (NaN where a point failed sorts last)."""
    per_f = np.max(np.where(np.isfinite(rms), rms, -np.inf), axis=-1)
    out = -np.sort(-per_f, axis=-1)[:, :depth]
    return np.where(np.isfinite(out), out, np.nan)


def leximax_order(profiles, rtol: float = 1e-6, tie=None) -> np.ndarray:
    """Indices of the rows of ``profiles`` ``(B, k)`` (each descending: the largest
    values of a response over the band) from best to worst: by the peak, ties (within
    ``rtol`` of the largest value) broken by the next largest value, and so on; rows
    still tied go by ``tie`` ``(B,)`` (smaller first), then by index. Rows with a NaN
    peak go last.

    Why: a stage's phasing cannot lower a peak that another stage's excitation sets (a
    torsional mode driven by the other stage loads every ring mesh alike); the peak then
    ties across the stage's candidates and the next values decide.
    """
    p = np.asarray(profiles, dtype=float)
    p = p.reshape(p.shape[0], -1)
    scale = np.nanmax(np.abs(p)) if np.any(np.isfinite(p)) else 1.0
    q = np.where(np.isfinite(p), np.round(p / (rtol * (scale or 1.0))), np.inf)
    keys = [q[:, k] for k in range(q.shape[1] - 1, -1, -1)]
    if tie is not None:
        keys.insert(0, np.asarray(tie, dtype=float))
    return np.lexsort(tuple(keys))


def _with_stage(train, v: StageVariables, angles, gamma, stage_phase=None):
    t = train
    if v.planets:
        for i, a in enumerate(np.asarray(angles, float)[1:], start=2):
            t = set_path(t, f"{v.stage}.planet_angles_deg.{i}", float(a), "--vary")
    if v.sun_ring:
        t = set_path(t, f"{v.stage}.sun_ring_phase_deg", float(gamma), "--vary")
    if v.stage_phase and stage_phase is not None:
        t = set_path(t, f"{v.stage}.stage_phase_deg", float(stage_phase), "--vary")
    return t


def theta_of(train, paths) -> np.ndarray:
    """The values (file units) of ``paths`` in ``train``."""
    return np.asarray([float(get_path(train, p, "--vary")) for p in paths])


def train_at(train, paths, theta) -> Train:
    """``train`` with ``paths`` set to ``theta``."""
    for p, x in zip(paths, np.asarray(theta, float)):
        train = set_path(train, p, float(x), "--vary")
    return train


def _row(stage, angles, gamma, phase, proxy, lin_stage, lin_all, incumbent=False) -> dict:
    return dict(stage=stage, planet_angles_deg=np.asarray(angles, float),
                sun_ring_phase_deg=float(gamma), stage_phase_deg=float(phase),
                proxy_peak=float(proxy), linear_stage_peak=float(lin_stage),
                linear_peak=float(lin_all), nonlinear_stage_peak=math.nan,
                nonlinear_peak=math.nan, nonlinear_coverage=math.nan,
                incumbent=incumbent, selected=False)


def _columns(rows, n_max) -> dict:
    out = {k: [] for k in rows[0]} if rows else {}
    for r in rows:
        for k, val in r.items():
            if k == "planet_angles_deg":
                pad = np.full(n_max, np.nan)
                pad[:len(val)] = val
                val = pad
            out[k].append(val)
    return {k: np.asarray(v) for k, v in out.items()}


def _show_set(angles) -> str:
    return "[" + ", ".join(f"{a:g}" for a in np.asarray(angles, float)) + "] deg"


def _check_band(band_hz) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in band_hz)
    except (TypeError, ValueError):
        raise fail("command line", "--band", band_hz, "needs two frequencies LO HI in Hz"
                   ) from None
    if not (0 < lo < hi and math.isfinite(hi)):
        raise fail("command line", "--band", [lo, hi],
                   "needs 0 < LO < HI, reference-stage mesh frequencies in Hz")
    return lo, hi


def _check_settings(s: OptimizeSettings) -> None:
    for name, flag, low in (("proxy_points", "--proxy-points", 2),
                            ("phase_grid", "--phase-grid", 1), ("screen", "--screen", 1),
                            ("screen_points", "--points", 2), ("nonlinear", "--nonlinear", 0),
                            ("final_points", "--final-points", 2),
                            ("restarts", "--restarts", 0),
                            ("max_points", "--max-points", 2),
                            ("relax_iterations", "--relax-iterations", 0),
                            ("passes", "--passes", 1),
                            ("chunk", "--chunk", 1)):
        val = getattr(s, name)
        if int(val) != val or val < low:
            raise fail("command line", flag, val, f"must be an integer >= {low}")
    for name, flag in (("harmonics", "--harmonics"), ("nonlinear_harmonics", "--harmonics")):
        val = getattr(s, name)
        if val is not None and (int(val) != val or val < 1):
            raise fail("command line", flag, val, "must be an integer >= 1")
    if s.max_step_hz is not None and not (s.max_step_hz > 0 and math.isfinite(s.max_step_hz)):
        raise fail("command line", "--max-step", s.max_step_hz, "must be > 0 Hz")
    if not s.temperature > 0:
        raise fail("command line", "--temperature", s.temperature, "must be > 0")


# ------------------------------------------------------------------------ relaxation


def _wrap_deg(x) -> float:
    """``x`` (deg) in ``[0, 360)``, with values a rounding error below 360 as 0."""
    v = float(x) % 360.0
    return 0.0 if v > 360.0 - 1e-9 else v


def resonance_frequencies(system, orders, mu_ref: int, lo: float, hi: float) -> np.ndarray:
    """Reference-stage mesh frequencies (Hz) in ``[lo, hi]`` where an excitation of base
    order ``o`` meets an elastic natural frequency ``f_k`` of the mean-stiffness model,
    ``mu_ref f_k / o``: where every linear peak of every phasing sits (the phasing
    changes how hard a mode is driven, not where), sorted."""
    from ._modal import modes

    hz = np.asarray([m.hz for m in modes(system).modes if m.cls == "elastic"], dtype=float)
    f = np.asarray([mu_ref * fk / o for fk in np.unique(np.round(hz, 6)) for o in orders
                    if o > 0], dtype=float)
    return np.unique(np.round(f[(f >= lo) & (f <= hi)], 6))


def relax(train: Train, variables, paths, screen: _Screen, freqs_hz,
          settings: OptimizeSettings) -> tuple[Relaxation, np.ndarray]:
    """Minimise the smooth peak of the linear model at ``freqs_hz`` over continuous planet
    angles (gaps kept above the overlap limit) and phases, from ``train``'s values, by
    L-BFGS with gradients from ``jax.grad`` (module docstring). **Returns:**
    ``(Relaxation, design vector)``; the relaxation's peak is at ``freqs_hz`` until the
    caller re-evaluates it."""
    layout, gmin = [], []
    for v in variables:
        st = train.stage(v.stage)
        N = st.n_planets if v.planets else 0
        layout.append((N, int(v.sun_ring) + int(v.stage_phase)))
        gmin.append(min_planet_gap_deg(st) * (1 + 1e-9) if N else 0.0)
    mapping = _Relaxed(layout=tuple(layout), g_min=tuple(gmin))
    theta0 = theta_of(train, paths)
    z0 = mapping.start(theta0)
    family, hb_settings = screen.family, screen.settings
    omegas = jnp.asarray(screen.to_omega(np.asarray(freqs_hz, dtype=float)))

    def rms_of(z):
        return batched_rms(family, mapping(z)[None], omegas, hb_settings, solver="linear")[0]

    hard = jax.jit(lambda z: jnp.max(rms_of(z)))
    peak0 = float(hard(jnp.asarray(z0)))
    tau = settings.temperature * peak0
    smooth = lambda z: tau * jax.scipy.special.logsumexp(rms_of(z) / tau)  # noqa: E731
    value_and_grad = jax.jit(jax.value_and_grad(smooth))

    def fun(z):
        val, grad = value_and_grad(jnp.asarray(z))
        return float(val), np.asarray(grad, dtype=float)

    s0 = fun(z0)[0]
    res = scipy.optimize.minimize(fun, z0, jac=True, method="L-BFGS-B",
                                  options={"maxiter": settings.relax_iterations})
    message = str(res.message)
    z = res.x
    if not (res.fun <= s0 and float(hard(jnp.asarray(z))) <= peak0):
        z, message = z0, f"no descent of the peak, start kept ({message})"
    theta = np.asarray(mapping(jnp.asarray(z)))
    values = {p: _wrap_deg(x) for p, x in zip(paths, theta)}
    relaxed = train_at(train, paths, [values[p] for p in paths])
    off, worst = 0, 0.0
    for v in variables:
        if v.planets:
            a = np.asarray(relaxed.stage(v.stage).planet_angles_deg, float)
            q = assembly_slots(relaxed.stage(v.stage)) * a / 360.0
            off += int(np.sum(np.abs(q - np.round(q)) > 1e-6))
            worst = max(worst, float(np.max(np.abs(q - np.round(q)))))
    return Relaxation(values=values, start_peak=peak0, linear_peak=float(hard(jnp.asarray(z))),
                      smooth_start=float(s0), smooth_end=float(min(res.fun, s0)),
                      iterations=int(res.nit), message=message,
                      assembly_violations=off, max_slot_offset=worst, linear_rms=None), theta


# ----------------------------------------------------------------- results, JSON


def _settings_dict(settings: OptimizeSettings) -> dict:
    out = {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}
    out["devices"] = None if settings.devices is None else len(list(settings.devices))
    return out


def _design_json(d: Design) -> dict:
    nl = d.nonlinear
    return {
        "values": d.values,
        "planet_angles_deg": {k: v.tolist() for k, v in d.planet_sets.items()},
        "admissible": d.admissible,
        "linear_peak": d.linear_peak,
        "linear_stage_peaks": d.linear_stage_peaks,
        "nonlinear_peak": None if nl is None else nl.peak,
        "nonlinear_stage_peaks": None if nl is None else nl.stage_peaks,
        "nonlinear_coverage": None if nl is None else nl.coverage,
        "nonlinear_unstable_points": None if nl is None else nl.unstable,
        "nonlinear_implausible_points": None if nl is None else nl.implausible,
        "nonlinear_sweeps": None if nl is None else [
            {"from_hz": a, "stop": b} for a, b in zip(nl.starts_hz, nl.stops)],
    }


def optimize_json(result: OptimizeResult) -> dict:
    """The ``optimize`` JSON: ``baseline``, ``optimum`` (values, peaks), ``improvement``
    (optimum / baseline peak, linear and with backlash), ``relaxation``, ``stages``,
    ``candidates`` (those solved by the linear harmonic balance), settings."""
    b, o = result.baseline, result.optimum
    ratio = lambda x, y: (x / y) if (y and np.isfinite(x) and np.isfinite(y)) else None  # noqa
    cand = result.candidates
    rows = []
    for k in np.flatnonzero(np.isfinite(cand["linear_peak"])):
        row = {key: (val[k].tolist() if isinstance(val[k], np.ndarray) else val[k])
               for key, val in cand.items()}
        row["planet_angles_deg"] = [a for a in row["planet_angles_deg"] if np.isfinite(a)]
        rows.append(row)
    r = result.relaxation
    return {
        "gear": result.gear,
        "reference_stage": result.reference_stage,
        "band_hz": list(result.band_hz),
        "vary": list(result.vary),
        "objective": "largest RMS alternating mesh force over the band and every mesh (N)",
        "baseline": _design_json(b),
        "optimum": _design_json(o),
        "improvement": {"linear": ratio(o.linear_peak, b.linear_peak),
                        "nonlinear": ratio(o.nonlinear_peak, b.nonlinear_peak)},
        "relaxation": None if r is None else {
            "values": r.values, "linear_peak": r.linear_peak, "start_peak": r.start_peak,
            "iterations": r.iterations, "message": r.message, "assemblable": False,
            "assembly_violations": r.assembly_violations,
            "max_slot_offset": r.max_slot_offset},
        "stages": result.stages,
        "candidates": rows,
        "settings": _settings_dict(result.settings),
        "seconds": result.seconds,
    }


def optimize_frame(result: OptimizeResult):
    """Baseline, optimum and relaxation side by side: a ``pandas.DataFrame`` with one row
    per design and the columns ``linear peak (N)`` (common grid), ``backlash peak (N)``
    (stable points of the sweeps; NaN where not swept), the linear peak of each stage's
    meshes, each varied stage's planet angles (deg), planet imbalance
    (:func:`planet_imbalance`), sun-ring and stage phases (deg), and ``assemblable``."""
    import pandas as pd

    b, o, r = result.baseline, result.optimum, result.relaxation
    stages = list(dict.fromkeys(result.mesh_stage))
    rows = {}
    designs = [("baseline", b.values, b.linear_rms, b.nonlinear_peak, b.admissible),
               ("optimum", o.values, o.linear_rms, o.nonlinear_peak, o.admissible)]
    if r is not None:
        designs.append(("relaxed", r.values, r.linear_rms, math.nan, False))
    for name, values, rms, nl, ok in designs:
        row = {"linear peak (N)": float(np.nanmax(rms)), "backlash peak (N)": nl}
        for sid in stages:
            cols = np.asarray(result.mesh_stage) == sid
            row[f"stage {sid} linear peak (N)"] = float(np.nanmax(rms[:, cols]))
        for sid in stages:
            angles = [0.0] + [values[p] for p in values
                              if p.startswith(f"{sid}.planet_angles_deg.")]
            if len(angles) > 1:
                row[f"{sid}.planet_angles_deg"] = np.round(angles, 3).tolist()
                row[f"{sid} imbalance"] = planet_imbalance(angles)
            for key in ("sun_ring_phase_deg", "stage_phase_deg"):
                if f"{sid}.{key}" in values:
                    row[f"{sid}.{key}"] = values[f"{sid}.{key}"]
        row["assemblable"] = bool(ok)
        rows[name] = row
    return pd.DataFrame(rows).T


def optimize_dataset(result: OptimizeResult, attrs: dict | None = None):
    """The optimisation as an ``xarray.Dataset`` (``kind = "optimize"``).

    Dimensions ``candidate`` (every screened candidate, stage by stage, the incumbent
    first), ``planet`` (1-based, padded with NaN), ``frequency`` (the linear screen's
    grid), ``mesh`` (with ``stage``, ``side``, ``planet_of_mesh`` coordinates), ``design``
    (``baseline``, ``optimum``) and, with backlash, ``baseline_point`` and
    ``optimum_point`` (the converged points of their sweeps). Variables: the candidate
    columns of :class:`OptimizeResult` (``proxy_peak`` etc., N), ``linear_rms``
    (``design, frequency, mesh``, N), ``baseline_nonlinear_rms`` /
    ``optimum_nonlinear_rms`` with their ``..._frequency_hz``. Attributes: ``kind``,
    ``gear``, ``reference_stage``, ``band_hz``, ``vary``, the peaks
    (``baseline_peak_linear``, ``optimum_peak_linear``, ``baseline_peak_nonlinear``,
    ``optimum_peak_nonlinear``, ``relaxed_peak_linear``; NaN where not computed), the
    values (JSON), ``stages``, ``settings``, ``train_toml`` (the optimum),
    ``baseline_train_toml``, ``gearjax_version``, ``created``.
    """
    import datetime

    import xarray as xr

    from . import __version__
    from ._results import _attr
    from ._toml_io import dumps_train

    c = result.candidates
    r = result.relaxation
    n_max = c["planet_angles_deg"].shape[1]
    units = {"proxy_peak": "N", "linear_stage_peak": "N", "linear_peak": "N",
             "nonlinear_stage_peak": "N", "nonlinear_peak": "N", "nonlinear_coverage": "1",
             "sun_ring_phase_deg": "deg", "stage_phase_deg": "deg", "incumbent": "1",
             "selected": "1"}
    names = {"proxy_peak": "largest RMS mesh force, first-order proxy",
             "linear_stage_peak": "largest RMS force of the stage's meshes, linear HB",
             "linear_peak": "largest RMS mesh force, linear time-varying HB",
             "nonlinear_stage_peak": "largest RMS force of the stage's meshes, with backlash",
             "nonlinear_peak": "largest RMS mesh force, sweeps with backlash",
             "nonlinear_coverage": "share of the band (log frequency) the sweeps traced",
             "sun_ring_phase_deg": "sun-ring phase", "stage_phase_deg": "stage phase",
             "incumbent": "the design before this stage's step",
             "selected": "chosen at this stage's step"}
    data = {
        "candidate_stage": ("candidate", c["stage"].astype(str), {"long_name": "stage varied"}),
        "planet_angles_deg": (("candidate", "planet"), c["planet_angles_deg"],
                              {"units": "deg", "long_name": "planet angles of the stage"}),
    }
    for key in units:
        data[key] = ("candidate", c[key], {"units": units[key], "long_name": names[key]})
    data["linear_rms"] = (("design", "frequency", "mesh"),
                          np.stack([result.baseline.linear_rms, result.optimum.linear_rms]
                                   + ([r.linear_rms] if r is not None else [])),
                          {"units": "N", "long_name": "RMS alternating mesh force, linear "
                           "time-varying harmonic balance"})
    for which, d in (("baseline", result.baseline), ("optimum", result.optimum)):
        if d.nonlinear is not None:
            data[f"{which}_nonlinear_frequency_hz"] = (
                f"{which}_point", d.nonlinear.frequencies_hz,
                {"units": "Hz", "long_name": "reference-stage mesh frequency"})
            data[f"{which}_nonlinear_rms"] = (
                (f"{which}_point", "mesh"), d.nonlinear.rms_force,
                {"units": "N", "long_name": "RMS alternating mesh force with backlash"})
    coords = {
        "candidate": np.arange(len(c["stage"])),
        "planet": np.arange(1, n_max + 1),
        "frequency": ("frequency", result.frequencies_hz,
                      {"units": "Hz", "long_name": "reference-stage mesh frequency"}),
        "mesh": np.asarray(result.meshes, dtype=str),
        "stage": ("mesh", np.asarray(result.mesh_stage, dtype=str)),
        "side": ("mesh", np.asarray(result.mesh_side, dtype=str)),
        "planet_of_mesh": ("mesh", np.asarray(result.mesh_planet, dtype=np.int64)),
        "design": np.asarray(["baseline", "optimum"] + (["relaxed"] if r is not None else [])),
    }
    out = {
        "kind": "optimize",
        "gear": result.gear,
        "reference_stage": result.reference_stage,
        "band_hz": list(result.band_hz),
        "vary": list(result.vary),
        "objective": "largest RMS alternating mesh force over the band and every mesh (N)",
        "baseline_peak_linear": result.baseline.linear_peak,
        "optimum_peak_linear": result.optimum.linear_peak,
        "baseline_peak_nonlinear": result.baseline.nonlinear_peak,
        "optimum_peak_nonlinear": result.optimum.nonlinear_peak,
        "relaxed_peak_linear": math.nan if r is None else r.linear_peak,
        "baseline_values": result.baseline.values,
        "optimum_values": result.optimum.values,
        "relaxed_values": {} if r is None else r.values,
        "stages": result.stages,
        "settings": _settings_dict(result.settings),
        "train_toml": dumps_train(result.train),
        "baseline_train_toml": dumps_train(result.baseline_train),
        "gearjax_version": __version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "seconds": result.seconds,
    }
    out.update(attrs or {})
    return xr.Dataset(data, coords=coords, attrs={k: _attr(v) for k, v in out.items()})


# ------------------------------------------------------------------------- re-check


@dataclasses.dataclass(frozen=True)
class Recheck:
    """An independent re-check of a phasing optimisation (:func:`recheck`).

    **Fields:** ``band_hz``: the band swept; ``sweeps``: ``{"baseline", "optimum"}`` ->
    :class:`~gearjax.SweepResult`, fresh sweeps with backlash (the sweep's own
    frequency-dependent harmonics, no point budget of the optimiser); ``orbits``: the same
    keys -> results Dataset of the time integration started from the sweep's peak orbit
    (one point); ``verify``: the same keys -> :class:`~gearjax.VerifyResult` at
    ``verify_hz`` (harmonic balance solved afresh at each point, then integrated);
    ``peaks``: ``pandas.DataFrame``, one row per design: the optimiser's peaks (linear,
    with backlash), the fresh sweep's peak over its stable points (N), where and on which
    mesh, the integration's RMS of that mesh from that orbit and their difference, the
    sweep's points, unstable points, restarts and stop; ``points``: ``pandas.DataFrame``,
    one row per design and ``verify_hz`` frequency: the largest RMS mesh force by
    harmonic balance and by integration (N), the largest stage-relative difference, the
    integration result, whether every mesh is within the tolerance; ``seconds``.
    """

    band_hz: tuple[float, float]
    verify_hz: tuple[float, ...]
    sweeps: dict
    orbits: dict
    verify: dict
    peaks: object
    points: object
    seconds: float


def band_peak(ds, max_dlf: float = MAX_DLF) -> tuple[float, float, str, int]:
    """``(peak RMS (N), reference-stage Hz, mesh, point index)`` of a sweep Dataset over
    its converged, stable points whose load factors are at most ``max_dlf`` (as
    :class:`NonlinearBand`); ``(nan, nan, "", -1)`` when there is none."""
    ok = np.asarray(ds["converged"].values, bool) & (np.asarray(ds["stable"].values) == 1)
    dlf = np.asarray(ds["dlf"].values, float)
    ok &= np.nanmax(np.where(np.isfinite(dlf), dlf, 0.0), axis=1) <= max_dlf
    rms = np.where(ok[:, None], np.asarray(ds["rms_force"].values, float), -np.inf)
    if not np.any(np.isfinite(rms)):
        return math.nan, math.nan, "", -1
    i, j = np.unravel_index(int(np.argmax(rms)), rms.shape)
    return (float(rms[i, j]), float(ds["mesh_frequency_hz"].values[i]),
            str(ds["mesh"].values[j]), int(i))


def point_state(ds, i: int):
    """``(x0, v0)`` ``(n,)``: the state at ``t = 0`` of point ``i`` of a sweep Dataset
    (its ``displacement_cos`` / ``displacement_sin`` harmonics), to start an integration
    on that orbit (:func:`~gearjax.hb_initial_state`)."""
    from ._results import displacement_coefficients
    from ._time_domain import hb_initial_state

    X = displacement_coefficients(ds, i)
    eta = json_solver(ds).get("eta", 1)
    return hb_initial_state(jnp.asarray(X), float(ds["omega"].values[i]), int(eta))


def json_solver(ds) -> dict:
    import json

    try:
        return json.loads(ds.attrs.get("solver", "{}"))
    except ValueError:
        return {}


def _recheck_designs(result) -> tuple[str, str, tuple, dict]:
    """``(gear, reference stage, band, {name: (train, linear peak, backlash peak)})`` of an
    :class:`OptimizeResult` or of its Dataset."""
    if isinstance(result, OptimizeResult):
        return result.gear, result.reference_stage, result.band_hz, {
            "baseline": (result.baseline_train, result.baseline.linear_peak,
                         result.baseline.nonlinear_peak),
            "optimum": (result.train, result.optimum.linear_peak,
                        result.optimum.nonlinear_peak)}
    import json

    from ._toml_io import loads_train

    attrs = getattr(result, "attrs", {})
    if attrs.get("kind") != "optimize":
        raise ValueError("recheck needs an OptimizeResult or its Dataset (kind 'optimize'), "
                         f"not {type(result).__name__} of kind {attrs.get('kind')!r}")
    band = attrs["band_hz"]
    band = json.loads(band) if isinstance(band, str) else list(band)
    peak = lambda key: float(attrs.get(key, math.nan))  # noqa: E731
    return str(attrs["gear"]), str(attrs["reference_stage"]), tuple(band), {
        "baseline": (loads_train(attrs["baseline_train_toml"]), peak("baseline_peak_linear"),
                     peak("baseline_peak_nonlinear")),
        "optimum": (loads_train(attrs["train_toml"]), peak("optimum_peak_linear"),
                    peak("optimum_peak_nonlinear"))}


def recheck(
    result,
    band_hz: tuple[float, float] | None = None,
    *,
    verify_hz: Sequence[float] | None = None,
    harmonics: int | None = None,
    max_step_hz: float | None = None,
    max_points: int = 3000,
    progress: Callable[[str], None] | None = None,
) -> Recheck:
    """Re-check the baseline and the optimum of ``result`` independently of the optimiser.

    ``result``: an :class:`OptimizeResult`, or the Dataset of a saved one
    (:func:`optimize_dataset`, ``gearjax optimize --out``; ``gj.load_results``).

    For each design: (1) a fresh sweep with backlash over ``band_hz`` (default the
    optimisation's band; a part of it around the peaks is cheaper) by
    :func:`gearjax.sweep` with its own frequency-dependent harmonics (``harmonics``: a
    fixed K instead), ``max_step_hz`` and ``max_points``; its peak over stable points
    (:func:`band_peak`); (2) time integration (diffrax) started from the sweep's peak
    orbit: a stable orbit is what the integration settles on, with the same RMS; (3)
    :func:`gearjax.verify_gear` at ``verify_hz`` (default: the fresh peak frequencies of
    both designs), the harmonic balance solved afresh there and integrated.

    **Returns:** :class:`Recheck` (tables ``peaks`` and ``points``). **Raises:**
    ``TrainError`` for a bad band or frequencies, as :func:`gearjax.sweep`.
    """
    import pandas as pd

    from ._simulate import simulate_gear
    from ._sweep import sweep
    from ._verify import verify_gear

    t0 = time.perf_counter()
    say = progress or (lambda message: None)
    gear, ref, band, designs = _recheck_designs(result)
    lo, hi = _check_band(band if band_hz is None else band_hz)
    sweeps, orbits, peak_rows, peak_at = {}, {}, [], {}
    for name, (train, linear_peak, nonlinear_peak) in designs.items():
        say(f"recheck: {name}, sweep with backlash {lo:g}-{hi:g} Hz")
        sw = sweep(train, gear, lo, hi, stage=ref,
                   harmonics=harmonics, max_step_hz=max_step_hz, max_points=max_points)
        sweeps[name] = sw
        ds = sw.dataset
        peak, f_peak, mesh, i = band_peak(ds)
        row = {"design": name, "optimiser linear peak (N)": linear_peak,
               "optimiser backlash peak (N)": nonlinear_peak,
               "sweep peak (N)": peak, "at (Hz)": f_peak, "mesh": mesh}
        if i >= 0:
            peak_at[name] = f_peak
            say(f"recheck: {name}, {ds.sizes['point']} points in {sw.seconds:.0f} s, peak "
                f"{peak:.1f} N at {f_peak:.1f} Hz ({mesh}); integrating from that orbit")
            x0, v0 = point_state(ds, i)
            ni = simulate_gear(train, gear, [f_peak], stage=ref, x0=x0, v0=v0)
            orbits[name] = ni
            j = list(ds["mesh"].values).index(mesh)
            rms_ni = float(ni["rms_force"].values[0, j])
            row.update({"integrated (N)": rms_ni, "rel diff": abs(rms_ni - peak) / peak,
                        "integration": str(ni["result"].values[0])})
        else:
            row.update({"integrated (N)": math.nan, "rel diff": math.nan,
                        "integration": "no stable point"})
        stable = np.asarray(ds["stable"].values)
        row.update({"points": int(ds.sizes["point"]), "unstable": int(np.sum(stable == 0)),
                    "restarts": len(sw.restarts), "stop": sw.stop,
                    "sweep seconds": sw.seconds})
        peak_rows.append(row)
    if verify_hz is None:
        verify_hz = sorted(set(round(f, 3) for f in peak_at.values()))
    verify_hz = tuple(float(f) for f in verify_hz)
    checks, point_rows = {}, []
    if verify_hz:
        for name, (train, *_) in designs.items():
            say(f"recheck: {name}, harmonic balance and time integration at "
                f"{', '.join(f'{f:g}' for f in verify_hz)} Hz")
            v = verify_gear(train, gear, list(verify_hz), stage=ref, harmonics=harmonics)
            checks[name] = v
            for k, f in enumerate(verify_hz):
                hb_row, ni_row = v.rms_hb[k], v.rms_ni[k]
                j = int(np.nanargmax(hb_row)) if np.any(np.isfinite(hb_row)) else 0
                point_rows.append({
                    "design": name, "Hz": f, "mesh": str(v.hb["mesh"].values[j]),
                    "harmonic balance (N)": float(hb_row[j]),
                    "integration (N)": float(ni_row[j]),
                    "max rel diff": float(np.nanmax(v.rel_diff[k]))
                    if np.any(np.isfinite(v.rel_diff[k])) else math.nan,
                    "hb stable": bool(v.hb["stable"].values[k] == 1),
                    "integration": str(v.ni["result"].values[k]),
                    "all meshes ok": bool(np.all(v.ok[k]))})
    return Recheck(band_hz=(lo, hi), verify_hz=verify_hz, sweeps=sweeps, orbits=orbits,
                   verify=checks, peaks=pd.DataFrame(peak_rows).set_index("design"),
                   points=pd.DataFrame(point_rows), seconds=time.perf_counter() - t0)
