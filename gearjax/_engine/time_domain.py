"""Time integration of a ``System`` to its steady state, with diffrax.

The equations are exactly those of the harmonic balance (``_hb``):

    M x'' + C x' + K x + W^T F(t) = f(t),   p = W x - e(t),
    F = mesh_force(p, p', kappa(t), kbar, b, c)

with the stiffness ``kappa`` the truncated Fourier series of the system
(``fourier_series`` of ``k_cos``, ``k_sin``: the ``H`` stiffness harmonics, not a
true rectangular wave), the transmission error ``e`` the series of ``te_cos``,
``te_sin`` and the forcing ``f_mean`` plus the ``f_cos``, ``f_sin`` columns, each
series at its true rate (``System.mesh_rates``, ``System.forcing_rates`` times
``Omega``: whole multiples for a periodic system, incommensurate floats for one with
several torus angles). The mesh force comes from the one shared ``mesh_force``.

Integration variables are scaled: the phase ``tau = Omega t`` (one base period is
``2 pi``) and ``y = x / x_scale`` with the harmonic balance's ``x_scale`` (the
rotation that deflects a mesh by the characteristic length), so the state
``(y, dy/dtau)`` is of order one and ``rtol``, ``atol`` mean fractions of the
backlash (or static mesh deflection).

Solver: the paper's braked members sit on 1e10 N m/rad housing springs, a
~0.4 MHz mode with damping ratio ~4e-4, against mesh frequencies of a few kHz, and
the response also holds the 39-45 kHz shaft modes (damping ratio ~0.005, excited
through the parametric mesh stiffness) that ``rtol = 1e-8`` must resolve. The
default is the explicit 8th-order ``diffrax.Dopri8`` with an I step-size controller: it
is 7-11 times faster than the L-stable ``diffrax.Kvaerno5`` on the stiff brake springs
at this tolerance, with the same forces
(docs/time_domain.md has the measurements). Both are available
(``TimeDomain(solver=diffrax.Kvaerno5(), pcoeff=0.3, icoeff=0.3)``) and tested against
each other.

Backlash makes the right-hand side piecewise linear in ``p`` (a kink; with
``contact_damping`` a jump of the damping term). A step that straddles a contact
switch has an embedded error estimate of low order, so the controller rejects it
and shrinks the step onto the switch: the switch is resolved to the tolerance
without event location (events would restart the solver at every one of the
dozens of switches per period). Convergence is checked by halving the tolerances
(tests).

Steady state: integrate one base period ``2 pi / Omega`` at a time and compare
the Poincare points (mesh deflections ``W x`` and rates ``W x'``, not the full
state: the undamped near-rigid-body mode never settles but carries no mesh force)
with those 1..8 periods earlier. The samples of the last ``sample_periods`` periods come
from integrating those periods again from the state they started in, from one sample
time to the next (:func:`gearjax._engine.integrator.sample`: a program without a host
callback, so JAX's persistent cache keeps it). Only a periodic excitation has such a
period: the steady-state search refuses a quasi-periodic ``System`` (``ValueError``,
:func:`require_periodic`), whose time integration is windowed (``windowed.py``).
"""

from __future__ import annotations

import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._config import require_x64
from . import integrator as _integrator
from .initial_state import (  # where an integration starts; importable from here too
    contact_state as contact_state,
    contact_state_jit as contact_state_jit,
    hb_initial_state as hb_initial_state,
    start_state as start_state,
)
from .integrator import Integrator
from .kept import kept_program
from .mesh_force import mesh_force, stiffness_series, transmission_error
from .programs import float_arrays
from .results import RESULTS
from .static import static_deflection
from .system import System



