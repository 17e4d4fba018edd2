"""Newton at a fixed frequency with the condensed LU and with matrix-free BiCGStab
(``HarmonicBalance.linear_solver``), against the number of unknowns.

For each size: one Newton solve of the harmonic balance from the linear, in-contact
guess (``solve_hb``) with each linear solver, compiled first (compile time apart), then
the median of repeats, LU and Krylov interleaved; the BiCGStab steps of one solve with
the Jacobian at the converged point; the two solutions' largest difference; what the
default (``"auto"``) chooses for Newton (``gearjax.uses_krylov``). The growth
exponent of the time per solve against the unknowns is fitted over the sizes each
solver ran (least squares in log-log).

Cases: the paper's first gear (examples/al_shyyab_2009.toml, 0.05 mm backlash, four
stiffness harmonics) at stage-1 mesh frequency 4.2 kHz with K from 32 to ``--max-K``
(LU up to ``--max-lu-K``); ``--torus``: tests/data/two_stage_14_17.toml (two frequency
groups) at 3 kHz, orders (8, 8) to (64, 32).

    python benchmarks/linear_solves.py [--max-K 1024] [--max-lu-K 256] [--torus] [--repeats 3]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import time
import warnings

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import lineax as lx  # noqa: E402
import numpy as np  # noqa: E402

import gearjax as gj  # noqa: E402

DATA = pathlib.Path(__file__).resolve().parents[1] / "tests" / "data"


def _solve(problem, omega):
    sol = gj.solve_hb(problem, omega)
    return sol.X, sol.result, sol.stats["num_steps"]


_solve_jit = jax.jit(_solve)


def _timed(problem, omega):
    """``(seconds, (X, result, steps))`` of one compiled call."""
    t = time.perf_counter()
    out = _solve_jit(problem, omega)
    jax.block_until_ready(out)
    return time.perf_counter() - t, out


@jax.jit
def _bicgstab_steps(problem, y, omega, b):
    sol = lx.linear_solve(gj.HBJacobian(problem, y, omega), b, gj.KrylovHB(), throw=False)
    return sol.stats["num_steps"]


def measure(system, K, f_hz, with_lu: bool, repeats: int) -> dict:
    """One size: compile and run times of Newton with each solver, BiCGStab steps."""
    omega = jnp.asarray(2 * np.pi * f_hz / system.mesh_mu[0])
    problems = {s: gj.hb_problem(system, gj.harmonics_settings(system, K, linear_solver=s))
                for s in (("lu", "krylov") if with_lu else ("krylov",))}
    problem = problems["krylov"]
    C, n = problem.shape
    r = n - (0 if problem.mesh_null is None else problem.mesh_null.shape[1])
    auto = gj.hb_problem(system, gj.harmonics_settings(system, K))
    row = {"K": str(K), "N": problem.size, "N_lu": C * r,
           "auto": "krylov" if gj.uses_krylov(auto) else "lu"}
    first, out = {}, {}
    for s, p in problems.items():
        first[s], out[s] = _timed(p, omega)
    times = {s: [] for s in problems}
    for _ in range(repeats):  # interleaved
        for s, p in problems.items():
            times[s].append(_timed(p, omega)[0])
    for s in problems:
        row[f"t_{s}"] = statistics.median(times[s])
        row[f"compile_{s}"] = max(first[s] - row[f"t_{s}"], 0.0)
        row[f"ok_{s}"] = bool(out[s][1] == gj.RESULTS.successful)
        row[f"newton_{s}"] = int(out[s][2])
    X = out["krylov"][0]
    y = (X / problems["krylov"].x_scale).reshape(-1)
    b = jnp.asarray(np.random.default_rng(0).normal(size=y.size))
    row["bicgstab"] = int(_bicgstab_steps(problems["krylov"], y, omega, b))
    if with_lu:
        row["diff"] = float(jnp.max(jnp.abs(X - out["lu"][0])) / jnp.max(jnp.abs(out["lu"][0])))
    return row


def exponent(rows, key) -> float:
    pts = [(r["N"], r[key]) for r in rows if key in r]
    if len(pts) < 2:
        return float("nan")
    n, t = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(n, t, 1)[0])


def table(title, rows):
    print(f"\n{title}")
    print(f"{'K':>10} {'N':>7} {'N LU':>7} {'auto':>6} {'LU s':>8} {'Krylov s':>9} "
          f"{'LU/Kr':>6} {'Newton':>7} {'BiCGStab':>8} {'compile LU':>10} {'compile Kr':>10} "
          f"{'diff':>8}")
    for r in rows:
        lu = f"{r['t_lu']:8.3f}" if "t_lu" in r else f"{'-':>8}"
        ratio = f"{r['t_lu'] / r['t_krylov']:6.1f}" if "t_lu" in r else f"{'-':>6}"
        clu = f"{r['compile_lu']:10.1f}" if "t_lu" in r else f"{'-':>10}"
        newton = f"{r.get('newton_lu', '-')}/{r['newton_krylov']}"
        ok = "" if r["ok_krylov"] and r.get("ok_lu", True) else " (not converged)"
        diff = f"{r['diff']:8.1e}" if "diff" in r else f"{'-':>8}"
        print(f"{r['K']:>10} {r['N']:7d} {r['N_lu']:7d} {r['auto']:>6} {lu} {r['t_krylov']:9.3f} "
              f"{ratio} {newton:>7} {r['bicgstab']:8d} {clu} {r['compile_krylov']:10.1f} "
              f"{diff}{ok}")
    print(f"growth exponent of the time per Newton solve against N: LU "
          f"{exponent(rows, 't_lu'):.2f}, Krylov {exponent(rows, 't_krylov'):.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-K", type=int, default=1024)
    ap.add_argument("--max-lu-K", type=int, default=256)
    ap.add_argument("--torus", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"jax {jax.__version__}, {jax.devices()[0].device_kind}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        paper = gj.assemble(gj.load_train())
    rows = []
    K = 32
    while K <= args.max_K:
        rows.append(measure(paper, K, 4200.0, K <= args.max_lu_K, args.repeats))
        print(f"  paper K = {K}: done", flush=True)
        K *= 2
    table("Paper first gear, 4.2 kHz, 0.05 mm backlash: one Newton solve (median seconds)",
          rows)
    if args.torus:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", gj.GeometryWarning)
            train = gj.load_train(DATA / "two_stage_14_17.toml")
        system = gj.gear_case(train, torus=True).system
        rows = []
        for K in ((8, 8), (16, 16), (32, 16), (64, 32)):
            rows.append(measure(system, K, 3000.0, K <= (16, 16), args.repeats))
            print(f"  torus K = {K}: done", flush=True)
        table("Two frequency groups (14 : 17), 3 kHz: one Newton solve (median seconds)", rows)


if __name__ == "__main__":
    main()
