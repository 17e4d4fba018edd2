"""Execute the notebooks in reading order and report each one's wall time.

    python notebooks/run_all.py            # execute and store the outputs in place
    python notebooks/run_all.py --check    # execute copies; the files stay as they are
    GEARJAX_NOTEBOOK_QUICK=1 python notebooks/run_all.py --check   # CI smoke run

``GEARJAX_NOTEBOOK_QUICK=1`` (read by each notebook's first code cell) lowers harmonics,
points and bands so that every notebook runs in about a minute on 2 cores; the committed
notebooks are executed without it (settings in each notebook's first cells). Exits 1
when a cell raises (the error is printed), 2 on bad arguments.
"""

from __future__ import annotations

import argparse
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
    args = parser.parse_args(argv)
    # the kernel inherits this environment: draw figures inline even where MPLBACKEND=Agg
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    quick = os.environ.get("GEARJAX_NOTEBOOK_QUICK") == "1"
    print(f"notebooks: {'quick' if quick else 'normal'} mode, "
          f"{'check only' if args.check else 'outputs written in place'}", flush=True)
    failed = []
    total = 0.0
    for path in notebooks(args.notebooks):
        seconds, error = execute(path, write=not args.check, timeout=args.timeout)
        total += seconds
        print(f"  {path.name:28s} {seconds:7.1f} s  {'FAILED' if error else 'ok'}", flush=True)
        if error:
            failed.append(path.name)
            print(error, file=sys.stderr)
    print(f"  {'total':28s} {total:7.1f} s")
    if failed:
        print(f"run_all.py: cell errors in {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
