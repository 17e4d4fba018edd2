"""Floquet multipliers of a periodic solution: the monodromy matrix by Magnus steps.

Stability of periodic solutions: Floquet multipliers, Hill's method, classification.

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
``max(K, highest excitation)``, and at least 256 (on a torus: the multiple of
:data:`CHUNK` with as many per period of the highest frequency over the ``q`` turns of
the near return, below). The stiff modes need no steps (the
exponential is exact for them); the error comes from the time variation and the
switches. docs/stability.md gives its measured accuracy.

Grazing contacts: a contact (or gap) much shorter than the step is found only as
well as the interpolant resolves the depth ``|p| - b`` of its turning point, and the
multipliers depend on that depth like its square root (the contact time), so a very
shallow graze costs accuracy (docs/stability.md).

**Solutions on a torus** (model.md, "Incommensurate stages"). A quasi-periodic solution
``x(theta)``, ``theta = (r_1, ..., r_G) omega_0 t``, has no period and no monodromy
matrix. Its linearisation is ``dz' = A(theta(t)) dz``; where it is reducible,
``Phi(t) = P(theta(t)) exp(B t) P(theta(0))^-1`` with ``P`` a function on the torus,
and the characteristic exponents (the eigenvalues of ``B``, the Lyapunov exponents'
real parts) decide stability. After ``q`` turns of the base angle the line
``theta(t)`` returns to within the drift ``d_g = q r_g - round(q r_g)`` turns of its
start (:func:`return_turns`: the fewest ``q <= MAX_RETURN_TURNS`` with every
``|d_g| <= RETURN_DRIFT``); the monodromy over those ``q`` turns of the *true* line
(the steps above over ``q 2 pi / omega_0``) is ``P(theta(0) + 2 pi d) exp(B q T_0)
P(theta(0))^-1``: its eigenvalues are ``exp(s q T_0)`` up to the relative perturbation
``P^-1 dP/dtheta . 2 pi d``. The verdict takes the ``q``-th root, the growth per turn
of the base angle (:func:`gearjax._engine.verdict.verdict`). This is the rational
approximation of the frequency ratio used for quasi-periodic Mathieu equations
(Zounes & Rand, SIAM J. Appl. Math. 58 (1998) 1094), without replacing the rates: the
equations integrated are the true ones; only the closure is approximate. ``G = 1`` is
``q = 1`` with no drift, the periodic monodromy. ``hill`` (Hill's method on the torus
basis) is the independent cross-check; its dense eigenproblem of ``2 (2P+1) n``
unknowns is too costly for a sweep.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Complex

from . import aft as _aft
from .hb import HBProblem
from .mesh_force import in_contact, stiffness_series, transmission_error


_GAUSS = 0.5 / np.sqrt(3.0)
"""Offset of the two Gauss points from the middle of a step, in steps."""

CHUNK = 16
"""Steps whose exponentials are formed together (a batch inside the scan over the period),
small enough that a batch of a sweep's chunk of points stays in a core's cache
(docs/stability.md has the measurements)."""


# ------------------------------------------------------------------------ helpers


RETURN_DRIFT = 0.02
"""Largest drift (turns of each torus angle) of the near return over which the monodromy
of a torus solution is taken (module docstring, "Solutions on a torus")."""

MAX_RETURN_TURNS = 256
"""Most turns of the base angle the near return may take; where none within it meets
:data:`RETURN_DRIFT`, the turns of the smallest drift are taken (and reported)."""


def return_turns(rates, max_turns: int = MAX_RETURN_TURNS, drift: float = RETURN_DRIFT
                 ) -> tuple[int, float]:
    """``(q, d)``: the fewest whole turns ``q`` of the base angle after which every angle
    of ``rates`` (each angle's rate over the base frequency ``omega_0``) is within
    ``drift`` turns of a whole turn, and the largest such distance ``d``; where no
    ``q <= max_turns`` does, the ``q`` of the smallest ``d``. ``(1, 0.0)`` for a periodic
    basis (rates whole numbers)."""
    r = np.asarray(rates, dtype=float)
    best = (1, math.inf)
    for q in range(1, max_turns + 1):
        d = float(np.max(np.abs(q * r - np.round(q * r))))
        if d <= max(drift, 1e-12):
            return q, d
        if d < best[1] - 1e-12:
            best = (q, d)
    return best


def top_frequency(problem: HBProblem) -> float:
    """The highest frequency (over ``omega_0``) in the solution or the excitation: the
    largest frequency number of the basis, each mesh's top stiffness or transmission-error
    harmonic, and each forcing rate (``K`` or the highest excitation order for a periodic
    problem)."""
    s, eta = problem.system, problem.settings.eta
    H = max(s.k_cos.shape[-1], s.te_cos.shape[-1])
    tops = [float(np.max(_aft.frequency_numbers(problem.basis)))]
    tops += [H * eta * float(r) for r in s.mesh_rates()]
    tops += [eta * float(r) for r in s.forcing_rates()]
    return max(tops + [1.0])


def floquet_steps(problem: HBProblem, per_harmonic: int = 32) -> int:
    """Default number of steps over the monodromy's span (static): at least
    ``per_harmonic`` per period of the highest frequency (:func:`top_frequency`) over the
    ``q`` turns of :func:`return_turns`, and 256; a power of two for a periodic solution
    (one period), a multiple of :data:`CHUNK` on a torus (where a power of two could
    almost double the many turns' steps); see the module docstring (a sweep takes 16,
    ``SWEEP_FLOQUET_STEPS`` of the sweep)."""
    q, _ = return_turns(problem.basis.rates)
    need = max(256, per_harmonic * top_frequency(problem) * q)
    if q == 1:
        return int(2 ** int(np.ceil(np.log2(need))))
    return int(CHUNK * math.ceil(need / CHUNK))


class _Orbit(eqx.Module):
    """Mesh deflections ``p_m(t)`` of the solution along its line ``theta = rates omega_0 t``
    (one period of a periodic solution, ``turns`` turns of the base angle on a torus)."""

    P: Array  # (C, m) coefficients of W x(theta)
    w0: Array
    omega: Array
    problem: HBProblem
    turns: int = eqx.field(static=True, default=1)

    def deflection(self, t):
        """Deflection and time rate ``(m,)`` at time ``t`` (s, scalar) along the line."""
        s = self.problem.system
        rates = jnp.asarray(s.mesh_rates(), dtype=float)
        p, dp = _line_series(self.P, self.problem.basis, self.w0, self.w0 * t)
        e, de = transmission_error(s.te_mean, s.te_cos, s.te_sin, rates, self.omega * t)
        return p - e, dp - self.omega * de

    def on_grid(self, n: int):
        """Deflection and rate ``(n, m)`` at the ``n`` equally spaced instants ``t_j = j S /
        n`` of the span ``S = turns 2 pi / omega_0``: for a periodic solution inverse FFTs
        of the coefficients (exact for ``n > 2K``), on a torus the series summed along the
        line; the transmission error evaluated in phase (it does not depend on ``Omega``)."""
        s, basis = self.problem.system, self.problem.basis
        eta = self.problem.settings.eta
        tau = jnp.asarray(2 * np.pi * self.turns * np.arange(n) / n)
        if basis.G == 1 and self.turns == 1:
            p = _aft.synthesis(self.P, n)
            dp = self.w0 * _aft.synthesis(_aft.derivative(self.P), n)
        else:  # the line's basis functions at the steps, in phase (no Omega in them)
            p, dp = _line_series(self.P, basis, self.w0, tau)
        rates = jnp.asarray(s.mesh_rates(), dtype=float) * eta
        e, de = transmission_error(s.te_mean, s.te_cos, s.te_sin, rates, tau)
        return p - e.T, dp - self.w0 * de.T


def _line_series(C: Array, basis, w0, phase):
    """Value and time derivative of the function with coefficients ``C`` ``(2P+1, m)`` on
    ``basis`` along the line ``theta = rates w0 t``, at phases ``phase = w0 t`` (rad,
    scalar or ``(n,)``): ``C[0] + sum_j C[2j-1] cos(nu_j phase) + C[2j] sin(nu_j phase)``,
    ``nu_j`` the frequency numbers (the harmonics ``1..K`` of a periodic basis).
    **Returns:** two ``(m,)`` (or ``(n, m)``) arrays."""
    nu = jnp.asarray(_aft.frequency_numbers(basis)[1::2])
    arg = jnp.asarray(phase)[..., None] * nu  # (..., P)
    c, s = jnp.cos(arg), jnp.sin(arg)
    a, b = C[1::2], C[2::2]
    return C[0] + c @ a + s @ b, w0 * ((c * nu) @ b - (s * nu) @ a)


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


class ScaledFrame(eqx.Module):
    """Scaled coordinates ``q = L^T dz``, ``u = L^-1 v / w_s`` (M = L L^T)."""

    Linv: Array  # (n, n)
    Wt: Array  # (m, n): W L^-T
    WW: Array  # (m, n * n): the outer products w~_m w~_m^T of the rows of Wt
    Kt: Array  # (n, n): L^-1 K L^-T
    Ct: Array  # (n, n): L^-1 C L^-T
    Cm: Array  # (n, n): Ct + sum_m c_m w~_m w~_m^T (the damping when it acts everywhere)
    ws: Array  # scale frequency (rad/s)


def scaled_frame(problem: HBProblem) -> ScaledFrame:
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
    return ScaledFrame(Linv=Linv, Wt=Wt, WW=WW, Kt=Kt, Ct=Ct, Cm=Cm, ws=ws)


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
    is per matrix, ``ceil(log2(||A||_1 / 1.13))``; ``||A||_1`` is about ``h w_s``.
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


def monodromy_scaled(problem: HBProblem, X, omega, n_steps: int | None, frame=None):
    """Monodromy in the scaled coordinates ``(q, u)``, with the frame and the orbit: over one
    period of a periodic solution, over the ``q`` turns of the base angle of
    :func:`return_turns` on a torus (module docstring). ``frame``: from
    :func:`scaled_frame` (built here when ``None``); given, the computation calls no LAPACK
    routine (see :func:`gearjax._engine.verdict.verdict_basis`)."""
    n_steps = floquet_steps(problem) if n_steps is None else n_steps
    if n_steps < 2 or (n_steps & (n_steps - 1) and n_steps % CHUNK):
        raise ValueError(f"n_steps must be a power of two >= 2 or a multiple of {CHUNK} "
                         f"(steps over the span), not {n_steps!r}")
    s = problem.system
    turns, _ = return_turns(problem.basis.rates)
    omega = jnp.asarray(omega, dtype=float)
    eta = problem.settings.eta
    w0 = omega / eta
    h = turns * 2 * jnp.pi / w0 / n_steps
    frame = scaled_frame(problem) if frame is None else frame
    orbit = _Orbit(P=X @ s.W.T, w0=w0, omega=omega, problem=problem, turns=turns)
    chunk = min(CHUNK, n_steps)
    p, dp = orbit.on_grid(n_steps)  # (N, m) at the step starts
    by_chunk = lambda a: a.reshape(n_steps // chunk, chunk, -1)  # noqa: E731
    # the line closes (periodic) or nearly so (torus): the last step ends on the first
    # sample, as in the periodic case; on a torus the true end lies within the drift
    ends = tuple(by_chunk(a) for a in (p, jnp.roll(p, -1, axis=0), dp, jnp.roll(dp, -1, axis=0)))
    if turns > 1 or problem.basis.G > 1:
        p_end, dp_end = orbit.deflection(turns * 2 * jnp.pi / w0)
        ends = (ends[0], ends[1].at[-1, -1].set(p_end), ends[2], ends[3].at[-1, -1].set(dp_end))
    # the stiffness at the two Gauss points of every step, in phase: the same for every
    # Omega, so under vmap over the points of a sweep it is evaluated once
    step = 2 * np.pi * turns / n_steps
    rates = jnp.asarray(s.mesh_rates(), dtype=float) * eta
    kappa = tuple(by_chunk(stiffness_series(s.k_cos, s.k_sin, rates, jnp.asarray(
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
    if s.contact_damping:
        p, _ = orbit.deflection(0.0)
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
    Phi, frame, orbit = monodromy_scaled(problem, X, omega, n_steps)
    P = _to_physical(problem, frame, orbit)
    return P @ Phi @ jnp.linalg.inv(P)


def floquet_multipliers(problem: HBProblem, X: Array, omega, n_steps: int | None = None
                        ) -> Complex[Array, " 2n"]:
    """Floquet multipliers ``(2n,)`` (complex) of the periodic solution ``X`` at ``omega``.

    Eigenvalues of the monodromy matrix over one response period ``2 pi eta / Omega``
    (see the module docstring for the method). Jit- and vmap-able over ``X`` and
    ``omega``. **Arguments:** as :func:`monodromy`.
    """
    Phi, _, _ = monodromy_scaled(problem, X, omega, n_steps)
    return jnp.linalg.eigvals(Phi)
