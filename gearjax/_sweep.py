"""Frequency-response sweeps of a gear: the gear-train surface of the harmonic balance.

Frequencies are the mesh frequency (Hz) of a reference stage; with the gear's
coprime ``mu``, ``Omega = 2 pi f / mu_ref`` is the base frequency of every
excitation. The number of solution harmonics depends on frequency
(:func:`harmonics_rule`): low base frequencies need many harmonics to reach the
modes the excitation drives, high ones few. It is fixed within a segment of the
band, so each segment compiles once; at a segment boundary the solution is padded
or truncated to the next segment's harmonics and re-converged.

Linear sweeps (no backlash) are independent points: the periodic solution of a
linear time-periodic system is unique wherever it exists, so a grid of frequencies
is solved in one batched call and no continuation is needed (near a parametric
instability boundary the response grows without bound; those points are unstable).
Non-linear sweeps are pseudo-arclength continuations through the folds.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from . import _continuation, _hb
from ._assembly import assemble
from ._errors import fail
from ._kinematics import kinematics, require_base
from ._responses import mesh_responses, static_mesh_forces
from ._results import mesh_coordinates, sweep_dataset
from ._stability import bifurcation_kind, stability
from ._toml_io import dumps_train
from ._train import Train

RESPONSE_CUTOFF_HZ = 20e3
"""Response content the default harmonics must reach (covers the modes the meshes drive)."""

MAX_DEFAULT_HARMONICS = 64


def harmonics_rule(base_hz: float, min_harmonics: int, eta: int = 1,
                   cutoff_hz: float = RESPONSE_CUTOFF_HZ) -> int:
    """Default solution harmonics K at base frequency ``base_hz`` (Hz).

    ``K = eta * ceil16(cutoff / base)``, at least the highest excitation harmonic
    ``min_harmonics`` and at most 64 (times ``eta``): enough that RMS mesh forces
    change by < 0.5% when K doubles on the paper case (tests/test_sweep.py). Steps of
    16 keep a 2-15 kHz sweep to three segments (three compilations).
    """
    k = 16 * math.ceil(cutoff_hz / max(base_hz, 1e-9) / 16)
    return eta * int(min(max(k, min_harmonics // eta if eta else min_harmonics,
                             8), MAX_DEFAULT_HARMONICS))


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A finished (or stopped) sweep: ``dataset`` (xarray, interface.md layout),
    ``folds_hz`` (located folds, reference-stage Hz), ``stop`` (why it ended),
    ``segments`` (``(from_hz, to_hz, K)`` in sweep order), ``seconds``."""

    dataset: object
    folds_hz: tuple[float, ...]
    stop: str
    segments: tuple[tuple[float, float, int], ...]
    seconds: float


