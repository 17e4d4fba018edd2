"""``gearjax sensitivity`` and ``gearjax optimize``: derivatives of a response, and the
phasing optimisation."""

from __future__ import annotations

import math

from .._errors import ArgumentError, fail
from .outputs import atomic
from .report import EXIT_NOT_CONVERGED, EXIT_OK, emit, to_stderr


def sensitivity_command(args, train, notes) -> int:
    from .._studies.sensitivity import sensitivity, sensitivity_json

    if not (args.at > 0 and math.isfinite(args.at)):
        raise fail("command line", "--at", args.at, "must be a positive mesh frequency in Hz")
    result = sensitivity(train, args.gear, args.at, response=args.response, mesh=args.mesh,
                         paths=args.vary, stage=args.stage, linear=args.linear,
                         harmonics=args.harmonics, progress=to_stderr)
    out = sensitivity_json(result)
    out["warnings"] = notes
    code = EXIT_OK if result.ok else EXIT_NOT_CONVERGED
    if not result.ok:
        to_stderr(f"gearjax: {result.message}")
    if args.json:
        emit(out)
        return code
    kind = "linear" if args.linear else "with backlash"
    print(f"sensitivity of the {result.response} of mesh {result.mesh} ({result.value:.6g} "
          f"{result.unit}) at {result.mesh_frequency_hz:g} Hz, gear {result.gear!r}, {kind}, "
          f"K = {result.harmonics}: {result.result}")
    if not result.ok:
        return code
    print(f"ranked {out['ranking']}")
    print(f"{'path':>28} {'value':>12} {'dR/dp':>13} {'per':>8} {'(p/R) dR/dp':>12} "
          f"{'step s':>10} {'(s/R) dR/dp':>12}")
    for row in out["derivatives"]:
        norm = "-" if row["normalised"] is None else f"{row['normalised']:+.4e}"
        rel = "-" if row["relative"] is None else f"{row['relative']:+.4e}"
        step = ("value" if row["step_rule"] is None else f"{row['step']:.4g} {row['unit']}")
        print(f"{row['path']:>28} {row['value']:>12.5g} {row['derivative']:>+13.5e} "
              f"{row['unit']:>8} {norm:>12} {step:>10} {rel:>12}")
    return code


# ------------------------------------------------------------------------- optimize


