"""Batched design sweeps: one jitted, vmapped call over a batch of designs vs a Python loop.

Each design is an admissible planet set of the paper train's stage 1 (first gear) with
a sun-ring phase per stage; each design sweep is the linear, time-varying harmonic
balance (``gearjax.design_sweep``) at ``--frequencies`` reference-stage mesh frequencies
from 2 to 15 kHz, RMS mesh force of every mesh. Both methods run the same compiled
point solve; the loop calls the compiled one-design function once per design (the
way a script without batching would). Prints compile time, the median of
``--repeats`` runs, design sweeps per minute and the ratio, and the largest relative
difference between the two. Runs on whatever JAX uses by default (CPU, or a GPU
when one is present; nothing here needs one); ``--shard`` also spreads the batch over
every device (:func:`gearjax.batched_rms`).

    python benchmarks/design_batch.py [--designs 32] [--frequencies 8] [--harmonics K]

``--harmonics`` defaults to the fewest that hold the train's stiffness excitation
(:func:`gearjax.excitation_floor`, 32 for the paper's first gear).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import gearjax as gj

PATHS = ("1.planet_angles_deg.2", "1.planet_angles_deg.3", "1.planet_angles_deg.4",
         "1.sun_ring_phase_deg", "2.sun_ring_phase_deg")


def timed(fn, repeats):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        runs.append(time.perf_counter() - t0)
    return out, first, statistics.median(runs)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--designs", type=int, default=32)
    p.add_argument("--frequencies", type=int, default=8)
    p.add_argument("--harmonics", type=int, default=None)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--shard", action="store_true", help="also shard over every device")
    a = p.parse_args()
    jax.config.update("jax_enable_x64", True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train()
    rng = np.random.default_rng(0)
    sets = gj.admissible_planet_sets(train.stage("1"))
    pick = sets[rng.choice(len(sets), a.designs, replace=False)]
    thetas = np.column_stack([pick[:, 1:], rng.uniform(0, 360, (a.designs, 2))])
    family = gj.GearFamily.of(train, PATHS, "first", linear=True)
    if a.harmonics is None:
        a.harmonics = gj.excitation_floor(gj.assemble(train, "first"))
    settings = gj.HarmonicBalance(n_harmonics=a.harmonics)
    f = np.geomspace(2000.0, 15000.0, a.frequencies)
    omegas = jnp.asarray(2 * math.pi * f / 7)
    th = jnp.asarray(thetas)

    def batched():
        return gj.batched_rms(family, th, omegas, settings)[0]

    def looped():
        return jnp.stack([gj.batched_rms(family, th[b:b + 1], omegas, settings)[0][0]
                          for b in range(a.designs)])

    print(f"backend {jax.default_backend()} ({jax.devices()[0].device_kind}, "
          f"{len(jax.devices())} device(s)); {a.designs} designs x {a.frequencies} "
          f"frequencies, K = {a.harmonics}, {gj.assemble(train).n_dof} DOF, "
          f"{(2 * a.harmonics + 1) * gj.assemble(train).n_dof} unknowns per point")
    rows = []
    out_b, first_b, run_b = timed(batched, a.repeats)
    rows.append(("vmapped, one call", first_b - run_b, run_b))
    out_l, first_l, run_l = timed(looped, a.repeats)
    rows.append(("Python loop over designs", first_l - run_l, run_l))
    if a.shard:
        devices = jax.devices()
        out_s, first_s, run_s = timed(
            lambda: gj.batched_rms(family, th, omegas, settings, devices=devices)[0], a.repeats)
        rows.append((f"vmapped, sharded on {len(devices)}", first_s - run_s, run_s))
        rel_s = float(jnp.max(jnp.abs(out_s - out_b) / jnp.abs(out_b)))
    print(f"{'method':>28} {'compile s':>10} {'run s':>9} {'sweeps/min':>11} {'vs loop':>8}")
    for name, compile_s, run_s in rows:
        print(f"{name:>28} {compile_s:>10.2f} {run_s:>9.3f} {60 * a.designs / run_s:>11.1f} "
              f"{run_l / run_s:>7.2f}x")
    rel = float(jnp.max(jnp.abs(out_l - out_b) / jnp.abs(out_b)))
    print(f"largest relative difference, vmapped vs loop: {rel:.2e}"
          + (f"; sharded vs unsharded: {rel_s:.2e}" if a.shard else ""))
    print(f"(a design sweep = {a.frequencies} frequencies; compile = first call - median run)")


if __name__ == "__main__":
    main()
