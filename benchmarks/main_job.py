"""The README's main job from the command line, cold and warm: wall
time of whole ``gearjax`` processes, interpreter start included.

Four runs of the same command, in turn:

1. ``cold, cache off``: ``GEARJAX_CACHE_DIR=0`` (nothing compiled is kept);
2. ``first, cache on``: a fresh, empty cache directory (it fills it);
3. ``second, cache on``: the same directory again (the daily user's second run);
4. ``after compile``: the same directory, one process running the command twice (the
   CLI's ``main``); its second call, timed in the process, is the run with nothing left
   to trace, lower or load: the floor a second process can approach.

    python benchmarks/main_job.py [--full | --oscillator [--own-jit]] [--rounds 1] [--keep DIR]

The command is the README's first one, ``gearjax sweep --from 3290 --to 3450 --out
sweep.nc --plot sweep.png`` (the bundled paper case, 0.05 mm backlash, through the fold
pair at 3.32 kHz); ``--full`` runs the paper's whole band, 2-15 kHz, instead. Each run's
JSON summary gives the sweep's own time (``seconds``), so the table shows what the
process spends outside the sweep (start, tracing, loading or compiling programs,
writing the files), and the sweep's ``phase_seconds``, where its time went (assembly,
truncation check, walk, completion, results).

``--oscillator``: instead of the four, the first three runs of a Python process that
imports gearjax and runs the clearance-oscillator continuation of
``benchmarks/clearance_oscillator.py`` (K = 15, 0.5 -> 1.5; its first call, then one
more), the whole process timed (pyHarm's sweep of the same oscillator takes about
1.3 s): gearjax's compiled calls (``solve_hb_points``, ``continue_compiled``, kept
between processes), or with ``--own-jit`` the same inside the caller's own ``jax.jit``
(traced in every process). ``--rounds N`` repeats the runs N times, interleaved.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

BANDS = {"main": ("3290", "3450"), "full": ("2000", "15000")}
OSCILLATOR = """
import sys, time
sys.path.insert(0, {here!r})
import clearance_oscillator as c
r = c.hb_sweep(15, 256, 1, own_jit={own_jit})  # its first call (compiling or loaded), then one more
print(r["points"], r["compile_s"])
"""


def run_oscillator(cache: str, own_jit: bool = False) -> tuple[float, dict]:
    """One Python process running the clearance-oscillator continuation: ``(wall
    seconds, {"seconds": its call's time, "points": [...]})``; ``own_jit``: inside the
    caller's own ``jax.jit`` (traced in every process), else gearjax's compiled calls."""
    env = {**os.environ, "GEARJAX_CACHE_DIR": cache}
    code = OSCILLATOR.format(here=str(pathlib.Path(__file__).resolve().parent),
                             own_jit=own_jit)
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=False)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"main_job.py: the oscillator run exited {proc.returncode}:\n"
                         f"{proc.stderr[-2000:]}")
    points, seconds = proc.stdout.split()[-2:]
    return wall, {"seconds": float(seconds), "points": [None] * int(points)}


def run(band, cache: str, workdir: pathlib.Path) -> tuple[float, dict]:
    """One ``gearjax sweep`` process: ``(wall seconds, its JSON summary)``."""
    env = {**os.environ, "GEARJAX_CACHE_DIR": cache}
    exe = shutil.which("gearjax", path=os.path.dirname(sys.executable)) or "gearjax"
    cmd = [exe, "sweep", "--from", band[0], "--to", band[1],
           "--out", str(workdir / "sweep.nc"), "--plot", str(workdir / "sweep.png"), "--json"]
    t = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"main_job.py: {' '.join(cmd)} exited {proc.returncode}:\n"
                         f"{proc.stderr[-2000:]}")
    return wall, json.loads(proc.stdout)


AFTER_COMPILE = """
import contextlib, io, json, sys, time
from gearjax._cli import main
for k in range(2):  # the first call traces, loads or compiles; the second finds it all
    out = io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stdout(out):
        code = main({argv!r})
    wall = time.perf_counter() - t
    if code != 0:
        sys.exit(code)
print(json.dumps({{"wall": wall, "summary": json.loads(out.getvalue())}}))
"""


def run_after_compile(band, cache: str, workdir: pathlib.Path) -> tuple[float, dict]:
    """The command twice in one process: ``(wall seconds of the second call, its JSON
    summary)``."""
    argv = ["sweep", "--from", band[0], "--to", band[1], "--out", str(workdir / "sweep.nc"),
            "--plot", str(workdir / "sweep.png"), "--json"]
    proc = subprocess.run([sys.executable, "-c", AFTER_COMPILE.format(argv=argv)],
                          env={**os.environ, "GEARJAX_CACHE_DIR": cache},
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"main_job.py: the after-compile run exited {proc.returncode}:\n"
                         f"{proc.stderr[-2000:]}")
    out = json.loads(proc.stdout.splitlines()[-1])
    return out["wall"], out["summary"]


PHASES = ("gear", "check", "walk", "completion", "results")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the whole 2-15 kHz band")
    ap.add_argument("--oscillator", action="store_true",
                    help="the clearance-oscillator continuation in a fresh process")
    ap.add_argument("--own-jit", action="store_true",
                    help="the oscillator's calls inside the caller's own jax.jit")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--keep", help="cache directory to use (default: a fresh temporary one)")
    args = ap.parse_args()
    band = BANDS["full" if args.full else "main"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        workdir = pathlib.Path(tmp)
        for k in range(args.rounds):
            cache = args.keep or str(workdir / f"cache{k}")
            runs = [("cold, cache off", "0"), ("first, cache on", cache),
                    ("second, cache on", cache)]
            for name, where in runs + ([] if args.oscillator else
                                       [("after compile", cache)]):
                wall, out = (run_oscillator(where, args.own_jit) if args.oscillator
                             else run_after_compile(band, where, workdir)
                             if name == "after compile" else run(band, where, workdir))
                rows.append((k + 1, name, wall, float(out.get("seconds", float("nan"))),
                             len(out.get("points", [])), out.get("folds_hz", []),
                             out.get("phase_seconds", {})))
                print(f"round {k + 1}, {name}: {wall:.1f} s", flush=True)
    what = (f"clearance oscillator, K = 15, 0.5 -> 1.5, "
            f"{'own jit' if args.own_jit else 'gearjax calls'} (the call: its 'sweep s')"
            if args.oscillator else
            f"gearjax sweep --from {band[0]} --to {band[1]} (paper case, 0.05 mm backlash)")
    print(f"\n== {what}, whole processes, {os.cpu_count()} CPUs")
    print(f"{'round':>5} {'run':<18} {'wall s':>7} {'sweep s':>8} {'outside s':>10} "
          f"{'points':>7}" + ("" if args.oscillator else
                              "   " + " ".join(f"{p:>10}" for p in PHASES)))
    for k, name, wall, sweep_s, points, _, phases in rows:
        print(f"{k:>5} {name:<18} {wall:>7.1f} {sweep_s:>8.1f} {wall - sweep_s:>10.1f} "
              f"{points:>7}" + ("" if args.oscillator else "   " + " ".join(
                  f"{phases[p]:>10.1f}" if p in phases else f"{'-':>10}" for p in PHASES)))
    if not args.oscillator:
        print("(after compile: the command's second call in one process, timed there: no "
              "interpreter start or imports; phases: the sweep's phase_seconds)")
    if not args.oscillator:
        folds = rows[-1][5]
        print(f"folds (Hz): {', '.join(f'{f:.0f}' for f in folds) if folds else 'none'}")


if __name__ == "__main__":
    main()
