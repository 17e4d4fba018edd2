"""Floquet multipliers by Hill's method: a cross-check of :mod:`floquet`.

With ``dz = exp(s t) q(tau)``, ``q`` periodic,
``d/dt`` becomes ``s + omega_0 D`` on the harmonic coefficients, and the harmonic-
balance Jacobian turns into the quadratic eigenvalue problem

    [ s^2 I(x)M + s (2 omega_0 D(x)M + I(x)Ct)
      + I(x)K + omega_0^2 D^2(x)M + omega_0 D(x)Ct + sum_m Jk_m(x)w_m w_m^T ] q = 0

with ``Ct = C + sum_m c_m w_m w_m^T`` and ``Jk_m`` the AFT matrix of multiplication by
``kbar_m kappa_m g'(p_m)`` on the HB time grid (the stiffness half of
``_hb.mesh_blocks``; its damping half is ``c_m I`` when the damping acts everywhere).
Each Floquet exponent appears as a family ``s + i j omega_0`` whose members have
eigenvectors shifted by ``-j`` harmonics; the member centred on harmonic 0 (the
power-weighted mean of its complex-exponential harmonic index in ``(-1/2, 1/2]``) is
kept, one per family, ``2n`` in all; ``mu = exp(s T)`` is the same for every member.
(Choosing the ``2n`` exponents of smallest ``|Im s|`` instead picks, for the stiff
modes whose exponents lie hundreds of ``omega_0`` from the real axis, members at the
truncated edge of the family, and is ambiguous at ``Im s = omega_0 / 2``.) Backlash
enters through ``g'`` sampled on the HB time grid, so switching instants are resolved
only to ``T / n_time`` , and couplings through stiffness harmonics above ``K`` are lost (the
paper gear's stiffness reaches harmonic 32 of ``omega_0``: with ``K = 16`` Hill is off
by up to 2e-2 there). Floquet is the reference.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Complex

from . import aft as _aft
from .floquet import scaled_frame
from .hb import HBProblem
from .mesh_force import in_contact


HILL_TIE_BREAK = 1e-3
"""Offset of the harmonic-centre criterion of Hill's method (prefers centre +1/2 to -1/2)."""


def hill_exponents(problem: HBProblem, X: Array, omega) -> Complex[Array, " 2n"]:
    """Floquet exponents ``s`` (1/s), ``(2n,)`` complex, by Hill's method (see module docstring).

    The quadratic eigenvalue problem is mass-normalised, scaled by the highest natural
    frequency and linearised to a ``2 (2K+1) n`` companion matrix; one exponent per
    family ``s + i j omega_0`` is kept (eigenvector centred on harmonic 0). Dense
    non-symmetric eigenvalues: jit-able on CPU, ``O((2 (2K+1) n)^3)``.
    """
    s = problem.system
    if s.contact_damping:
        raise ValueError(
            "hill_multipliers does not support contact_damping=True: the damping force jumps "
            "when the teeth touch, and the impulse c d(g')/dt of its linearisation has no "
            "harmonic-balance representation; use floquet_multipliers, which handles it.")
    K, n, T = problem.settings.n_harmonics, s.n_dof, problem.n_time
    C = 2 * K + 1
    w0 = jnp.asarray(omega, dtype=float) / problem.settings.eta
    frame = scaled_frame(problem)
    Wt, ws = frame.Wt, frame.ws
    D = jnp.asarray(_aft.derivative_matrix(K))
    I = jnp.eye(C)
    # AFT blocks of the mesh stiffness kbar kappa g'(p) (the stiffness half of _hb.mesh_blocks)
    p = _aft.synthesis(X @ s.W.T, T).T - problem.te  # (m, T)
    gk = s.kbar[:, None] * problem.kappa * in_contact(p, s.backlash[:, None])
    Jk = _aft.product_matrix(gk, K)  # (m, C, C)
    Ct = frame.Cm  # damping acts everywhere: Jc_m = c_m I
    mesh = jnp.einsum("mab,mi,mj->aibj", Jk, Wt, Wt).reshape(C * n, C * n)
    M1 = jnp.kron(2 * w0 * D, jnp.eye(n)) + jnp.kron(I, Ct)
    M0 = (jnp.kron(I, frame.Kt) + w0**2 * jnp.kron(D @ D, jnp.eye(n)) + w0 * jnp.kron(D, Ct)
          + mesh)
    N = C * n
    Z = jnp.block([[jnp.zeros((N, N)), jnp.eye(N)], [-M0 / ws**2, -M1 / ws]])
    sigma, V = jnp.linalg.eig(Z)
    q = V[:N].T.reshape(2 * N, C, n)
    c_pos = 0.5 * (q[:, 1::2] - 1j * q[:, 2::2])  # e^{+ik tau}
    c_neg = 0.5 * (q[:, 1::2] + 1j * q[:, 2::2])  # e^{-ik tau}
    w_pos = jnp.sum(jnp.abs(c_pos) ** 2, axis=-1)
    w_neg = jnp.sum(jnp.abs(c_neg) ** 2, axis=-1)
    total = jnp.sum(jnp.abs(q[:, 0]) ** 2, axis=-1) + jnp.sum(w_pos + w_neg, axis=-1)
    k = jnp.arange(1, K + 1)
    centre = jnp.sum(k * (w_pos - w_neg), axis=-1) / total
    # one member per family: centre in (-1/2, 1/2]; the small offset breaks the exact tie of a
    # negative real multiplier, whose family has conjugate members at centre +-1/2
    keep = jnp.argsort(jnp.abs(centre - HILL_TIE_BREAK))[: 2 * n]
    return ws * sigma[keep]


def hill_multipliers(problem: HBProblem, X: Array, omega) -> Complex[Array, " 2n"]:
    """Floquet multipliers ``exp(s T)`` ``(2n,)`` by Hill's method: a cross-check of
    :func:`floquet_multipliers` (``T = 2 pi eta / Omega``). Truncation to ``K`` harmonics
    limits it to solutions and modes well resolved by the harmonic balance; backlash
    enters through the AFT of ``g'`` on the HB time grid.

    **Raises** ``ValueError`` for ``contact_damping=True`` systems.
    """
    w0 = jnp.asarray(omega, dtype=float) / problem.settings.eta
    return jnp.exp(hill_exponents(problem, X, omega) * 2 * jnp.pi / w0)
