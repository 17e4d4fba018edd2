"""The paper's first gear (bundled example): linear and 0.05 mm backlash frequency sweeps.

Runs ``gearjax.sweep`` over a band of stage-1 mesh frequency (default the paper's
2-15 kHz, Figs 4-6) twice and prints, per sweep: points, the first run's wall time and
the part of it spent compiling (JAX's compile-duration events: tracing, lowering, XLA),
the second run's (everything compiled: the time after compile) and its time per point,
harmonics per segment, the folds and stability changes
located, the largest RMS mesh force of each stage and where, the largest separation
and back-contact shares, and the mean-force check (per stage and side, the sum over
planets of the mean mesh force against the static one: equilibrium of the mean fixes
it whatever the dynamics, up to the torque the 1e2 N m/rad housing springs leak).
A machine reference goes with each sweep: the time of a LAPACK LU of a dense 1806 x 1806
matrix (the paper case at K = 64), for which the issue's 30 s target assumes 60-80 ms,
and the time after compile in units of it.

    python benchmarks/paper_sweep.py [--from 2000 --to 15000] [--linear-only]
        [--max-points 3000] [--out-dir DIR]

Writes ``paper_linear.nc``/``.png`` and ``paper_backlash.nc``/``.png`` to ``--out-dir``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import warnings

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

import gearjax as gj


def _best_of(fn, *args, repeat: int = 5) -> float:
    """Best wall time (s) of ``fn(*args)`` after one warm-up call (compile excluded)."""
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t)
    return min(times)


def breakdown(train, result) -> None:
    """Cost per K, at a point of its first segment (ms, compile excluded): one residual,
    one structured Jacobian, one bordered factorisation + solve of the continuation, done
    dense (the Jacobian, its LU) and condensed to the motions that deflect a mesh
    (``gearjax.bordered_factor``), the latter also with its LU in single precision (what the
    sweep's continuation does), and one Floquet stability evaluation."""
    ds = result.dataset
    system = gj.assemble(train, "first")
    if bool(json.loads(ds.attrs["solver"])["linear"]):
        system = dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))
    print(f"{'K':>4} {'unknowns':>9} {'condensed':>10} {'residual':>9} {'jacobian':>9} "
          f"{'dense LU':>9} {'condensed':>10} {'ratio':>6} {'single':>7} {'stability':>10} "
          f"{'post/pt':>8}"
          f"  (ms, one evaluation; factor + solve of the bordered system, Jacobian included;"
          f" post/pt: responses + stability of 32 points, {gj.threads()} threads)")
    first = {}  # the first segment of each K
    for f_a, f_b, K in result.segments:
        first.setdefault(K, (f_a, f_b))
    for K, (f_a, f_b) in first.items():
        problem = gj.hb_problem(system, gj.HarmonicBalance(n_harmonics=K))
        dense = dataclasses.replace(problem, mesh_null=None)
        i = int(np.argmin(np.abs(ds["mesh_frequency_hz"].values - (f_a + f_b) / 2)))
        omega = jnp.asarray(float(ds["omega"].values[i]))
        y = gj.linear_guess(problem, omega)
        g = gj.omega_derivative(problem, y, omega)
        t = jnp.ones(problem.size + 1) / np.sqrt(problem.size + 1)
        res = jax.jit(gj.hb_residual)
        jac = jax.jit(gj.hb_jacobian)
        bordered = jax.jit(lambda p, y, w, g, t, single: gj.bordered_solve(
            gj.bordered_factor(p, y, w, g, t[:-1], t[-1], single), t), static_argnums=5)
        X = y.reshape(problem.shape) * problem.x_scale
        stab = jax.jit(gj.stability)
        F_static = gj.static_mesh_forces(system)
        post = lambda p, X, w: gj.responses_and_stability(  # noqa: E731
            p, jnp.stack([X] * 32), jnp.full(32, w), np.zeros(32, int), F_static)
        nv = 0 if problem.mesh_null is None else problem.mesh_null.shape[1]
        reduced = (problem.shape[1] - nv) * problem.shape[0]
        t_dense = _best_of(bordered, dense, y, omega, g, t, False)
        t_cond = _best_of(bordered, problem, y, omega, g, t, False)
        t_single = _best_of(bordered, problem, y, omega, g, t, True)
        print(f"{K:>4} {problem.size:>9} {reduced:>10} "
              f"{1e3 * _best_of(res, problem, y, omega):>9.2f} "
              f"{1e3 * _best_of(jac, problem, y, omega):>9.2f} {1e3 * t_dense:>9.2f} "
              f"{1e3 * t_cond:>10.2f} {t_dense / t_cond:>6.2f} {1e3 * t_single:>7.2f} "
              f"{1e3 * _best_of(stab, problem, X, omega, repeat=2):>10.2f} "
              f"{1e3 / 32 * _best_of(post, problem, X, omega, repeat=2):>8.2f}")


_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration",
                   "/jax/core/compile/jaxpr_to_mlir_module_duration",
                   "/jax/core/compile/backend_compile_duration")