def sweep(
    train: Train,
    gear: str | None = None,
    from_hz: float = 2000.0,
    to_hz: float = 15000.0,
    *,
    stage: str | None = None,
    linear: bool = False,
    harmonics: int | None = None,
    eta: int = 1,
    max_step_hz: float | None = None,
    points: int = 300,
    max_points: int = 3000,
    smoothing: float = 0.0,
    progress: Callable[[int, float], None] | None = None,
) -> SweepResult:
    """Frequency response of ``gear`` from ``from_hz`` to ``to_hz`` (reference-stage mesh Hz).

    **Arguments:** ``stage``: reference stage id (default: first turning stage);
    ``linear``: drop the backlash; ``harmonics``: fixed K (default: frequency-dependent,
    :func:`harmonics_rule`); ``eta``: sub-harmonic index; ``max_step_hz``: largest
    frequency step; ``points``: grid size of a linear sweep; ``max_points``: cap on a
    continuation; ``smoothing``: corner rounding of the backlash relative to it (0: exact
    piecewise-linear, see :func:`gearjax._mesh.backlash`); ``progress(points_done,
    frequency_hz)``: called per point.

    **Raises:** ``TrainError`` for a gear where no mesh turns, an impractical ``mu``,
    an unknown stage, or backlash on an unloaded stage without ``drag_torque``.
    """
    t_start = time.perf_counter()
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    mu = require_base(kin, train.source)
    ref = _reference_stage(train, kin, stage)
    mu_ref = mu[train.stage_ids.index(ref)]
    system = assemble(train, g.name, kin)
    if linear:
        system = dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))
    else:
        _check_unloaded(train, g, kin, system)
    for name, f in (("--from", from_hz), ("--to", to_hz)):
        if not (f > 0 and math.isfinite(f)):
            raise fail("command line", name, f, "must be a positive mesh frequency in Hz")
    if from_hz == to_hz:
        raise fail("command line", "--to", to_hz, "must differ from --from")
    if eta < 1:
        raise fail("command line", "--eta", eta, "must be an integer >= 1")
    if not (0.0 <= smoothing < 1.0):
        raise fail("command line", "--smoothing", smoothing,
                   "must be >= 0 (0: exact backlash) and < 1 (relative to the backlash)")
    if harmonics is not None and harmonics < 1:
        raise fail("command line", "--harmonics", harmonics, "must be an integer >= 1")

    to_omega = lambda f: 2 * math.pi * f / mu_ref  # noqa: E731  base frequency, rad/s
    min_k = _hb.highest_excitation(system, eta)
    segments = _segments(from_hz, to_hz, mu_ref, min_k, eta, harmonics)
    F_static = static_mesh_forces(system)
    solver = {"method": "harmonic balance", "linear": linear, "eta": eta,
              "segments": [list(s) for s in segments], "reference_stage": ref,
              "max_step_hz": max_step_hz, "cutoff_hz": RESPONSE_CUTOFF_HZ,
              "smoothing": smoothing}
    rows: list[dict] = []
    folds: list[float] = []
    stop = "reached_end"
    y = None
    done = 0
    for f_a, f_b, K in segments:
        problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=K, eta=eta,
                                                             smoothing=smoothing))
        if linear:
            n = max(2, round(points * abs(f_b - f_a) / abs(to_hz - from_hz)))
            last = (f_b == segments[-1][1])
            freqs = np.linspace(f_a, f_b, n, endpoint=last)
            omegas = jnp.asarray([to_omega(f) for f in freqs])
            sols = _solve_points(problem, omegas)
            ok = np.asarray(sols.result)
            rows.append(_point_rows(problem, sols.X, omegas, ok, F_static))
            done += n
            if progress:
                progress(done, float(freqs[-1]))
            continue
        omega_ref = to_omega(from_hz)
        param = _continuation.FrequencyParameter(problem=problem, omega_ref=jnp.asarray(omega_ref))
        lam_a, lam_b = to_omega(f_a) / omega_ref, to_omega(f_b) / omega_ref
        y, code = _enter_segment(problem, param, y, lam_a, omega_ref)
        if code != _hb.CONVERGED:
            stop = f"no converged start at {f_a:.1f} Hz ({_hb.RESULTS[code]})"
            break
        settings = _settings(max_step_hz, to_hz - from_hz, from_hz, mu_ref)

        def on_point(i, state, f_ref=from_hz, start=done):
            if progress:
                progress(start + i + 1, float(state.lam) * f_ref)

        branch = _continuation.continue_branch(param, y, lam_a, lam_b, settings,
                                               max_points=max_points - done, on_point=on_point)
        omegas = jnp.asarray(branch.omega)
        Xs = jnp.asarray(branch.y).reshape((-1,) + problem.shape) * problem.x_scale
        skip = 1 if rows else 0  # the segment's first point repeats the previous last
        rows.append(_point_rows(problem, Xs[skip:], omegas[skip:],
                                np.zeros(len(omegas) - skip, int), F_static))
        folds += [float(lam) * from_hz for lam in branch.fold_lam[branch.fold]]
        done += len(omegas) - skip
        y = (K, branch.y[-1], branch.lam[-1])
        if branch.stop != "reached_end":
            stop = branch.stop
            break
    if not rows:
        raise RuntimeError(f"sweep produced no point: {stop}")
    data = {k: np.concatenate([r[k] for r in rows]) for k in rows[0] if k != "responses"}
    data["responses"] = jax.tree.map(lambda *a: np.concatenate(a),
                                     *[r["responses"] for r in rows])
    omegas = data["omega"]
    f_ref = omegas * mu_ref / (2 * math.pi)
    stage_hz = np.outer(omegas / (2 * math.pi), np.asarray(mu, float))
    bif = bifurcations(f_ref, data["stable"], data["multipliers"], data["excluded"])
    coords = mesh_coordinates(system)
    ds = sweep_dataset(
        data["responses"], **coords,
        mesh_frequency_hz=f_ref,
        stage_mesh_frequency_hz=stage_hz,
        input_rpm=np.array([kin.input_rpm(ref, f) for f in f_ref]),
        omega=omegas,
        result=[_hb.RESULTS[c] for c in data["result"]],
        stable=data["stable"],
        static_force=np.asarray(F_static),
        train_toml=dumps_train(train),
        gear=g.name,
        solver=solver,
        attrs={"folds_hz": folds, "stop": stop, "reference_stage": ref,
               "bifurcations": bif, "command": " ".join(sys.argv)},
    )
    ds["max_multiplier"] = ("point", data["max_multiplier"], {
        "units": "1", "long_name": "largest Floquet multiplier modulus (rigid-body excluded)"})
    return SweepResult(dataset=ds, folds_hz=tuple(folds), stop=stop,
                       segments=tuple(segments), seconds=time.perf_counter() - t_start)


