"""Stability of periodic solutions: Floquet multipliers, Hill's method, classification.

The equations linearised about a periodic solution ``x(t)`` of period
``T = 2 pi eta / Omega`` are

    M dz'' + C dz' + K dz + sum_m w_m (kbar_m kappa_m(t) g'(p_m(t)) w_m.dz
                                       + c_m d/dt(h_m(t) w_m.dz)) = 0

with ``g' = 1`` in contact and 0 in the backlash gap, and ``h_m = 1`` (damping also in
the gap, the default) or ``h_m = g'`` (``contact_damping``). With contact-only damping
the mesh force jumps when the teeth touch; its linearisation
``c (h dp' + h' dp) = c d/dt(h dp)`` carries the impulse that a saltation matrix
would add at every contact change, and the momentum-like variable
``v = M dz' + (C + G(t)) dz``, ``G = sum_m c_m h_m w_m w_m^T``, absorbs it exactly:

    dz' = M^-1 (v - (C + G(t)) dz),     v' = -(K + sum_m kbar_m kappa_m g'_m w_m w_m^T) dz

has bounded, piecewise-smooth coefficients and no impulses (with damping everywhere
``G`` is constant and ``v`` is an ordinary change of variables). ``G(T) = G(0)``, so
the monodromy matrix in ``(dz, v)`` is similar to the physical one: same multipliers.

**Floquet (the reference method).** ``Phi = prod_j expm(Omega_j)`` over ``N`` equal
steps of one period, with the fourth-order Magnus exponent of each step

    Omega_j = A0 + [A1, A0] / h,   A0 = int A dt,   A1 = int A (t - t_mid) dt

(for smooth coefficients this is the two-point Gauss Magnus method; Blanes, Casas,
Oteo & Ros, Phys. Rep. 470 (2009) 151). Why this and not a Runge-Kutta method:

- the coefficients are stiff: the paper's 1e10 N m/rad brake springs give a 0.42 MHz
  penalty mode, about 1000 times the base frequency. Classical RK4 needs
  ``w_max h < 2.8`` for stability alone (2,200 steps a period at 3 kHz, each four
  sequential evaluations), and its error at a backlash switch is first order unless
  the steps are aligned with it. The exponential is exact for the constant part at
  any step. The state is mass-normalised and scaled by the highest natural frequency
  ``w_s`` (``q = L^T dz``, ``u = L^-1 v / w_s``, ``M = L L^T``), so ``||Omega_j||`` is of
  order ``w_s h`` and the exponential (Taylor degree 18 with scaling and squaring,
  matrix products only) is well conditioned;
- the stiffness part of ``A`` is ``A_lin + sum_m B_m a_m(t)`` with ``a_m = kappa_m g'_m``
  and every ``B_m`` in the same off-diagonal block, so ``[B_m, B_l] = 0``: ``A0`` and
  ``A1`` need only the zeroth and first moments of each scalar ``a_m`` over the step,
  and these are integrated exactly across the backlash switches. The switching
  instants of every mesh are located inside the step on the cubic Hermite interpolant
  of ``p`` from its values and rates at the step ends, all of them from one inverse
  FFT of the solution's harmonics on the step grid (an error of
  ``(2 pi k / N)^4 / 384`` relative to harmonic ``k``, under 4e-6 at ``k = K``): up to
  two per flank and step, so a contact or a gap shorter than a step is found
  (:func:`_contact_intervals`), ``kappa`` is linear in the step (its
  two Gauss-point values), and the moments of ``kappa g'`` are integrated in closed
  form on the contact sub-intervals. A step that contains a switch then has a local
  error of third order in ``h`` (instead of the first order of a midpoint or sampled
  ``g'``); smooth steps are fourth order. With contact-only damping the damping and
  stiffness blocks do not commute; ``A0`` and ``A1`` are still exact, and the omitted
  part of the second Magnus term only affects the switching steps;
- steps are independent: the exponents and exponentials of a chunk of steps are
  formed as one batch and multiplied as a balanced tree, inside a ``jax.lax.scan``
  over the chunks: fixed shapes (jit, and vmap over points), little memory. The
  stiffness at the Gauss points is a function of phase, the same for every ``Omega``:
  under ``vmap`` over the points of a sweep it is evaluated once. The commutator is
  formed from ``n x n`` blocks (:func:`_magnus_exponent`): one product of ``n x n``
  matrices with the damping everywhere, instead of two of ``2n x 2n``.

Step rule (:func:`floquet_steps`): ``N`` is the power of two with at least 32 steps
per period of the highest harmonic of ``tau`` in the solution or the excitation,
``max(K, highest excitation)``, and at least 256. The stiff modes need no steps (the
exponential is exact for them); the error comes from the time variation and the
switches. Measured: the paper's first gear at 3 kHz (K = 16, 1024 steps) is within
2.5e-7 of 16,384 steps and of ``solve_ivp`` (DOP853, rtol 1e-11) on the variational
equations; the impacting clearance oscillator (1024 steps) within 3e-8 of
``solve_ivp`` between the switches, error falling about 8 times per doubling of ``N``.

Grazing contacts: a contact (or gap) much shorter than the step is found only as
well as the interpolant resolves the depth ``|p| - b`` of its turning point, and the
multipliers depend on that depth like its square root (the contact time), so a very
shallow graze costs accuracy (test: the clearance oscillator with a contact half a step
long, 1.3e-6 deep against an amplitude of 0.33: 6e-5 at the default step; missed,
6.5e-2). Measured
over the 843 points of the paper's backlash sweep (2-15 kHz, ``K`` = 64 / 48 / 32,
2048 / 2048 / 1024 steps) against four times the steps: largest ``|mu|`` within
3.4e-4 / 3e-6 / 7.6e-4 relative, within 1.0e-4 where ``|mu|`` is within 1e-2 of 1;
before the sub-step switches (a chord and one Newton step per step), 2.4e-3 and
3.8e-3: a 0.5-step contact of the stage-2 meshes at the 6656 Hz fold was missed. A
sweep takes half these steps (16 per period of the highest harmonic,
``_sweep.SWEEP_FLOQUET_STEPS``): the error that adds is below the one the truncation of
the orbit at ``K`` puts into the multipliers.

**Hill's method (a cross-check).** With ``dz = exp(s t) q(tau)``, ``q`` periodic,
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
only to ``T / n_time`` (about 1e-2 in the multipliers of the impacting clearance
oscillator), and couplings through stiffness harmonics above ``K`` are lost (the
paper gear's stiffness reaches harmonic 32 of ``omega_0``: with ``K = 16`` Hill is off
by up to 2e-2 there). Floquet is the reference.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Complex, Float

from . import _aft
from ._hb import HBProblem, highest_excitation, stiffness_at_phases
from ._mesh import in_contact
from ._modal import mode_classes

HILL_TIE_BREAK = 1e-3
"""Offset of the harmonic-centre criterion of Hill's method (prefers centre +1/2 to -1/2)."""

