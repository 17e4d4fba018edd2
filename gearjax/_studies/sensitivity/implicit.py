"""The derivative of a harmonic-balance response at one converged point, and the rule
that refuses it.

At a converged harmonic-balance point the scaled residual ``res(y, p) = 0``
(:mod:`gearjax._engine.hb`) defines the solution ``y(p)`` implicitly. For a response
``R(p) = r(y(p), p)`` (the RMS, peak or load factor of one mesh) the implicit function
theorem gives

    dR/dp = dr/dp - lambda^T dres/dp,    J^T lambda = dr/dy,    J = dres/dy,

with ``J`` the structured Jacobian of :func:`gearjax._engine.hb.jacobian`
(:func:`gearjax._engine.adjoint.implicit_coefficients`, the engine's one implicit
derivative). One adjoint solve per response and one reverse pass of the residual
through ``assemble`` and ``hb_problem`` give the derivative with respect to every
parameter at once; the Newton iterations are never differentiated.

Where the derivative is refused (:func:`check_point`):

- the point is at or near a fold: there ``J`` is singular and ``dy/dp`` unbounded. The
  test is a Floquet multiplier within ``fold_tol`` (default :data:`FOLD_TOL`) of +1
  (:func:`point_status` says why not the singular values of ``J``). A linear system
  (no backlash) has no fold: there a multiplier that close to +1 comes from a lightly
  damped mode, near-rigid (slow against the response period) or in resonance with a
  harmonic of the response, which makes ``J`` nearly singular and the derivative
  ill-conditioned; the refusal names that mode (:func:`slow_mode`);
- the periodic solution is unstable (Floquet multipliers, :func:`gearjax.stability`):
  it is not the response a gearbox shows (in a linear system: a parametric
  instability, unbounded).

(A point that did not converge has no derivative either; the studies say so before
asking.)

Backlash makes the mesh force piecewise linear. The harmonic balance samples it on
its time grid, so the discrete residual is piecewise smooth in ``y`` and ``p`` with
kinks only where a sample crosses a clearance edge ``|p| = b``: the derivative is that
of the solver's own response, exact where contact is kept and well defined wherever
no sample sits on an edge. ``max_force`` is the largest sample, so its derivative is
that of the force at the sample where the peak is.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._engine import hb as _hb
from ..._engine.adjoint import implicit_coefficients
from ..._engine.newton import newton
from ..._engine.results import RESULTS, result_word
from ..._engine.verdict import scaled_monodromy, stability, verdict, verdict_basis

FOLD_TOL = 0.05
"""Smallest distance ``min |mu - 1|`` of the Floquet multipliers ``mu`` from +1 accepted
(closer: the point is at or near a fold; :func:`point_status`)."""


class PointGradient(eqx.Module):
    """A response and its implicit derivative at one converged point.

    **Fields:** ``value``: the response ``R``; ``gradient`` ``(p,)``: ``dR/dtheta``;
    ``partial`` ``(p,)``: the explicit part ``dr/dtheta`` at fixed solution.
    """

    value: Array
    gradient: Array
    partial: Array


@eqx.filter_jit
def implicit_gradient(family, theta: Float[Array, " p"], settings: _hb.HarmonicBalance,
                      y: Float[Array, " N"], omega, response) -> PointGradient:
    """``dR/dtheta`` of ``R = response(problem(theta), X(theta), omega)`` at a converged
    point, by the implicit function theorem (module docstring).

    **Arguments:** ``family``: ``theta -> System`` (e.g.
    :class:`~gearjax._studies.sensitivity.GearFamily`, or any ``equinox.Module`` with
    ``__call__``); ``theta`` ``(p,)``: the nominal parameters; ``settings``: the harmonic
    balance ``y`` was solved with; ``y`` ``(N,)``: scaled unknowns converged at ``theta``
    (``HBSolution.y`` of ``hb_problem(family(theta), settings)``); ``omega``: base
    frequency (rad/s); ``response``: ``(problem, X, omega) -> scalar`` (e.g.
    :class:`~gearjax._studies.sensitivity.MeshResponse`), ``X`` ``(C, n)`` physical
    coefficients (``C = 2K+1``, or ``2P+1`` for the ``P`` wave vectors of a torus basis:
    the derivative is generic over the basis).

    **Returns:** :class:`PointGradient`. Whether the point may be differentiated (not at
    or near a fold, stable) is the caller's test: :func:`point_status`,
    :func:`check_point`.
    """
    theta = jnp.asarray(theta, dtype=float)
    omega = jnp.asarray(omega, dtype=float)

    def responses(th):  # along the solution y(theta), and at the fixed solution
        problem = _hb.hb_problem(family(th), settings)
        X_fixed = y.reshape(problem.shape) * jax.lax.stop_gradient(problem.x_scale)
        X = implicit_coefficients(problem, y, omega)
        return response(problem, X, omega), response(problem, X_fixed, omega)

    (_, value), pullback = jax.vjp(responses, theta)
    one, zero = jnp.ones_like(value), jnp.zeros_like(value)
    (gradient,), (partial,) = pullback((one, zero)), pullback((zero, one))
    return PointGradient(value=value, gradient=gradient, partial=partial)


@eqx.filter_jit
def solve_at(family, theta: Float[Array, " p"], settings: _hb.HarmonicBalance, omega,
             X0: Array | None = None) -> _hb.HBSolution:
    """Newton at ``omega`` (rad/s) for the system ``family(theta)``, from the physical
    coefficients ``X0`` ``(C, n)`` or, when ``None``, the linear in-contact guess."""
    problem = _hb.hb_problem(family(theta), settings)
    y0 = _hb.linear_guess(problem, omega) if X0 is None else (X0 / problem.x_scale).reshape(-1)
    return newton(problem, omega, y0)


def response_at(family, theta, settings: _hb.HarmonicBalance, omega, response,
                X0: Array | None = None) -> tuple[float, RESULTS]:
    """``(R, result)`` by re-solving at ``theta`` (Newton from ``X0``): the
    finite-difference reference for :func:`implicit_gradient`."""
    theta = jnp.asarray(theta, dtype=float)
    sol = solve_at(family, theta, settings, jnp.asarray(omega, dtype=float), X0)
    value = _response_jit(family, theta, settings, sol.X, jnp.asarray(omega, dtype=float),
                          response)
    return float(value), sol.result


@eqx.filter_jit
def _response_jit(family, theta, settings, X, omega, response):
    return response(_hb.hb_problem(family(theta), settings), X, omega)


# ------------------------------------------------------------------------ refusal


class SensitivityRefused(ValueError):
    """A point that has no derivative: ``result`` is the word of ``RESULTS.fold`` or
    ``RESULTS.unstable``; the message names the point and the reason."""

    def __init__(self, result: RESULTS, message: str):
        super().__init__(message)
        self.result = result_word(result)


@eqx.filter_jit
def point_status(problem: _hb.HBProblem, X: Array, omega) -> tuple[Array, Array]:
    """``(stable, fold_distance)`` of the solution ``X`` ``(C, n)`` (``C = 2K+1``, or ``2P+1``
    on a torus) at ``omega`` (rad/s).

    ``stable``: :func:`gearjax.stability`; ``fold_distance``: ``min |mu - 1|`` over its
    Floquet multipliers ``mu`` (those of mesh-free rigid-body modes excluded). A fold
    (saddle-node) of the periodic solution is where a real multiplier passes through +1:
    there ``dres/dy`` is singular and ``dy/dp`` unbounded.

    On a torus (``G > 1``) the multipliers are those of :func:`gearjax.stability`: the
    ``q``-th roots of the monodromy over the near return of the torus line (growth per
    turn of the base angle, ``gearjax._engine.floquet``). A torus fold puts one of them
    at +1 as well; the test is conservative there, since a root's angle is only known
    within ``2 pi / q`` (exponents are defined modulo the torus's combination
    frequencies), so a lightly damped mode far below the base frequency can also come
    within ``fold_tol`` of +1 and refuse a point that has a derivative.

    Why the multipliers and not the singular values of the HB Jacobian: the sampled
    (AFT) backlash force makes the discrete residual piecewise smooth, so at a fold the
    Jacobian jumps across the singularity instead of passing through it; soft housing
    springs give near-rigid-body singular values at every point; and near a sharp linear
    resonance the branch tangent is as steep as near a fold. The multipliers, from exact
    contact intervals, have none of these faults.
    """
    s = stability(problem, X, omega)
    return s.stable, jnp.min(jnp.where(s.excluded, jnp.inf, jnp.abs(s.multipliers - 1.0)))


def slow_mode(problem: _hb.HBProblem, X: Array, omega) -> dict:
    """The mode behind the Floquet multiplier nearest +1 of the solution ``X`` ``(C, n)``
    at ``omega`` (rad/s), of those the verdict keeps (:func:`gearjax.stability`): the
    mode of the mean-stiffness model (:func:`gearjax._engine.modal.mode_classes`) that
    holds the largest share of that Floquet mode (in the mass norm).

    **Returns:** ``{"hz", "damping_ratio", "share", "harmonic", "response_hz",
    "multiplier", "distance", "max_multiplier"}``: the mode's natural frequency (Hz)
    and modal damping ratio ``phi^T (C + W^T diag(c) W) phi / (2 w)`` (``phi``
    mass-normalised; ``c`` the mesh damping; ``None`` for ``w = 0``), its share of the Floquet mode, the
    harmonic of the response frequency ``response_hz`` nearest to it (0: a near-rigid
    mode, slow against the response period), the multiplier, its distance from +1,
    and the largest retained multiplier modulus. Host NumPy (one eigen-decomposition
    of the monodromy matrix)."""
    s = problem.system
    basis = verdict_basis(problem)
    Phi = np.asarray(scaled_monodromy(problem, basis, X, jnp.asarray(omega)))
    mu, V = np.linalg.eig(Phi)
    mu, V = mu.astype(complex), V.astype(complex)
    st = verdict(problem, basis, jnp.asarray(mu), jnp.asarray(V))
    kept = ~np.asarray(st.excluded)
    mults = np.asarray(st.multipliers)
    distance = np.where(kept, np.abs(mults - 1.0), np.inf)
    k = int(np.argmin(distance))
    dz = np.asarray(basis.frame.Linv).T @ V[: s.n_dof, k]
    modal = np.asarray(basis.modal)
    content = np.abs(modal.T @ (np.asarray(s.M) @ dz)) ** 2
    i = int(np.argmax(content))
    phi = modal[:, i]
    w = math.sqrt(max(float(phi @ np.asarray(s.mean_stiffness()) @ phi), 0.0))
    W = np.asarray(s.W)
    C = np.asarray(s.C) + W.T @ (np.asarray(s.damping)[:, None] * W)
    zeta = float(phi @ C @ phi) / (2 * w) if w > 0 else None  # None: a rigid-body mode
    response_hz = float(omega) / (2 * math.pi * problem.settings.eta)
    hz = w / (2 * math.pi)
    return {"hz": hz, "damping_ratio": zeta,
            "share": float(content[i] / np.sum(content)) if np.sum(content) > 0 else 0.0,
            "harmonic": int(round(hz / response_hz)), "response_hz": response_hz,
            "multiplier": [float(mults[k].real), float(mults[k].imag)],
            "distance": float(distance[k]),
            "max_multiplier": float(np.max(np.abs(mults[kept]))) if kept.any() else None}


LIGHT_DAMPING = 0.05
"""Modal damping ratio below which :func:`check_point` calls a mode lightly damped."""


def check_point(stable, fold_distance, where: str, fold_tol: float = FOLD_TOL, *,
                torus: bool = False, linear: bool = False, mode: dict | None = None) -> None:
    """Raise :class:`SensitivityRefused` when the point ``where`` (e.g. ``"3000 Hz"``) is
    at or near a fold (``fold_distance < fold_tol``) or unstable; ``torus``: the solution
    is quasi-periodic (the message says so). A ``linear`` point (no backlash) has no
    fold: a multiplier within ``fold_tol`` of +1 is refused as ``lightly_damped_mode``,
    naming the mode ``mode`` (:func:`slow_mode`) where given, and an unstable one as a
    parametric instability (unbounded)."""
    d = float(fold_distance)
    mult = ("a multiplier per turn of the base angle (the near-return monodromy's q-th "
            "root)" if torus else "a Floquet multiplier")
    if not d >= fold_tol and linear:
        raise SensitivityRefused(RESULTS.lightly_damped_mode, (
            f"the linear response at {where} has no fold, but {_mode_words(mode)} puts "
            f"{mult} {d:.2g} from +1, closer than {fold_tol:g}: its derivatives there are "
            "dominated by that mode and ill-conditioned; choose another frequency, or "
            "damp or stiffen that mode"))
    if not d >= fold_tol:
        raise SensitivityRefused(RESULTS.fold, (
            f"the point at {where} is at or near a fold of the response curve ({mult} lies "
            f"{d:.2g} from +1, closer than {fold_tol:g}): the response jumps "
            "there and is not a differentiable function of the parameters; choose a "
            "frequency away from the fold"))
    if not bool(stable) and linear:
        top = None if mode is None else mode.get("max_multiplier")
        size = "" if top is None else f", largest |mu| = {top:.4f}"
        raise SensitivityRefused(RESULTS.unstable, (
            f"the linear response at {where} has a parametric instability (unbounded: "
            f"{mult} lies outside the unit circle{size}): any disturbance grows without "
            "bound there, so its derivatives describe no response the train shows"))
    if not bool(stable):
        kind = "quasi-periodic (torus)" if torus else "periodic"
        raise SensitivityRefused(RESULTS.unstable, (
            f"the {kind} solution at {where} is unstable ({mult} lies outside "
            "the unit circle): its derivatives describe no response the train shows"))


def _mode_words(mode: dict | None) -> str:
    """The mode of :func:`slow_mode` in words."""
    if mode is None:
        return "a lightly damped mode"
    zeta = mode["damping_ratio"]
    if zeta is None:
        return f"a rigid-body mode ({mode['hz']:.4g} Hz, undamped)"
    light = "lightly damped " if zeta < LIGHT_DAMPING else ""
    if mode["harmonic"] == 0:
        return (f"a {light}near-rigid mode ({mode['hz']:.4g} Hz, damping ratio {zeta:.2g}, "
                f"slow against the response at {mode['response_hz']:.4g} Hz)")
    return (f"a {light}mode at {mode['hz']:.4g} Hz (damping ratio {zeta:.2g}) in resonance "
            f"with harmonic {mode['harmonic']} of the response "
            f"({mode['harmonic'] * mode['response_hz']:.4g} Hz)")