# ---------------------------------------------------------------------------- parts


def _reference_stage(train, kin, stage):
    if stage is None:
        return next(s.id for s in kin.stages if s.turning)
    if stage not in train.stage_ids:
        raise fail(train.source, "--stage", stage, f"no such stage; stages are "
                   f"{list(train.stage_ids)}")
    if not kin.stage(stage).turning:
        raise fail(train.source, "--stage", stage, f"stage {stage!r} does not turn in gear "
                   f"{kin.gear!r}: its mesh frequency is 0")
    return stage


def _check_unloaded(train, g, kin, system):
    back = np.asarray(system.backlash)
    for s in kin.stages:
        rows = [i for i, grp in enumerate(system.mesh_group) if grp == s.id]
        if not s.loaded and np.any(back[rows] > 0) and float(g.drag_torque) == 0.0:
            raise fail(train.source, f"gears.{g.name}.drag_torque", 0.0,
                       f"stage {s.id!r} carries no static load in gear {g.name!r} (a central "
                       "member is free), so with backlash its meshes rattle at an undetermined "
                       "mean position: give the gear a drag_torque, or sweep with --linear")


def _segments(from_hz, to_hz, mu_ref, min_k, eta, fixed):
    """``(f_a, f_b, K)`` in sweep order; K constant on each."""
    if fixed is not None:
        return [(from_hz, to_hz, int(fixed))]
    lo, hi = sorted((from_hz, to_hz))
    edges = np.geomspace(lo, hi, 65)
    ks = [harmonics_rule(f / mu_ref / eta, min_k, eta) for f in edges[:-1]]
    segs = []
    for f_a, f_b, k in zip(edges[:-1], edges[1:], ks):
        if segs and segs[-1][2] == k:
            segs[-1] = (segs[-1][0], f_b, k)
        else:
            segs.append((f_a, f_b, k))
    segs = [(float(a), float(b), k) for a, b, k in segs]
    if from_hz > to_hz:
        segs = [(b, a, k) for a, b, k in reversed(segs)]
    segs[0] = (float(from_hz), segs[0][1], segs[0][2])
    segs[-1] = (segs[-1][0], float(to_hz), segs[-1][2])
    return segs


def _settings(max_step_hz, span_hz, f_ref, mu_ref):
    """Continuation settings: parameter steps of at most ``max_step_hz`` (default 1/100 of
    the band), in units of the start frequency."""
    max_step_hz = max_step_hz or abs(span_hz) / 100
    return _continuation.Settings(step=0.02, max_step=0.5,
                                  max_dlambda=float(max_step_hz / f_ref), fold_step=1e-3)


@jax.jit
def _solve_points(problem, omegas):
    return jax.vmap(lambda w: _hb.solve_hb(problem, w))(omegas)


def _enter_segment(problem, param, previous, lam, omega_ref):
    """Scaled unknowns converged at ``lam`` with this segment's harmonics."""
    if previous is None:
        return start_point(problem, lam * omega_ref)
    K_old, y_old, lam_old = previous
    sol = _newton_jit(problem, jnp.asarray(lam_old * omega_ref),
                      resize_harmonics(y_old, K_old, problem))
    return sol.y, int(sol.result)