class TimeDomain(Integrator):
    """Time-integration settings (static: they are compile keys).

    **Fields:**

    - ``solver``, ``rtol``, ``atol``, ``pcoeff``, ``icoeff``, ``max_steps``: the ODE
      solver and its step-size controller
      (:class:`~gearjax._engine.integrator.Integrator`; a point that needs more than
      ``max_steps`` steps a base period ends with ``max_steps``);
    - ``n_samples``: uniform samples per base period in the returned trajectory;
    - ``sample_periods``: base periods sampled at the end (set it to a found
      sub-harmonic period to get that orbit's responses);
    - ``max_periods``: base periods integrated at most before ``not_periodic``;
    - ``periodic_tol``: tolerance on the change of the Poincare point (mesh
      deflections over the characteristic length, rates ``dp/dtau`` over the length
      times the largest mesh multiplier) after one period; keep it well above the
      integration noise (about ``100 rtol``: with ``rtol = 1e-6`` the paper's case
      never settles to ``1e-6``);
    - ``max_subharmonic``: longest period (in base periods) looked for. A period
      ``q > 1`` counts when the Poincare point repeats after ``q`` periods at ``q``
      checks in a row while it moves by more than ``100 periodic_tol`` over every
      shorter period (so integration noise near the tolerance is not a sub-harmonic).
    """

    n_samples: int = eqx.field(static=True, default=512)
    sample_periods: int = eqx.field(static=True, default=1)
    max_periods: int = eqx.field(static=True, default=100)
    periodic_tol: float = eqx.field(static=True, default=1e-6)
    max_subharmonic: int = eqx.field(static=True, default=8)

    def __check_init__(self):
        for name in ("n_samples", "sample_periods", "max_periods",
                     "max_subharmonic"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"TimeDomain.{name} must be a positive integer, not "
                                 f"{getattr(self, name)!r}.")
        if not float(self.periodic_tol) > 0:
            raise ValueError(f"TimeDomain.periodic_tol must be positive, not "
                             f"{self.periodic_tol!r}.")


class Trajectory(eqx.Module):
    """The end of a time integration: the last ``sample_periods`` base periods.

    Shapes are for one frequency; batched calls add leading axes. ``T`` =
    ``n_samples * sample_periods``.

    **Fields:**

    - ``omega``: base frequency (rad/s);
    - ``t`` ``(T,)``: sample times (s), uniform, from the start of the sampled periods;
    - ``x``, ``v`` ``(n, T)``: coordinates (rad or m) and their rates (per s);
    - ``p``, ``p_dot`` ``(m, T)``: mesh deflections ``W x - e`` (m) and rates (m/s);
    - ``F`` ``(m, T)``: mesh forces (N), from ``mesh_force``;
    - ``x_end``, ``v_end`` ``(n,)``: the state after the last period (at phase 0 of
      the excitation), where a sweep continues;
    - ``result``: a :class:`~gearjax._engine.results.RESULTS` item: ``successful``
      (periodic with the base period), ``not_periodic``, ``max_steps_reached``,
      ``solver_failed`` or ``nonfinite``; ``periods``: base periods integrated;
      ``period``: the period found in base periods (1 when periodic;
      ``2..max_subharmonic`` a sub-harmonic; 0 none: quasi-periodic, chaotic or still transient);
      ``distance`` ``(max_subharmonic,)``: change of the Poincare point over
      ``1..max_subharmonic`` periods at the last check (scaled, see
      ``TimeDomain.periodic_tol``); ``stats``: ``num_steps``, ``num_rejected``:
      accepted and rejected solver steps in all.
    """

    omega: Float[Array, ""]
    t: Float[Array, " T"]
    x: Float[Array, "n T"]
    v: Float[Array, "n T"]
    p: Float[Array, "m T"]
    p_dot: Float[Array, "m T"]
    F: Float[Array, "m T"]
    x_end: Float[Array, " n"]
    v_end: Float[Array, " n"]
    result: RESULTS
    periods: Int[Array, ""]
    period: Int[Array, ""]
    distance: Float[Array, " Q"]
    stats: dict

    @property
    def periodic(self):
        """Whether the trajectory settled with the base period (a boolean array)."""
        return self.result == RESULTS.successful

    @property
    def integrated(self):
        """Whether the integration ran its periods, periodic or not (a boolean array):
        false where the solver failed, whose samples are stale."""
        return (self.result == RESULTS.successful) | (self.result == RESULTS.not_periodic)


# ------------------------------------------------------------------------ the model