_GAUSS = 0.5 / np.sqrt(3.0)
"""Offset of the two Gauss points from the middle of a step, in steps."""

CHUNK = 16
"""Steps whose exponentials are formed together (a batch inside the scan over the period).
With the sweep's chunks of 8 points (``_sweep.POST_CHUNK``) a batch holds 128 matrices of
28 x 28 on the paper case, which stay in the 1 MiB per-core L2 cache: measured on 2
cores, 27 ms a point at K = 64 and 13 ms at K = 32, against 54 and 18 ms with 64 steps."""


# ------------------------------------------------------------------------ helpers


def floquet_steps(problem: HBProblem, per_harmonic: int = 32) -> int:
    """Default number of steps per period (static, a power of two): at least
    ``per_harmonic`` per period of the highest harmonic, and 256; see the module
    docstring (a sweep takes 16, ``_sweep.SWEEP_FLOQUET_STEPS``)."""
    K, eta = problem.settings.n_harmonics, problem.settings.eta
    top = max(K, highest_excitation(problem.system, eta), 1)
    need = max(256, per_harmonic * top)
    return int(2 ** int(np.ceil(np.log2(need))))


def _series(C: Array, w0, t: Array):
    """Value and time derivative of ``C[0] + sum_k C[2k-1] cos(k w0 t) + C[2k] sin(k w0 t)``.

    ``C``: ``(2K+1, m)``; ``t``: ``(..., m)`` (a time per column) -> two ``(..., m)`` arrays.
    """
    K = (C.shape[0] - 1) // 2
    k = jnp.arange(1, K + 1)
    arg = w0 * t[..., None, :] * k[:, None]  # (..., K, m)
    c, s = jnp.cos(arg), jnp.sin(arg)
    a, b = C[1::2], C[2::2]  # (K, m)
    value = C[0] + jnp.sum(a * c + b * s, axis=-2)
    rate = w0 * jnp.sum(k[:, None] * (b * c - a * s), axis=-2)
    return value, rate


