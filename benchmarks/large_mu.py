"""A periodic train with large mu: the torus balance against the periodic balance at
K = H max(mu) and against the periodic time integration.

The paper's topology with stage 2 teeth 43/19/81: stage mesh frequencies in the ratio
81/70, so one common base needs mu = (70, 81) and a periodic balance that holds the 4
stiffness harmonics of both stages needs K = H max(mu) = 324 harmonics of it (6491
unknowns in the condensed factorisation). The torus balance solves the same train on
two angles, one per stage (``gj.gear_case(train, torus=True)``), with orders from the
sweep's first-choice rule (``gj.torus_orders_rule``: (8, 8) at 2 kHz down to (4, 4)).

At each stage-1 mesh frequency, linear (backlash removed) and with the file's 0.05 mm
half backlash:

- torus: Newton from the linear guess, the mesh responses on the line ``theta = (1,
  81/70) Omega t`` (the torus series mapped onto harmonics ``j = 70 k_1 + 81 k_2`` of the
  common base, evaluated over one period of it) and as torus averages, and the
  Floquet verdict (``gj.stability``);
- periodic: Newton at K = 324 (``--harmonics``) from the linear guess (with backlash,
  where that fails, from the torus solution restricted to the line, truncated to K);
  its mesh responses;
- time integration: ``gj.simulate`` of the periodic system from the periodic balance's
  state at t = 0 until the mesh deflections repeat after one period (1e-6), 8192
  samples of the last period.

Printed per point and model: the torus orders and time (solve, then the Floquet verdict),
the periodic Newton steps and time, the integration's periods and time, and the largest
relative difference over the meshes of the RMS alternating force (and of the mean force)
between the three, with the torus verdict and the largest separation share. Times are
after compilation (a first point at each shape is run and discarded for the torus and
the periodic balance; the integration's compile time is printed on its own).

    nice python benchmarks/large_mu.py [--khz 3 5 7.5 11] [--harmonics 324]
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import gearjax as gj

def train_81():
    """The bundled paper train with stage 2 teeth 43/19/81 (instead of 44/18/80)."""
    text = gj.bundled_example_path().read_text()
    old = "teeth = { sun = 44, planet = 18, ring = 80 }"
    assert old in text
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.loads_train(text.replace(old, "teeth = { sun = 43, planet = 19, ring = 81 }"),
                              source="al_shyyab_2009 with stage 2 teeth 43/19/81")


def linear_case(case):
    """The case with its backlash removed (a new ``System``, same everything else)."""
    system = dataclasses.replace(case.system, backlash=jnp.zeros_like(case.system.backlash))
    return dataclasses.replace(case, system=system, linear=True)


def on_line(basis, X, mu, K):
    """Torus coefficients ``X`` restricted to the line ``theta = (mu_0, mu_1) tau`` as ``2K+1``
    coefficients of harmonics of ``tau`` (wave vector ``k`` is harmonic ``k . mu``; a
    negative one flips its sine); harmonics above ``K`` are dropped, and their share of the
    mean square returned with the coefficients."""
    X = np.asarray(X)
    out = np.zeros((2 * K + 1, X.shape[1]))
    out[0] = X[0]
    dropped = 0.0
    for i, j in enumerate(np.asarray(basis.orders) @ np.asarray(mu)):
        a, b = X[2 * i + 1], X[2 * i + 2]
        if j == 0:
            out[0] += a
        elif abs(j) > K:
            dropped += float(np.sum(a**2 + b**2))
        else:
            out[2 * abs(j) - 1] += a
            out[2 * abs(j)] += np.sign(j) * b
    total = float(np.sum(X[1:] ** 2))
    return out, dropped / max(total, 1e-300)


def largest_relative(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def timed(fn):
    t = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - t


def run(khz, K_periodic, n_samples):
    train = train_81()
    torus_case = gj.gear_case(train, torus=True)
    periodic_case = gj.gear_case(train, torus=False)
    mu = tuple(int(m) for m in periodic_case.mu)
    H = periodic_case.system.k_cos.shape[-1]
    print(f"train: stage mesh frequencies mu = {mu} of a common base; H = {H}; "
          f"H max(mu) = {H * max(mu)}; torus angles {torus_case.system.angle_ratio}")
    r = int(np.linalg.matrix_rank(np.asarray(periodic_case.system.W)))
    N = (2 * K_periodic + 1) * r + 1
    print(f"periodic balance at K = {K_periodic}: {N} unknowns in the condensed "
          f"factorisation ({(2 * K_periodic + 1)} coefficient rows x {r} motions that deflect "
          f"a mesh), {8 * N * N / 1e9:.2f} GB a dense copy")
    cutoff = gj.response_cutoff_hz(torus_case.system)
    stability = jax.jit(gj.stability)
    newton = jax.jit(gj.hb_newton)
    settings = gj.TimeDomain(n_samples=n_samples, max_periods=60)
    rows = []
    warm = set()
    for linear in (True, False):
        tc = linear_case(torus_case) if linear else torus_case
        pc = linear_case(periodic_case) if linear else periodic_case
        pp = gj.hb_problem(pc.system, gj.HarmonicBalance(n_harmonics=K_periodic))
        F_static = jnp.asarray(pc.F_static)
        for f in khz:
            f_hz = 1e3 * f
            w_t, w_p = float(tc.omega(f_hz)), float(pc.omega(f_hz))
            K = gj.torus_orders_rule(tc.system, w_t, cutoff_hz=cutoff)
            tp = gj.hb_problem(tc.system, gj.harmonics_settings(tc.system, K))
            w = jnp.asarray(w_t)

            def torus_solve():
                return newton(tp, w, gj.linear_guess(tp, w))

            if ("torus", K) not in warm:  # compile
                jax.block_until_ready(torus_solve())
                jax.block_until_ready(stability(tp, torus_solve().X, w))
                warm.add(("torus", K))
            sol_t, t_torus = timed(torus_solve)
            st, t_stab = timed(lambda: stability(tp, sol_t.X, w))
            ok_t = bool(sol_t.result == gj.RESULTS.successful)
            # the torus on the line: harmonics of the common base up to the highest j
            j_max = int(np.max(np.abs(np.asarray(tp.basis.orders) @ np.asarray(mu))))
            K_line = max(j_max, K_periodic)
            line_problem = gj.hb_problem(pc.system, gj.HarmonicBalance(n_harmonics=K_line))
            X_line, _ = on_line(tp.basis, sol_t.X, mu, K_line)
            r_line = gj.mesh_responses(line_problem, jnp.asarray(X_line), jnp.asarray(w_p),
                                       F_static)
            r_avg = gj.mesh_responses(tp, sol_t.X, w, F_static)
            X_start, dropped = on_line(tp.basis, sol_t.X, mu, K_periodic)

            wp = jnp.asarray(w_p)
            if "periodic" not in warm:
                jax.block_until_ready(newton(pp, wp, gj.linear_guess(pp, wp)))
                warm.add("periodic")
            sol_p, t_periodic = timed(lambda: newton(pp, wp, gj.linear_guess(pp, wp)))
            start = "linear guess"
            if not bool(sol_p.result == gj.RESULTS.successful):
                y0 = jnp.asarray(X_start / np.asarray(pp.x_scale)).reshape(-1)
                sol_p, t2 = timed(lambda: newton(pp, wp, y0))
                t_periodic += t2
                start = "torus start"
            ok_p = bool(sol_p.result == gj.RESULTS.successful)
            r_p = gj.mesh_responses(pp, sol_p.X, wp, F_static)

            x0, v0 = gj.hb_initial_state(sol_p.X, wp)
            if "simulate" not in warm:
                t = time.perf_counter()
                gj.compile_simulate_points(pc.system, wp[None], x0=x0, v0=v0, settings=settings)
                print(f"(integration compiled in {time.perf_counter() - t:.1f} s)")
                warm.add("simulate")
            tr, t_sim = timed(lambda: gj.simulate_points(pc.system, wp[None], x0=x0, v0=v0,
                                                         settings=settings))
            r_td = gj.responses_from_samples(tr.p[0], tr.F[0], pc.system.backlash, F_static,
                                             pc.system.mesh_radius)
            rows.append(dict(
                f=f, model="linear" if linear else "backlash", K=K, ok_t=ok_t,
                t_torus=t_torus, t_stab=t_stab, stable=bool(st.stable),
                max_abs=float(st.max_abs), steps_p=int(sol_p.stats["num_steps"]), ok_p=ok_p,
                start=start, t_periodic=t_periodic, periods=int(tr.periods[0]),
                periodic=bool(tr.periodic[0]), t_sim=t_sim, dropped=dropped, j_max=j_max,
                sep=float(np.max(r_line.separation)),
                line_p=largest_relative(r_line.rms_force, r_p.rms_force),
                line_td=largest_relative(r_line.rms_force, r_td.rms_force),
                p_td=largest_relative(r_p.rms_force, r_td.rms_force),
                avg_line=largest_relative(r_avg.rms_force, r_line.rms_force),
                mean_line_td=largest_relative(r_line.mean_force, r_td.mean_force),
                mean_p_td=largest_relative(r_p.mean_force, r_td.mean_force)))
            print_row(rows[-1], header=len(rows) == 1)
    return rows


def print_row(r, header=False):
    if header:
        print("\n| f1 kHz | model | torus K | torus s (solve + Floquet) | verdict |"
              " periodic K=324 s (Newton steps) | integration s (periods) | separation |"
              " RMS torus-line vs periodic | torus-line vs integration | periodic vs"
              " integration | mean torus-line vs integration | torus average vs line |"
              " torus power above K |")
        print("|---" * 14 + "|")
    verdict = f"{'stable' if r['stable'] else 'UNSTABLE'} {r['max_abs']:.4f}"
    flags = ("" if r["ok_t"] else " torus FAILED") + ("" if r["ok_p"] else " periodic FAILED") + (
        "" if r["periodic"] else " integration NOT PERIODIC")
    print(f"| {r['f']:g} | {r['model']}{flags} | {r['K']} | {r['t_torus']:.2f} + "
          f"{r['t_stab']:.2f} | {verdict} | {r['t_periodic']:.1f} ({r['steps_p']}, "
          f"{r['start']}) | {r['t_sim']:.1f} ({r['periods']}) | {r['sep']:.3f} | "
          f"{r['line_p']:.2e} | {r['line_td']:.2e} | {r['p_td']:.2e} | "
          f"{r['mean_line_td']:.2e} | {r['avg_line']:.2e} | {r['dropped']:.1e} |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--khz", type=float, nargs="+", default=[3.0, 5.0, 7.5, 11.0],
                        help="stage-1 mesh frequencies (kHz)")
    parser.add_argument("--harmonics", type=int, default=324,
                        help="K of the periodic balance (default H max(mu) = 324)")
    parser.add_argument("--samples", type=int, default=8192,
                        help="samples of the integration's last period")
    args = parser.parse_args()
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        run(args.khz, args.harmonics, args.samples)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\ntotal {time.perf_counter() - t:.0f} s; peak resident memory {peak:.0f} MB")


if __name__ == "__main__":
    main()
