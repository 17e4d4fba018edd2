"""Time integration of a gear: the gear-train surface of ``_time_domain``.

Frequencies are the mesh frequency (Hz) of a reference stage exactly as in
:func:`~gearjax._studies.sweep.sweep`: with the gear's coprime ``mu``,
``Omega = 2 pi f / mu_ref`` is the base frequency of every excitation. Two ways
through a set of frequencies:

- ``at_hz``: independent points, one batched call of
  :func:`~gearjax._engine.time_domain.simulate_points`; every point starts from the same
  state (the static solution in contact, or a given state per point);
- ``from_hz``, ``to_hz``, ``points``: a run-up (``from < to``) or run-down sweep,
  :func:`~gearjax._engine.time_domain.simulate_sweep`, each point continued from the end
  state of the one before, so coexisting branches show up as in a test rig.

The results are a Dataset in the layout of sweeps (``_results``), with ``result``
``converged`` (the orbit repeats after one base period), ``not_periodic`` (``period``
says after how many base periods it repeats, 0 none found), ``max_steps``,
``solver_failed`` or ``nonfinite``; ``stable`` is unknown (an integration does not
classify stability; a stable orbit is what it tends to). Responses are statistics of
the last base period (:func:`~gearjax._engine.responses.responses_from_samples`, the same
definition as the harmonic balance); a failed point has NaN responses and its code.

**Quasi-periodic gears.** Where the gear's mesh frequencies fall in ``G > 1``
incommensurate groups (:func:`~gearjax.gear_frequency_groups`; the case is assembled
with ``torus=True``, model.md, "Incommensurate stages") the response has no period and
the periodic search has nothing to find: each point is integrated in windows
(:func:`~gearjax._engine.windowed.simulate_windowed`, :class:`~gearjax.Windowed`
settings, default :data:`WINDOWED`) until consecutive windows' statistics agree. Its
``result`` is ``quasi_periodic`` (converged: the statistics are stationary),
``not_stationary`` (the windows ran out without agreeing: a long transient, a
locking or chaotic response; the last window's statistics are kept, not converged),
``max_steps``, ``solver_failed`` or ``nonfinite`` (NaN responses); ``period`` is 0
(none); the responses are the last window's statistics. A sweep continues each point
from the previous end state *and phase*: the next point's excitation is the previous
one's clock shifted by the time integrated (:func:`time_shifted`), so no mesh phase
jumps between points. A periodic gear (``G = 1``) is integrated as before.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .._engine import time_domain as td
from .._engine import windowed as wd
from .._errors import bad_argument, fail
from .._engine.responses import responses_from_samples
from .._engine.results import result_word
from .._io.bearing_results import add_bearing_samples
from .._io.results import sweep_dataset
from .._engine.system import System
from .._gear.case import GearCase, gear_case, torus_fields
from .._gear.toml_io import dumps_train
from .._gear.translational import bearing_table
from .._gear.train import Train
from .validity import warn_contact_loss

DEFAULT_SWEEP_POINTS = 20
"""Points of a ``from_hz``/``to_hz`` sweep when ``points`` is not given."""

WINDOWED = wd.Windowed()
"""Windowed-integration settings of a quasi-periodic gear where the caller gives none
(read at each call)."""

STATIONARY_WORDS = ("quasi_periodic", "not_stationary")
"""Windowed results whose last window's statistics are kept (the others have none)."""

