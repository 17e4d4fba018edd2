"""Batched modal analysis of design variants: one jitted, vmapped call vs a SciPy loop.

Each design scales the eight inertias of the paper's train (first gear) by random
factors in [0.7, 1.3]; the output is every natural frequency. Prints compile time,
the median of repeats, throughput and the ratio against a loop of scipy.linalg.eigh
on the same matrices (assembled beforehand, so the baseline pays for eigen-solves
only), and the largest relative difference between the two.

    python benchmarks/modes_batch.py [--designs 64] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg

import gearjax as gj

PATHS = [(s, k) for s in (0, 1) for k in ("sun", "ring", "carrier", "planet")]


def with_scales(train, scales):
    for (s, k), f in zip(PATHS, scales):
        train = eqx.tree_at(lambda t, s=s, k=k: getattr(t.stages[s].inertia, k), train,
                            getattr(train.stages[s].inertia, k) * f)
    return train


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--designs", type=int, default=64)
    p.add_argument("--repeats", type=int, default=5)
    a = p.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train()
    kin = gj.kinematics(train)
    scales = jnp.asarray(np.random.default_rng(0).uniform(0.7, 1.3, (a.designs, len(PATHS))))

    def hz(scale):
        system = gj.assemble(with_scales(train, scale), kin=kin)
        lam = gj.generalized_eigvals(system.mean_stiffness(), system.M)
        return jnp.sqrt(jnp.clip(lam, 0.0)) / (2 * jnp.pi)

    batched = jax.jit(jax.vmap(hz))
    t0 = time.perf_counter()
    out = batched(scales).block_until_ready()
    compile_s = time.perf_counter() - t0
    runs = []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        batched(scales).block_until_ready()
        runs.append(time.perf_counter() - t0)
    jax_s = statistics.median(runs)

    systems = [gj.assemble(with_scales(train, s), kin=kin) for s in scales]
    mats = [(np.asarray(s.mean_stiffness()), np.asarray(s.M)) for s in systems]
    runs = []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        ref = np.array([scipy.linalg.eigh(K, M, eigvals_only=True) for K, M in mats])
        runs.append(time.perf_counter() - t0)
    scipy_s = statistics.median(runs)
    ref_hz = np.sqrt(np.clip(ref, 0, None)) / (2 * np.pi)
    elastic = ref_hz > 100.0  # the near-rigid mode (~41 Hz) is ill-conditioned in both
    diff = np.max(np.abs(np.asarray(out)[elastic] / ref_hz[elastic] - 1))

    print(f"batched modal analysis, {a.designs} designs x {train.n_dof} DOF "
          f"({jax.devices()[0].platform})")
    print(f"{'method':<34} {'time (ms)':>10} {'designs/s':>12} {'ratio':>8}")
    print(f"{'scipy.linalg.eigh loop (baseline)':<34} {1e3 * scipy_s:>10.2f} "
          f"{a.designs / scipy_s:>12.0f} {1.0:>8.2f}")
    print(f"{'gearjax jit(vmap(assemble+eig))':<34} {1e3 * jax_s:>10.2f} "
          f"{a.designs / jax_s:>12.0f} {scipy_s / jax_s:>8.2f}")
    print(f"compile time {compile_s:.2f} s; max relative difference (modes > 100 Hz) {diff:.1e}")


if __name__ == "__main__":
    main()
