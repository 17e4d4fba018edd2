"""Verification of the harmonic balance by time integration, at the same points.

Every point is solved twice:

1. harmonic balance with ``K`` from :func:`~gearjax._studies.harmonics.harmonics_rule` at that
   point (or the given ``harmonics``); points that share a ``K`` are solved in one
   batched Newton call from the linear, in-contact guess. With backlash a point
   whose Newton fails is re-started as the sweep starts a segment: continuation in
   the backlash from 0 to its value at fixed frequency. In a sweep (``from_hz``,
   ``to_hz``) with backlash each point first starts from the previous converged
   point (padded or truncated to its ``K``), so the harmonic balance follows a branch
   in the sweep direction as far as Newton can step;
2. time integration from the harmonic-balance state at ``t = 0``
   (:func:`~gearjax.hb_initial_state`), so both land on the same branch where it is
   stable (an unstable harmonic-balance orbit is left by the integration: its
   ``stable`` flag, from Floquet multipliers, says so). A point whose harmonic balance
   failed is integrated from the static solution in contact.

Comparison, per point and mesh: ``rel_diff = |rms_ni - rms_hb| / max_j rms_hb_j``,
the maximum over the meshes ``j`` of the same stage. The alternating force of one
mesh can be small next to its neighbours' (e.g. a stage whose planets' sun meshes
cancel each other's excitation); relative to its own RMS a tiny force would fail on
a discretisation difference of a few newtons that is irrelevant to the stage's
loading, and relative to the stage's largest RMS the tolerance reads "within 1% of
the dynamic load level of the stage". ``ok`` holds where both methods converged
(integration: periodic with the base period) and ``rel_diff <= tolerance``: 1% for a
system without backlash (``linear``, or a train without backlash), 2% with backlash
(the switches make both methods converge more slowly).

**Quasi-periodic gears** (mesh frequencies in ``G > 1`` incommensurate groups; model.md,
"Incommensurate stages"): step 1 is the torus harmonic balance, orders ``K = (K_1, ...,
K_G)`` per point from :func:`~gearjax._studies.harmonics.torus_orders_rule` (or
``harmonics`` on every angle) on the diamond truncation set, solved and started as
above (with backlash the homotopy in backlash where Newton fails: a torus has no
period to settle to); its responses are torus averages and ``stable`` is the torus
stability verdict. Step 2 integrates from the torus solution's state at ``t = 0``
(:func:`~gearjax.hb_initial_state` on its basis) in windows
(:func:`~gearjax._studies.simulate.integrate_windowed`) until consecutive windows' statistics agree: the reference is the last window's
statistics (``VerifyResult.reference`` says the window length, the windows' agreement
tolerance and how many must agree). An integration point is converged where its result
is ``quasi_periodic``. Where a non-linear response locks onto a rational winding or
turns chaotic the torus solution is not what the integration follows: the windows do
not agree (``not_stationary``: ``rel_diff`` is missing, ``ok`` false) or the two
differ beyond the tolerance (``ok`` false); the JSON names each point's ``agreement``
(:data:`AGREEMENT`), never a pass.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from . import harmonics as _harmonics
from .._engine import hb as _hb
from .._engine import time_domain as td
from .._engine.results import RESULTS, result_word
from .._errors import bad_argument
from .._io.bearing_results import add_bearing_forces
from .._io.results import add_displacement_harmonics, json_number, sweep_dataset
from .._gear.case import GearCase, gear_case
from .._engine import windowed as wd
from .._gear.case import torus_fields
from .simulate import (frequency_points, integrate, integrate_windowed, solver_settings,
                       trajectory_dataset, windowed_dataset, windowed_settings)
from .point_truncation import checked_orders
from .validity import warn_contact_loss
from .sweep import backlash_start, newton, point_rows, resize_harmonics, solve_points, start_point
from .._gear.toml_io import dumps_train
from .._gear.train import Train
from .._gear.translational import bearing_table

TOL_LINEAR, TOL_NONLINEAR = 0.01, 0.02
"""Default tolerances on ``rel_diff`` without and with backlash."""


@dataclasses.dataclass(frozen=True)
class VerifyResult:
    """Harmonic balance against time integration at ``P`` points, ``m`` meshes.

    **Fields:** ``hb``, ``ni``: results Datasets (``_results`` layout) of the harmonic
    balance (``stable`` from Floquet multipliers; per point ``harmonics``) and of the
    integration (``period``, ``periods``, ``num_steps``); ``rms_hb``, ``rms_ni``,
    ``rel_diff`` ``(P, m)``: RMS alternating mesh forces (N) and their difference
    relative to the largest harmonic-balance RMS of the mesh's stage (NaN where a
    method failed); ``ok`` ``(P, m)``: both converged and ``rel_diff <= tolerance``;
    ``tolerance``; ``seconds``: wall time of each method (``harmonic_balance``,
    ``integration``, with compilation) and ``total``; ``reference``: for a quasi-periodic
    gear, what the integration's statistics are (:func:`window_reference`), ``None`` for a
    periodic one (its reference is the periodic orbit).
    """

    hb: object
    ni: object
    rms_hb: np.ndarray
    rms_ni: np.ndarray
    rel_diff: np.ndarray
    ok: np.ndarray
    tolerance: float
    seconds: dict
    reference: dict | None = None

    @property
    def all_ok(self) -> bool:
        return bool(np.all(self.ok))


def verify_gear(
    train: Train,
    gear: str | None = None,
    at_hz: Sequence[float] | None = None,
    *,
    from_hz: float | None = None,
    to_hz: float | None = None,
    points: int | None = None,
    stage: str | None = None,
    linear: bool = False,
    harmonics: int | None = None,
    tol_linear: float = TOL_LINEAR,
    tol_nonlinear: float = TOL_NONLINEAR,
    settings: td.TimeDomain = td.TimeDomain(),
    batch_size: int | None | str = "auto",
    progress: Callable[[str], None] | None = None,
    command: str | None = None,
    windowed: wd.Windowed | None = None,
) -> VerifyResult:
    """RMS mesh forces of ``gear`` by harmonic balance and by time integration.

    **Arguments:** the points (``at_hz``, or ``from_hz``, ``to_hz``, ``points``),
    ``stage``, ``linear``, ``settings``, ``batch_size`` as
    :func:`~gearjax._studies.simulate.simulate_gear`; ``harmonics``: fixed K (default: the
    frequency-dependent rule of the sweep); ``tol_linear``, ``tol_nonlinear``:
    tolerances on ``rel_diff`` without and with backlash (module docstring);
    ``progress(message)``: called as each method starts and ends; ``command``: how the
    verification was asked for, kept as both datasets' ``command`` attribute (default:
    empty); ``windowed``: :class:`~gearjax.Windowed` settings of the integration of a
    quasi-periodic gear (module docstring, "Quasi-periodic gears"; default
    :data:`gearjax._studies.simulate.WINDOWED`).

    **Returns:** :class:`VerifyResult`. **Raises:** ``ArgumentError`` (a ``TrainError``)
    naming the argument for bad frequencies, harmonics or tolerances, and as
    :func:`~gearjax._gear.case.gear_case`; for a quasi-periodic gear as
    :func:`~gearjax._studies.simulate.simulate_gear` (a window too long, a ``windowed.tol``
    below ``1 / windowed.n_beats``).

    **Warns:** :class:`~gearjax._studies.validity.ContactLossWarning` where a linear
    verification's harmonic-balance mesh force alternates by more than the static one
    (the teeth would leave contact), naming the first frequency.
    """
    t0 = time.perf_counter()
    f_hz, is_sweep = frequency_points(at_hz, from_hz, to_hz, points)
    for name, tol in (("tol_linear", tol_linear), ("tol_nonlinear", tol_nonlinear)):
        if not (0 < tol < 1):
            raise bad_argument(name, tol, "must be a relative tolerance in (0, 1)")
    if harmonics is not None and (int(harmonics) != harmonics or harmonics < 1):
        raise bad_argument("harmonics", harmonics, "must be an integer >= 1")
    case = gear_case(train, gear, stage, linear, torus=True)
    tolerance = tol_nonlinear if case.has_backlash else tol_linear
    say = progress or (lambda message: None)
    if case.G > 1:
        return _verify_torus(case, f_hz, is_sweep, harmonics, tolerance, windowed,
                             batch_size, say, command, t0, progress)

    say(f"verify: harmonic balance at {len(f_hz)} points")
    hb = harmonic_balance_points(case, f_hz, harmonics, follow=is_sweep and case.has_backlash)
    t_hb = time.perf_counter() - t0
    say(f"verify: harmonic balance done in {t_hb:.1f} s; integrating from its states")
    omegas = case.omega(f_hz)
    x0, v0 = jax.vmap(td.hb_initial_state)(jnp.asarray(hb["X"]), jnp.asarray(omegas))
    x_static, _ = td.contact_state(case.system)
    good = hb["result"] == result_word(RESULTS.successful)
    x0 = jnp.where(good[:, None], x0, x_static[None, :])
    v0 = jnp.where(good[:, None], v0, 0.0)
    tr = integrate(case, f_hz, False, x0, v0, settings, batch_size, progress=progress)
    jax.block_until_ready(tr)
    t_ni = time.perf_counter() - t0 - t_hb
    say(f"verify: integration done in {t_ni:.1f} s")

    solver = {"linear": linear, "reference_stage": case.stage,
              "mode": "sweep" if is_sweep else "points"}
    common = {"command": "" if command is None else command, "mode": solver["mode"]}
    hb_ds = _hb_dataset(case, f_hz, hb, {"method": "harmonic balance",
                                         "harmonics": harmonics, **solver,
                                         "truncation_checks": hb["truncation"],
                                         "truncation_target": _harmonics.TRUNCATION_TARGET},
                        t_hb, common)
    hb_ds["harmonics"] = ("point", hb["harmonics"], {"units": "1",
                                                     "long_name": "solution harmonics K"})
    ni_ds = trajectory_dataset(case, f_hz, tr, {**solver_settings(settings), **solver},
                               attrs={"start": "harmonic balance", "seconds": t_ni, **common})
    warn_contact_loss(hb_ds)
    rms_hb, rms_ni, rel, ok = compare_rms(hb_ds, ni_ds, tolerance)
    return VerifyResult(hb=hb_ds, ni=ni_ds, rms_hb=rms_hb, rms_ni=rms_ni, rel_diff=rel, ok=ok,
                        tolerance=tolerance,
                        seconds={"harmonic_balance": t_hb, "integration": t_ni,
                                 "total": time.perf_counter() - t0})


def _verify_torus(case: GearCase, f_hz, is_sweep: bool, harmonics, tolerance: float,
                  settings, batch_size, say, command, t0, progress=None) -> VerifyResult:
    """:func:`verify_gear` of a quasi-periodic gear: the torus harmonic balance against
    the windowed integration from its states (module docstring)."""
    solver = {"linear": case.linear, "reference_stage": case.stage,
              "mode": "sweep" if is_sweep else "points"}
    ni_solver = {**windowed_settings(case, settings), **solver}  # refuses a bad window first
    say(f"verify: torus harmonic balance at {len(f_hz)} points ({case.G} incommensurate "
        "frequency groups: the response is quasi-periodic)")
    hb = harmonic_balance_points(case, f_hz, harmonics, follow=is_sweep and case.has_backlash)
    t_hb = time.perf_counter() - t0
    say(f"verify: harmonic balance done in {t_hb:.1f} s; integrating from its states in "
        f"windows of {ni_solver['window_periods']} base periods until consecutive windows "
        f"agree within {ni_solver['tol']:g}")
    good = hb["result"] == result_word(RESULTS.successful)
    x_static, _ = td.contact_state(case.system)
    x0 = np.where(good[:, None], hb["x0"], np.asarray(x_static)[None, :])
    v0 = np.where(good[:, None], hb["v0"], 0.0)
    out = integrate_windowed(case, f_hz, False, x0, v0, settings, batch_size,
                             progress=progress)
    jax.block_until_ready(out)
    t_ni = time.perf_counter() - t0 - t_hb
    say(f"verify: integration done in {t_ni:.1f} s")
    common = {"command": "" if command is None else command, "mode": solver["mode"]}
    hb_ds = _hb_dataset(case, f_hz, hb, {
        "method": "torus harmonic balance", "harmonics": harmonics,
        "truncation": _harmonics.TORUS_TRUNCATION, "torus": torus_fields(case), **solver,
        "truncation_checks": hb["truncation"],
        "truncation_target": _harmonics.TRUNCATION_TARGET},
        t_hb, common)
    hb_ds["harmonics"] = (("point", "angle"), hb["harmonics"], {
        "units": "1", "long_name": "orders K_g of the point's truncation set, per torus "
                                   "angle"})
    ni_ds = windowed_dataset(case, f_hz, out, ni_solver,
                             attrs={"start": "harmonic balance", "seconds": t_ni, **common})
    warn_contact_loss(hb_ds, stacklevel=3)
    rms_hb, rms_ni, rel, ok = compare_rms(hb_ds, ni_ds, tolerance)
    return VerifyResult(hb=hb_ds, ni=ni_ds, rms_hb=rms_hb, rms_ni=rms_ni, rel_diff=rel, ok=ok,
                        tolerance=tolerance,
                        seconds={"harmonic_balance": t_hb, "integration": t_ni,
                                 "total": time.perf_counter() - t0},
                        reference=window_reference(ni_solver))


def _hb_dataset(case: GearCase, f_hz, hb: dict, solver: dict, seconds: float,
                common: dict):
    """The harmonic-balance side of a verification as a sweep dataset: the points of
    ``hb`` (:func:`harmonic_balance_points`) at ``f_hz``, with ``solver`` and ``common``
    attributes and the time ``seconds`` it took; on a periodic translational gear also
    the displacement harmonics and the bearing forces they give."""
    ds = sweep_dataset(
        hb["responses"], **case.point_coordinates(f_hz),
        result=list(hb["result"]),
        stable=hb["stable"],
        static_force=case.F_static,
        train_toml=dumps_train(case.train),
        gear=case.gear.name,
        solver=solver,
        attrs={"reference_stage": case.stage, "seconds": seconds, **common},
    )
    if case.train.translational and case.system.n_angles == 1:
        K = np.asarray(hb["harmonics"], dtype=int)
        X = [np.asarray(Xp)[:2 * k + 1] for Xp, k in zip(hb["X"], K)]
        ds = add_displacement_harmonics(ds, X, case.system.dof_labels, K)
        ds = add_bearing_forces(ds, **bearing_table(case.train))
    return ds


def window_reference(solver: dict) -> dict:
    """What the integration statistics of a quasi-periodic verification are, from the
    windowed integration's settings (:func:`~gearjax._studies.simulate.windowed_settings`):
    ``method``, ``window_periods`` (base periods per window), ``n_beats`` (cycles of the
    slowest beat a window spans), ``agreement_tolerance`` (consecutive windows' relative
    agreement of the mean and RMS mesh forces), ``n_agree``, ``transient_windows``,
    ``max_windows``, and ``statistics``: the responses are those of the last window."""
    return {"method": "windowed time integration", "window_periods": solver["window_periods"],
            "n_beats": solver["n_beats"], "agreement_tolerance": solver["tol"],
            "n_agree": solver["n_agree"], "transient_windows": solver["transient_windows"],
            "max_windows": solver["max_windows"],
            "statistics": "the last window's, once n_agree consecutive windows agree"}


def compare_rms(hb_ds, ni_ds, tolerance: float):
    """RMS mesh forces of two methods at the same ``P`` points and ``m`` meshes, compared.

    **Arguments:** ``hb_ds``, ``ni_ds``: results Datasets (or any Datasets with
    ``rms_force`` ``(point, mesh)`` in N and ``converged`` ``(point,)``; ``hb_ds`` also
    ``stage`` ``(mesh,)``); ``tolerance``: the largest accepted ``rel_diff``.

    **Returns:** ``(rms_hb, rms_ni, rel_diff, ok)``, each ``(P, m)``: ``rel_diff =
    |rms_ni - rms_hb|`` relative to the largest ``rms_hb`` of the mesh's stage at that
    point (module docstring), NaN where either method did not converge; ``ok``: both
    converged and ``rel_diff <= tolerance``."""
    rms_hb = np.asarray(hb_ds["rms_force"].values, dtype=float)
    rms_ni = np.asarray(ni_ds["rms_force"].values, dtype=float)
    both = (np.asarray(hb_ds["converged"].values) & np.asarray(ni_ds["converged"].values))
    stages = np.asarray(hb_ds["stage"].values)
    scale = np.full_like(rms_hb, np.nan)
    for s in np.unique(stages):
        cols = stages == s
        with np.errstate(invalid="ignore"):
            scale[:, cols] = np.max(rms_hb[:, cols], axis=1, keepdims=True)
    diff = np.abs(rms_ni - rms_hb)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(diff == 0, 0.0, diff / scale)
    rel = np.where(both[:, None], rel, np.nan)
    with np.errstate(invalid="ignore"):
        ok = both[:, None] & (rel <= tolerance)
    return rms_hb, rms_ni, rel, ok


# ----------------------------------------------------------------- harmonic balance


def point_orders(case: GearCase, f_hz, harmonics: int | None = None) -> list:
    """The orders ``K`` of each point at ``f_hz`` (Hz): an ``int`` from
    :func:`~gearjax._studies.harmonics.harmonics_rule` for a periodic gear, a tuple from
    :func:`~gearjax._studies.harmonics.torus_orders_rule` on a torus (``G > 1``), each
    with the system's response cutoff; ``harmonics``: that K (on every torus angle).

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming ``harmonics`` below the
    excitation floor, or a K whose factorisation does not fit in memory."""
    s = case.system
    if harmonics is not None:
        _harmonics.require_harmonics(s, harmonics)
    cutoff = _harmonics.response_cutoff_hz(s)
    if case.G > 1:
        ks = [(int(harmonics),) * case.G if harmonics is not None else
              _harmonics.torus_orders_rule(s, float(w), cutoff_hz=cutoff)
              for w in case.omega(f_hz)]
    else:
        min_k = _harmonics.excitation_floor(s)
        ks = [int(harmonics) if harmonics is not None else
              _harmonics.harmonics_rule(f / case.mu_ref, min_k, cutoff_hz=cutoff)
              for f in np.asarray(f_hz, dtype=float)]
    for K in dict.fromkeys(ks):
        _harmonics.require_size(s, K, mu=case.mu)
    return ks


def harmonic_balance_points(case: GearCase, f_hz, harmonics: int | None = None,
                            follow: bool = False) -> dict:
    """Harmonic-balance solutions of ``case`` at ``f_hz`` (Hz), in the order given.

    ``K`` per point from :func:`point_orders`; one batched Newton solve from the linear
    guess per distinct ``K``, then, with backlash,
    :func:`~gearjax._studies.sweep.backlash_start` for each point that failed (on a torus
    the homotopy in backlash: no period to settle to). ``follow``: first start each point
    from the previous converged one (a sweep).

    **Returns:** a dict of per-point arrays: ``harmonics``, ``result`` ``(P,)`` words
    (:func:`~gearjax._engine.results.result_word`), ``stable`` ``(P,)`` bool (NaN where
    not converged), ``responses`` (:class:`~gearjax.MeshResponses`, fields ``(P, m)``;
    NaN where not converged), ``x0``, ``v0`` ``(P, n)``: the state at ``t = 0`` of each
    solution (rad or m, and per s; :func:`~gearjax.hb_initial_state` on the point's
    basis), and ``X``. Periodic gear: ``X`` ``(P, 2Kmax+1, n)`` (coefficients
    zero-padded to the largest K) and ``harmonics`` ``(P,)``; torus: ``X`` a list of ``(C_p, n)`` (each point's own truncation set) and ``harmonics``
    ``(P, G)`` orders.
    """
    f_hz = np.asarray(f_hz, dtype=float)
    omegas = case.omega(f_hz)
    ks = point_orders(case, f_hz, harmonics)
    P, n = len(f_hz), case.system.n_dof
    converged = result_word(RESULTS.successful)
    result = np.full(P, result_word(RESULTS.nonlinear_max_steps_reached), dtype=object)
    stable = np.zeros(P, dtype=bool)
    rows = [None] * P
    problems = {K: _hb.hb_problem(case.system, _harmonics.settings_for(case.system, K))
                for K in dict.fromkeys(ks)}
    groups = {K: np.array([i for i in range(P) if ks[i] == K]) for K in problems}
    ys = [None] * P
    if follow:
        previous = None
        for i in range(P):
            problem = problems[ks[i]]
            y, code = None, RESULTS.nonlinear_max_steps_reached
            if previous is not None:
                sol = newton(problem, jnp.asarray(omegas[i]),
                             resize_harmonics(*previous, problem))
                y, code = sol.y, sol.result
            if not bool(code == RESULTS.successful):
                y, code = start_point(problem, omegas[i])
            ys[i], result[i] = y, result_word(code)
            if result[i] == converged:
                previous = (y, ks[i])
    else:
        for K, problem in problems.items():
            idx = groups[K]
            sols = solve_points(problem, jnp.asarray(omegas[idx]))
            words = result_word(sols.result)
            for j, i in enumerate(idx):
                ys[i], result[i] = sols.y[j], words[j]
                if words[j] != converged and case.has_backlash:
                    sol = backlash_start(problem, omegas[i])
                    ys[i], result[i] = sol.y, result_word(sol.result)
    truncation = [[] for _ in range(P)]
    for i in range(P):
        if result[i] == converged:
            ks[i], ys[i], truncation[i] = checked_orders(case, problems, ks[i], ys[i],
                                                         omegas[i], fixed=harmonics is not None)
    groups = {K: np.array([i for i in range(P) if ks[i] == K]) for K in dict.fromkeys(ks)}
    problems = {K: problems[K] for K in groups}
    torus = case.G > 1
    X = [None] * P if torus else np.zeros((P, 2 * max(ks) + 1, n))
    x0, v0 = np.zeros((P, n)), np.zeros((P, n))
    for K, problem in problems.items():
        idx = groups[K]
        Xs = jnp.stack([ys[i] for i in idx]).reshape((-1,) + problem.shape) * problem.x_scale
        post = point_rows(problem, Xs, jnp.asarray(omegas[idx]), result[idx],
                          jnp.asarray(case.F_static))
        for j, i in enumerate(idx):
            if torus:
                X[i] = np.asarray(Xs[j])
            else:
                X[i, :problem.shape[0]] = np.asarray(Xs[j])
            x0[i], v0[i] = td.hb_initial_state(Xs[j], omegas[i], 1, problem.basis)
            stable[i] = bool(post["stable"][j])
            rows[i] = jax.tree.map(lambda a: np.asarray(a[j]), post["responses"])
    responses = jax.tree.map(lambda *a: np.stack(a), *rows)
    result = result.astype(str)
    failed = result != converged
    responses = jax.tree.map(lambda a: np.where(failed[:, None], np.nan, a), responses)
    return {"X": X, "harmonics": np.array(ks, dtype=int), "result": result,
            "stable": np.where(failed, np.nan, stable), "responses": responses,
            "x0": x0, "v0": v0, "truncation": truncation}


# ------------------------------------------------------------------------------ JSON


def verify_json(result: VerifyResult) -> dict:
    """interface.md's ``verify`` JSON: ``points``, each with the point fields of a sweep
    (``result`` and ``converged`` of both methods), ``truncation`` (the a posteriori
    checks of the point's orders, :func:`checked_orders`) and per mesh ``rms_hb``,
    ``rms_ni``, ``rel_diff``, ``ok`` (``reason`` where a value is missing). A quasi-periodic gear
    adds ``reference`` (:func:`window_reference`) and ``torus``
    (:func:`~gearjax._gear.case.torus_fields`), and per point ``harmonics`` as the
    orders per angle, ``period`` null with ``period_reason``, ``windows``, ``window_s``,
    ``window_change`` and ``agreement`` (:data:`AGREEMENT`) with ``agreement_reason``
    and ``shortfall`` with ``shortfall_reason`` (where the answers differ, which side fell
    short of its own check and why, :func:`shortfall`; else ``None``)."""
    hb, ni = result.hb, result.ni
    torus = result.reference is not None
    names = hb["mesh"].values.tolist()
    stage, side = hb["stage"].values.tolist(), hb["side"].values.tolist()
    planet = hb["planet"].values.tolist()
    checks = json.loads(hb.attrs.get("solver", "{}")).get("truncation_checks", [])
    points = []
    for k in range(hb.sizes["point"]):
        res_hb, res_ni = str(hb["result"].values[k]), str(ni["result"].values[k])
        point_checks = checks[k] if k < len(checks) else []
        conv_hb, conv_ni = bool(hb["converged"].values[k]), bool(ni["converged"].values[k])
        meshes = []
        for j, name in enumerate(names):
            mesh = {"name": str(name), "stage": str(stage[j]), "side": str(side[j]),
                    "planet": int(planet[j]), "rms_hb": json_number(result.rms_hb[k, j]),
                    "rms_ni": json_number(result.rms_ni[k, j]),
                    "rel_diff": json_number(result.rel_diff[k, j]),
                    "ok": bool(result.ok[k, j])}
            if mesh["rel_diff"] is None:
                why = [f"harmonic balance {res_hb}"] if not conv_hb else []
                if not conv_ni:
                    period = int(ni["period"].values[k])
                    why.append(f"integration {res_ni}" + (f" (period {period})" if period > 1
                                                          else ""))
                mesh["reason"] = "; ".join(why) or "not finite"
            meshes.append(mesh)
        stable = int(hb["stable"].values[k])
        points.append({
            "mesh_frequency_hz": float(hb["mesh_frequency_hz"].values[k]),
            "stage_mesh_frequency_hz": [float(v) for v in
                                        hb["stage_mesh_frequency_hz"].values[k]],
            "input_rpm": float(hb["input_rpm"].values[k]),
            "result": res_hb if not conv_hb else res_ni,
            "converged": conv_hb and conv_ni,
            "result_hb": res_hb,
            "result_ni": res_ni,
            "stable": None if stable < 0 else bool(stable),
            "period": int(ni["period"].values[k]) or None,  # 0: no repeat found
            "harmonics": None if torus else int(hb["harmonics"].values[k]),
            "truncation": point_checks,
            "ok": bool(np.all(result.ok[k])),
            "meshes": meshes,
        })
        if torus:
            points[-1].update(_torus_point(result, k, conv_hb, res_ni, point_checks))
    out = {
        "gear": hb.attrs.get("gear"),
        "reference_stage": hb.attrs.get("reference_stage"),
        "tolerance": result.tolerance,
        "relative_to": "largest rms_hb of the mesh's stage at that point",
        "all_ok": result.all_ok,
        "max_rel_diff": json_number(np.nanmax(result.rel_diff)) if np.any(
            np.isfinite(result.rel_diff)) else None,
        "seconds": result.seconds,
        "points": points,
    }
    if torus:
        out["reference"] = result.reference
        out["torus"] = json.loads(hb.attrs["solver"])["torus"]
    return out


AGREEMENT = {
    "agree": "both converged and every mesh within the tolerance",
    "differ": "both converged but a mesh differs by more than the tolerance: the torus "
              "solution is not what the integration follows (the response locks onto a "
              "rational winding, turns chaotic, the torus is unstable, or its truncation is "
              "short)",
    "not_stationary": "consecutive windows of the integration did not agree: no stationary "
                      "statistics to compare (a locking or chaotic response, or a transient "
                      "longer than the windows)",
    "hb_failed": "the harmonic balance did not converge",
    "integration_failed": "the integration failed",
}
"""The per-point ``agreement`` of a quasi-periodic verification, and what each means."""


def _torus_point(result: VerifyResult, k: int, conv_hb: bool, res_ni: str,
                 checks: list) -> dict:
    """The fields a quasi-periodic verification adds to point ``k`` of the JSON: the
    orders per angle, no period (with the reason), the windows, the ``agreement``
    (:data:`AGREEMENT`) with its ``agreement_reason``, and where the answers differ the
    ``shortfall`` judged from the point's truncation ``checks`` (:func:`shortfall`)."""
    ni = result.ni
    K = [int(v) for v in result.hb["harmonics"].values[k]]
    if not conv_hb:
        word = "hb_failed"
    elif res_ni == "not_stationary":
        word = "not_stationary"
    elif res_ni != "quasi_periodic":
        word = "integration_failed"
    else:
        word = "agree" if bool(np.all(result.ok[k])) else "differ"
    side = why = None
    if word == "differ":
        side, why = shortfall([c for c in checks if c["K"] == K],
                              float(ni["window_change"].values[k]),
                              result.reference["agreement_tolerance"], result.tolerance)
    return {"harmonics": K,
            "period": None,
            "period_reason": "quasi-periodic: the mesh frequencies fall in incommensurate "
                             "groups, so the response never repeats; the integration's "
                             "statistics are over windows",
            "windows": int(ni["windows"].values[k]),
            "window_s": json_number(ni["window_s"].values[k]),
            "window_change": json_number(ni["window_change"].values[k]),
            "agreement": word, "agreement_reason": AGREEMENT[word],
            "shortfall": side, "shortfall_reason": why}


SHORTFALL = ("harmonic_balance", "integration", "neither")
"""Which side of a quasi-periodic point that differs fell short of its own check
(:func:`shortfall`)."""


def shortfall(checks: list, window_change: float, window_tol: float,
              tolerance: float) -> tuple[str, str]:
    """Which side of a converged quasi-periodic point whose two answers differ by more
    than ``tolerance`` fell short of its own check, and why, in words: the harmonic
    balance (its a posteriori truncation checks at the orders it kept, ``checks``,
    :func:`checked_orders`: an estimate over ``TRUNCATION_TARGET``, or an angle not
    checked), else the integration (its last
    two windows, ``window_change``, differ by more than ``tolerance / 4``: the statistics
    still move by a share of the tolerance; ``window_tol`` is the agreement it was given),
    else ``"neither"``: each side meets its own check, so the difference is the
    response's (the torus is not what the integration follows).

    **Returns:** ``(side, words)``, ``side`` one of :data:`SHORTFALL`."""
    target = _harmonics.TRUNCATION_TARGET
    made = [c["change"] for c in checks if c.get("change") is not None]
    if made and max(made) > target:
        return "harmonic_balance", (f"the harmonic balance fell short: its truncation "
                                    f"estimate {max(made):.2%} exceeds the {target:.1%} "
                                    "target (omit `--harmonics`, or raise it)")
    unchecked = [c for c in checks if c.get("change") is None] if checks else [{}]
    if unchecked:
        return "harmonic_balance", ("the harmonic balance's truncation was not checked at "
                                    "this point (" + "; ".join(
                                        c.get("skipped", "no check") for c in unchecked)
                                    + "): it may be short")
    if np.isfinite(window_change) and window_change > tolerance / 4:
        return "integration", (f"the integration fell short: its last two windows differ by "
                               f"{window_change:.2%}, a share of the {tolerance:.0%} "
                               f"tolerance (agreement asked: {window_tol:g}; lower "
                               "Windowed.tol)")
    return "neither", (f"each side meets its own check (truncation estimate "
                       f"{max(made):.2%}, windows within {window_change:.2%}): the "
                       "difference is the response's")