def frequency_points(at_hz: Sequence[float] | None = None, from_hz: float | None = None,
                     to_hz: float | None = None, points: int | None = None
                     ) -> tuple[np.ndarray, bool]:
    """The frequencies (Hz) of ``at_hz``, or ``points`` from ``from_hz`` to ``to_hz``.

    **Returns:** ``(f_hz, is_sweep)``. **Raises:** ``ArgumentError`` (a ``TrainError``)
    naming the argument unless exactly one of the two forms is given with positive,
    finite frequencies, ``from_hz != to_hz`` and ``points >= 2``.
    """
    sweep_given = any(v is not None for v in (from_hz, to_hz, points))
    if at_hz is not None and sweep_given:
        raise bad_argument("at_hz", list(at_hz), "give either `at_hz` HZ ... or `from_hz` HZ "
                           "`to_hz` HZ `points` N, not both")
    if at_hz is not None:
        f = [float(v) for v in np.atleast_1d(np.asarray(at_hz, dtype=float))]
        if not f:
            raise bad_argument("at_hz", [], "needs at least one mesh frequency in Hz")
        for v in f:
            if not (v > 0 and math.isfinite(v)):
                raise bad_argument("at_hz", v, "must be a positive mesh frequency in Hz")
        return np.asarray(f), False
    if from_hz is None or to_hz is None:
        raise bad_argument("from_hz" if from_hz is None else "to_hz", None,
                           "give `at_hz` HZ ... or both `from_hz` HZ and `to_hz` HZ (with "
                           "`points` N)")
    for name, v in (("from_hz", from_hz), ("to_hz", to_hz)):
        if not (v > 0 and math.isfinite(v)):
            raise bad_argument(name, v, "must be a positive mesh frequency in Hz")
    if from_hz == to_hz:
        raise bad_argument("to_hz", to_hz, "must differ from `from_hz`")
    points = DEFAULT_SWEEP_POINTS if points is None else points
    if int(points) != points or points < 2:
        raise bad_argument("points", points, "must be an integer >= 2")
    return np.linspace(float(from_hz), float(to_hz), int(points)), True


REPORT_EVERY_S = 10.0
"""Seconds between two lines of an integration's progress (the first point, or the first
window of each point of a quasi-periodic gear, is always reported)."""


def _batch_size(batch_size):
    """``"auto"``: one point at a time on a CPU (a vmapped batch advances in lock-step, see
    :func:`~gearjax.simulate_points`), the whole batch vmapped on an accelerator."""
    if batch_size == "auto":
        return 1 if jax.default_backend() == "cpu" else None
    return batch_size


def integrate(case: GearCase, f_hz, is_sweep: bool, x0=None, v0=None,
              settings: td.TimeDomain = td.TimeDomain(), batch_size="auto",
              progress: Callable[[str], None] | None = None) -> td.Trajectory:
    """Steady states of ``case`` at ``f_hz`` (Hz): independent points or a sweep (see the
    module docstring). ``x0``, ``v0``: ``(n,)`` or ``(P, n)`` start states (rad or m, and
    per s), None for the static solution in contact; ``progress(message)``: where points
    run one at a time (a sweep, or independent points on a CPU), told each point as it
    ends (the first, then at most a line every :data:`REPORT_EVERY_S` seconds, and the
    last), with the time left at the pace so far. **Returns:** a
    :class:`~gearjax.Trajectory` with a leading axis ``P``."""
    omegas = case.omega(f_hz)
    size = _batch_size(batch_size)
    if progress is None or len(omegas) < 2 or (size != 1 and not is_sweep):
        if is_sweep:
            return td.simulate_sweep(case.system, omegas, x0=x0, v0=v0, settings=settings)
        return td.simulate_points(case.system, omegas, x0=x0, v0=v0, settings=settings,
                                  batch_size=size)
    P, t0, shown, parts = len(omegas), time.perf_counter(), -math.inf, []

    def own(a, i):  # a point's start state: shared (n,) or its row of (P, n)
        return a if a is None or np.ndim(a) == 1 else a[i:i + 1]

    for i in range(P):
        if is_sweep:  # from the end state of the point before (its own where it failed)
            tr = jax.block_until_ready(td.simulate_sweep(
                case.system, omegas[i:i + 1], x0=x0, v0=v0, settings=settings))
            if bool(np.asarray(tr.integrated)[0]):
                x0, v0 = tr.x_end[0], tr.v_end[0]
        else:
            tr = jax.block_until_ready(td.simulate_points(
                case.system, omegas[i:i + 1], x0=own(x0, i), v0=own(v0, i),
                settings=settings, batch_size=1))
        parts.append(tr)
        now = time.perf_counter()
        if i in (0, P - 1) or now - shown >= REPORT_EVERY_S:
            shown = now
            progress(f"integration: point {i + 1} of {P} ({float(f_hz[i]):.1f} Hz): "
                     f"{int(np.asarray(tr.stats['num_steps'])[0])} solver steps, "
                     f"{result_word(tr.result)[0]}; {now - t0:.0f} s, about "
                     f"{(now - t0) / (i + 1) * (P - i - 1):.0f} s left")
    return _joined(parts)