def _mesh_series(cos: Array, sin: Array, mu: Array, omega, t: Array):
    """Value and rate of ``sum_h cos_h cos(h mu Omega t) + sin_h sin(...)`` with a time per mesh.

    ``cos``, ``sin``: ``(m, H)``; ``t``: ``(..., m)``.
    """
    H = cos.shape[-1]
    if H == 0:
        return jnp.zeros_like(t), jnp.zeros_like(t)
    f = jnp.arange(1, H + 1)[None, :] * mu[:, None] * omega  # (m, H)
    arg = t[..., None] * f  # (..., m, H)
    c, s = jnp.cos(arg), jnp.sin(arg)
    value = jnp.sum(cos * c + sin * s, axis=-1)
    rate = jnp.sum(f * (sin * c - cos * s), axis=-1)
    return value, rate


class _Orbit(eqx.Module):
    """Mesh deflections ``p_m(t)`` of the periodic solution and the stiffness ``kappa_m(t)``."""

    P: Array  # (2K+1, m) coefficients of W x(tau)
    w0: Array
    omega: Array
    problem: HBProblem

    def deflection(self, t):
        s = self.problem.system
        mu = jnp.asarray(s.mesh_mu, dtype=float)
        p, dp = _series(self.P, self.w0, t)
        e, de = _mesh_series(s.te_cos, s.te_sin, mu, self.omega, t)
        return p - e, dp - de

    def on_grid(self, n: int):
        """Deflection and rate ``(n, m)`` at the ``n`` equally spaced instants ``t_j = j T / n``
        of the period: inverse FFTs of the coefficients (exact for ``n > 2K``), and the
        transmission error evaluated in phase (it does not depend on ``Omega``)."""
        s = self.problem.system
        eta = self.problem.settings.eta
        p = _aft.synthesis(self.P, n)
        dp = self.w0 * _aft.synthesis(_aft.derivative(self.P), n)
        mu = jnp.asarray(s.mesh_mu, dtype=float) * eta
        e, de = _mesh_series(s.te_cos, s.te_sin, mu, 1.0, _aft.phases(n)[:, None])
        return p - e, dp - self.w0 * de


def _contact_intervals(p0, p1, dp0, dp1, h, b):
    """Sub-intervals ``[u, v]`` (normalised to [0, 1]) of each step where a flank touches.

    **Arguments:** ``p0``, ``p1`` ``(c, m)`` deflections and ``dp0``, ``dp1`` their rates
    at the step ends; ``h`` the step (s); ``b`` ``(m,)``. **Returns:** ``u``, ``v``, each
    ``(4, c, m)``: two intervals of each flank, the positive (``p > b``) and the negative
    (``-p > b``); an empty one has ``u = v``.

    ``p`` is the cubic Hermite interpolant of its values and rates at the step ends
    (within ``h^4 / 384`` times the largest fourth derivative of ``p``). The step is split
    at the cubic's interior maximum where it lies beyond the threshold, else at its
    interior minimum where that lies short of it: so a contact or a gap shorter than the
    step (a graze) is found, and so is a switch near a step end where the chord of the
    whole step points the wrong way (the cubic crosses, turns, and ends just past the
    threshold). On each part the switch is located on the chord and refined by two Newton
    steps on the cubic. Left out: a step over which the cubic turns twice beyond the
    threshold (a wiggle of the deflection within a thirty-second of the period of its
    highest harmonic, see :func:`floquet_steps`).
    """
    sign = jnp.array([1.0, -1.0])[:, None, None]
    q0, q1 = sign * p0, sign * p1  # (2, c, m)
    m0, m1 = sign * dp0 * h, sign * dp1 * h  # rates per unit of the normalised step
    a2 = 3 * (q1 - q0) - 2 * m0 - m1  # q(r) = q0 + m0 r + a2 r^2 + a3 r^3
    a3 = 2 * (q0 - q1) + m0 + m1

    def cubic(r):
        return q0 + r * (m0 + r * (a2 + r * a3)), m0 + r * (2 * a2 + 3 * r * a3)

    def ratio(num, den, empty):
        ok = jnp.abs(den) > 0.0
        return jnp.where(ok, num / jnp.where(ok, den, 1.0), empty)

    # interior extrema, q'(r) = 0 (q'' = -2 d at the maximum, +2 d at the minimum): the
    # root formulas that do not cancel (a3 -> 0 leaves a parabola)
    disc = a2 * a2 - 3 * a3 * m0
    d = jnp.sqrt(jnp.maximum(disc, 0.0))
    r_max = jnp.where(a2 <= 0, ratio(m0, d - a2, -1.0), ratio(-a2 - d, 3 * a3, -1.0))
    r_min = jnp.where(a2 >= 0, ratio(m0, -a2 - d, -1.0), ratio(d - a2, 3 * a3, -1.0))
    inside = lambda r: (disc > 0) & (r > 0.0) & (r < 1.0)  # noqa: E731
    q_max, q_min = cubic(r_max)[0], cubic(r_min)[0]
    at_max = inside(r_max) & (q_max > b)
    at_min = ~at_max & inside(r_min) & (q_min < b)
    split = jnp.where(at_max, r_max, jnp.where(at_min, r_min, 1.0))
    q_split = jnp.where(at_max, q_max, jnp.where(at_min, q_min, q1))
    u, v = [], []
    for s0, s1, Q0, Q1 in ((0.0, split, q0, q_split), (split, 1.0, q_split, q1)):
        # contact on [r, s1] (rising) or [s0, r] (falling), r the switch, or a part's end
        # where there is none
        r = jnp.clip(s0 + (s1 - s0) * ratio(b - Q0, Q1 - Q0, jnp.where(Q0 > b, 0.0, 1.0)),
                     s0, s1)
        crossing = (Q0 - b) * (Q1 - b) < 0
        for _ in range(2):
            q, rate = cubic(r)
            r = jnp.where(crossing, jnp.clip(r - ratio(q - b, rate, 0.0), s0, s1), r)
        rising = Q1 >= Q0
        u.append(jnp.where(rising, r, s0))
        v.append(jnp.where(rising, s1, r))
    return jnp.concatenate(u), jnp.concatenate(v)


