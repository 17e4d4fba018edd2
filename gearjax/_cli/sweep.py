"""``gearjax sweep``: the frequency response, its journal locked while the run is live."""

from __future__ import annotations

import sys

import numpy as np

from .outputs import atomic
from .report import EXIT_NOT_CONVERGED, EXIT_OK, emit, to_stderr


def sweep_command(args, train, notes) -> int:
    from .._io.journal import journal_path, lock

    journal = journal_path(args.out) if args.out else None
    held = lock(journal) if journal else None  # refused while another run writes it
    try:
        return _sweep_run(args, train, notes, journal)
    finally:
        if held is not None:
            held.release()


def _sweep_run(args, train, notes, journal) -> int:
    from .._io.results import save_results
    from .._studies.sweep import progress_bar, summary_json, sweep
    from .._studies.sweep.default_band import resolve_band
    from .._studies.sweep.summary import bifurcation_lines, change_words

    if args.resume and journal.exists():
        to_stderr(f"sweep: resuming from {journal}")
    g = train.gear(args.gear)
    args.from_hz, args.to_hz, chosen = resolve_band(train, g.name, args.stage, args.linear,
                                                    args.from_hz, args.to_hz)
    if chosen is not None:
        to_stderr(f"sweep: no --from/--to: band {args.from_hz:.1f}-{args.to_hz:.1f} Hz, "
                  f"chosen {chosen}")
    # a bar on a terminal; under --json or off a terminal only its final line
    with progress_bar(args.from_hz, args.to_hz, sys.stderr, quiet=args.json) as bar:
        result = sweep(train, g.name, args.from_hz, args.to_hz, stage=args.stage,
                       linear=args.linear, harmonics=args.harmonics, eta=args.eta,
                       max_step_hz=args.max_step, points=args.points,
                       max_points=args.max_points, smoothing=args.smoothing,
                       progress=bar, say=bar.note, journal=journal, resume=args.resume,
                       command=args.command_line, complete=args.complete,
                       seeds=args.seeds)
    ds = result.dataset
    if args.out:
        save_results(ds, args.out)
        journal.unlink(missing_ok=True)  # consolidated into the results file
    if args.plot:
        from .._plot.save import plot_sweep

        kind = "linear" if args.linear else "backlash"
        with atomic(args.plot) as fig:
            plot_sweep(ds, fig, title=f"{train.name}: gear {g.name}, {kind}")
    out = summary_json(result)
    out["warnings"] = notes
    converged = bool(np.any(ds["converged"].values))
    code = EXIT_OK if converged else EXIT_NOT_CONVERGED
    if args.json:
        emit(out)
        return code
    stable = ds["stable"].values
    print(f"sweep of gear {g.name!r}: {ds.sizes['point']} points, "
          f"{'linear' if args.linear else 'with backlash'}, stop: {result.stop}, "
          f"{result.seconds:.1f} s")
    print("segments (Hz, harmonics): " + ", ".join(
        f"{a:.0f}-{b:.0f} K={k}" for a, b, k in result.segments))
    refinement = out["solver"].get("refinement")
    if refinement:
        print(f"points: {refinement['grid']} of the even grid (--points {args.points}) and "
              f"{refinement['added']} placed where a straight line missed the RMS or peak "
              f"mesh force by more than {100 * refinement['tolerance']:g}%; "
              f"{refinement['solved']} solved with the {refinement['checked']} middles "
              f"checked, of at most {refinement['max_points']} (--max-points)")
    if result.folds_hz:
        print("folds at " + ", ".join(f"{f:.1f}" for f in result.folds_hz) + " Hz")
    if len(out["branches"]) > 1:
        print("branches: " + "; ".join(
            f"{b['branch']} {b['found']} ({b['seed_hz']:.1f} Hz)" for b in out["branches"]))
    if out["coexisting_hz"]:
        print("coexisting stable states (jumps up and down differ) over " + ", ".join(
            f"{a:.1f}-{b:.1f}" for a, b in out["coexisting_hz"]) + " Hz")
        for c in out["coexisting"]:
            print(f"  {c['from_hz']:.1f}-{c['to_hz']:.1f} Hz: {c['states']} stable states; "
                  "jumps sweeping up at " + (", ".join(f"{f:.1f}" for f in c["jump_up_hz"])
                                             or "-") + " Hz, sweeping down at "
                  + (", ".join(f"{f:.1f}" for f in c["jump_down_hz"]) or "-") + " Hz")
    for r in result.restarts:
        print(f"branch left at {r['from_hz']:.1f} Hz ({r['reason']}); new branch from "
              f"{r['at_hz']:.1f} Hz")
    print(f"unstable points: {int(np.sum(stable == 0))}")
    for b in out["bifurcations"]:
        print(f"  stability changes near {b['mesh_frequency_hz']:.1f} Hz: {change_words(b)}")
    for line in bifurcation_lines(out["bifurcation_notes"]):
        print(f"  {line}")
    lo, hi = out["band_hz"]
    for row in out["largest"]:  # stable, converged points inside the band asked for
        scope = (f"(stable points inside {lo:.1f}-{hi:.1f} Hz: {row['points']} of "
                 f"{row['of']})")
        if row["rms_force"] is None:
            print(f"stage {row['stage']}: {row['reason']}")
            continue
        share = "-" if row["separation"] is None else f"{row['separation']:.3f}"
        print(f"stage {row['stage']}: largest RMS mesh force {row['rms_force']:.1f} N at "
              f"{row['mesh_frequency_hz']:.1f} Hz ({row['mesh']}); largest separation share "
              f"{share} {scope}")
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return code
