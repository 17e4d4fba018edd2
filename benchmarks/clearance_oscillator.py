"""One-degree-of-freedom clearance oscillator: compiled HB continuation vs a SciPy sweep.

    x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(Omega t),   unit stiffness, half clearance 1,

continued in Omega from 0.5 to 1.5, starting on the contact (linear) solution and
passing both folds (near 0.852 and 0.6365). The whole continuation runs as one
compiled ``lax.while_loop``. Baseline in the same run: ``scipy.integrate.solve_ivp``
(RK45, rtol 1e-8) up and down sweeps, each point continued from the previous end
state, 40 periods to settle and one to measure.

    python benchmarks/clearance_oscillator.py [--repeats 3] [--ivp-points 101]
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate

import gearjax as gj


def oscillator():
    return gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                                   f_mean=[0.1], f_cos=[[0.03]], f_sin=[[0.0]], forcing_mu=[1])


def hb_sweep(K: int, T: int, repeats: int, own_jit: bool = True):
    """The continuation from 0.5 to 1.5: ``own_jit``, the caller's ``jax.jit`` around
    gearjax's solve and continuation (traced and lowered in every process); else
    gearjax's compiled calls themselves (their programs kept between processes)."""
    problem = gj.hb_problem(oscillator(), gj.HarmonicBalance(n_harmonics=K, n_time=T))
    param = gj.FrequencyParameter(problem=problem, omega_ref=jnp.asarray(1.0))
    settings = gj.ContinuationSettings(step=0.05, max_step=0.3, max_dlambda=0.02)

    if own_jit:
        @jax.jit
        def run(omega0):
            y0 = gj.solve_hb(problem, omega0).y
            return gj.continue_compiled(param, y0, omega0, 1.5, settings, 400)
    else:
        def run(omega0):
            y0 = gj.solve_hb_points(problem, jnp.asarray([omega0])).y[0]
            return gj.continue_compiled(param, y0, omega0, 1.5, settings, 400)

    t0 = time.perf_counter()
    out = jax.block_until_ready(run(0.5))
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(run(0.5))
        times.append(time.perf_counter() - t0)
    branch = out.trimmed()
    n = branch.n_points
    X = branch.y.reshape(n, 2 * K + 1, 1) * np.asarray(problem.x_scale)
    x = np.asarray(jax.vmap(lambda c: gj.aft_synthesis(c, T))(jnp.asarray(X)))[..., 0]
    amplitude = (x.max(1) - x.min(1)) / 2
    return {
        "points": n,
        "stop": gj.result_word(branch.result),
        "folds": gj.distinct_folds(branch.fold_lam[branch.fold]),
        "max_amp": float(amplitude.max()),
        "compile_s": compile_s,
        "ms_per_point": 1e3 * statistics.median(times) / n,
    }


def ivp_sweep(omegas: np.ndarray, settle: int = 40):
    def rhs(t, z, w):
        x, v = z
        g = x - np.clip(x, -1.0, 1.0)
        return [v, 0.1 + 0.03 * np.cos(w * t) - 0.1 * v - g]

    z = np.array([1.1, 0.0])  # contact equilibrium
    amps = []
    for w in omegas:
        period = 2 * np.pi / w
        sol = scipy.integrate.solve_ivp(rhs, (0, settle * period), z, args=(w,), rtol=1e-8,
                                        atol=1e-10)
        z = sol.y[:, -1]
        last = scipy.integrate.solve_ivp(rhs, (0, period), z, args=(w,), rtol=1e-8, atol=1e-10,
                                         t_eval=np.linspace(0, period, 400))
        z = last.y[:, -1]
        amps.append((last.y[0].max() - last.y[0].min()) / 2)
    return np.array(amps)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--ivp-points", type=int, default=101)
    a = p.parse_args()
    print("clearance oscillator x'' + 0.1x' + g(x) = 0.1 + 0.03 cos(Omega t), Omega 0.5 -> 1.5")
    print(f"{'method':<28} {'points':>6} {'folds':>18} {'max amp':>8} {'compile s':>9} "
          f"{'ms/point':>9}")
    rows = {}
    for K, T in ((15, 256), (20, 512)):
        r = hb_sweep(K, T, a.repeats)
        rows[K] = r
        folds = ", ".join(f"{f:.4f}" for f in r["folds"])
        label = f"HB K={K} T={T} ({r['stop']})"
        print(f"{label:<28} {r['points']:>6} {folds:>18} "
              f"{r['max_amp']:>8.4f} {r['compile_s']:>9.2f} {r['ms_per_point']:>9.3f}")
    omegas = np.linspace(0.5, 1.5, a.ivp_points)
    t0 = time.perf_counter()
    up = ivp_sweep(omegas)
    down = ivp_sweep(omegas[::-1])[::-1]
    ivp_s = time.perf_counter() - t0
    ms = 1e3 * ivp_s / (2 * len(omegas))
    differ = omegas[np.abs(up - down) > 0.05]
    band = f"{differ.min():.3f}-{differ.max():.3f}" if differ.size else "none"
    print(f"{'solve_ivp up+down sweep':<28} {2 * len(omegas):>6} {'branches ' + band:>18} "
          f"{max(up.max(), down.max()):>8.4f} {'-':>9} {ms:>9.3f}")
    for K, r in rows.items():
        print(f"speed-up HB K={K} vs solve_ivp per point: {ms / r['ms_per_point']:.0f}x")


if __name__ == "__main__":
    main()
