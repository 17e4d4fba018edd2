"""The first-order proxy: mesh forces to first order in the stiffness variation.

The forced response to first order in the stiffness variation is, per base excitation
order ``o``, ``F_o = (I - D_o W H(o Omega) W^T) q_o`` with
``q_o = kbar kappa_o p_static - (kbar + i o Omega c) e_o``, ``H`` the mean-stiffness
receptance and ``D_o = diag(kbar + i o Omega c)``: the phasing cancellation of every
stiffness harmonic weighted by the modes it drives. The transfer matrices are computed
once (:class:`FirstOrder`; phasing does not change them) and every planet set and phase
pair is then a few small products (:func:`proxy_screen`).

On a torus (``G > 1`` incommensurate frequency groups, model.md) an excitation tone is a
pair ``(angle g, order o)`` at ``o r_g Omega`` (``r_g`` the angle's rate): tones of
different angles are distinct wave vectors, and the torus average of the squared force
is the sum over tones as in the periodic case, so the proxy is the same sum over the
tones of every angle. For ``G = 1`` every tone is on angle 0 at rate 1.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..._engine.static import static_deflection
from ..._gear.paths import set_path
from ..._gear.train import Train
from ..sensitivity import GearFamily
from .ranking import TIE_DEPTH


class FirstOrder(eqx.Module):
    """Mesh-force transfer of a gear to first order in its stiffness variation.

    **Fields:** ``transfer`` ``(F, O, m, m)``: ``T_o(f) = I - D_o W H(o Omega_f) W^T``,
    the alternating force of every mesh per unit excitation force of every mesh at base
    order ``o`` (complex amplitudes, ``x = Re(X e^{i w t})``); ``forced`` ``(F, O, m)``:
    the external torques' share (``D_o W H g_o``); ``omegas`` ``(F,)`` (rad/s);
    ``static_p`` ``(m,)``: static mesh deflections (m); ``kbar``, ``damping``;
    ``orders`` (static): the order of every excitation tone (mesh harmonic or forcing
    column) on its torus angle ``order_angles`` (all 0 for a periodic system), whose
    rates over Omega are ``angle_ratio``; :attr:`tone_rates`: each tone's frequency over
    Omega.
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
    order_angles: tuple[int, ...] = eqx.field(static=True, default=())
    mesh_angles: tuple[int, ...] = eqx.field(static=True, default=())
    angle_ratio: tuple[float, ...] = eqx.field(static=True, default=(1.0,))

    @property
    def tone_rates(self) -> np.ndarray:
        """``(O,)``: each tone's frequency over Omega, ``orders[j] angle_ratio[angle]``
        (the order itself for a periodic system)."""
        angles = self.order_angles or (0,) * len(self.orders)
        return np.asarray([o * self.angle_ratio[g] for o, g in zip(self.orders, angles)],
                          dtype=float)


def first_order(system, omegas) -> FirstOrder:
    """:class:`FirstOrder` of ``system`` (a :class:`~gearjax.System`) at base frequencies
    ``omegas`` ``(F,)`` (rad/s)."""
    s = system
    H = max(s.k_cos.shape[-1], s.te_cos.shape[-1])
    tones = sorted({(g, h * mu) for mu, g in zip(s.mesh_mu, s.mesh_angles) if mu
                    for h in range(1, H + 1)}
                   | {(g, mu) for mu, g in zip(s.forcing_mu, s.forcing_angles) if mu})
    orders = [o for _, o in tones]
    fo_static = dict(orders=tuple(orders), mesh_mu=tuple(s.mesh_mu),
                     forcing_mu=tuple(s.forcing_mu), order_angles=tuple(g for g, _ in tones),
                     mesh_angles=tuple(s.mesh_angles),
                     angle_ratio=tuple(float(r) for r in s.angle_ratio))
    omegas = jnp.asarray(omegas, dtype=float)
    Kt = s.mean_stiffness()
    Ct = s.C + s.W.T @ (s.damping[:, None] * s.W)
    x_static, _ = static_deflection(s)
    o = jnp.asarray([s.angle_ratio[a] * order for a, order in tones], dtype=float)  # rates
    w = omegas[:, None] * o[None, :]  # (F, O)
    A = (Kt[None, None] - (w**2)[..., None, None] * s.M[None, None]
         + 1j * w[..., None, None] * Ct[None, None])
    D = s.kbar[None, None, :] + 1j * w[..., None] * s.damping[None, None, :]  # (F, O, m)
    HWt = jnp.linalg.solve(A, jnp.broadcast_to(s.W.T.astype(complex), A.shape[:2] + s.W.T.shape))
    transfer = jnp.eye(s.n_meshes)[None, None] - D[..., :, None] * (s.W @ HWt)
    g = _forcing_orders(s, tones)  # (O, n)
    Hg = jnp.linalg.solve(A, jnp.broadcast_to(g, A.shape[:2] + g.shape[-1:])[..., None])[..., 0]
    forced = D * jnp.einsum("mn,fon->fom", s.W, Hg)
    return FirstOrder(transfer=transfer, forced=forced, omegas=omegas,
                      static_p=s.W @ x_static - s.te_mean, kbar=s.kbar, damping=s.damping,
                      **fo_static)