_compile_seconds = [0.0]


def _on_event(name, seconds, **_):
    if name in _COMPILE_EVENTS:
        _compile_seconds[0] += seconds


jax.monitoring.register_event_duration_secs_listener(_on_event)


def machine_reference() -> float:
    """Best time (s) of a LAPACK LU of a random dense 1806 x 1806 float64 matrix (the paper
    case's K = 64 system, unfactorised): the issue states its 30 s target on machines
    where this takes about 60-80 ms, so a run can be judged on a slower or faster one."""
    A = jax.random.normal(jax.random.PRNGKey(0), (1806, 1806))
    return _best_of(jax.jit(jax.scipy.linalg.lu_factor), A)


def report(name, first, compile_s, result, lu_s) -> None:
    """Summary of a sweep run twice: ``first`` (compiling, ``compile_s`` of JAX's compile
    events), ``result`` (the second run, compiled: the time after compile). Compile
    events overlap other work (the post-processing compiles in its own thread), so the
    second run's time, not the first's minus compilation, is the time after compile."""
    ds = result.dataset
    P = ds.sizes["point"]
    run = result.seconds
    print(f"\n== {name}: {P} points; first run {first.seconds:.1f} s, compilation (tracing, "
          f"lowering, XLA) {compile_s:.1f} s of it; after compile (second run) {run:.1f} s, "
          f"{1e3 * run / P:.0f} ms per point; stop: {result.stop}")
    if first.dataset.sizes["point"] != P:
        print(f"(the first run had {first.dataset.sizes['point']} points)")
    print(f"machine reference: dense LU of 1806 unknowns {1e3 * lu_s:.1f} ms; after compile "
          f"{run / lu_s:.0f} such LUs ({70e-3 * run / lu_s:.1f} s where one takes 70 ms, the "
          f"middle of the issue's 60-80 ms)")
    print("segments: " + ", ".join(f"{a:.0f}-{b:.0f} Hz K={k}" for a, b, k in result.segments))
    if result.folds_hz:
        print("folds (Hz): " + ", ".join(f"{f:.1f}" for f in result.folds_hz))
    for b in json.loads(ds.attrs.get("bifurcations", "[]")):
        print(f"stability change near {b['mesh_frequency_hz']:.1f} Hz: {b['kind']}")
    stable = ds["stable"].values
    print(f"unstable points: {int(np.sum(stable == 0))} of {P}")
    table(ds)


def table(ds) -> None:
    """Per stage and side, over the points that are not unstable (what a rig can see):
    the peak RMS mesh force and where, the largest separation and back-contact shares,
    and the mean-force check (sum over planets of the mean force / static force - 1)."""
    keep = ds["stable"].values != 0
    rms, f = ds["rms_force"].values[keep], ds["mesh_frequency_hz"].values[keep]
    print(f"{'stage':>6} {'side':>5} {'peak RMS N':>11} {'at Hz':>9} {'max sep':>8} "
          f"{'max back':>9} {'mean/static-1':>14}   ({int(keep.sum())} stable points)")
    for stage in dict.fromkeys(ds["stage"].values.tolist()):
        for side in ("sun", "ring"):
            cols = (ds["stage"].values == stage) & (ds["side"].values == side)
            i = int(np.nanargmax(np.nanmax(rms[:, cols], axis=1)))
            mean = ds["mean_force"].values[keep][:, cols].sum(axis=1)
            static = ds["static_force"].values[cols].sum()
            err = np.nanmax(np.abs(mean / static - 1))
            print(f"{stage:>6} {side:>5} {np.nanmax(rms[:, cols]):>11.1f} {f[i]:>9.1f} "
                  f"{np.nanmax(ds['separation'].values[keep][:, cols]):>8.3f} "
                  f"{np.nanmax(ds['back_contact'].values[keep][:, cols]):>9.3f} {err:>14.2e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="f_from", type=float, default=2000.0)
    ap.add_argument("--to", dest="f_to", type=float, default=15000.0)
    ap.add_argument("--points", type=int, default=300, help="linear sweep grid")
    ap.add_argument("--max-points", type=int, default=3000, help="continuation cap")
    ap.add_argument("--linear-only", action="store_true")
    ap.add_argument("--out-dir", default=".")
    args = ap.parse_args()
    out = pathlib.Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train()
    runs = [("linear", True)] + ([] if args.linear_only else [("backlash", False)])
    lu_s = machine_reference()
    for name, linear in runs:
        compiled = _compile_seconds[0]
        first, result = (gj.sweep(train, "first", args.f_from, args.f_to, linear=linear,
                                  points=args.points, max_points=args.max_points,
                                  progress=gj.progress_printer(sys.stderr)) for _ in range(2))
        report(name, first, _compile_seconds[0] - compiled, result, lu_s)
        breakdown(train, result)
        gj.save_results(result.dataset, out / f"paper_{name}.nc")
        gj.plot_sweep(result.dataset, out / f"paper_{name}.png",
                   title=f"paper first gear, {name}")


if __name__ == "__main__":
    main()
