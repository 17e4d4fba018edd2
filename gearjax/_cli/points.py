"""``gearjax simulate`` and ``gearjax verify``: steady states by time integration,
and the harmonic balance against it."""

from __future__ import annotations

import json
import math

import numpy as np

from .._errors import fail
from .outputs import atomic
from .report import EXIT_NOT_CONVERGED, EXIT_OK, emit, to_stderr


def simulate_command(args, train, notes) -> int:
    from .._io.results import json_number, points_json, save_results
    from .._studies.simulate import simulate_gear

    g = train.gear(args.gear)
    ds = simulate_gear(train, g.name, args.at, from_hz=args.from_hz, to_hz=args.to_hz,
                       points=args.points, stage=args.stage, linear=args.linear,
                       progress=to_stderr, command=args.command_line)
    if args.out:
        save_results(ds, args.out)
    if args.plot:
        from .._plot.save import plot_points

        kind = "linear" if args.linear else "backlash"
        with atomic(args.plot) as fig:
            plot_points(ds, fig, title=f"{train.name}: gear {g.name}, {kind}, time "
                                       "integration")
    converged = bool(np.any(ds["converged"].values))
    code = EXIT_OK if converged else EXIT_NOT_CONVERGED
    out = {"gear": g.name, "reference_stage": ds.attrs["reference_stage"],
           "mode": ds.attrs["mode"], "seconds": ds.attrs["seconds"],
           "points": points_json(ds), "solver": json.loads(ds.attrs["solver"]),
           "warnings": notes}
    for p, periods, steps in zip(out["points"], ds["periods"].values, ds["num_steps"].values):
        p["periods"], p["num_steps"] = int(periods), int(steps)
    windowed = "windows" in ds  # a quasi-periodic gear: statistics over windows
    if windowed:
        for k, p in enumerate(out["points"]):
            p["windows"] = int(ds["windows"].values[k])
            p["window_s"] = json_number(ds["window_s"].values[k])
            p["window_change"] = json_number(ds["window_change"].values[k])
            p["period_reason"] = ("quasi-periodic: the mesh frequencies fall in "
                                  "incommensurate groups, so the response never repeats; "
                                  "statistics of the last of the windows")
    if args.json:
        emit(out)
        return code
    rms = ds["rms_force"].values
    print(f"simulation of gear {g.name!r}: {ds.sizes['point']} points "
          f"({ds.attrs['mode']}), {'linear' if args.linear else 'with backlash'}, "
          f"{ds.attrs['seconds']:.1f} s")
    if windowed:
        sv = out["solver"]
        print(f"quasi-periodic ({sv['torus']['G']} incommensurate frequency groups): "
              f"statistics over windows of {sv['window_periods']} base periods, "
              f"consecutive windows agreeing within {sv['tol']:g}")
    stages = list(dict.fromkeys(ds["stage"].values.tolist()))
    wide = 14 if windowed else 13  # "quasi_periodic"
    print(f"{'Hz':>9} {'result':>{wide}} {'period':>6} {'periods':>7} "
          + " ".join(f"{'max RMS ' + s + ' (N)':>14}" for s in stages))
    for k, p in enumerate(out["points"]):
        cols = [np.nanmax(rms[k, ds["stage"].values == s]) if p["converged"] or
                p["result"] in ("not_periodic", "not_stationary") else math.nan
                for s in stages]
        period = "-" if p["period"] is None else f"{p['period']:.0f}"
        print(f"{p['mesh_frequency_hz']:>9.1f} {p['result']:>{wide}} {period:>6} "
              f"{p['periods']:>7} " + " ".join(f"{c:>14.1f}" for c in cols))
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return code