def state_scales(system: System):
    """The scaling of the integration state: ``(length, x_scale)``.

    ``length`` (m, scalar): the characteristic mesh length, the largest of the backlash
    and the static mesh deflections; ``x_scale`` ``(n,)`` (rad or m): per coordinate, the
    motion that deflects a mesh by ``length``, as the harmonic balance's. The integrator's
    state is ``y = x / x_scale`` and ``dy/dtau`` with ``tau = Omega t`` (module
    docstring). A system without meshes gets ``1`` and ones (SI units)."""
    if not system.n_meshes:
        return jnp.asarray(1.0), jnp.ones(system.n_dof)
    _, F_static = static_deflection(system)
    p_static = jnp.abs(F_static / system.kbar)
    length = jnp.max(jnp.concatenate([system.backlash, p_static, jnp.array([1e-12])]))
    lever = jnp.max(jnp.abs(system.W), axis=0)
    return length, length / jnp.where(lever > 0, lever, 1.0)


def excitation(system: System, tau):
    """The excitation at base phases ``tau = Omega t`` (rad, scalar or ``(T,)``).

    Every series turns at its true rate: mesh ``m`` at ``system.mesh_rates()[m]`` and
    forcing column ``l`` at ``system.forcing_rates()[l]`` times ``Omega`` (floats, so a
    quasi-periodic ``System`` with ``G > 1`` torus angles gets its incommensurate
    excitation; integers when periodic). **Returns:** stiffness ``kappa``, transmission
    error ``e`` (m) and ``de/dtau`` (m/rad), each ``(m,)`` or ``(m, T)``, and the forcing
    ``f`` (N m or N), ``(n,)`` or ``(n, T)``."""
    rate = jnp.asarray(system.mesh_rates(), dtype=float)
    kappa = stiffness_series(system.k_cos, system.k_sin, rate, tau)
    te, te_rate = transmission_error(system.te_mean, system.te_cos, system.te_sin, rate, tau)
    f = system.f_mean if jnp.ndim(tau) == 0 else system.f_mean[:, None] * jnp.ones(jnp.shape(tau))
    if system.forcing_mu:
        arg = jnp.asarray(system.forcing_rates(), dtype=float)[:, None] * jnp.atleast_1d(tau)
        harm = system.f_cos @ jnp.cos(arg) + system.f_sin @ jnp.sin(arg)
        f = f + (harm if jnp.ndim(tau) else harm[:, 0])
    return kappa, te, te_rate, f


def excitation_rates(system: System) -> tuple[float, ...]:
    """The fundamental rate over ``Omega`` of every mesh and forcing column (floats)."""
    return tuple(float(r) for r in system.mesh_rates()) + tuple(
        float(r) for r in system.forcing_rates())


def require_periodic(system: System, caller: str) -> None:
    """Refuse a ``System`` whose excitation is not periodic in ``2 pi / Omega``.

    **Raises:** ``ValueError`` naming the angle ratios when the system has more than one
    torus angle or an excitation rate that is not a whole multiple of ``Omega``: such a
    train has no period, so no periodic steady state to search for."""
    rates = excitation_rates(system)
    whole = all(abs(r - round(r)) <= 1e-12 * max(1.0, abs(r)) for r in rates)
    if system.n_angles > 1 or not whole:
        raise ValueError(
            f"{caller}: system.angle_ratio = {tuple(system.angle_ratio)} gives excitation "
            f"rates {tuple(round(r, 12) for r in rates)} (times Omega), not all whole "
            f"multiples of one base frequency: the train is quasi-periodic and has no "
            f"period, so there is no periodic steady state to search for. Integrate it in "
            f"windows instead (simulate_windowed), which reports the statistics of the "
            f"response once consecutive windows agree.")


class IntegrationProblem(eqx.Module):
    """A ``System`` prepared for integration in ``tau = Omega t`` and ``y = x / x_scale``."""

    system: System
    Minv: Array  # (n, n)
    K: Array  # (n, n)
    x_scale: Array  # (n,)
    length: Array  # ()
    rate_scale: Array  # (): mesh rate scale, length * the fastest fundamental rate


def integration_problem(system: System) -> IntegrationProblem:
    """``system`` prepared for :func:`vector_field`: inverse mass, stiffness, scales."""
    length, x_scale = state_scales(system)
    top = max(excitation_rates(system) + (1,))
    return IntegrationProblem(system=system, Minv=jnp.linalg.inv(system.M), K=system.K,
                              x_scale=x_scale, length=length, rate_scale=length * top)