def _moments(alpha, beta, u, v):
    """Zeroth and first moments about 1/2 of ``alpha + beta (s - 1/2)`` on ``[u, v]``."""
    a, b = u - 0.5, v - 0.5
    d1, d2, d3 = b - a, (b**2 - a**2) / 2, (b**3 - a**3) / 3
    return alpha * d1 + beta * d2, alpha * d2 + beta * d3


# ------------------------------------------------------------------------- Floquet


class _Frame(eqx.Module):
    """Scaled coordinates ``q = L^T dz``, ``u = L^-1 v / w_s`` (M = L L^T)."""

    Linv: Array  # (n, n)
    Wt: Array  # (m, n): W L^-T
    WW: Array  # (m, n * n): the outer products w~_m w~_m^T of the rows of Wt
    Kt: Array  # (n, n): L^-1 K L^-T
    Ct: Array  # (n, n): L^-1 C L^-T
    Cm: Array  # (n, n): Ct + sum_m c_m w~_m w~_m^T (the damping when it acts everywhere)
    ws: Array  # scale frequency (rad/s)


def _frame(problem: HBProblem) -> _Frame:
    s = problem.system
    L = jnp.linalg.cholesky(0.5 * (s.M + s.M.T))
    Linv = jax.scipy.linalg.solve_triangular(L, jnp.eye(s.n_dof), lower=True)
    Kt = Linv @ s.K @ Linv.T
    Ct = Linv @ s.C @ Linv.T
    Wt = s.W @ Linv.T
    Km = Kt + Wt.T @ (s.kbar[:, None] * Wt)
    ws = jnp.sqrt(jnp.maximum(jnp.max(jnp.linalg.eigvalsh(0.5 * (Km + Km.T))), 1e-300))
    WW = (Wt[:, :, None] * Wt[:, None, :]).reshape(s.n_meshes, -1)
    Cm = Ct + Wt.T @ (s.damping[:, None] * Wt)
    return _Frame(Linv=Linv, Wt=Wt, WW=WW, Kt=Kt, Ct=Ct, Cm=Cm, ws=ws)


def _step_weights(problem, kappa, ends, h):
    """Mesh weights of the Magnus exponents of ``c`` steps: ``(s0, s1)``, or ``(s0, s1, d0,
    d1)`` with contact-only damping, each ``(c, m)``: ``kbar_m`` times the zeroth and first
    moments about the step middle of ``kappa_m g'_m`` over the step (stiffness times s and
    s^2), and ``c_m`` times those of the contact indicator (damping times s and s^2).

    ``kappa``: ``(k_a, k_b)``, each ``(c, m)``, the stiffness at the two Gauss points of
    every step; ``ends``: ``(p0, p1, dp0, dp1)``, each ``(c, m)``, the mesh deflections and
    rates at the step ends; ``h`` the step (s).
    """
    s = problem.system
    k_a, k_b = kappa
    alpha, beta = 0.5 * (k_a + k_b), (k_b - k_a) / (2 * _GAUSS)  # kappa = alpha + beta (s - 1/2)
    u, v = _contact_intervals(*ends, h, s.backlash)  # (4, c, m)
    k0, k1 = (jnp.sum(x, axis=0) for x in _moments(alpha, beta, u, v))
    # int kbar kappa g' dt, int kbar kappa g' (t - t_mid) dt over the step
    weights = (h * k0 * s.kbar, h**2 * k1 * s.kbar)
    if s.contact_damping:
        c0, c1 = (jnp.sum(x, axis=0) for x in _moments(1.0, 0.0, u, v))
        weights += (h * c0 * s.damping, h**2 * c1 * s.damping)
    return weights