def _joined(parts):
    """Batched results ``parts`` joined along their leading axis, on the host and put back
    with ``jax.device_put`` (``jnp.concatenate`` would compile a program per count)."""
    return jax.tree.map(lambda *a: jax.device_put(np.concatenate(a)), *parts)


def _stacked(outs):
    """Per-point results ``outs`` stacked on a new leading axis, as :func:`_joined`."""
    return jax.tree.map(lambda *a: jax.device_put(np.stack(a)), *outs)


def trajectory_dataset(case: GearCase, f_hz, tr: td.Trajectory, solver: dict | None = None,
                       attrs: dict | None = None):
    """The results Dataset (``_results`` layout) of trajectories ``tr`` at ``f_hz`` (Hz).

    Adds per point ``periods`` (base periods integrated), ``num_steps`` and
    ``num_rejected`` (solver steps) to the common layout; ``period`` is the response
    period in base periods (0: none found).
    """
    s = case.system
    resp = responses_from_samples(tr.p, tr.F, s.backlash, case.F_static, s.mesh_radius)
    failed = ~np.asarray(tr.integrated)  # samples of a failed point are stale: no values
    resp = jax.tree.map(lambda a: np.where(failed[:, None], np.nan, np.asarray(a)), resp)
    ds = sweep_dataset(
        resp, **case.point_coordinates(f_hz),
        result=list(result_word(tr.result)),
        stable=None,
        period=np.asarray(tr.period),
        static_force=case.F_static,
        train_toml=dumps_train(case.train),
        gear=case.gear.name,
        solver=solver,
        attrs={"reference_stage": case.stage, **(attrs or {})},
    )
    if case.train.translational:
        x = np.where(failed[:, None, None], np.nan, np.asarray(tr.x))
        v = np.where(failed[:, None, None], np.nan, np.asarray(tr.v))
        ds = add_bearing_samples(ds, **bearing_table(case.train), x=x, v=v)
    for name, value, long_name in (
            ("periods", tr.periods, "base periods integrated"),
            ("num_steps", tr.stats["num_steps"], "accepted solver steps"),
            ("num_rejected", tr.stats["num_rejected"], "rejected solver steps")):
        ds[name] = ("point", np.asarray(value), {"units": "1", "long_name": long_name})
    return ds


# ---------------------------------------------------------------- quasi-periodic gears


