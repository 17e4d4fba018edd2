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
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import jax
import numpy as np

from .._engine import time_domain as td
from .._errors import bad_argument
from .._engine.responses import responses_from_samples
from .._engine.results import result_word
from .._io.results import sweep_dataset
from .._gear.case import GearCase, gear_case
from .._gear.toml_io import dumps_train
from .._gear.train import Train

DEFAULT_SWEEP_POINTS = 20
"""Points of a ``from_hz``/``to_hz`` sweep when ``points`` is not given."""

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


def _batch_size(batch_size):
    """``"auto"``: one point at a time on a CPU (a vmapped batch advances in lock-step, see
    :func:`~gearjax.simulate_points`), the whole batch vmapped on an accelerator."""
    if batch_size == "auto":
        return 1 if jax.default_backend() == "cpu" else None
    return batch_size


def integrate(case: GearCase, f_hz, is_sweep: bool, x0=None, v0=None,
              settings: td.TimeDomain = td.TimeDomain(), batch_size="auto") -> td.Trajectory:
    """Steady states of ``case`` at ``f_hz`` (Hz): independent points or a sweep (see the
    module docstring). ``x0``, ``v0``: ``(n,)`` or ``(P, n)`` start states (rad or m, and
    per s), None for the static solution in contact. **Returns:** a
    :class:`~gearjax.Trajectory` with a leading axis ``P``."""
    omegas = case.omega(f_hz)
    if is_sweep:
        return td.simulate_sweep(case.system, omegas, x0=x0, v0=v0, settings=settings)
    return td.simulate_points(case.system, omegas, x0=x0, v0=v0, settings=settings,
                              batch_size=_batch_size(batch_size))


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
    for name, value, long_name in (
            ("periods", tr.periods, "base periods integrated"),
            ("num_steps", tr.stats["num_steps"], "accepted solver steps"),
            ("num_rejected", tr.stats["num_rejected"], "rejected solver steps")):
        ds[name] = ("point", np.asarray(value), {"units": "1", "long_name": long_name})
    return ds


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
    - ``progress(message)``: called before and after the integration;
    - ``command``: how the simulation was asked for, kept as the ``command`` attribute
      (default: empty).

    **Returns:** an ``xarray.Dataset`` (``_results`` layout: ``result``, ``converged``,
    ``stable`` unknown, ``period``, responses; plus ``periods``, ``num_steps``,
    ``num_rejected``); attributes ``reference_stage``, ``mode`` (``points`` or
    ``sweep``), ``start``, ``seconds``, ``command``.

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming the argument for bad
    frequencies, and as :func:`gear_case`.
    """
    t0 = time.perf_counter()
    f_hz, is_sweep = frequency_points(at_hz, from_hz, to_hz, points)
    case = gear_case(train, gear, stage, linear)
    if progress:
        progress(f"simulate: integrating {len(f_hz)} points "
                 f"({'sweep' if is_sweep else 'independent'}; the first call compiles)")
    tr = integrate(case, f_hz, is_sweep, x0, v0, settings, batch_size)
    jax.block_until_ready(tr)
    seconds = time.perf_counter() - t0
    if progress:
        progress(f"simulate: {len(f_hz)} points in {seconds:.1f} s")
    solver = {**solver_settings(settings), "linear": linear, "reference_stage": case.stage}
    return trajectory_dataset(case, f_hz, tr, solver, attrs={
        "kind": "simulate", "mode": "sweep" if is_sweep else "points",
        "start": "static contact" if x0 is None else "given",
        "seconds": seconds, "command": "" if command is None else command})