def _step_exponents(problem, frame, weights, h):
    """Magnus exponents ``(c, 2n, 2n)`` of ``c`` steps of ``h`` seconds, from their mesh
    weights (:func:`_step_weights`, each ``(c, m)``)."""
    s = problem.system
    n, ws = s.n_dof, frame.ws

    def mesh_sum(w):  # sum_m w_m w~_m w~_m^T: (c, m) -> (c, n, n)
        return (w @ frame.WW).reshape(w.shape[:-1] + (n, n))

    S = (h * frame.Kt + mesh_sum(weights[0])) / ws
    S1 = mesh_sum(weights[1]) / ws
    if s.contact_damping:
        D = h * frame.Ct + mesh_sum(weights[2])
        D1 = mesh_sum(weights[3])
    else:
        D, D1 = jnp.broadcast_to(h * frame.Cm, S.shape), None
    return _magnus_exponent(D, D1, S, S1, h, ws)


def _magnus_exponent(D, D1, S, S1, h, ws):
    """``A0 + [A1, A0] / h`` from its ``(c, n, n)`` blocks, ``A0 = [[-D, e I], [-S, 0]]``,
    ``A1 = [[-D1, 0], [-S1, 0]]``, ``e = h w_s`` (``D1 = None``: zero, the damping acting
    everywhere). The commutator takes ``n x n`` products, not ``2n x 2n`` ones:
    ``[A1, A0] = [[D1 D - D D1 + e S1, -e D1], [S1 D - S D1, -e S1]]``."""
    eye = jnp.broadcast_to(h * ws * jnp.eye(S.shape[-1]), S.shape)
    if D1 is None:
        top = jnp.concatenate([-D + ws * S1, eye], -1)
        bottom = jnp.concatenate([-S + (S1 @ D) / h, -ws * S1], -1)
    else:
        top = jnp.concatenate([-D + (D1 @ D - D @ D1) / h + ws * S1, eye - ws * D1], -1)
        bottom = jnp.concatenate([-S + (S1 @ D - S @ D1) / h, -ws * S1], -1)
    return jnp.concatenate([top, bottom], -2)


_THETA = 1.13
"""Scaling target of :func:`_expm`: ``||A||_1 <= 1.13``, where the Taylor remainder of
degree 18 is below ``1.13^19 / 19! < 1e-16``."""

# Taylor polynomial of degree 18 in five matrix products (Bader, Blanes & Casas,
# "Computing the matrix exponential with an optimized Taylor polynomial approximation",
# Mathematics 7 (2019) 1174, their degree-18 scheme):
# q31 = sum_i _EXPM_A[i] A^i (i = 0..3), q6j = sum_i _EXPM_B[j][i] A^i (i = 0, 1, 2, 3, 6),
# q91 = q31 q64 + q63, T18 = q61 + (q62 + q91) q91. Its 19 coefficients equal 1/k! to
# 4e-16 relative (tests/test_stability.py).
_EXPM_A = (0.0, -0.10036558103014462001, -0.0080292464824115696012,
           -0.00089213849804572995569)
_EXPM_B = (
    (0.0, 0.39784974949964507615, 1.3678377846041171992, 0.49828962252538267756,
     -0.00063789819459472330924),
    (-10.967639605296206259, 1.6801581387890619718, 0.057177984647886551270,
     -0.0069821012248805208429, 0.000033497501708607053831),
    (-0.090431683239081056197, -0.067640451907138190756, 0.067596130177045964608,
     0.029555257042931552743, -0.000013918025751606070112),
    (0.0, 0.0, -0.092336461936711859276, -0.016936493900208171719,
     -0.000014008679818203615979),
)