def time_shifted(system: System, tau0: float) -> System:
    """``system`` with its clock started at base phase ``tau0 = Omega t0`` (rad): its
    stiffness, transmission-error and forcing series at ``tau`` are ``system``'s at
    ``tau + tau0`` (each harmonic's cosine and sine coefficients rotated by its phase
    ``h r tau0``, ``r`` the series' rate over ``Omega``). The static fields are the same,
    so a compiled integration of ``system`` runs the shifted one too."""
    def rotate(c, s_, rates):
        if c.shape[-1] == 0 or len(rates) == 0:
            return c, s_
        h = np.arange(1, c.shape[-1] + 1)
        a = np.mod(np.outer(np.asarray(rates, float), h) * float(tau0), 2 * np.pi)
        ca, sa = jnp.asarray(np.cos(a)), jnp.asarray(np.sin(a))
        return c * ca + s_ * sa, s_ * ca - c * sa

    rates = system.mesh_rates()
    k_cos, k_sin = rotate(system.k_cos, system.k_sin, rates)
    te_cos, te_sin = rotate(system.te_cos, system.te_sin, rates)
    f_cos, f_sin = system.f_cos, system.f_sin
    if system.forcing_mu:  # one phase per column: the columns' own rates, h = 1
        a = np.mod(np.asarray(system.forcing_rates(), float) * float(tau0), 2 * np.pi)
        ca, sa = jnp.asarray(np.cos(a)), jnp.asarray(np.sin(a))
        f_cos, f_sin = f_cos * ca + f_sin * sa, f_sin * ca - f_cos * sa
    return dataclasses.replace(system, k_cos=k_cos, k_sin=k_sin, te_cos=te_cos,
                               te_sin=te_sin, f_cos=f_cos, f_sin=f_sin)


def integrate_windowed(case: GearCase, f_hz, is_sweep: bool, x0=None, v0=None,
                       settings: wd.Windowed | None = None, batch_size="auto",
                       progress: Callable[[str], None] | None = None
                       ) -> wd.WindowedResponse:
    """Windowed statistics of ``case`` at ``f_hz`` (Hz): independent points or a sweep
    (module docstring, "Quasi-periodic gears"). ``x0``, ``v0``: ``(n,)`` or ``(P, n)``
    start states (sweeps: ``(n,)``), None for the static solution in contact;
    ``settings``: :class:`~gearjax.Windowed` (default :data:`WINDOWED`); ``batch_size``
    as :func:`~gearjax.simulate_windowed_points` (``"auto"``: one point at a time on a
    CPU, every point through the same compiled program); ``progress(message)``: told
    the windows as they run (:class:`WindowProgress`; the program then reports them,
    ``Windowed.report``), the result computed before returning.

    **Returns:** a :class:`~gearjax.WindowedResponse` with a leading axis ``P``.
    **Raises:** ``ValueError`` as :func:`~gearjax.simulate_windowed` (a window too long,
    a tolerance below ``1 / n_beats``)."""
    settings = WINDOWED if settings is None else settings
    if progress is not None:
        settings = dataclasses.replace(settings, report=True)
        with wd.window_reports(WindowProgress(progress, f_hz, settings)):
            return jax.block_until_ready(
                integrate_windowed(case, f_hz, is_sweep, x0, v0, settings, batch_size))
    s = case.system
    omegas = case.omega(f_hz)
    if x0 is None:
        x0, v0 = td.contact_state_jit(s)
    x0 = jnp.asarray(x0, dtype=float)
    v0 = jnp.zeros_like(x0) if v0 is None else jnp.asarray(v0, dtype=float)
    if is_sweep:
        outs, tau, x, v = [], 0.0, x0, v0
        for w in omegas:
            out = wd.simulate_windowed(time_shifted(s, tau), float(w), x0=x, v0=v,
                                       settings=settings)
            tau += 2 * np.pi * int(out.windows) * out.plan.periods  # the clock goes on
            x, v = out.x_end, out.v_end
            outs.append(out)
        return _stacked(outs)
    size = _batch_size(batch_size)
    if size != 1:
        return wd.simulate_windowed_points(s, omegas, x0=x0, v0=v0, settings=settings,
                                           batch_size=size)
    x0 = jnp.broadcast_to(x0, (len(omegas), s.n_dof))
    v0 = jnp.broadcast_to(v0, (len(omegas), s.n_dof))
    outs = [wd.simulate_windowed(s, float(w), x0=x0[i], v0=v0[i], settings=settings)
            for i, w in enumerate(omegas)]
    return _stacked(outs)