def vector_field(tau, z, args):
    """``d(y, dy/dtau)/dtau`` of the scaled state ``z`` ``(2n,)`` at phase ``tau`` (rad);
    ``args = (problem, omega)``, ``omega`` the base frequency (rad/s)."""
    problem, omega = args
    s = problem.system
    n = s.n_dof
    y, u = z[:n], z[n:]
    x = problem.x_scale * y
    v = omega * problem.x_scale * u
    kappa, te, te_rate, f = excitation(s, tau)
    p = s.W @ x - te
    p_dot = s.W @ v - omega * te_rate
    F = mesh_force(p, p_dot, kappa, s.kbar, s.backlash, s.damping, s.contact_damping)
    acc = problem.Minv @ (f - s.C @ v - problem.K @ x - s.W.T @ F)
    return jnp.concatenate([u, acc / (omega**2 * problem.x_scale)])


def mesh_samples(problem: IntegrationProblem, omega, tau, z):
    """Coordinates and mesh quantities of scaled states ``z`` ``(2n, T)`` at phases
    ``tau`` ``(T,)`` (rad): ``(x, v, p, p_dot, F)``, ``(n, T)`` coordinates (rad or m) and
    rates (per s), ``(m, T)`` mesh deflections (m), rates (m/s) and forces (N, from the
    one shared ``mesh_force``)."""
    s, n = problem.system, problem.system.n_dof
    x = problem.x_scale[:, None] * z[:n]
    v = omega * problem.x_scale[:, None] * z[n:]
    kappa, te, te_rate, _ = excitation(s, tau)
    p = s.W @ x - te
    p_dot = s.W @ v - omega * te_rate
    F = mesh_force(p, p_dot, kappa, s.kbar[:, None], s.backlash[:, None], s.damping[:, None],
                   s.contact_damping)
    return x, v, p, p_dot, F


def sample_trajectory(system: System, omega, x0, v0, tau, settings: TimeDomain = TimeDomain()):
    """The motion from ``(x0, v0)`` at ``t = 0`` sampled at the base phases ``tau``
    ``(S,)`` (rad, ``tau = Omega t``, increasing, ``tau[0] > 0``; NumPy: the span is a
    compile key), any system (periodic or quasi-periodic). The equations, scaling and
    solver of :func:`simulate` (``settings``: its tolerances, controller and
    ``max_steps`` per base period). **Returns:** ``(x, v, ok)``: ``x``, ``v`` ``(S, n)``
    (rad or m, and per s) and whether the solver reached the last phase."""
    tau = np.asarray(tau, dtype=float)
    periods = max(1, math.ceil(float(tau[-1]) / (2 * math.pi)))
    return _sample_trajectory(system, *float_arrays(omega, x0, v0, tau), settings, periods)


@eqx.filter_jit
def _sample_trajectory(system, omega, x0, v0, tau, settings, periods):
    require_x64()
    problem = integration_problem(system)
    n = system.n_dof
    z0 = jnp.concatenate([x0 / problem.x_scale, v0 / (omega * problem.x_scale)])
    z, leg = _integrator.sample(settings, dfx.ODETerm(vector_field), 0.0, z0, tau,
                                (problem, omega), settings.max_steps * periods)
    x = problem.x_scale * z[:, :n]
    v = omega * problem.x_scale * z[:, n:]
    return x, v, leg.ok


# ---------------------------------------------------------------------- steady state


def _poincare(problem: IntegrationProblem, z):
    """Scaled mesh deflections and rates (the full state for a system without meshes)."""
    s, n = problem.system, problem.system.n_dof
    if not s.n_meshes:
        return z
    p = s.W @ (problem.x_scale * z[:n]) / problem.length
    r = s.W @ (problem.x_scale * z[n:]) / problem.rate_scale
    return jnp.concatenate([p, r])