def _expm(A):
    """``expm`` of a batch ``(c, k, k)``: Taylor degree 18 with scaling and squaring.

    Matrix products only (a library ``expm`` evaluates all its Pade orders under ``vmap``,
    and a linear solve costs more to compile than the products it saves): the degree-18
    polynomial takes 5 products (:data:`_EXPM_B`), where degree 16 in Paterson-Stockmeyer
    form took 6 and needed ``||A||_1 <= 0.8``; the number of squarings
    is per matrix, ``ceil(log2(||A||_1 / 1.13))``. On the paper sweep ``||A||_1`` is about
    ``h w_s``, 1.2 to 4.5: at most two squarings, against up to three at 0.8.
    """
    norm = jnp.max(jnp.sum(jnp.abs(A), axis=-2), axis=-1)
    s = jnp.maximum(0, jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / _THETA))).astype(int)
    A = A * (0.5**s)[:, None, None]
    eye = jnp.broadcast_to(jnp.eye(A.shape[-1]), A.shape)
    A2 = A @ A
    A3 = A2 @ A
    A6 = A3 @ A3
    powers = (eye, A, A2, A3, A6)

    def combine(coef, terms):
        return sum(c * X for c, X in zip(coef, terms) if c != 0.0)

    q31 = combine(_EXPM_A, powers[:4])
    q61, q62, q63, q64 = (combine(c, powers) for c in _EXPM_B)
    q91 = q31 @ q64 + q63
    E = q61 + (q62 + q91) @ q91

    def square(state):
        i, E = state
        return i + 1, jnp.where((i < s)[:, None, None], E @ E, E)

    _, E = jax.lax.while_loop(lambda state: state[0] < jnp.max(s), square, (0, E))
    return E