def windowed_dataset(case: GearCase, f_hz, out: wd.WindowedResponse,
                     solver: dict | None = None, attrs: dict | None = None):
    """The results Dataset (``_results`` layout) of windowed integrations ``out`` at
    ``f_hz`` (Hz), as :func:`trajectory_dataset`: ``result`` a windowed word,
    ``converged`` where ``quasi_periodic``, ``period`` 0 (none), the responses of the last
    window (NaN where no statistics: failed points). Adds per point ``periods`` (base
    periods integrated), ``num_steps``, ``num_rejected``, ``windows`` (windows
    integrated), ``window_s`` (the window length, s) and ``window_change`` (the last
    window's largest relative change of a mesh's mean or RMS from the one before, NaN
    with fewer than two windows)."""
    words = np.asarray(result_word(out.result), dtype=str).reshape(-1)
    kept = np.isin(words, STATIONARY_WORDS)
    resp = jax.tree.map(lambda a: np.where(kept[:, None], np.asarray(a), np.nan),
                        out.responses)
    windows = np.asarray(out.windows).reshape(-1)
    change = np.asarray(out.change)
    last = np.array([change[i, w - 1] if w >= 2 else np.nan for i, w in enumerate(windows)])
    ds = sweep_dataset(
        resp, **case.point_coordinates(f_hz),
        result=list(words),
        converged=words == "quasi_periodic",
        stable=None,
        period=np.zeros(len(words)),
        static_force=case.F_static,
        train_toml=dumps_train(case.train),
        gear=case.gear.name,
        solver=solver,
        attrs={"reference_stage": case.stage, **(attrs or {})},
    )
    for name, value, units, long_name in (
            ("periods", windows * out.plan.periods, "1", "base periods integrated"),
            ("num_steps", out.stats["num_steps"], "1", "accepted solver steps"),
            ("num_rejected", out.stats["num_rejected"], "1", "rejected solver steps"),
            ("windows", windows, "1", "windows integrated"),
            ("window_s", out.window_time, "s", "length of a window"),
            ("window_change", last, "1", "largest relative change of a mesh's mean or RMS "
                                         "force from the window before, last window")):
        ds[name] = ("point", np.asarray(value).reshape(-1),
                    {"units": units, "long_name": long_name})
    return ds


def windowed_settings(case: GearCase, settings: wd.Windowed | None = None) -> dict:
    """The windowed integration of ``case`` as a JSON-able dict: ``method`` (``windowed
    time integration``), the :class:`~gearjax.Windowed` fields, the window plan
    (``window_periods``, ``samples_per_period``, ``slowest_beat``: the slowest
    non-integer excitation frequency or beat over ``Omega``) and ``torus``
    (:func:`~gearjax._gear.case.torus_fields`). **Raises:** ``TrainError`` naming the
    gear where a window would be longer than ``settings.max_window_periods`` (two
    frequency groups so close that their beat takes longer: :func:`~gearjax.window_plan`;
    no statistics are given rather than those of a window that truncates the beat)."""
    settings = WINDOWED if settings is None else settings
    try:
        plan = wd.window_plan(case.system, settings)
    except ValueError as e:
        ratios = [str(r) for r in case.layout.ratio] if case.layout is not None else None
        raise fail(case.train.source, f"gears.{case.gear.name}", ratios,
                   f"the frequency groups' angle ratios ask for too long a window: "
                   f"{str(e).removeprefix('simulate_windowed: ')}") from None
    out = {"method": "windowed time integration", "solver": type(settings.solver).__name__}
    for f in dataclasses.fields(settings):
        if f.name not in ("solver", "report"):
            out[f.name] = getattr(settings, f.name)
    out.update(window_periods=plan.periods, samples_per_period=plan.samples,
               slowest_beat=plan.slowest, torus=torus_fields(case))
    return out