def _steady_state(problem: IntegrationProblem, omega, x0, v0, settings: TimeDomain) -> Trajectory:
    require_x64()
    s = problem.system
    n, N, P, Q = s.n_dof, settings.n_samples, settings.sample_periods, settings.max_subharmonic
    # a non-positive frequency (only where it is traced: the public functions refuse a
    # concrete one, ``_positive``) integrates nothing and is ``nonfinite``
    positive = jnp.asarray(omega, dtype=float) > 0
    omega = jnp.where(positive, omega, 1.0)
    z0 = jnp.concatenate([x0 / problem.x_scale, v0 / (omega * problem.x_scale)])
    term = dfx.ODETerm(vector_field)
    args = (problem, omega)
    q = jnp.arange(1, Q + 1)

    def cond(state):
        return ~state["done"]

    def body(state):
        k, z = state["k"], state["z"]
        # every excitation is 2 pi periodic in tau: each period runs over [0, 2 pi]
        leg = _integrator.integrate(settings, term, 0.0, 2 * jnp.pi, z, args,
                                    settings.max_steps)
        z_new = leg.z
        finite = jnp.all(jnp.isfinite(z_new))
        good = leg.ok & finite
        point = _poincare(problem, z_new)
        d = jnp.max(jnp.abs(point[None, :] - state["buffer"]), axis=1)  # (Q,)
        d = jnp.where(q <= k + 1, d, jnp.inf)
        streak = jnp.where(d < settings.periodic_tol, state["streak"] + 1, 0)
        # a sub-harmonic must also move clearly over every shorter period
        shorter = jnp.tril(jnp.ones((Q, Q), dtype=bool), k=-1)  # shorter[i, j]: j < i
        apart = jnp.all(~shorter | (d[None, :] > 100 * settings.periodic_tol), axis=1)
        found = (streak >= q) & ((q == 1) | apart)
        period = jnp.where(jnp.any(found), jnp.argmax(found) + 1, 0)
        k_new = k + 1
        code = _failure(leg, finite, RESULTS.where(period == 1, RESULTS.successful,
                                                   RESULTS.not_periodic))
        done = ~good | (((period > 0) & (k_new >= P)) | (k_new >= max(settings.max_periods, P)))
        last = jnp.where((d < settings.periodic_tol) & apart, q, Q + 1)
        return dict(
            k=jnp.where(good, k_new, k),
            z=jnp.where(good, z_new, z),
            buffer=jnp.where(good, jnp.concatenate([point[None], state["buffer"][:-1]]),
                             state["buffer"]),
            starts=jnp.where(good, jnp.concatenate([state["starts"][1:], z[None]]),
                             state["starts"]),
            streak=streak,
            done=done,
            code=code,
            period=jnp.where(period > 0, period,
                             jnp.where(jnp.min(last) <= Q, jnp.min(last), 0)),
            distance=d,
            steps=state["steps"] + leg.steps,
            rejected=state["rejected"] + leg.rejected,
        )

    init = dict(
        k=jnp.asarray(0),
        z=z0,
        buffer=jnp.broadcast_to(_poincare(problem, z0), (Q,) + _poincare(problem, z0).shape),
        starts=jnp.broadcast_to(z0, (P,) + z0.shape),
        streak=jnp.zeros(Q, dtype=int),
        done=~positive,
        code=RESULTS.where(positive, RESULTS.not_periodic, RESULTS.nonfinite),
        period=jnp.asarray(0),
        distance=jnp.full(Q, jnp.inf),
        steps=jnp.asarray(0),
        rejected=jnp.asarray(0),
    )
    # at least ``sample_periods`` periods, so that ``starts`` holds the start of each
    state = jax.lax.while_loop(cond, body, init)
    # the last P periods again, from the start of the first, through the sample times
    # (module docstring of ``integrator``: no saving at given times inside the loop)
    start = state["starts"][0]
    rest, leg = _integrator.sample(settings, term, 0.0, start,
                                   2 * jnp.pi * jnp.arange(1, P * N) / N, args,
                                   settings.max_steps)
    samples = jnp.concatenate([start[None], rest])
    integrated = (state["code"] == RESULTS.successful) | (state["code"] == RESULTS.not_periodic)
    code = RESULTS.where(integrated, _failure(leg, jnp.all(jnp.isfinite(samples)), state["code"]),
                         state["code"])
    k = state["k"]
    tau = 2 * jnp.pi * (k - P) + 2 * jnp.pi * jnp.arange(P * N) / N
    x, v, p, p_dot, F = mesh_samples(problem, omega, tau, samples.T)
    z_end = state["z"]
    return Trajectory(omega=omega, t=tau / omega, x=x, v=v, p=p, p_dot=p_dot, F=F,
                      x_end=problem.x_scale * z_end[:n],
                      v_end=omega * problem.x_scale * z_end[n:],
                      result=code, periods=k, period=state["period"],
                      distance=state["distance"],
                      stats={"num_steps": state["steps"] + leg.steps,
                             "num_rejected": state["rejected"] + leg.rejected})