def optimize_command(args, train, notes) -> int:
    from .._errors import bad_argument
    from .._studies.optimize import (OptimizeSettings, optimize, optimize_dataset,
                                     optimize_json, recheck, recheck_json)
    from .._studies.optimize.settings import check_band
    from .._io.results import save_results
    from .._gear.toml_io import save_train

    settings = OptimizeSettings(
        proxy_points=args.proxy_points, phase_grid=args.phase_grid, screen=args.screen,
        screen_points=args.points, final_points=args.final_points, harmonics=args.harmonics,
        nonlinear=args.nonlinear,
        max_step_hz=args.max_step, max_points=args.max_points, seeds=args.seeds,
        relax_iterations=args.relax_iterations,
        passes=args.passes)
    rechecking = args.recheck and args.nonlinear > 0
    recheck_band = tuple(args.recheck_band) if args.recheck_band is not None else None
    if rechecking:  # refused before the optimisation, in the re-check flags' words
        if args.recheck_band is not None:  # (the default, --band, the optimiser checks)
            try:
                check_band(recheck_band)
            except ArgumentError as e:
                raise bad_argument("recheck_band_hz", e.value, e.rule) from None
        if args.recheck_harmonics is not None and args.recheck_harmonics < 1:
            raise bad_argument("recheck_harmonics", args.recheck_harmonics,
                               "must be an integer >= 1")
    g = train.gear(args.gear)
    result = optimize(train, g.name, None if args.band is None else tuple(args.band),
                      args.vary, stage=args.stage,
                      settings=settings, progress=to_stderr)
    check = None
    if rechecking:
        check = recheck(result, recheck_band, verify_hz=[],
                        harmonics=args.recheck_harmonics, max_points=args.max_points,
                        seeds=args.seeds, progress=to_stderr)
    outcome = check.verdict if check is not None else result.verdict
    recommended = check.recommended_train if check is not None else result.recommended_train
    if args.out_train:
        with atomic(args.out_train) as tmp:
            save_train(recommended, tmp)
    attrs = {"command": args.command_line}
    if check is not None:
        attrs.update(recheck=recheck_json(check), recheck_verdict=check.verdict["text"],
                     recommended=check.recommended)
    if args.out:
        save_results(optimize_dataset(result, attrs), args.out)
    out = optimize_json(result)
    out.update(recheck=None if check is None else recheck_json(check),
               recommended=outcome["recommended"], conclusion=outcome["text"],
               out_train=args.out_train, out=args.out, warnings=notes)
    code = EXIT_OK if result.converged else EXIT_NOT_CONVERGED
    if args.json:
        emit(out)
        return code
    b, o = result.baseline, result.optimum
    print(f"phasing optimisation of gear {g.name!r}, band {result.band_hz[0]:g}-"
          f"{result.band_hz[1]:g} Hz (stage {result.reference_stage}), varying "
          f"{', '.join(result.vary)}: {result.seconds:.0f} s")
    print(f"{'':>10} {'peak RMS, linear (N)':>22} {'with backlash (N)':>18}  "
          "planet angles, phases")
    for name, d in (("baseline", b), ("optimum", o)):
        nl = "-" if d.nonlinear is None else f"{d.nonlinear_peak:.1f}"
        print(f"{name:>10} {d.linear_peak:>22.1f} {nl:>18}  " + _values_text(d.values))
    models = result.models or {}
    print(f"models: proxy {models['proxy']['frequencies']} frequencies x "
          f"{models['proxy']['phase_grid']} phases; linear screen K = "
          f"{models['linear']['harmonics']}, {models['linear']['frequencies_per_candidate']} "
          "frequencies per candidate; with backlash: "
          + ("none (--nonlinear 0)" if models.get("backlash") is None
             else models["backlash"]["text"] + ", peak over every stable state")
          + ("" if check is None else f"; re-check: {check.settings.text()}, "
             f"{check.band_hz[0]:g}-{check.band_hz[1]:g} Hz"))
    if check is not None:
        print(f"{'re-check':>10} {'fresh peak (N)':>22} {'at (Hz)':>18}  integration from "
              "that orbit")
        for name, row in check.peaks.iterrows():
            print(f"{name:>10} {row['sweep peak (N)']:>22.1f} {row['at (Hz)']:>18.1f}  "
                  f"{row.get('integrated (N)', math.nan):.1f} N ({row['integration']}), "
                  f"branch found by {row['branch found by'] or '-'}"
                  + ("" if row["complete"] else ", sweep NOT complete"))
    print(f"optimiser: {result.verdict['text']}")
    if check is not None:
        print(f"re-check: {check.verdict['text']}")
    r = result.relaxation
    if r is not None:
        print(f"{'relaxed':>10} {r.linear_peak:>22.1f} {'-':>18}  " + _values_text(r.values)
              + "  (continuous: not assemblable)")
    for s in result.stages:
        print(f"stage {s['stage']}: {s['planet_sets']} admissible planet sets"
              + f" ({s['screened_sets']} distinct phasings"
              + (" up to a rotation" if s["modulo_rotation"] else "") + ")"
              + f", {s['linear_screened']} solved linear, {s['nonlinear_swept']} with "
              f"backlash: {s['chosen']}")
    if args.out_train:
        print(f"{'optimised' if outcome['recommended'] == 'optimum' else 'baseline'} train "
              f"(the recommended design) written to {args.out_train}")
    if args.out:
        print(f"results written to {args.out}")
    return code


def _values_text(values: dict) -> str:
    """``1.planet_angles_deg [0, 90, ...]``-style summary of design values."""
    planets: dict[str, list[float]] = {}
    rest = []
    for path, v in values.items():
        sid, key, *i = path.split(".")
        if key == "planet_angles_deg":
            planets.setdefault(sid, [0.0]).append(v)
        else:
            rest.append(f"{path} {v:.4g}")
    return ", ".join([f"{sid}.planets [" + ", ".join(f"{a:.4g}" for a in a_s) + "]"
                      for sid, a_s in planets.items()] + rest)
