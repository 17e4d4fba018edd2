"""Sweeps of trains whose stage mesh frequencies share no small common base: the
multi-frequency (torus) harmonic balance.

``--case g2`` (default): the paper's topology with stage 2 re-toothed 43/19/81
(tests/data/two_stage_43_19_81.toml; mesh frequencies 70 : 81, two frequency groups),
0.05 mm backlash, 2-15 kHz of stage-1 mesh frequency. The sweep runs twice (the first
compiles; the second is the time after compilation) and prints points, times, orders
per segment, folds, unstable points and the peak RMS force per stage and side. Then, at
a handful of frequencies, the cost of one point beside the single-base periodic balance
of the same train at ``K = H max(mu)`` (the fewest harmonics of the common base that hold
the excitation: 324, one factorisation of 9,000 unknowns; linear, so that one Newton step
solves it and both solutions can be compared), and beside a SciPy integration (DOP853, the
fastest of SciPy's methods here) over as many base periods as gearjax's windowed
integration needs for consecutive windows to agree.

``--case g3``: tests/data/three_stage_incommensurate.toml, three stages and three
frequency groups (a 3-torus), 0.05 mm backlash, a band of stage-A mesh frequency
(default 2-4.4 kHz, the lower of the 2-8 kHz band's two segments of orders: above
4.46 kHz the checks ask for orders of about 10,000 unknowns a factorisation), at least
``--min-points`` points: time and peak memory (the process's largest resident set).

    python benchmarks/torus_sweep.py [--case g2|g3] [--from HZ --to HZ] [--skip-periodic]
        [--skip-scipy] [--once] [--no-complete] [--out-dir DIR]

``--once``: one sweep, not two (a long G = 3 run): its time includes compilation.
``--no-complete``: the walk alone (``complete=False``), without the completion's search
for the stable states the walk did not trace.

Every number comes from this run on this machine; the ratios compare quantities measured
in the same run.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import resource
import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import gearjax as gj

DATA = pathlib.Path(__file__).resolve().parents[1] / "tests" / "data"
TRAINS = {"g2": DATA / "two_stage_43_19_81.toml", "g3": DATA / "three_stage_incommensurate.toml"}
BANDS = {"g2": (2000.0, 15000.0), "g3": (2000.0, 4400.0)}

_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration",
                   "/jax/core/compile/jaxpr_to_mlir_module_duration",
                   "/jax/core/compile/backend_compile_duration")
_compile_seconds = [0.0]


def _on_event(name, seconds, **_):
    if name in _COMPILE_EVENTS:
        _compile_seconds[0] += seconds


jax.monitoring.register_event_duration_secs_listener(_on_event)


def load(case: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.load_train(TRAINS[case])


def report(name, first, compile_s, result) -> None:
    ds = result.dataset
    P = ds.sizes["point"]
    solver = json.loads(ds.attrs["solver"])
    torus = solver.get("torus") or {}
    second = ("(one run only)" if result is first else
              f"after compile (second run) {result.seconds:.1f} s, "
              f"{1e3 * result.seconds / P:.0f} ms per point")
    print(f"\n== {name}: {P} points; first run {first.seconds:.1f} s (compilation: tracing, "
          f"lowering, XLA {compile_s:.1f} s of it); {second}; stop: {result.stop}")
    print(f"torus: G = {torus.get('G')}, angle ratios {torus.get('angle_ratio_exact')}, "
          f"{torus.get('truncation')} sets; stability over {torus.get('return_turns')} turns "
          f"(drift {torus.get('return_drift', 0):.3f})")
    print("segments: " + ", ".join(f"{a:.0f}-{b:.0f} Hz K={tuple(k)}" for a, b, k in
                                   solver["segments"]))
    print("truncation estimates: " + ", ".join(
        f"{e['K']}->{e['K_check']}: {e['change']:.1e}" for e in solver["truncation"]
        if e.get("change") is not None))
    if result.folds_hz:
        print(f"folds: {len(result.folds_hz)} (" + ", ".join(f"{f:.0f}" for f in
                                                          sorted(result.folds_hz)) + " Hz)")
    stable = ds["stable"].values
    print(f"unstable points: {int(np.sum(stable == 0))} of {P}; restarts: "
          f"{len(result.restarts)}; coexisting stable states over "
          f"{[(round(a), round(b)) for a, b in gj.coexisting_bands(ds)]} Hz")
    keep = stable == 1
    rms, f = ds["rms_force"].values[keep], ds["mesh_frequency_hz"].values[keep]
    print(f"{'stage':>6} {'side':>5} {'peak RMS N':>11} {'at Hz':>9} {'max sep':>8}")
    for stage in dict.fromkeys(ds["stage"].values.tolist()):
        for side in ("sun", "ring"):
            cols = (ds["stage"].values == stage) & (ds["side"].values == side)
            i = int(np.nanargmax(np.nanmax(rms[:, cols], axis=1)))
            print(f"{stage:>6} {side:>5} {np.nanmax(rms[:, cols]):>11.1f} {f[i]:>9.1f} "
                  f"{np.nanmax(ds['separation'].values[keep][:, cols]):>8.3f}")


def sweep_twice(train, f_from, f_to, min_points, once=False, complete=True):
    """The sweep run twice (``once``: one run, whose time includes compilation;
    ``complete``: the sweep's completion after the walk, as by default):
    ``(first, compile seconds of the first, second)``."""
    compiled = _compile_seconds[0]
    kw = dict(complete=complete)
    first = gj.sweep(train, None, f_from, f_to, progress=gj.progress_printer(sys.stderr),
                     **kw)
    compile_s = _compile_seconds[0] - compiled
    if first.dataset.sizes["point"] < min_points:
        print(f"(fewer than {min_points} points: steps of at most "
              f"{(f_to - f_from) / min_points:.1f} Hz)")
        kw["max_step_hz"] = (f_to - f_from) / min_points
        first = gj.sweep(train, None, f_from, f_to, progress=gj.progress_printer(sys.stderr),
                         **kw)
    if once:
        return first, compile_s, first
    result = gj.sweep(train, None, f_from, f_to, progress=gj.progress_printer(sys.stderr), **kw)
    return first, compile_s, result


# --------------------------------------------------------- one point, three ways


def _best(fn, repeat=3):
    jax.block_until_ready(fn())
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return min(times), out


def per_point(train, freqs) -> None:
    """Linear points: the torus balance (orders of the sweep's rule) beside the periodic
    balance of the common base at K = H max(mu), one warm solve each, and their largest
    RMS mesh forces."""
    torus = gj.gear_case(train, linear=True, torus=True)
    periodic = gj.gear_case(train, linear=True, torus=False)
    K_p = gj.excitation_floor(periodic.system)
    print(f"\n== one linear point: torus balance beside the periodic balance of the common "
          f"base (mu = {list(periodic.mu)}, K = H max(mu) = {K_p})")
    print(f"{'Hz':>7} {'torus K':>9} {'unknowns':>9} {'time s':>8} {'periodic unknowns':>18} "
          f"{'time s':>8} {'ratio':>7} {'max RMS torus N':>16} {'rel diff':>9}")
    cutoff = gj.response_cutoff_hz(torus.system)
    F_t = jnp.asarray(torus.F_static)
    P_p = gj.hb_problem(periodic.system, gj.HarmonicBalance(n_harmonics=K_p))
    solve = jax.jit(gj.solve_hb_linear)
    for f in freqs:
        K_t = gj.torus_orders_rule(torus.system, torus.omega(f), cutoff_hz=cutoff)
        P_t = gj.hb_problem(torus.system, gj.harmonics_settings(torus.system, K_t))
        t_t, sol_t = _best(lambda: solve(P_t, jnp.asarray(torus.omega(f)))) # noqa: B023
        t_p, sol_p = _best(lambda: solve(P_p, jnp.asarray(periodic.omega(f))), repeat=1)  # noqa: B023
        r_t = np.asarray(gj.mesh_responses(P_t, sol_t.X, torus.omega(f), F_t).rms_force)
        r_p = np.asarray(gj.mesh_responses(P_p, sol_p.X, periodic.omega(f),
                                           jnp.asarray(periodic.F_static)).rms_force)
        print(f"{f:>7.0f} {str(K_t):>9} {P_t.size:>9} {t_t:>8.3f} {P_p.size:>18} {t_p:>8.2f} "
              f"{t_p / t_t:>7.0f} {r_t.max():>16.1f} "
              f"{np.max(np.abs(r_t - r_p)) / r_p.max():>9.1e}")


def scipy_windows(train, f_hz, periods: int = 20) -> None:
    """A plain SciPy integration (``solve_ivp``, DOP853, the fastest of SciPy's methods on
    this train: LSODA, BDF and Radau take 3-15 times longer) of the same equations,
    timed over ``periods`` base periods and scaled to the base periods gearjax's windowed
    integration needs to reach agreeing windows (diffrax, timed in full); the torus
    balance of the same point beside them."""
    from scipy.integrate import solve_ivp

    case = gj.gear_case(train, torus=True)
    s = case.system
    omega = case.omega(f_hz)
    M, C, K = (np.asarray(a) for a in (s.M, s.C, s.K))
    Minv = np.linalg.inv(M)
    W, kbar, b, c = (np.asarray(a) for a in (s.W, s.kbar, s.backlash, s.damping))
    k_cos, k_sin = np.asarray(s.k_cos), np.asarray(s.k_sin)
    rates = np.asarray(s.mesh_rates()) * omega
    h = np.arange(1, k_cos.shape[1] + 1)
    f_mean = np.asarray(s.f_mean)
    n = s.n_dof

    def force(t, x, v):
        arg = rates[:, None] * h[None, :] * t
        kappa = 1 + np.sum(k_cos * np.cos(arg) + k_sin * np.sin(arg), axis=1)
        p, dp = W @ x, W @ v
        g = np.where(p > b, p - b, np.where(p < -b, p + b, 0.0))
        return kbar * kappa * g + c * dp

    def rhs(t, z):
        x, v = z[:n], z[n:]
        return np.concatenate([v, Minv @ (f_mean - C @ v - K @ x - W.T @ force(t, x, v))])

    x0, v0 = (np.asarray(a) for a in gj.contact_state(s))
    start = time.perf_counter()
    solve_ivp(rhs, (0.0, periods * 2 * math.pi / omega), np.concatenate([x0, v0]),
              method="DOP853", rtol=1e-8, atol=1e-12)
    per_period = (time.perf_counter() - start) / periods
    t_dfx, out = _best(lambda: gj.simulate_windowed(s, omega), repeat=1)
    needed = int(out.windows) * out.plan.periods
    K = gj.torus_orders_rule(s, omega, cutoff_hz=gj.response_cutoff_hz(s))
    problem = gj.hb_problem(s, gj.harmonics_settings(s, K))
    newton = jax.jit(gj.solve_hb)
    t_hb, _ = _best(lambda: newton(problem, jnp.asarray(omega)))
    print(f"\n== windowed statistics at {f_hz:.0f} Hz: gearjax's windowed integration "
          f"(diffrax Dopri8) {int(out.windows)} windows of {out.plan.periods} base periods "
          f"({gj.result_word(out.result)}) in {t_dfx:.0f} s; SciPy DOP853 "
          f"{per_period:.2f} s a base period, {needed * per_period:.0f} s for the same "
          f"{needed} periods (from {periods} timed); the torus balance (Newton from the "
          f"linear guess, orders {K}) {1e3 * t_hb:.0f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=("g2", "g3"), default="g2")
    ap.add_argument("--from", dest="f_from", type=float)
    ap.add_argument("--to", dest="f_to", type=float)
    ap.add_argument("--min-points", type=int, default=None)
    ap.add_argument("--once", action="store_true",
                    help="one sweep (its time includes compilation), not two")
    ap.add_argument("--no-complete", action="store_true",
                    help="the walk alone, without the completion's search for other "
                         "stable states")
    ap.add_argument("--skip-periodic", action="store_true")
    ap.add_argument("--skip-scipy", action="store_true")
    ap.add_argument("--out-dir", default=".")
    args = ap.parse_args()
    out = pathlib.Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    train = load(args.case)
    lo, hi = BANDS[args.case]
    f_from, f_to = args.f_from or lo, args.f_to or hi
    min_points = args.min_points or (300 if args.case == "g2" else 100)
    print(f"{args.case}: {TRAINS[args.case].name}, {gj.threads()} threads, jax "
          f"{jax.__version__} on {jax.devices()[0].platform}")
    first, compile_s, result = sweep_twice(train, f_from, f_to, min_points, args.once,
                                           complete=not args.no_complete)
    report(f"{args.case} sweep {f_from:.0f}-{f_to:.0f} Hz, 0.05 mm backlash", first, compile_s,
           result)
    gj.save_results(result.dataset, out / f"torus_{args.case}.nc")
    gj.plot_sweep(result.dataset, out / f"torus_{args.case}.png",
                  title=f"{TRAINS[args.case].stem}, backlash 0.05 mm (torus balance)")
    if args.case == "g2" and not args.skip_periodic:
        per_point(train, [2500.0, 5000.0, 10000.0])
    if args.case == "g2" and not args.skip_scipy:
        scipy_windows(train, 5000.0)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory of this process: {peak:.0f} MB")


if __name__ == "__main__":
    main()