def _forcing_orders(s, tones) -> Array:
    """``(O, n)`` complex forcing of every tone ``(angle, order)``."""
    g = jnp.zeros((len(tones), s.n_dof), complex)
    for col, (mu, angle) in enumerate(zip(s.forcing_mu, s.forcing_angles)):
        if (angle, mu) in tones:
            g = g.at[tones.index((angle, mu))].add(s.f_cos[:, col] - 1j * s.f_sin[:, col])
    return g


def excitation(fo: FirstOrder, k_cos, k_sin, te_cos, te_sin) -> tuple[Array, Array]:
    """``(a, b)``, each ``(O, m)``: the first-order excitation force of every mesh at every
    base order is ``q_o = a_o + i o Omega b_o`` (N) (module docstring), from one design's
    stiffness and transmission-error coefficients."""
    O, m = len(fo.orders), fo.kbar.shape[0]
    a = jnp.zeros((O, m), complex)
    b = jnp.zeros((O, m), complex)
    mu = np.asarray(fo.mesh_mu)
    on = np.asarray(fo.mesh_angles or (0,) * m)
    angles = fo.order_angles or (0,) * O
    for h in range(1, max(k_cos.shape[-1], te_cos.shape[-1]) + 1):
        for j, o in enumerate(fo.orders):
            hit = (mu * h == o) & (mu > 0) & (on == angles[j])
            sel = jnp.asarray(hit)
            if not bool(np.any(hit)):
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
    o = jnp.asarray(fo.tone_rates, dtype=float)
    q = a[None] + 1j * (fo.omegas[:, None] * o[None, :])[..., None] * b[None]  # (F, O, m)
    F = jnp.einsum("foij,foj->foi", fo.transfer, q) + fo.forced
    return jnp.sqrt(jnp.sum(jnp.abs(F) ** 2, axis=1) / 2)


@eqx.filter_jit
def _proxy_chunk(fo: FirstOrder, family, thetas, phases, idx, h, h_stage, cols_s, cols_r,
                 fixed, rest, mask, depth: int):
    """Band profiles ``(b, G, depth)`` (N; :func:`.ranking.band_profile`) of a chunk of
    planet sets at the phase pairs ``phases`` ``(G, 2)`` (sun-ring phase gamma, stage
    phase Gamma; rad):
    ``F_o = fixed_o + exp(i h'_o Gamma) (A_o + exp(i h_o gamma) B_o)`` with ``A``, ``B``
    the shares of the stage's sun and ring meshes (at gamma = Gamma = 0), ``h'`` the
    stage phase's multiplier (``h``, or 1 with ``phasing = "paper"``) and ``rest`` the
    squared RMS of the orders the stage does not excite."""
    o = jnp.asarray(fo.tone_rates, dtype=float)[idx]
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
                 stage_phases_deg=None, layout=None) -> np.ndarray:
    """First-order band profiles ``(S, G, depth)`` (N; :func:`.ranking.band_profile`: the
    largest per-frequency peaks, descending) of planet sets ``sets`` ``(S, N)`` (deg) of
    stage ``stage_id`` at sun-ring phases ``gammas_deg`` ``(G,)``, over the base
    frequencies ``omegas`` (rad/s) and the meshes of ``mesh_mask`` ``(m,)``; with
    ``stage_phases_deg`` ``(P,)`` also at each of these stage phases of the stage:
    ``(S, G, P, depth)``. Every other value is ``train``'s. One compilation per
    ``chunk``. ``layout``: the gear's torus layout (``GearCase.layout``; ``None``: its
    periodic system); the stage's tones are those on its torus angle."""
    N = train.stage(stage_id).n_planets
    base = set_path(train, f"{stage_id}.sun_ring_phase_deg", 0.0)
    if stage_phases_deg is not None:
        base = set_path(base, f"{stage_id}.stage_phase_deg", 0.0)
    paths = [f"{stage_id}.planet_angles_deg.{i}" for i in range(2, N + 1)]
    family = GearFamily.of(base, paths, gear, linear=True, layout=layout)
    sets = np.asarray(sets, dtype=float).reshape(-1, N)
    system = family(family.theta())
    fo = first_order(system, omegas)
    mu_n = system.mesh_mu[system.mesh_group.index(stage_id)]
    angle_n = system.mesh_angles[system.mesh_group.index(stage_id)]
    in_stage = np.asarray([grp == stage_id for grp in system.mesh_group])
    ring = in_stage & (np.asarray(system.mesh_side) == "ring")
    sun = in_stage & ~ring
    tone_angles = fo.order_angles or (0,) * len(fo.orders)
    idx = np.asarray([j for j, (o, g) in enumerate(zip(fo.orders, tone_angles))
                      if o % mu_n == 0 and g == angle_n], dtype=int)
    h = jnp.asarray([fo.orders[j] // mu_n for j in idx], dtype=float)
    h_stage = h if train.phasing == "physical" else jnp.ones_like(h)
    # the fixed part: every other mesh's excitation, and the forcing
    a, b = excitation(fo, system.k_cos, system.k_sin, system.te_cos, system.te_sin)
    o = jnp.asarray(fo.tone_rates, dtype=float)
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


@eqx.filter_jit
def batched_first_order_rms(fo: FirstOrder, family, thetas) -> Array:
    """:func:`first_order_rms` ``(B, F, m)`` (N) of the systems ``family(theta)`` for
    the design vectors ``thetas`` ``(B, p)`` (one compilation per shape)."""
    return jax.vmap(lambda th: first_order_rms(fo, family(th)))(thetas)