def _failure(leg: _integrator.Leg, finite, otherwise) -> RESULTS:
    """The result of an integration ``leg``: the solver's failure (``max_steps_reached``
    or ``solver_failed``), else ``nonfinite`` where the state is not ``finite``, else
    ``otherwise``."""
    return RESULTS.where(
        ~leg.ok, RESULTS.where(leg.result == dfx.RESULTS.max_steps_reached,
                               RESULTS.max_steps_reached, RESULTS.solver_failed),
        RESULTS.where(~finite, RESULTS.nonfinite, otherwise))


# ------------------------------------------------------------------------ public API


def simulate(system: System, omega, *, x0=None, v0=None,
             settings: TimeDomain = TimeDomain()) -> Trajectory:
    """Integrate ``system`` at base frequency ``omega`` until its steady state.

    Starts at ``t = 0`` from ``(x0, v0)`` (e.g. :func:`hb_initial_state` of a
    harmonic-balance solution) or, when ``x0`` is None, from the static solution in
    contact (:func:`contact_state`), then integrates whole base periods
    ``2 pi / omega`` until the mesh deflections and rates repeat after one period
    (``RESULTS.successful``), repeat after ``2..max_subharmonic`` periods over a whole cycle
    (``not_periodic`` with ``period`` set), or ``max_periods`` pass (``not_periodic``,
    ``period`` the shortest near-repetition at the last check or 0). Solver failure is
    a result, never an exception. jit-compiled; vmap it or use
    :func:`simulate_points` and :func:`simulate_sweep` for many frequencies.

    **Arguments:** ``system``: the :class:`System`; ``omega``: base frequency Omega
    (rad/s, scalar); ``x0``, ``v0``: ``(n,)`` initial coordinates (rad or m) and
    rates (per s); ``settings``: :class:`TimeDomain`. **Returns:** a :class:`Trajectory`.

    **Raises:** ``ValueError`` for a quasi-periodic ``system`` (:func:`require_periodic`)
    or an ``omega`` that is not positive (where it is traced, under a caller's ``jit``:
    the result ``nonfinite`` instead).
    """
    require_periodic(system, "simulate")
    _positive(omega, "simulate")
    # both start arrays given: one compiled program whatever the caller passes
    return _simulate(system, *float_arrays(omega, *start_state(system, x0, v0)), settings)


def _positive(omega, caller: str) -> None:
    """Refuse a concrete base frequency that is not positive (``ValueError``); a traced
    one integrates nothing and gives ``nonfinite`` (``_steady_state``)."""
    if isinstance(omega, jax.core.Tracer):
        return
    w = np.asarray(omega, dtype=float).reshape(-1)
    bad = w[~(w > 0)]
    if bad.size:
        raise ValueError(f"{caller}: the base frequency omega must be positive (rad/s), not "
                         f"{float(bad[0])!r}")


@kept_program(filtered=True)
def _simulate(system, omega, x0, v0, settings):
    return _steady_state(integration_problem(system), omega, x0, v0, settings)


