"""Hill's method on the harmonic-balance basis, periodic or on a torus: characteristic
exponents of the linearised equations about a harmonic-balance solution.

With ``dz = exp(s t) q(theta)``, ``q`` a function on the torus of the basis (one angle:
periodic; model.md, "Incommensurate stages"), ``d/dt`` becomes ``s + omega_0 D`` on the
coefficients of ``q`` (``D`` :func:`~gearjax._engine.aft.torus_derivative_matrix`, the
frequency number ``nu_k = k . rates`` of each wave vector built in), and the
harmonic-balance Jacobian turns into the quadratic eigenvalue problem

    [ s^2 I(x)M + s (2 omega_0 D(x)M + I(x)Ct)
      + I(x)K + omega_0^2 D^2(x)M + omega_0 D(x)Ct + sum_m Jk_m(x)w_m w_m^T ] q = 0

with ``Ct = C + sum_m c_m w_m w_m^T`` and ``Jk_m`` the AFT matrix of multiplication by
``kbar_m kappa_m g'(p_m)`` on the grid of the basis
(:func:`~gearjax._engine.aft.torus_product_matrix`, the stiffness half of
``hb.mesh_blocks``; its damping half is ``c_m I`` when the damping acts everywhere).
It is mass-normalised, scaled by the highest natural frequency ``w_s`` and linearised
to a companion matrix of size ``2 (2P+1) n`` (``P`` wave vectors in the half set).

**Families and the selection.** Each exponent appears as a family
``s + i omega_0 (k . rates)`` over the wave vectors ``k``, whose members have
eigenvectors shifted by ``-k``; all members have the same real part. For each
eigenvector the *centre* is its power-weighted mean wave vector (a ``G``-vector: the
complex-exponential coefficients ``q_k`` weighted by ``|q_k|^2``, summed over the
coordinates); the centres of one family's members are ``c_0 + k`` (exactly so in the
untruncated problem), so exactly one member per family has its centre in the cell
``(-1/2, 1/2]^G`` and every other member lies at least ``1/2`` from the origin in the
maximum norm. The ``2n`` eigenvalues whose centres are nearest the tie point
``t = HILL_TIE_BREAK (1, 1/pi, 1/pi^2, ...)`` in the maximum norm are kept. (The
Euclidean norm would not do for ``G > 1``: a dropped member at ``(0.55, 0.05)`` is nearer
than a kept one at ``(0.45, 0.45)``. Choosing the ``2n`` exponents of smallest
``|Im s|`` fails even for ``G = 1``: the stiff modes, hundreds of ``omega_0`` from the real
axis, would be represented by members at the truncated edge of their family.)

*Tie rule.* A family containing its own conjugate (``Im s = omega_0 (k . rates) / 2``, as
in a parametric resonance, a negative real multiplier for ``G = 1``) has two members with
centres ``+-c`` exactly (conjugate eigenvectors), at the same distance from the origin;
the tie point keeps the one whose centre's largest-magnitude entry is positive (the first
such entry where several share the largest magnitude). For ``G = 1`` this is today's
rule, centre in ``(-1/2, 1/2]``. Where truncation blurs two members of one family to
nearly the same distance, either may be kept: they have the same real part, so the
stability verdict does not depend on the choice.

*Checks* (:class:`HillSelection`): ``cell_violation`` (how far the ``2n``-th kept centre
lies outside the cell, or the first dropped one inside it: 0 for an unambiguous
selection, up to ``1/2``), ``conjugate_error`` (every kept exponent must have its
conjugate kept, or be the conjugate of a member of its own family: the kept set is
closed under conjugation modulo the families) and ``edge_power`` (share of each kept
eigenvector's power on the boundary wave vectors of the truncation set: a truncation
that cuts the eigenvector off).

Limits: backlash enters through ``g'`` sampled on the AFT grid, so switching instants are
resolved only to the grid spacing; couplings through stiffness harmonics above the
truncation are lost (the paper gear's stiffness reaches harmonic 32 of ``omega_0``: with
``K = 16`` Hill is off by up to 2e-2 there). For ``G = 1`` Floquet
(:mod:`~gearjax._engine.floquet`) is the reference; on a torus there is no monodromy
matrix and Hill's method is the stability method (:mod:`~gearjax._engine.torus_stability`).
The dense non-symmetric eigen-decomposition costs ``O((2 (2P+1) n)^3)``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Complex, Float

from . import aft as _aft
from .floquet import scaled_frame
from .hb import HBProblem
from .mesh_force import in_contact


HILL_TIE_BREAK = 1e-3
"""Size of the tie point of the centre criterion of Hill's method (see the module
docstring; for ``G = 1``: prefers centre ``+1/2`` to ``-1/2``)."""

CELL_VIOLATION_MAX = 0.1
"""Largest ``cell_violation`` of a selection called reliable (the centres of kept and dropped
members then sit on their sides of the cell boundary, within a tenth of a wave vector)."""

CONJUGATE_ERROR_MAX = 1e-6
"""Largest ``conjugate_error`` (relative to ``w_s``) of a selection called reliable."""

EDGE_POWER_MAX = 1e-3
"""Largest share of a kept eigenvector's power on the boundary of the truncation set of a
selection called reliable (more: the truncation cuts the Floquet mode off)."""


def tie_point(G: int) -> np.ndarray:
    """The tie point ``HILL_TIE_BREAK (1, 1/pi, ..., 1/pi^(G-1))`` of the selection, ``(G,)``."""
    return HILL_TIE_BREAK * np.pi ** -np.arange(G, dtype=float)


class HillSpectrum(eqx.Module):
    """Every eigenvalue of the truncated Hill problem (``N = (2P+1) n``).

    **Fields:** ``exponents`` ``(2N,)`` complex (1/s); ``vectors`` ``(2N, 2P+1, n)``
    complex: the displacement part of each eigenvector, real-coefficient rows of the
    basis, in the mass-normalised coordinates ``q = L^T dz`` (``M = L L^T``);
    ``centres`` ``(2N, G)``: power-weighted mean wave vectors; ``edge_power`` ``(2N,)``:
    power share on the boundary wave vectors of the truncation set; ``scale``: ``w_s``
    (rad/s), the highest natural frequency of the mean-stiffness model; ``omega_0``
    (rad/s).
    """

    exponents: Complex[Array, " 2N"]
    vectors: Complex[Array, "2N C n"]
    centres: Float[Array, "2N G"]
    edge_power: Float[Array, " 2N"]
    scale: Float[Array, ""]
    omega_0: Float[Array, ""]


class HillSelection(eqx.Module):
    """One exponent per family (see the module docstring), ``2n`` of them.

    **Fields:** ``exponents`` ``(2n,)`` complex (1/s); ``vectors`` ``(2n, 2P+1, n)`` and
    ``centres`` ``(2n, G)``, ``edge_power`` ``(2n,)`` of the kept eigenvectors
    (:class:`HillSpectrum`); ``distance`` ``(2n,)``: maximum-norm distance of each kept
    centre from the tie point; ``cell_violation``: ``max(d_(2n) - 1/2, 1/2 - d_(2n+1),
    0)`` with ``d_(j)`` the ``j``-th smallest distance over all eigenvalues (0: every kept
    centre in the cell and every dropped one outside); ``conjugate_error``: the largest,
    over the kept exponents, of the distance from ``conj(s)`` to the nearest kept exponent
    or to ``s + i omega_0 (k . rates)`` with ``k = round(2 c)`` (the member of its own
    family with centre ``-c``: its conjugate), over ``w_s``; ``reliable`` bool: ``cell_violation``, ``conjugate_error`` and
    the largest ``edge_power`` within :data:`CELL_VIOLATION_MAX`,
    :data:`CONJUGATE_ERROR_MAX` and :data:`EDGE_POWER_MAX`.
    """

    exponents: Complex[Array, " 2n"]
    vectors: Complex[Array, "2n C n"]
    centres: Float[Array, "2n G"]
    edge_power: Float[Array, " 2n"]
    distance: Float[Array, " 2n"]
    cell_violation: Float[Array, ""]
    conjugate_error: Float[Array, ""]
    reliable: Array


def _check_supported(problem: HBProblem) -> None:
    if problem.system.contact_damping:
        raise ValueError(
            "hill_multipliers does not support contact_damping=True: the damping force jumps "
            "when the teeth touch, and the impulse c d(g')/dt of its linearisation has no "
            "harmonic-balance representation; use floquet_multipliers, which handles it.")


def boundary_pairs(basis: _aft.Basis) -> np.ndarray:
    """``(P,)`` bool: the wave vectors of the half set on the boundary of the truncation
    set ``S = {0} + S+ + (-S+)`` (some neighbour ``k +- e_g`` outside ``S``)."""
    k = np.asarray(basis.orders, dtype=np.int64).reshape(basis.n_pairs, basis.G)
    full = {tuple(v) for v in k} | {tuple(-v) for v in k} | {(0,) * basis.G}
    out = np.zeros(basis.n_pairs, dtype=bool)
    for j, v in enumerate(k):
        for g in range(basis.G):
            for step in (-1, 1):
                w = v.copy()
                w[g] += step
                out[j] |= tuple(w) not in full
    return out


def hill_spectrum(problem: HBProblem, X: Array, omega) -> HillSpectrum:
    """The whole spectrum of the truncated Hill problem at the solution ``X``
    ``(2P+1, n)`` (rad or m) and base frequency ``omega`` (rad/s); jit-able on CPU.

    **Raises** ``ValueError`` for ``contact_damping=True`` systems.
    """
    _check_supported(problem)
    s, basis = problem.system, problem.basis
    n, C = s.n_dof, basis.n_coefficients
    w0 = jnp.asarray(omega, dtype=float) / problem.settings.eta
    frame = scaled_frame(problem)
    Wt, ws = frame.Wt, frame.ws
    D = jnp.asarray(_aft.torus_derivative_matrix(basis))
    I = jnp.eye(C)
    # AFT blocks of the mesh stiffness kbar kappa g'(p) (the stiffness half of hb.mesh_blocks)
    p = _aft.torus_synthesis(basis, X @ s.W.T).T - problem.te  # (m, T)
    gk = s.kbar[:, None] * problem.kappa * in_contact(p, s.backlash[:, None])
    Jk = _aft.torus_product_matrix(basis, gk)  # (m, C, C)
    Ct = frame.Cm  # damping acts everywhere: Jc_m = c_m I
    mesh = jnp.einsum("mab,mi,mj->aibj", Jk, Wt, Wt).reshape(C * n, C * n)
    M1 = jnp.kron(2 * w0 * D, jnp.eye(n)) + jnp.kron(I, Ct)
    M0 = (jnp.kron(I, frame.Kt) + w0**2 * jnp.kron(D @ D, jnp.eye(n)) + w0 * jnp.kron(D, Ct)
          + mesh)
    N = C * n
    Z = jnp.block([[jnp.zeros((N, N)), jnp.eye(N)], [-M0 / ws**2, -M1 / ws]])
    sigma, V = jnp.linalg.eig(Z)
    q = V[:N].T.reshape(2 * N, C, n)
    c_pos = 0.5 * (q[:, 1::2] - 1j * q[:, 2::2])  # coefficient of e^{+i k . theta}
    c_neg = 0.5 * (q[:, 1::2] + 1j * q[:, 2::2])  # e^{-i k . theta}
    w_pos = jnp.sum(jnp.abs(c_pos) ** 2, axis=-1)
    w_neg = jnp.sum(jnp.abs(c_neg) ** 2, axis=-1)
    total = jnp.sum(jnp.abs(q[:, 0]) ** 2, axis=-1) + jnp.sum(w_pos + w_neg, axis=-1)
    k = np.asarray(basis.orders, dtype=np.int64).reshape(basis.n_pairs, basis.G)
    centres = jnp.stack([jnp.sum(jnp.asarray(k[:, g]) * (w_pos - w_neg), axis=-1) / total
                         for g in range(basis.G)], axis=-1)
    edge = jnp.asarray(boundary_pairs(basis))
    edge_power = jnp.sum(jnp.where(edge, w_pos + w_neg, 0.0), axis=-1) / total
    return HillSpectrum(exponents=ws * sigma, vectors=q, centres=centres, edge_power=edge_power,
                        scale=ws, omega_0=w0)


def select_families(problem: HBProblem, spectrum: HillSpectrum) -> HillSelection:
    """Keep one member per family of ``spectrum``: the ``2n`` centres nearest the tie
    point in the maximum norm, with the checks of :class:`HillSelection` (jit-able)."""
    basis, n = problem.basis, problem.system.n_dof
    t = jnp.asarray(tie_point(basis.G))
    d = jnp.max(jnp.abs(spectrum.centres - t), axis=-1)
    order = jnp.argsort(d)
    keep = order[: 2 * n]
    d_sorted = d[order]
    cell_violation = jnp.maximum(jnp.maximum(d_sorted[2 * n - 1] - 0.5, 0.5 - d_sorted[2 * n]),
                                 0.0)
    s = spectrum.exponents[keep]
    c = spectrum.centres[keep]
    rates = jnp.asarray(basis.rates)
    # the family's member s + i omega_0 (k . rates) has centre c - k: with k = 2 c, -c
    partner = s + 1j * spectrum.omega_0 * (jnp.round(2 * c) @ rates)
    to_kept = jnp.min(jnp.abs(jnp.conj(s)[:, None] - s[None, :]), axis=-1)
    conjugate_error = jnp.max(jnp.minimum(to_kept, jnp.abs(jnp.conj(s) - partner))) / (
        spectrum.scale)
    edge_power = spectrum.edge_power[keep]
    reliable = ((cell_violation <= CELL_VIOLATION_MAX)
                & (conjugate_error <= CONJUGATE_ERROR_MAX)
                & (jnp.max(edge_power) <= EDGE_POWER_MAX))
    return HillSelection(exponents=s, vectors=spectrum.vectors[keep], centres=c,
                         edge_power=edge_power, distance=d[keep],
                         cell_violation=cell_violation, conjugate_error=conjugate_error,
                         reliable=reliable)


def hill_selection(problem: HBProblem, X: Array, omega) -> HillSelection:
    """:func:`select_families` of :func:`hill_spectrum`: one exponent per family and the
    checks of the selection, at the solution ``X`` ``(2P+1, n)`` and ``omega`` (rad/s).

    **Raises** ``ValueError`` for ``contact_damping=True`` systems.
    """
    return select_families(problem, hill_spectrum(problem, X, omega))


def hill_exponents(problem: HBProblem, X: Array, omega) -> Complex[Array, " 2n"]:
    """Characteristic (Floquet) exponents ``s`` (1/s), ``(2n,)`` complex, by Hill's method
    on the basis of ``problem`` (see the module docstring): one per family, in order of
    the distance of their centres from the tie point. Dense non-symmetric eigenvalues:
    jit-able on CPU, ``O((2 (2P+1) n)^3)``.

    **Raises** ``ValueError`` for ``contact_damping=True`` systems.
    """
    return hill_selection(problem, X, omega).exponents


def hill_multipliers(problem: HBProblem, X: Array, omega) -> Complex[Array, " 2n"]:
    """Floquet multipliers ``exp(s T)`` ``(2n,)`` by Hill's method: a cross-check of
    :func:`floquet_multipliers` (``T = 2 pi eta / Omega``; periodic systems). Truncation to
    ``K`` harmonics limits it to solutions and modes well resolved by the harmonic
    balance; backlash enters through the AFT of ``g'`` on the HB time grid.

    **Raises** ``ValueError`` for ``contact_damping=True`` systems, and for a system of
    ``G > 1`` torus angles (a quasi-periodic solution has no period: use
    :func:`hill_exponents` or :func:`~gearjax._engine.torus_stability.torus_stability`).
    """
    if problem.basis.G > 1:
        raise ValueError(
            f"hill_multipliers needs a periodic solution; the system has {problem.basis.G} "
            "torus angles and no period: use hill_exponents or torus_stability")
    w0 = jnp.asarray(omega, dtype=float) / problem.settings.eta
    return jnp.exp(hill_exponents(problem, X, omega) * 2 * jnp.pi / w0)
