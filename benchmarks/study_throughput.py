"""Design-study throughput: candidates per minute of ``gearjax study`` run serially
(``--workers 0``: every candidate in one process) and on a local Dask cluster of 1 and 2
worker processes, in one run.

The study: the helicopter five-planet stage (``tests/data``) with ``--candidates`` values
of the sun mesh stiffness (every candidate one shape, so each process compiles once), each
analysed by its modes and a linear sweep of ``--points`` grid points (K = 4, refined
where the curve bends). A first, untimed run fills the persistent compilation cache, so
every configuration finds the programs compiled (each process still traces and loads
them once); then each configuration runs ``--rounds`` times, interleaved, as a fresh
``gearjax study`` process into a fresh store, and its best wall time (start-up and
cluster included) is printed with the candidates per minute and the ratio to the serial
run.

    python benchmarks/study_throughput.py [--candidates 8] [--points 100] [--rounds 2]
"""

from __future__ import annotations

import argparse
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

import gearjax as gj

ROOT = pathlib.Path(__file__).resolve().parents[1]


def study_file(folder: pathlib.Path, candidates: int, points: int) -> pathlib.Path:
    path = folder / "throughput.toml"
    path.write_text(
        f'train = "{ROOT / "tests" / "data" / "helicopter_five_planets.toml"}"\n'
        'gear = "flight"\n'
        '[[vary]]\npath = "main.mesh_stiffness.sun"\n'
        f"from = 0.8e9\nto = 1.2e9\npoints = {candidates}\n"
        "[analysis]\nmodes = true\n"
        f"linear = {{ band_hz = [2000.0, 3000.0], points = {points}, harmonics = 4 }}\n")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, default=8)
    parser.add_argument("--points", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    configs = {"serial": 0, "1 worker": 1, "2 workers": 2}
    exe = shutil.which("gearjax")
    cmd = [exe] if exe else [sys.executable, "-m", "gearjax._cli"]
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        spec = study_file(folder, args.candidates, args.points)
        reference = gj.study(spec, folder / "warm", workers=0).dataset
        best = {name: float("inf") for name in configs}
        for r in range(args.rounds):
            order = list(configs) if r % 2 == 0 else list(reversed(configs))
            for name in order:
                store = folder / f"{r}-{configs[name]}"
                t0 = time.perf_counter()
                subprocess.run([*cmd, "study", str(spec), "--out", str(store), "--workers",
                                str(configs[name])], check=True, capture_output=True)
                best[name] = min(best[name], time.perf_counter() - t0)
                ds = gj.load_study_results(store)
                assert (ds["status"].values == reference["status"].values).all()
    n = args.candidates
    print(f"{n} candidates (modes and a linear sweep of {args.points} grid points, K = 4), "
          f"best of {args.rounds} interleaved rounds, each a fresh process, compilation "
          "cache warm")
    print(f"{'configuration':<14} {'wall s':>8} {'cand/min':>9} {'vs serial':>10}")
    for name, seconds in best.items():
        print(f"{name:<14} {seconds:>8.1f} {60 * n / seconds:>9.1f} "
              f"{best['serial'] / seconds:>9.2f}x")


if __name__ == "__main__":
    main()