def solver_settings(settings: td.TimeDomain) -> dict:
    """The :class:`~gearjax.TimeDomain` settings as a JSON-able dict."""
    out = {"method": "time integration", "solver": type(settings.solver).__name__}
    for f in dataclasses.fields(settings):
        if f.name != "solver":
            out[f.name] = getattr(settings, f.name)
    return out


def simulate_gear(
    train: Train,
    gear: str | None = None,
    at_hz: Sequence[float] | None = None,
    *,
    from_hz: float | None = None,
    to_hz: float | None = None,
    points: int | None = None,
    stage: str | None = None,
    linear: bool = False,
    x0=None,
    v0=None,
    settings: td.TimeDomain = td.TimeDomain(),
    batch_size: int | None | str = "auto",
    progress: Callable[[str], None] | None = None,
    command: str | None = None,
    windowed: wd.Windowed | None = None,
):
    """Steady-state time integration of ``gear`` at reference-stage mesh frequencies.

    **Arguments:**

    - ``at_hz``: independent points (Hz), or ``from_hz``, ``to_hz``, ``points``
      (default 20): a sweep whose direction is the order, each point continued from
      the previous one (module docstring);
    - ``stage``: reference stage id (default: the first turning stage); ``linear``: drop
      the backlash;
    - ``x0``, ``v0``: start state, ``(n,)`` shared or ``(P, n)`` per point (sweeps: the
      first point's ``(n,)``), rad or m and per s, e.g.
      :func:`~gearjax.hb_initial_state` of harmonic-balance solutions; None: the static
      solution in contact (:func:`~gearjax.contact_state`);
    - ``settings``: :class:`~gearjax.TimeDomain`; ``batch_size``: as
      :func:`~gearjax.simulate_points` (``"auto"``: 1 on a CPU, all on an accelerator);
    - ``progress(message)``: called before and after the integration, as points end
      where they run one at a time (:func:`integrate`), and for a quasi-periodic gear
      as its windows are integrated (:class:`WindowProgress`);
    - ``command``: how the simulation was asked for, kept as the ``command`` attribute
      (default: empty);
    - ``windowed``: :class:`~gearjax.Windowed` settings of a quasi-periodic gear
      (``G > 1``, module docstring; default :data:`WINDOWED`); ``settings`` then unused.

    **Returns:** an ``xarray.Dataset`` (``_results`` layout: ``result``, ``converged``,
    ``stable`` unknown, ``period``, responses; plus ``periods``, ``num_steps``,
    ``num_rejected``; for a quasi-periodic gear also ``windows``, ``window_s``,
    ``window_change``, :func:`windowed_dataset`); attributes ``reference_stage``,
    ``mode`` (``points`` or ``sweep``), ``start``, ``seconds``, ``command``.

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming the argument for bad
    frequencies, and as :func:`gear_case`; for a quasi-periodic gear ``TrainError``
    where a window would be too long (:func:`windowed_settings`) and ``ValueError``
    where ``windowed.tol`` is below ``1 / windowed.n_beats``
    (:func:`~gearjax.simulate_windowed`).

    **Warns:** :class:`~gearjax._studies.validity.ContactLossWarning` where a linear
    run's alternating mesh force exceeds the static one (the teeth would leave contact),
    naming the first frequency (:func:`~gearjax._studies.validity.contact_loss`).
    """
    t0 = time.perf_counter()
    f_hz, is_sweep = frequency_points(at_hz, from_hz, to_hz, points)
    case = gear_case(train, gear, stage, linear, torus=True)
    if case.G > 1:
        return warn_contact_loss(_simulate_torus(case, f_hz, is_sweep, x0, v0, windowed,
                                                  batch_size, progress, command, t0))
    if progress:
        progress(f"simulate: integrating {len(f_hz)} points "
                 f"({'sweep' if is_sweep else 'independent'}; the first call compiles)")
    tr = integrate(case, f_hz, is_sweep, x0, v0, settings, batch_size, progress=progress)
    jax.block_until_ready(tr)
    seconds = time.perf_counter() - t0
    if progress:
        progress(f"simulate: {len(f_hz)} points in {seconds:.1f} s")
    solver = {**solver_settings(settings), "linear": linear, "reference_stage": case.stage}
    return warn_contact_loss(trajectory_dataset(case, f_hz, tr, solver, attrs={
        "kind": "simulate", "mode": "sweep" if is_sweep else "points",
        "start": "static contact" if x0 is None else "given",
        "seconds": seconds, "command": "" if command is None else command}))


