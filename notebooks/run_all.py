"""Execute the notebooks in reading order and report each one's wall time.

    python notebooks/run_all.py            # execute and store the outputs in place
    python notebooks/run_all.py --check    # execute copies; the files stay as they are
    GEARJAX_NOTEBOOK_QUICK=1 python notebooks/run_all.py --check --jobs 2   # CI smoke run

``GEARJAX_NOTEBOOK_QUICK=1`` (read by each notebook's first code cell) lowers harmonics,
points and bands so that every notebook runs in about a minute on 2 cores; the committed
notebooks are executed without it (settings in each notebook's first cells).
``--jobs N`` executes up to N notebooks at once, each in its own process and kernel (a
notebook's compilation is mostly one core's work); the report keeps reading order. Exits
1 when a cell raises (the error is printed), 2 on bad arguments.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import functools
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def notebooks(names: list[str]) -> list[Path]:
    if not names:
        return sorted(HERE.glob("[a-z]_*.ipynb"))
    out = []
    for name in names:
        path = Path(name)
        if not path.suffix:
            path = path.with_suffix(".ipynb")
        if not path.is_file():
            path = HERE / path.name
        if not path.is_file():
            raise SystemExit(f"run_all.py: notebook {name!r} not found in {HERE}")
        out.append(path)
    return out


def execute(path: Path, write: bool, timeout: int) -> tuple[float, str | None]:
    """Execute one notebook (in its own folder); ``(seconds, error or None)``."""
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                     record_timing=False,  # no timestamps: smaller diffs
                                     resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    error = None
    try:
        client.execute()
    except nbclient.exceptions.CellExecutionError as e:
        error = str(e)
    except nbclient.exceptions.CellTimeoutError as e:
        error = f"cell timed out after {timeout} s: {e}"
    seconds = time.perf_counter() - t0
    if write and error is None:
        nbformat.write(nb, path)
    return seconds, error


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("notebooks", nargs="*", help="names (default: every notebook here)")
    parser.add_argument("--check", action="store_true",
                        help="do not write outputs back (execute in memory only)")
    parser.add_argument("--timeout", type=int, default=3600,
                        help="seconds allowed per cell (default 3600)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="notebooks executed at once, each in its own process (default 1)")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs = {args.jobs}: must be at least 1")
    # the kernel inherits this environment: draw figures inline even where MPLBACKEND=Agg
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    quick = os.environ.get("GEARJAX_NOTEBOOK_QUICK") == "1"
    print(f"notebooks: {'quick' if quick else 'normal'} mode, "
          f"{'check only' if args.check else 'outputs written in place'}", flush=True)
    failed = []
    total = 0.0
    t0 = time.perf_counter()
    paths = notebooks(args.notebooks)
    run = functools.partial(execute, write=not args.check, timeout=args.timeout)
    jobs = max(1, min(args.jobs, len(paths)))
    with concurrent.futures.ProcessPoolExecutor(max_workers=jobs) as pool:
        outcomes = pool.map(run, paths)  # in reading order, each as soon as it is done
        for path, (seconds, error) in zip(paths, outcomes):
            total += seconds
            print(f"  {path.name:28s} {seconds:7.1f} s  {'FAILED' if error else 'ok'}",
                  flush=True)
            if error:
                failed.append(path.name)
                print(error, file=sys.stderr)
    print(f"  {'total':28s} {total:7.1f} s"
          + (f" ({time.perf_counter() - t0:.1f} s wall, {jobs} at once)" if jobs > 1 else ""))
    if failed:
        print(f"run_all.py: cell errors in {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
