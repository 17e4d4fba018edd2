"""Windowed time integration: the statistics of a response that need not be periodic.

A train driven at ``G > 1`` incommensurate frequencies (model.md, "Incommensurate
stages") never repeats, so the periodic steady-state search (``time_domain.simulate``)
has nothing to find. Its statistics still settle: integrate consecutive windows of
equal length from ``(x0, v0)``, take per mesh and per window the responses that
``responses.responses_from_samples`` defines for a period (mean force, RMS of the
alternating force, peak, dynamic load factor, separation and back-side shares; the
averages weighted, below), and stop when consecutive windows agree. The same
equations, scaling and solver as the periodic integration (``time_domain``:
``vector_field``, one shared ``mesh_force``); a periodic system (``G = 1``) is the case
whose windows are exact (for a response with the base period, band-limited below the
sampling's Nyquist frequency).

Window length. A window is a whole number ``N`` of base periods ``2 pi / Omega``, so
every excitation tone at a whole multiple of ``Omega`` (a periodic system's only
tones) and every product of two such tones averages exactly over it. What does not
average exactly is a tone at a non-integer frequency ``nu Omega``. The tones that
reach the window's statistics to second order (the mean of ``F`` and of ``F^2``) are
the excitation frequencies ``a`` (each mesh's stiffness and transmission-error
harmonics ``h r_m``, ``h = 1..H``, and each forcing rate) and their beats
``|a - b|``. With ``nu_min`` the slowest non-integer one among them
(:func:`window_plan`),

    N = max(min_periods, ceil(n_beats / nu_min))

spans at least ``n_beats`` cycles of the slowest beat.

Weighted averages. Where the response is quasi-periodic (``nu_min`` exists), a
window's averages are weighted by the smooth bump ``w(s) = exp(-1 / (s (1 - s)))``
over the window (``s`` from 0 to 1, normalised; :func:`window_weights`): the weighted
Birkhoff average, whose error on a quasi-periodic signal falls faster than any power
of the window's length, where the uniform mean's falls as its inverse. A tone running
``c`` cycles in the window leaves ``|w^(c)|`` of its amplitude in the weighted mean
(the bump's Fourier transform: 1.9e-7 at ``c = 20``, 2.7e-16 at 100) instead of up to
``1 / (pi c)`` (0.016 and 0.003); :attr:`WindowPlan.leak` is the largest over
``nu_min N`` to twice it (:func:`window_leak`). Two windows of a stationary response
then differ by about that much at most, so the agreement tolerance ``tol`` must not be
below ``LEAK_FACTOR`` times it (checked at the call), and the windows need span only
a few tens of beats. A periodic response keeps uniform weights: its windows are
exact. Peaks are over the samples, unweighted. Samples: a
window holds ``N S`` uniform samples, ``S = ceil(samples_per_cycle max(1, a_max))``
per base period with ``a_max`` the fastest excitation harmonic (the periodic
integration's 512 for the paper case's ``32 Omega`` with the default 16).

Agreement. Windows ``k - 1`` and ``k`` agree when on every mesh the mean force moves
by at most ``tol`` times ``max(|mean|, RMS)`` and the RMS by at most ``tol`` times the
RMS (largest of the two windows each), with a floor of ``1e-4`` of the train's force
scale (the largest static, mean or RMS mesh force): a mesh carrying a ten-thousandth
of that force does not hold the integration up on its integration noise (about
``rtol`` of the force scale). The first ``transient_windows`` windows are discarded;
``n_agree`` agreements in a row end the run with ``RESULTS.quasi_periodic`` (the
statistics are stationary; for ``G = 1`` nothing more: a periodic or a sub-harmonic
orbit passes alike), ``max_windows`` without them with ``RESULTS.not_stationary``.
Agreement bounds the change from one window to the next, not the transient left: one
that decays by a factor ``rho`` per window may still hold ``tol rho / (1 - rho)``, so
lower ``tol`` or discard more windows where the damping is light against the window.
The window loop is a ``lax.while_loop``: jit-able and vmappable over ``Omega``.
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Callable

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._config import require_x64
from .integrator import Integrator
from .programs import float_arrays
from .responses import MeshResponses, responses_from_samples, static_mesh_forces
from .results import RESULTS
from .system import System
from .time_domain import (IntegrationProblem, integration_problem, mesh_samples, start_state,
                          vector_field)

_FLOOR = 1e-4
"""Fraction of the train's force scale below which a change of a mesh's statistics is
not told apart from zero (module docstring, "Agreement")."""
_WHOLE = 1e-9
"""Relative distance from a whole number below which a frequency counts as whole."""
LEAK_FACTOR = 10.0
"""How far above a window's leak (:attr:`WindowPlan.leak`) the agreement tolerance
``Windowed.tol`` must be: the mean square holds products of two tones' amplitudes, each
truncated by up to the leak."""


class Windowed(Integrator):
    """Settings of the windowed integration (static: they are compile keys).

    **Fields:**

    - ``solver``, ``rtol``, ``atol``, ``pcoeff``, ``icoeff``: the ODE solver and its
      step-size controller (:class:`~gearjax._engine.integrator.Integrator`);
    - ``max_steps``: solver steps allowed per base period (a window of ``N`` periods
      gets ``N max_steps``; a window that needs more ends with ``max_steps_reached``);
    - ``n_beats``: cycles of the slowest non-integer beat a window spans (module
      docstring); ``min_periods``: base periods a window spans at least;
    - ``samples_per_cycle``: samples per cycle of the fastest excitation harmonic;
    - ``tol``: relative agreement of consecutive windows' mean and RMS mesh forces
      (module docstring; at least ``LEAK_FACTOR`` times the window's leak,
      :attr:`WindowPlan.leak`, for a quasi-periodic system);
    - ``transient_windows``: windows discarded before any comparison;
    - ``n_agree``: agreements in a row that end the run;
    - ``max_windows``: windows integrated at most (the history's length);
    - ``max_window_periods``: the longest window allowed, in base periods (a nearly
      commensurate pair of frequencies asks for a longer one: refused);
    - ``report``: after each window, tell the listeners of :func:`window_reports` (a
      host callback: such a program is compiled in each process, not kept in the
      persistent compilation cache).
    """

    n_beats: int = eqx.field(static=True, default=20)
    min_periods: int = eqx.field(static=True, default=1)
    samples_per_cycle: int = eqx.field(static=True, default=16)
    tol: float = eqx.field(static=True, default=1e-3)
    transient_windows: int = eqx.field(static=True, default=1)
    n_agree: int = eqx.field(static=True, default=2)
    max_windows: int = eqx.field(static=True, default=32)
    max_window_periods: int = eqx.field(static=True, default=100_000)
    report: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        for name in ("n_beats", "min_periods", "samples_per_cycle", "n_agree",
                     "max_windows", "max_window_periods"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Windowed.{name} must be a positive integer, not "
                                 f"{getattr(self, name)!r}.")
        if int(self.transient_windows) < 0:
            raise ValueError(f"Windowed.transient_windows must be zero or more, not "
                             f"{self.transient_windows!r}.")
        if not float(self.tol) > 0:
            raise ValueError(f"Windowed.tol must be positive, not {self.tol!r}.")
        need = self.transient_windows + self.n_agree + 1
        if self.max_windows < need:
            raise ValueError(f"Windowed.max_windows = {self.max_windows} leaves no room for "
                             f"transient_windows + n_agree + 1 = {need} windows.")


_LISTENERS: list[Callable] = []


@contextlib.contextmanager
def window_reports(listener: Callable[[np.ndarray, np.ndarray, np.ndarray], None]):
    """Within the block, ``listener(windows, steps, change)`` is called after each window
    of every windowed integration whose settings have ``report``: the windows done, the
    solver steps so far and the largest relative change of a mesh's mean or RMS force
    from the window before (NaN for the first), each an array (one element per point of
    a vmapped batch)."""
    _LISTENERS.append(listener)
    try:
        yield listener
    finally:
        _LISTENERS.remove(listener)


def _tell(windows, steps, change) -> None:
    for listener in list(_LISTENERS):
        listener(np.asarray(windows), np.asarray(steps), np.asarray(change))


class WindowPlan(eqx.Module):
    """How a system is cut into windows (:func:`window_plan`).

    **Fields:** ``periods``: base periods per window ``N``; ``samples``: samples per base
    period ``S`` (a window holds ``N S``); ``slowest``: ``nu_min``, the slowest
    non-integer excitation frequency or beat over ``Omega`` (``None``: every tone is a
    whole multiple of ``Omega`` and the windows are exact, uniformly weighted);
    ``fastest``: the fastest excitation harmonic over ``Omega``; ``leak``: the largest
    share of a unit tone's amplitude that the weighted mean over a window leaves, for a
    tone of ``slowest`` to twice it (:func:`window_leak`; 0 where ``slowest`` is
    ``None``)."""

    periods: int = eqx.field(static=True)
    samples: int = eqx.field(static=True)
    slowest: float | None = eqx.field(static=True)
    fastest: float = eqx.field(static=True)
    leak: float = eqx.field(static=True, default=0.0)


def _bump(s, xp=jnp):
    """The weight ``exp(-1 / (s (1 - s)))`` on ``0 < s < 1``, zero at and beyond the
    ends, in the array namespace ``xp`` (``jnp``: traced inside a program, no constant
    array; ``np``: on the host)."""
    inside = (s > 0) & (s < 1)
    return xp.where(inside, xp.exp(-1.0 / xp.where(inside, s * (1.0 - s), 1.0)), 0.0)


def window_weights(samples: int) -> Array:
    """The weights ``(samples,)`` of a quasi-periodic window's averages: the smooth bump
    ``exp(-1 / (s (1 - s)))`` at the sample instants ``s = j / samples`` of the window,
    normalised to sum to one (module docstring, "Weighted averages")."""
    w = _bump(jnp.arange(samples) / samples)
    return w / jnp.sum(w)


_LEAK_NODES = 4096
"""Quadrature nodes of :func:`window_leak` (the bump is smooth and vanishes with all its
derivatives at the ends: the rule converges faster than any power)."""


@functools.lru_cache(maxsize=64)
def window_leak(cycles: float) -> float:
    """The largest ``|integral w(s) exp(2 pi i c s) ds|`` over ``cycles <= c <= 2
    cycles``, ``w`` the normalised bump of :func:`window_weights`: what the weighted mean
    over a window leaves of a unit tone that runs ``c`` cycles in it (a uniform window
    leaves up to ``1 / (pi c)``). Kept per ``cycles`` (a plan is made for every
    integration call)."""
    s = (np.arange(_LEAK_NODES) + 0.5) / _LEAK_NODES
    w = _bump(s, np)
    w /= w.sum()
    c = np.linspace(cycles, 2 * cycles, 257)
    return float(np.max(np.abs(np.exp(2j * np.pi * np.outer(c, s)) @ w)))


def excitation_frequencies(system: System) -> np.ndarray:
    """Every excitation frequency over ``Omega`` (floats, sorted, unique): harmonics
    ``h r_m``, ``h = 1..H``, of each mesh's rate ``r_m`` where the mesh has stiffness or
    transmission-error harmonics, and each forcing column's rate."""
    H = max(system.k_cos.shape[-1], system.te_cos.shape[-1])
    rates = np.abs(system.mesh_rates())
    tones = [(np.arange(1, H + 1)[None, :] * rates[:, None]).ravel()]
    tones.append(np.abs(system.forcing_rates()))
    tones = np.concatenate(tones)
    return np.unique(tones[tones > 0])


def window_plan(system: System, settings: Windowed = Windowed()) -> WindowPlan:
    """Window length and sampling of ``system`` (module docstring, "Window length").

    **Raises:** ``ValueError`` when the slowest beat asks for more than
    ``settings.max_window_periods`` base periods (two frequencies so close that they
    are commensurate in practice: give them one torus angle, model.md)."""
    tones = excitation_frequencies(system)
    fastest = float(tones.max()) if tones.size else 0.0
    samples = math.ceil(settings.samples_per_cycle * max(1.0, fastest))
    candidates = np.concatenate([tones, np.abs(tones[:, None] - tones[None, :]).ravel()])
    off = np.abs(candidates - np.round(candidates)) > _WHOLE * np.maximum(1.0, candidates)
    if not np.any(off):
        return WindowPlan(periods=settings.min_periods, samples=samples, slowest=None,
                          fastest=fastest)
    slowest = float(candidates[off].min())
    periods = max(settings.min_periods, math.ceil(settings.n_beats / slowest))
    leak = window_leak(slowest * periods)
    if periods > settings.max_window_periods:
        raise ValueError(
            f"simulate_windowed: system.angle_ratio = {tuple(system.angle_ratio)} puts two "
            f"excitation frequencies {slowest:.3g} Omega apart, so a window spanning "
            f"Windowed.n_beats = {settings.n_beats} of their beats needs {periods} base "
            f"periods, more than Windowed.max_window_periods = "
            f"{settings.max_window_periods}: frequencies this close are commensurate in "
            f"practice; give them one torus angle.")
    return WindowPlan(periods=periods, samples=samples, slowest=slowest, fastest=fastest,
                      leak=leak)


class WindowedResponse(eqx.Module):
    """The statistics of a windowed integration.

    Shapes are for one frequency; batched calls add leading axes. ``m`` meshes, ``n``
    coordinates, ``Wn = Windowed.max_windows``.

    **Fields:**

    - ``omega``: base frequency (rad/s);
    - ``responses``: :class:`~gearjax._engine.responses.MeshResponses` ``(m,)`` of the
      last window integrated (NaN when none succeeded);
    - ``history``: ``MeshResponses`` ``(Wn, m)``, window by window (NaN rows after the
      last; the discarded transient windows included);
    - ``change`` ``(Wn,)``: per window, the largest relative change of a mesh's mean or
      RMS from the window before, on the scales ``Windowed.tol`` applies to (module
      docstring, "Agreement"; NaN for the first window and after the last);
    - ``x_end``, ``v_end`` ``(n,)``: the state at the end of the last window (rad or m,
      and per s);
    - ``result``: a ``RESULTS`` item: ``quasi_periodic`` (consecutive windows agree),
      ``not_stationary`` (the window budget ran out), ``max_steps_reached``,
      ``solver_failed`` or ``nonfinite`` (the failed window's statistics are not kept);
    - ``windows``: windows integrated successfully;
    - ``window_time``: the length of a window (s);
    - ``plan``: the :class:`WindowPlan` (static);
    - ``stats``: ``num_steps``, ``num_rejected``: solver steps in all; ``windows``.
    """

    omega: Float[Array, ""]
    responses: MeshResponses
    history: MeshResponses
    change: Float[Array, " Wn"]
    x_end: Float[Array, " n"]
    v_end: Float[Array, " n"]
    result: RESULTS
    windows: Int[Array, ""]
    window_time: Float[Array, ""]
    plan: WindowPlan
    stats: dict

    @property
    def stationary(self):
        """Whether consecutive windows agreed (a boolean array)."""
        return self.result == RESULTS.quasi_periodic


def _windows(problem: IntegrationProblem, plan: WindowPlan, F_static, omega, x0, v0,
             settings: Windowed) -> WindowedResponse:
    require_x64()
    s = problem.system
    n, m, Wn = s.n_dof, s.n_meshes, settings.max_windows
    omega = eqx.error_if(jnp.asarray(omega, dtype=float), ~(omega > 0),
                         "simulate_windowed: the base frequency omega must be positive (rad/s)")
    z0 = jnp.concatenate([x0 / problem.x_scale, v0 / (omega * problem.x_scale)])
    span = 2 * jnp.pi * plan.periods  # a window in tau
    T = plan.periods * plan.samples
    frac = jnp.arange(T) / T
    weights = None if plan.slowest is None else window_weights(T)
    term = dfx.ODETerm(vector_field)
    controller = settings.controller()

    def save_mesh(tau, z, args):
        _, _, p, _, F = mesh_samples(problem, omega, tau[None], z[:, None])
        return jnp.stack([p[:, 0], F[:, 0]])  # (2, m)

    def window(k, z):
        t0 = span * k
        ts = span * (k + frac)
        at = dfx.SaveAt(subs=[dfx.SubSaveAt(ts=ts, fn=save_mesh), dfx.SubSaveAt(t1=True)])
        sol = dfx.diffeqsolve(term, settings.solver, t0, span * (k + 1), None, z,
                              args=(problem, omega), saveat=at,
                              stepsize_controller=controller,
                              max_steps=settings.max_steps * plan.periods,
                              adjoint=dfx.ForwardMode(), throw=False)
        mesh, end = sol.ys
        p, F = mesh[:, 0].T, mesh[:, 1].T  # (m, T)
        r = responses_from_samples(p, F, s.backlash, F_static, s.mesh_radius, weights)
        return sol, r, end[-1]

    def relative_change(r, prev):
        scale = jnp.max(jnp.concatenate([jnp.abs(F_static), jnp.abs(r.mean_force),
                                         r.rms_force, jnp.zeros(1)]))
        floor = _FLOOR * scale + jnp.finfo(float).tiny
        rms_scale = jnp.maximum(jnp.maximum(r.rms_force, prev.rms_force), floor)
        mean_scale = jnp.maximum(jnp.maximum(jnp.abs(r.mean_force), jnp.abs(prev.mean_force)),
                                 rms_scale)
        d = jnp.concatenate([jnp.abs(r.rms_force - prev.rms_force) / rms_scale,
                             jnp.abs(r.mean_force - prev.mean_force) / mean_scale,
                             jnp.zeros(1)])
        return jnp.max(d)

    nan_m = jnp.full(m, jnp.nan)
    blank = MeshResponses(*(nan_m for _ in range(7)))
    history0 = jax.tree.map(lambda a: jnp.broadcast_to(a, (Wn, m)), blank)

    def cond(state):
        return ~state["done"]

    def body(state):
        k = state["k"]
        sol, r, z_new = window(k, state["z"])
        ok = sol.result == dfx.RESULTS.successful
        finite = (jnp.all(jnp.isfinite(z_new)) & jnp.all(jnp.isfinite(r.mean_force))
                  & jnp.all(jnp.isfinite(r.rms_force)) & jnp.all(jnp.isfinite(r.max_force)))
        good = ok & finite
        d = relative_change(r, state["last"])
        compared = k >= settings.transient_windows + 1  # the window before is kept too
        agree = compared & (d <= settings.tol)
        streak = jnp.where(agree, state["streak"] + 1, 0)
        k_new = k + 1
        code = RESULTS.where(
            ~ok, RESULTS.where(sol.result == dfx.RESULTS.max_steps_reached,
                               RESULTS.max_steps_reached, RESULTS.solver_failed),
            RESULTS.where(~finite, RESULTS.nonfinite,
                          RESULTS.where(streak >= settings.n_agree, RESULTS.quasi_periodic,
                                        RESULTS.not_stationary)))
        done = ~good | (streak >= settings.n_agree) | (k_new >= Wn)
        history = jax.tree.map(lambda h, a: h.at[k].set(a), state["history"], r)
        steps = state["steps"] + sol.stats["num_accepted_steps"]
        if settings.report:
            jax.debug.callback(_tell, k_new, steps, jnp.where(k > 0, d, jnp.nan))
        return dict(
            k=jnp.where(good, k_new, k),
            z=jnp.where(good, z_new, state["z"]),
            last=jax.tree.map(lambda a, b: jnp.where(good, a, b), r, state["last"]),
            history=jax.tree.map(lambda a, b: jnp.where(good, a, b), history,
                                 state["history"]),
            change=jnp.where(good & (k > 0), state["change"].at[k].set(d), state["change"]),
            streak=streak,
            done=done,
            code=code,
            steps=steps,
            rejected=state["rejected"] + sol.stats["num_rejected_steps"],
        )

    init = dict(
        k=jnp.asarray(0),
        z=z0,
        last=blank,
        history=history0,
        change=jnp.full(Wn, jnp.nan),
        streak=jnp.asarray(0),
        done=jnp.asarray(False),
        code=RESULTS.not_stationary,
        steps=jnp.asarray(0),
        rejected=jnp.asarray(0),
    )
    state = jax.lax.while_loop(cond, body, init)
    z_end = state["z"]
    return WindowedResponse(
        omega=omega, responses=state["last"], history=state["history"],
        change=state["change"], x_end=problem.x_scale * z_end[:n],
        v_end=omega * problem.x_scale * z_end[n:], result=state["code"], windows=state["k"],
        window_time=span / omega, plan=plan,
        stats={"num_steps": state["steps"], "num_rejected": state["rejected"],
               "windows": state["k"]})


def _checked_plan(system: System, settings: Windowed) -> WindowPlan:
    plan = window_plan(system, settings)
    if plan.slowest is not None and settings.tol < LEAK_FACTOR * plan.leak:
        raise ValueError(
            f"simulate_windowed: Windowed.tol = {settings.tol:g} is below {LEAK_FACTOR:g} "
            f"times the {plan.leak:.2g} of its slowest beat that a window of "
            f"Windowed.n_beats = {settings.n_beats} beats leaves in its averages (the "
            f"quasi-periodic system's angle_ratio = {tuple(system.angle_ratio)}), so two "
            f"windows of a stationary response may differ by that much; raise "
            f"Windowed.n_beats or Windowed.tol.")
    return plan


def simulate_windowed(system: System, omega, *, x0=None, v0=None,
                      settings: Windowed = Windowed()) -> WindowedResponse:
    """Integrate ``system`` at base frequency ``omega`` in windows until their statistics
    agree (module docstring: window length, sampling and agreement).

    Any system: quasi-periodic (``G > 1`` torus angles, non-integer rates) or periodic.
    Starts at ``t = 0`` from ``(x0, v0)`` or, when ``x0`` is None, from the static
    solution in contact (:func:`~gearjax._engine.time_domain.contact_state`). Solver
    failure is a result, never an exception. jit-compiled; for many frequencies use
    :func:`simulate_windowed_points`.

    **Arguments:** ``system``: the :class:`System`; ``omega``: base frequency Omega
    (rad/s, scalar); ``x0``, ``v0``: ``(n,)`` initial coordinates (rad or m) and rates
    (per s); ``settings``: :class:`Windowed`.

    **Returns:** a :class:`WindowedResponse`.

    **Raises:** ``ValueError`` when the window would be too long
    (:func:`window_plan`) or ``settings.tol`` is below ``1 / settings.n_beats`` for a
    quasi-periodic system.
    """
    plan = _checked_plan(system, settings)
    return _simulate_windowed(system, *float_arrays(omega, x0, v0), settings, plan)


@eqx.filter_jit
def _simulate_windowed(system, omega, x0, v0, settings, plan):
    x0, v0 = start_state(system, x0, v0)
    return _windows(integration_problem(system), plan, static_mesh_forces(system), omega,
                    x0, v0, settings)


def simulate_windowed_points(system: System, omegas, *, x0=None, v0=None,
                             settings: Windowed = Windowed(),
                             batch_size: int | None = None) -> WindowedResponse:
    """:func:`simulate_windowed` at every frequency of ``omegas`` in one jitted call.

    **Arguments:** ``omegas`` ``(B,)`` (rad/s); ``x0``, ``v0``: ``(n,)`` shared or
    ``(B, n)`` per point, None for the static contact state; ``batch_size``: None vmaps
    all ``B`` points (in lock-step: every point runs as many windows as the slowest); an
    integer runs ``jax.lax.map`` over chunks of that many vmapped points.

    **Returns:** a :class:`WindowedResponse` with a leading axis ``B`` on every array.
    **Raises:** as :func:`simulate_windowed`.
    """
    plan = _checked_plan(system, settings)
    return _simulate_windowed_points(system, *float_arrays(omegas, x0, v0), settings, plan,
                                     batch_size)


@eqx.filter_jit
def _simulate_windowed_points(system, omegas, x0, v0, settings, plan, batch_size):
    x0, v0 = start_state(system, x0, v0)
    problem = integration_problem(system)
    F_static = static_mesh_forces(system)
    x0 = jnp.broadcast_to(x0, omegas.shape + x0.shape[-1:])
    v0 = jnp.broadcast_to(v0, omegas.shape + v0.shape[-1:])

    def one(args):
        return _windows(problem, plan, F_static, *args, settings)

    if batch_size is None:
        return jax.vmap(one)((omegas, x0, v0))
    return jax.lax.map(one, (omegas, x0, v0), batch_size=batch_size)