def _tree_product(E):
    """``E[-1] @ ... @ E[1] @ E[0]`` for a power-of-two batch."""
    while E.shape[0] > 1:
        E = E.reshape(E.shape[0] // 2, 2, *E.shape[1:])
        E = E[:, 1] @ E[:, 0]
    return E[0]


def _monodromy_scaled(problem: HBProblem, X, omega, n_steps: int | None, frame=None):
    """Monodromy in the scaled coordinates ``(q, u)``, with the frame and the orbit.
    ``frame``: from :func:`_frame` (built here when ``None``); given, the computation
    calls no LAPACK routine (see :func:`verdict_basis`)."""
    n_steps = floquet_steps(problem) if n_steps is None else n_steps
    if n_steps < 2 or n_steps & (n_steps - 1):
        raise ValueError(
            f"n_steps must be a power of two >= 2 (steps per period), not {n_steps!r}")
    s = problem.system
    omega = jnp.asarray(omega, dtype=float)
    w0 = omega / problem.settings.eta
    period = 2 * jnp.pi / w0
    h = period / n_steps
    frame = _frame(problem) if frame is None else frame
    orbit = _Orbit(P=X @ s.W.T, w0=w0, omega=omega, problem=problem)
    chunk = min(CHUNK, n_steps)
    p, dp = orbit.on_grid(n_steps)  # (N, m) at the step starts
    by_chunk = lambda a: a.reshape(n_steps // chunk, chunk, -1)  # noqa: E731
    ends = tuple(by_chunk(a) for a in (p, jnp.roll(p, -1, axis=0), dp, jnp.roll(dp, -1, axis=0)))
    # the stiffness at the two Gauss points of every step, in phase: the same for every
    # Omega, so under vmap over the points of a sweep it is evaluated once
    step = 2 * np.pi / n_steps
    kappa = tuple(by_chunk(stiffness_at_phases(s, problem.settings.eta, jnp.asarray(
        step * (np.arange(n_steps) + 0.5 + x))).T) for x in (-_GAUSS, _GAUSS))

    def body(Phi, inputs):
        weights = _step_weights(problem, *inputs, h)
        E = _expm(_step_exponents(problem, frame, weights, h))
        return _tree_product(E) @ Phi, None

    Phi, _ = jax.lax.scan(body, jnp.eye(2 * s.n_dof), (kappa, ends))
    return Phi, frame, orbit


def _to_physical(problem, frame, orbit):
    """``P`` with ``(dz, dz') = P (q, u)`` at ``t = 0``."""
    s = problem.system
    n = s.n_dof
    LinvT = frame.Linv.T
    t0 = jnp.zeros((s.n_meshes,))
    if s.contact_damping:
        p, _ = orbit.deflection(t0)
        hm = in_contact(p, s.backlash)
    else:
        hm = jnp.ones((s.n_meshes,))
    G = s.W.T @ ((s.damping * hm)[:, None] * s.W)
    Minv = frame.Linv.T @ frame.Linv
    return jnp.block([[LinvT, jnp.zeros((n, n))], [-Minv @ (s.C + G) @ LinvT, frame.ws * LinvT]])


def monodromy(problem: HBProblem, X: Array, omega, n_steps: int | None = None) -> Array:
    """Monodromy matrix ``(2n, 2n)`` of ``(dz, dz')`` over one response period (physical units).

    **Arguments:** ``problem``: from ``hb_problem``; ``X``: ``(2K+1, n)`` HB coefficients
    (rad or m); ``omega``: base frequency ``Omega`` (rad/s); ``n_steps``: steps per period
    (static; default :func:`floquet_steps`).
    """
    Phi, frame, orbit = _monodromy_scaled(problem, X, omega, n_steps)
    P = _to_physical(problem, frame, orbit)
    return P @ Phi @ jnp.linalg.inv(P)


def floquet_multipliers(problem: HBProblem, X: Array, omega, n_steps: int | None = None
                        ) -> Complex[Array, " 2n"]:
    """Floquet multipliers ``(2n,)`` (complex) of the periodic solution ``X`` at ``omega``.

    Eigenvalues of the monodromy matrix over one response period ``2 pi eta / Omega``
    (see the module docstring for the method). Jit- and vmap-able over ``X`` and
    ``omega``. **Arguments:** as :func:`monodromy`.
    """
    Phi, _, _ = _monodromy_scaled(problem, X, omega, n_steps)
    return jnp.linalg.eigvals(Phi)


# ----------------------------------------------------------------------------- Hill


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
    frame = _frame(problem)
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


# ------------------------------------------------------------------------ stability


class Stability(eqx.Module):
    """Stability of one periodic solution (a batch of them under ``vmap``).

    **Fields:**

    - ``multipliers`` ``(2n,)`` complex: Floquet multipliers (eigenvalues of the
      monodromy matrix over one response period);
    - ``mesh_strain`` ``(2n,)``: how much each Floquet mode deflects the meshes,
      ``max_m |w_m . dz| / max_i (lever_i |dz_i|)``, ``lever_i = max_m |W_mi|`` (the
      mesh deflection a unit motion of coordinate ``i`` can cause; 0: no mesh strained);
    - ``rigid_share`` ``(2n,)``: share of each Floquet mode's displacement (in the mass
      norm, ``dz^H M dz``) that lies in the rigid-body modes of the mean-stiffness model
      (:func:`gearjax._modal.mode_classes`: strain energy mostly in the free-class housing
      springs, such as the 1e2 N m/rad ones of the paper, or eigenvalue zero);
    - ``excluded`` ``(2n,)`` bool: multipliers left out of the verdict, those of the
      (near-)rigid-body modes: with ``r`` rigid modes in the model, the ``2 r`` Floquet
      modes with the largest ``rigid_share``. Nothing damps such a mode (model.md) and
      it does not change the mesh forces; its pair of multipliers sits on the unit
      circle up to a slight parametric coupling through its small mesh strain (on the
      paper's backlash sweep up to 3.6e-5 outside, with a strain of 1e-3 against 0.4
      and more for every other mode), and an exact rigid-body mode gives the double
      multiplier +1. The verdict is on the gear's vibration: the other ``2 (n - r)``
      multipliers;
    - ``max_abs``: the largest ``|mu|`` of the multipliers that are not excluded;
    - ``stable`` bool: ``max_abs < 1 + tol``.
    """

    multipliers: Complex[Array, " 2n"]
    mesh_strain: Float[Array, " 2n"]
    rigid_share: Float[Array, " 2n"]
    excluded: Bool[Array, " 2n"]
    max_abs: Float[Array, ""]
    stable: Bool[Array, ""]


def stability(problem: HBProblem, X: Array, omega, tol=1e-6, n_steps: int | None = None
              ) -> Stability:
    """Floquet stability of the periodic solution ``X`` ``(2K+1, n)`` at ``omega`` (rad/s).

    Multipliers from :func:`floquet_multipliers` (``n_steps`` static, default
    :func:`floquet_steps`); ``tol`` is the margin on ``|mu| = 1`` for the verdict. The
    multipliers of the model's rigid-body modes are excluded (see :class:`Stability`).
    Jit- and vmap-able over ``X``, ``omega`` (CPU: it needs a non-symmetric
    eigen-decomposition).
    """
    basis = verdict_basis(problem)
    Phi, _, _ = _monodromy_scaled(problem, X, omega, n_steps, basis.frame)
    mu, V = jnp.linalg.eig(Phi)
    return verdict(problem, basis, mu, V, tol)


class VerdictBasis(eqx.Module):
    """What the Floquet verdict needs of the system, the same for every solution: the
    scaled frame of the monodromy (:class:`_Frame`) and the model's rigid-body modes
    (``modal`` ``(n, n)`` M-normalised shapes, ``rigid`` ``(n,)`` bool)."""

    frame: _Frame
    modal: Array
    rigid: Array


def verdict_basis(problem: HBProblem) -> VerdictBasis:
    """:class:`VerdictBasis` of ``problem`` (Cholesky and symmetric eigen-decompositions).

    With it, :func:`_monodromy_scaled` and :func:`verdict` call no LAPACK routine: the
    sweep evaluates them in several threads at once, and jaxlib 0.10's CPU LAPACK
    kernels can deadlock XLA's thread pool when several run concurrently (each waits
    on pool tasks that the others hold the threads for), so the only non-symmetric
    eigen-decomposition there is NumPy's, outside XLA."""
    _, modal, _, rigid, _ = mode_classes(problem.system)
    return VerdictBasis(frame=_frame(problem), modal=modal, rigid=rigid)


def scaled_monodromy(problem: HBProblem, basis: VerdictBasis, X: Array, omega,
                     n_steps: int | None = None) -> Array:
    """Monodromy matrix ``(2n, 2n)`` of one solution in the scaled coordinates of
    ``basis.frame`` (``n_steps`` static, default :func:`floquet_steps`; no LAPACK call):
    its eigenvalues are the Floquet multipliers, its eigenvalues and eigenvectors the
    input of :func:`verdict`."""
    return _monodromy_scaled(problem, X, omega, n_steps, basis.frame)[0]


def verdict(problem: HBProblem, basis: VerdictBasis, mu, V, tol=1e-6) -> Stability:
    """:class:`Stability` from the eigenvalues ``mu`` ``(2n,)`` and eigenvectors ``V``
    ``(2n, 2n)`` (columns) of the scaled monodromy matrix (jittable; no LAPACK call)."""
    s = problem.system
    dz = basis.frame.Linv.T @ V[: s.n_dof]  # (n, 2n): displacement part of every Floquet mode
    lever = jnp.max(jnp.abs(s.W), axis=0) if s.n_meshes else jnp.zeros(s.n_dof)
    size = jnp.max(lever[:, None] * jnp.abs(dz), axis=0)
    strain = jnp.max(jnp.abs(s.W @ dz), axis=0) if s.n_meshes else jnp.zeros(2 * s.n_dof)
    ratio = jnp.where(size > 0, strain / jnp.where(size > 0, size, 1.0), 0.0)
    a = jnp.abs(basis.modal.T @ (s.M @ dz)) ** 2  # (n, 2n): modal content of every Floquet mode
    total = jnp.sum(a, axis=0)
    share = jnp.sum(jnp.where(basis.rigid[:, None], a, 0.0), axis=0) / jnp.where(
        total > 0, total, 1.0)
    rank = jnp.argsort(jnp.argsort(-share))  # 0 for the most rigid-body-like Floquet mode
    excluded = rank < 2 * jnp.sum(basis.rigid)
    max_abs = jnp.max(jnp.where(excluded, 0.0, jnp.abs(mu)))
    return Stability(multipliers=mu, mesh_strain=ratio, rigid_share=share, excluded=excluded,
                     max_abs=max_abs, stable=max_abs < 1.0 + tol)


def bifurcation_kind(mult_before, mult_after, tol: float = 1e-6) -> str | None:
    """How a multiplier crossed the unit circle between two neighbouring solutions.

    **Arguments:** the multipliers at the two points (arrays, or :class:`Stability`
    objects, whose excluded multipliers are dropped); ``tol``: margin on ``|mu| = 1``.
    The multipliers are paired by a minimum-distance assignment; a pair whose side of
    the circle changed is located where its straight path crosses ``|mu| = 1``.

    **Returns:** ``"fold"`` (a real multiplier through +1), ``"period_doubling"``
    (through -1), ``"neimark_sacker"`` (a complex pair), or ``None`` if no multiplier
    changed side.
    """
    from scipy.optimize import linear_sum_assignment

    def retained(m):
        if isinstance(m, Stability):
            return np.asarray(m.multipliers)[~np.asarray(m.excluded)]
        return np.asarray(m).astype(complex).ravel()

    before, after = retained(mult_before), retained(mult_after)
    rows, cols = linear_sum_assignment(np.abs(before[:, None] - after[None, :]))
    b, a = before[rows], after[cols]
    changed = (np.abs(b) > 1 + tol) != (np.abs(a) > 1 + tol)
    if not changed.any():
        return None
    b, a = b[changed], a[changed]
    j = int(np.argmax(np.abs(np.abs(a) - np.abs(b))))
    b, a = b[j], a[j]
    real_b = abs(b.imag) <= 1e-8 * abs(b)
    real_a = abs(a.imag) <= 1e-8 * abs(a)
    if not (real_b or real_a):
        return "neimark_sacker"
    t = (1.0 - abs(b)) / (abs(a) - abs(b)) if abs(a) != abs(b) else 0.5
    crossing = b + np.clip(t, 0.0, 1.0) * (a - b)
    if real_b and real_a:
        return "fold" if crossing.real > 0 else "period_doubling"
    real = b if real_b else a
    return "fold" if real.real > 0 else "period_doubling"
