"""``gearjax plot``: a saved result or a study store drawn again."""

from __future__ import annotations

import pathlib

from .._errors import fail
from .outputs import atomic
from .report import EXIT_OK, emit


def plot_command(args, train, notes) -> int:
    from .._plot.save import plot_results

    results = pathlib.Path(args.results)
    fig = pathlib.Path(args.out) if args.out else results.with_suffix(".png")
    if results.is_dir():
        return _plot_study(args, results, fig)
    if args.pareto is not None:
        raise fail("command line", "--pareto", " ".join(args.pareto),
                   "is for a study store; RESULTS is a file")
    with atomic(fig) as tmp:
        kind, _ = plot_results(results, tmp, what=args.what)
    if args.json:
        return emit({"results": args.results, "kind": kind, "what": args.what,
                     "figure": str(fig)})
    print(f"{kind} results {args.results}: figure ({args.what}) written to {fig}")
    return EXIT_OK


def _plot_study(args, store: pathlib.Path, fig_path: pathlib.Path) -> int:
    from .._plot.study_figure import pareto_pair, study_figure
    from .._studies.study import load_study_results
    from .._studies.study.report import pareto

    ds = load_study_results(store)
    pair = pareto_pair(ds, None if args.pareto is None else tuple(args.pareto))
    fig = study_figure(ds, pair)
    with atomic(fig_path) as tmp:
        fig.savefig(tmp, format=fig_path.suffix.lstrip(".") or "png", dpi=120)
    best = pareto(ds, *pair) if pair is not None else None
    if args.json:
        return emit({"results": str(store), "kind": "study", "figure": str(fig_path),
                     "pareto_merits": None if pair is None else list(pair),
                     "pareto": best})
    print(f"study results {store}: figure written to {fig_path}"
          + (f"; Pareto set of {pair[0]} and {pair[1]}: candidates "
             f"{', '.join(map(str, best))}" if pair is not None else ""))
    return EXIT_OK
