"""Torsional and translational-rotational models of the paper's train: the same complete
sweep with backlash (every stable state), timed in one run.

The translational train is ``tests/data/al_shyyab_translational.toml`` (the paper's file
with masses and bearings added): 42 coordinates against the torsional 14, the same 16
meshes. Each model's sweep runs once untimed (compilation), then ``--rounds`` times,
interleaved; the best wall time of each is printed with points, branches and the ratio
translational / torsional (issue 47's target: at most 2).

    python benchmarks/translational_sweep.py [--from 2000] [--to 15000] [--rounds 2]
"""

from __future__ import annotations

import argparse
import pathlib
import time
import warnings

import gearjax as gj

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="lo", type=float, default=2000.0)
    parser.add_argument("--to", dest="hi", type=float, default=15000.0)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the paper's non-concentric stage 1, said in info
        trains = {"torsional": gj.load_train(),
                  "translational": gj.load_train(ROOT / "tests" / "data"
                                                 / "al_shyyab_translational.toml")}
    runs = {name: (lambda t=t: gj.sweep(t, "first", args.lo, args.hi)) for name, t in
            trains.items()}
    results = {name: run() for name, run in runs.items()}  # compile
    best = {name: float("inf") for name in runs}
    for r in range(args.rounds):
        for name in (list(runs) if r % 2 == 0 else list(reversed(runs))):
            t0 = time.perf_counter()
            results[name] = runs[name]()
            best[name] = min(best[name], time.perf_counter() - t0)
    print(f"complete sweep with backlash, paper train, gear first, {args.lo:g}-{args.hi:g} Hz,"
          f" best of {args.rounds}")
    print(f"{'model':>14} {'DOF':>4} {'points':>7} {'branches':>9} {'seconds':>8} {'ratio':>6}"
          "  phases of the last run (s)")
    for name, res in results.items():
        ds = res.dataset
        phases = ", ".join(f"{k} {v:.1f}" for k, v in res.phase_seconds.items())
        print(f"{name:>14} {trains[name].n_dof:>4} {ds.sizes['point']:>7} "
              f"{len(set(ds['branch'].values.tolist())):>9} {best[name]:>8.1f} "
              f"{best[name] / best['torsional']:>6.2f}  {phases}")


if __name__ == "__main__":
    main()