def start_point(problem, omega):
    """``(y, result code)`` at ``omega``: Newton from the linear, in-contact guess; with
    backlash, the homotopy in backlash 0 -> b when that fails."""
    sol = _newton_jit(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    if int(sol.result) != _hb.CONVERGED and bool(jnp.any(problem.system.backlash > 0)):
        sol = _backlash_homotopy(problem, omega)
    return sol.y, int(sol.result)


def resize_harmonics(y, K_old: int, problem):
    """Scaled unknowns of ``K_old`` harmonics padded with zeros or truncated to
    ``problem``'s K (flat)."""
    C, n = problem.shape
    old = np.asarray(y).reshape(2 * K_old + 1, n)
    new = np.zeros((C, n))
    rows = min(C, old.shape[0])
    new[:rows] = old[:rows]
    return jnp.asarray(new.reshape(-1))


_newton_jit = jax.jit(_hb.newton)


def _backlash_homotopy(problem, omega):
    """Continue from the linear solution in backlash scale 0 -> 1 at fixed ``omega``."""
    param = _continuation.SystemParameter(problem=problem, omega_value=jnp.asarray(omega),
                                          where=lambda s: s.backlash)
    lin = _hb.linear_guess(problem, omega)
    start = _newton_jit(param.split(0.0)[0], jnp.asarray(omega), lin)
    branch = _continuation.continue_branch(param, start.y, 0.0, 1.0,
                                           _continuation.Settings(max_dlambda=0.05), 500)
    sol = _newton_jit(problem, jnp.asarray(omega), jnp.asarray(branch.y[-1]))
    return sol


def _point_rows(problem, Xs, omegas, results, F_static):
    """Responses and stability of a batch of solutions (one compiled call per segment)."""
    resp, stab = _batch_post(problem, Xs, omegas, F_static)
    return {"responses": resp, "omega": np.asarray(omegas), "result": np.asarray(results),
            "stable": np.asarray(stab.stable), "max_multiplier": np.asarray(stab.max_abs),
            "multipliers": np.asarray(stab.multipliers), "excluded": np.asarray(stab.excluded)}


def bifurcations(f_hz, stable, multipliers, excluded) -> list[dict]:
    """Where stability changes between neighbouring points, and how (interface: a list of
    ``{"mesh_frequency_hz", "kind"}``, the frequency the midpoint of the two points).

    ``kind`` is from :func:`~gearjax._stability.bifurcation_kind`: ``fold``,
    ``period_doubling`` or ``neimark_sacker`` (``None`` where no multiplier left the unit
    circle, e.g. a change in the excluded rigid-body set).
    """
    out = []
    for i in np.flatnonzero(np.asarray(stable[1:]) != np.asarray(stable[:-1])):
        kind = bifurcation_kind(multipliers[i][~excluded[i]], multipliers[i + 1][~excluded[i + 1]])
        out.append({"mesh_frequency_hz": float((f_hz[i] + f_hz[i + 1]) / 2), "kind": kind})
    return out


@jax.jit
def _batch_post(problem, Xs, omegas, F_static):
    resp = jax.vmap(mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs, omegas, F_static)
    stab = jax.vmap(stability, in_axes=(None, 0, 0))(problem, Xs, omegas)
    return resp, stab


def progress_printer(stream=sys.stderr) -> Callable[[int, float], None]:
    """A progress line on ``stream``: rewritten in place on a terminal, every 25 points
    otherwise."""
    tty = stream.isatty()
    t0 = time.perf_counter()

    def show(n: int, f_hz: float) -> None:
        if tty or n % 25 == 0:
            end = "\r" if tty else "\n"
            stream.write(f"sweep: {n} points, at {f_hz:9.1f} Hz, {time.perf_counter() - t0:6.1f} s"
                         + end)
            stream.flush()

    return show


def summary_json(result: SweepResult) -> dict:
    """Top-level JSON of a sweep (points per interface.md plus summary fields)."""
    from ._results import points_json

    ds = result.dataset
    return {
        "gear": ds.attrs.get("gear"),
        "reference_stage": ds.attrs.get("reference_stage"),
        "stop": result.stop,
        "folds_hz": list(result.folds_hz),
        "bifurcations": json.loads(ds.attrs.get("bifurcations", "[]")),
        "segments": [list(s) for s in result.segments],
        "seconds": result.seconds,
        "points": points_json(ds),
        "solver": json.loads(ds.attrs.get("solver", "{}")),
    }