def simulate_points(system: System, omegas, *, x0=None, v0=None,
                    settings: TimeDomain = TimeDomain(), batch_size: int | None = None
                    ) -> Trajectory:
    """Independent steady states at every frequency of ``omegas`` in one jitted call.

    **Arguments:** ``omegas`` ``(B,)`` (rad/s); ``x0``, ``v0``: ``(n,)`` shared or
    ``(B, n)`` per point (e.g. :func:`hb_initial_state` vmapped over harmonic-balance
    solutions), None for the static contact state; ``batch_size``: None vmaps all
    ``B`` points (for accelerators); an integer runs ``jax.lax.map`` over chunks of
    that many vmapped points. A vmapped batch advances in lock-step (every point takes
    as many steps and periods as the slowest), which on a CPU usually costs more than it
    saves (docs/time_domain.md). **Returns:** a :class:`Trajectory` with a leading axis ``B``
    on every field. **Raises:** ``ValueError`` for a quasi-periodic ``system``
    (:func:`require_periodic`) or a frequency that is not positive (as :func:`simulate`).
    """
    require_periodic(system, "simulate_points")
    _positive(omegas, "simulate_points")
    return _simulate_points(system, *float_arrays(omegas, x0, v0), settings, batch_size)


def compile_simulate_points(system: System, omegas, *, x0=None, v0=None,
                            settings: TimeDomain = TimeDomain(), batch_size: int | None = None):
    """Compile :func:`simulate_points` for these arguments ahead of time, without running it.

    Arguments as :func:`simulate_points`; only their shapes, types and the static
    ``settings`` and ``batch_size`` matter. Time this to separate compilation from
    integration.

    **Returns:** the compiled program (``jax.stages.Compiled``).
    """
    require_periodic(system, "compile_simulate_points")
    return _simulate_points.lower(system, *float_arrays(omegas, x0, v0), settings,
                                  batch_size).compile()


@eqx.filter_jit
def _simulate_points(system, omegas, x0, v0, settings, batch_size):
    x0, v0 = start_state(system, x0, v0)
    problem = integration_problem(system)
    x0 = jnp.broadcast_to(x0, omegas.shape + x0.shape[-1:])
    v0 = jnp.broadcast_to(v0, omegas.shape + v0.shape[-1:])

    def one(args):
        return _steady_state(problem, *args, settings)

    if batch_size is None:
        return jax.vmap(one)((omegas, x0, v0))
    return jax.lax.map(one, (omegas, x0, v0), batch_size=batch_size)


def simulate_sweep(system: System, omegas, *, x0=None, v0=None,
                   settings: TimeDomain = TimeDomain()) -> Trajectory:
    """A frequency sweep: each point starts from the end state of the one before.

    The order of ``omegas`` is the sweep direction (increasing: up, decreasing:
    down), so coexisting branches show up as in a run-up or run-down test. A
    ``lax.scan`` over the last axis of ``omegas``, vmapped over any leading axes
    (sweep directions, designs): ``omegas`` ``(..., N)`` (rad/s). A point that fails
    (``max_steps``, ``solver_failed``, ``nonfinite``) passes its own start state on.

    **Arguments:** ``x0``, ``v0``: start of the first point, ``(n,)`` shared or
    ``(..., n)`` with all the leading axes of ``omegas``; None for the static contact
    state.
    **Returns:** a :class:`Trajectory` with leading axes ``(..., N)``. **Raises:**
    ``ValueError`` for a quasi-periodic ``system`` (:func:`require_periodic`) or a
    frequency that is not positive (as :func:`simulate`).
    """
    require_periodic(system, "simulate_sweep")
    _positive(omegas, "simulate_sweep")
    return _simulate_sweep(system, *float_arrays(omegas, x0, v0), settings)


@eqx.filter_jit
def _simulate_sweep(system, omegas, x0, v0, settings):
    x0, v0 = start_state(system, x0, v0)
    problem = integration_problem(system)

    def sweep(ws, a, b):
        def step(carry, w):
            xa, va = carry
            tr = _steady_state(problem, w, xa, va, settings)
            ok = tr.integrated
            return (jnp.where(ok, tr.x_end, xa), jnp.where(ok, tr.v_end, va)), tr

        _, out = jax.lax.scan(step, (a, b), ws)
        return out

    lead = omegas.ndim - 1
    fn = sweep
    for _ in range(lead):
        fn = jax.vmap(fn, in_axes=(0, 0 if x0.ndim > 1 else None, 0 if v0.ndim > 1 else None))
    return fn(omegas, x0, v0)