class WindowProgress:
    """A :func:`~gearjax.window_reports` listener that turns the windows of a windowed
    integration at ``f_hz`` (Hz, one point after the other or a vmapped batch) under
    ``settings`` (:class:`~gearjax.Windowed`) into lines for ``progress(message)``: the
    point, the window of at most ``max_windows``, the solver steps, how far the last two
    windows differ against the agreement asked for, the time so far and a bound on the
    time left (every point running all its windows at the pace so far); the first window
    of each point, then at most one line every :data:`REPORT_EVERY_S` seconds."""

    def __init__(self, progress: Callable[[str], None], f_hz, settings: wd.Windowed):
        self.progress, self.f_hz, self.settings = progress, np.asarray(f_hz, float), settings
        self.t0 = time.perf_counter()
        self.shown, self.point, self.last, self.windows = -math.inf, 0, 0, 0

    def __call__(self, windows, steps, change) -> None:
        k = int(np.max(windows))
        batch = np.size(windows) > 1
        if k <= self.last or self.point == 0:
            self.point += 1  # a point begins (one after the other)
        self.last, self.windows = k, self.windows + 1
        now = time.perf_counter()
        if k != 1 and now - self.shown < REPORT_EVERY_S:
            return
        self.shown = now
        s, P = self.settings, self.f_hz.size
        elapsed = now - self.t0
        left_windows = s.max_windows - k + (0 if batch else (P - self.point) * s.max_windows)
        where = (f"{P} points at once" if batch else
                 f"point {min(self.point, P)} of {P} "
                 f"({self.f_hz[min(self.point, P) - 1]:.1f} Hz)")
        d = float(np.nanmax(change)) if np.any(np.isfinite(change)) else math.nan
        differ = ("" if not math.isfinite(d) else
                  f", windows differ by {100 * d:.2g}% (agreement: within "
                  f"{100 * s.tol:g}%, {s.n_agree} in a row)")
        self.progress(f"integration: {where}: window {k} of at most {s.max_windows}, "
                      f"{int(np.max(steps))} solver steps{differ}; {elapsed:.0f} s, at most "
                      f"about {elapsed / self.windows * left_windows:.0f} s left")


def _simulate_torus(case: GearCase, f_hz, is_sweep: bool, x0, v0, settings, batch_size,
                    progress, command, t0):
    """:func:`simulate_gear` of a quasi-periodic gear (windowed integration)."""
    solver = {**windowed_settings(case, settings), "linear": case.linear,
              "reference_stage": case.stage}
    if progress:
        progress(f"simulate: integrating {len(f_hz)} points "
                 f"({'sweep' if is_sweep else 'independent'}) in windows of "
                 f"{solver['window_periods']} base periods: the {case.G} frequency groups "
                 "are incommensurate, so the response is quasi-periodic (the first call "
                 "compiles)")
    out = jax.block_until_ready(integrate_windowed(case, f_hz, is_sweep, x0, v0, settings,
                                                   batch_size, progress=progress))
    seconds = time.perf_counter() - t0
    if progress:
        progress(f"simulate: {len(f_hz)} points in {seconds:.1f} s")
    return windowed_dataset(case, f_hz, out, solver, attrs={
        "kind": "simulate", "mode": "sweep" if is_sweep else "points",
        "start": "static contact" if x0 is None else "given",
        "seconds": seconds, "command": "" if command is None else command})