def verify_command(args, train, notes) -> int:
    from .._io.verify_file import save_verify
    from .._studies.verify import verify_gear, verify_json

    g = train.gear(args.gear)
    curve = None
    if args.curve:
        from .._io.results import load_results

        try:
            curve = load_results(args.curve)
        except (OSError, ValueError) as e:
            raise fail("command line", "--curve", args.curve, f"cannot be read: {e}") from None
    result = verify_gear(train, g.name, args.at, from_hz=args.from_hz, to_hz=args.to_hz,
                         points=args.points, stage=args.stage, linear=args.linear,
                         harmonics=args.harmonics, tol_linear=args.tol_linear,
                         tol_nonlinear=args.tol_nonlinear, progress=to_stderr,
                         command=args.command_line)
    if args.plot:
        from .._plot.save import plot_verify

        kind = "linear" if args.linear else "backlash"
        with atomic(args.plot) as fig:
            plot_verify(result.hb, result.ni, fig, curve=curve,
                        title=f"{train.name}: gear {g.name}, {kind}: harmonic balance "
                              f"({'line' if curve is not None else '+'}) and time "
                              "integration (circles)")
    if args.out:
        with atomic(args.out) as tmp:
            save_verify(result, tmp)
    out = verify_json(result)
    out["warnings"] = notes
    converged = any(p["converged"] for p in out["points"])
    code = EXIT_OK if converged else EXIT_NOT_CONVERGED
    if args.json:
        emit(out)
        return code
    n_ok, n = int(np.sum(result.ok)), result.ok.size
    print(f"verification of gear {g.name!r}: {len(out['points'])} points, "
          f"{'linear' if args.linear else 'with backlash'}, tolerance {result.tolerance:g} "
          f"(relative to the stage's largest RMS); {n_ok} of {n} meshes ok; "
          f"harmonic balance {result.seconds['harmonic_balance']:.1f} s, "
          f"integration {result.seconds['integration']:.1f} s")
    ref = out.get("reference")  # a quasi-periodic gear: windowed statistics
    if ref is not None:
        print(f"quasi-periodic ({out['torus']['G']} incommensurate frequency groups): torus "
              f"harmonic balance against {ref['method']}, windows of "
              f"{ref['window_periods']} base periods, {ref['n_agree']} consecutive windows "
              f"agreeing within {ref['agreement_tolerance']:g}")
    kw, nw = (8, 14) if ref is not None else (3, 13)  # "(12, 10)", "quasi_periodic"
    print(f"{'Hz':>9} {'K':>{kw}} {'truncation':>10} {'HB':>10} {'NI':>{nw}} {'stable':>6} "
          f"{'max rel diff':>12} "
          f"{'worst mesh':>10} {'RMS HB (N)':>10} {'RMS NI (N)':>10}")
    for k, p in enumerate(out["points"]):
        rel = result.rel_diff[k]
        if np.any(np.isfinite(rel)):
            j = int(np.nanargmax(rel))
            tail = (f"{rel[j]:>12.2e} {p['meshes'][j]['name']:>10} "
                    f"{result.rms_hb[k, j]:>10.1f} {result.rms_ni[k, j]:>10.1f}")
        else:
            tail = f"{'-':>12} {'-':>10} {'-':>10} {'-':>10}"
        stable = {None: "?", True: "yes", False: "no"}[p["stable"]]
        K = p["harmonics"]
        K = K if isinstance(K, int) else "(" + ", ".join(map(str, K)) + ")"
        flag = "" if p["ok"] else "  NOT OK" + (f" ({p['agreement']})" if "agreement" in p
                                                else "")
        print(f"{p['mesh_frequency_hz']:>9.1f} {K:>{kw}} {_last_estimate(p):>10} "
              f"{p['result_hb']:>10} "
              f"{p['result_ni']:>{nw}} {stable:>6} " + tail + flag)
        if p.get("shortfall_reason"):
            print(f"{'':>9} {p['shortfall_reason']}")
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return code


def _last_estimate(point: dict) -> str:
    """The truncation estimate of a verified point's orders (the largest over the angles
    of its last check), or ``-`` where none was made."""
    K = point["truncation"][-1]["K"] if point["truncation"] else None
    changes = [c["change"] for c in point["truncation"]
               if c["K"] == K and c["change"] is not None]
    return f"{max(changes):.1e}" if changes else "-"
