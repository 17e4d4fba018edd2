"""The windowed integration of quasi-periodic trains against the torus harmonic balance:
accuracy and time for windows of several lengths and agreement tolerances.

``gearjax.verify_gear`` at each frequency (the torus balance, its orders chosen and
checked a posteriori, then the windowed integration from its state) with
``gearjax.Windowed(n_beats=N, tol=T)`` for each pair ``N:T`` of ``--windows``; printed
per pair: the window length (base periods), the windows run, how far the last two
differed, the integration's time (after a first, discarded run of the same settings,
which compiles), and the largest relative difference of a mesh's RMS alternating force
between the two (relative to the largest of its stage, as ``verify`` reports it). The
averages over each window are weighted by a smooth bump, so the difference
falls with the window length much faster than ``1 / n_beats``.

    python benchmarks/windowed_verify.py [--train tests/data/two_stage_43_19_81.toml]
        [--khz 10.5] [--windows 100:1e-2 20:1e-3 40:1e-5] [--backlash]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import gearjax as gj


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", default="tests/data/two_stage_43_19_81.toml")
    parser.add_argument("--gear", default=None)
    parser.add_argument("--khz", type=float, nargs="+", default=[10.5])
    parser.add_argument("--windows", nargs="+", default=["100:1e-2", "20:1e-3", "40:1e-5"])
    parser.add_argument("--backlash", action="store_true", help="keep the backlash")
    args = parser.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train(args.train)
    f_hz = [1e3 * f for f in args.khz]
    print(f"{args.train}, {'with backlash' if args.backlash else 'linear'}, "
          f"{', '.join(f'{f:g}' for f in f_hz)} Hz")
    print(f"{'n_beats':>7} {'tol':>7} {'periods':>8} {'windows':>8} {'last change':>12} "
          f"{'integration s':>13} {'max rel. diff.':>14}")
    for pair in args.windows:
        n_beats, tol = pair.split(":")
        settings = gj.Windowed(n_beats=int(n_beats), tol=float(tol))
        gj.verify_gear(train, args.gear, f_hz, linear=not args.backlash, windowed=settings)
        start = time.perf_counter()
        r = gj.verify_gear(train, args.gear, f_hz, linear=not args.backlash,
                           windowed=settings)
        seconds = r.seconds["integration"]
        ni = r.ni
        print(f"{n_beats:>7} {float(tol):>7.0e} {r.reference['window_periods']:>8} "
              f"{int(np.max(ni['windows'].values)):>8} "
              f"{float(np.nanmax(ni['window_change'].values)):>12.1e} {seconds:>13.1f} "
              f"{float(np.nanmax(r.rel_diff)):>14.2e}   ({time.perf_counter() - start:.1f} s "
              "in all)")


if __name__ == "__main__":
    main()
