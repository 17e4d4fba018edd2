"""``gearjax modes`` and ``gearjax calibrate``: natural frequencies, and parameters fitted
to targets."""

from __future__ import annotations

import collections

import numpy as np

from .outputs import atomic
from .report import EXIT_NOT_CONVERGED, EXIT_OK, emit


def modes_command(args, train, notes) -> int:
    from .._gear.assembly import assemble
    from .._engine.modal import REPEATED_RTOL, modes

    g = train.gear(args.gear)
    result = modes(assemble(train, g.name))
    out = {
        "train": train.name,
        "gear": g.name,
        "elastic_hz": result.elastic_hz,
        "repeated_rtol": REPEATED_RTOL,
        "modes": [
            {"hz": m.hz, "multiplicity": m.multiplicity, "class": m.cls, "family": m.family,
             "stage": m.stage, "shape": m.shape, "energy": m.energy, "kinetic": m.kinetic}
            for m in result.modes
        ],
        "warnings": notes,
    }
    if args.plot:
        from .._plot.save import plot_mode_shapes

        with atomic(args.plot) as fig:
            plot_mode_shapes(result, fig, title=f"{train.name}: gear {g.name}, elastic modes")
    if args.json:
        return emit(out)
    print(f"{train.name}: gear {g.name!r}, {len(result.modes)} modes "
          f"(repeated when within {REPEATED_RTOL:g} relative)")
    print(f"{'kHz':>10} {'mult':>4} {'class':>8} {'family':>14}  "
          "coordinates with most kinetic energy (share)")
    for m in result.modes:
        fam = f"planet {m.stage}" if m.family == "planet" else m.family
        top = sorted(m.kinetic.items(), key=lambda kv: -abs(kv[1]))[:3]
        print(f"{m.hz / 1e3:>10.4f} {m.multiplicity:>4} {m.cls:>8} {fam:>14}  "
              + ", ".join(f"{k} {v:.0%}" for k, v in top))
    if train.translational:
        counts = collections.Counter(m.family for m in result.modes)
        print("mode families: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
        for s in train.stages:
            gaps = np.diff(np.r_[np.asarray(s.planet_angles_deg, float), 360.0])
            if not np.allclose(gaps, gaps[0]):
                print(f"stage {s.id}: planets unequally spaced: Lin & Parker's rotational, "
                      "translational and planet types need equal spacing; modes that keep "
                      "one of them are named so, the rest overall")
    if args.plot:
        print(f"mode shapes written to {args.plot}")
    return EXIT_OK


# ------------------------------------------------------------------------ calibrate


def calibrate_command(args, train, notes) -> int:
    from .._gear.calibrate import calibrate
    from .._gear.toml_io import save_train

    g = train.gear(args.gear)
    result = calibrate(train, args.targets_hz, args.free, g.name)
    if args.out_train:
        with atomic(args.out_train) as tmp:
            save_train(result.train, tmp)
    out = {
        "train": train.name,
        "gear": g.name,
        "free": list(result.free),
        "initial": result.initial,
        "fitted": result.fitted,
        "targets_hz": list(result.targets_hz),
        "model_hz": list(result.model_hz),
        "residual_hz": list(result.residual_hz),
        "residual_rel": list(result.residual_rel),
        "converged": result.converged,
        "message": result.message,
        "nfev": result.nfev,
        "at_bound": list(result.at_bound),
        "out_train": args.out_train,
        "warnings": notes,
    }
    code = EXIT_OK if result.converged else EXIT_NOT_CONVERGED
    if args.json:
        emit(out)
        return code
    print(f"calibration of {', '.join(result.free)} on gear {g.name!r}: "
          f"{'converged' if result.converged else 'NOT converged'} ({result.message}, "
          f"{result.nfev} evaluations)")
    print(f"{'target Hz':>12} {'model Hz':>12} {'residual':>10}")
    for t, m, r in zip(result.targets_hz, result.model_hz, result.residual_rel):
        print(f"{t:>12.2f} {m:>12.2f} {100 * r:>9.4f}%")
    print(f"{'parameter':>20} {'initial':>12} {'fitted':>12}")
    for p in result.free:
        flag = "  (at bound)" if p in result.at_bound else ""
        print(f"{p:>20} {result.initial[p]:>12.5g} {result.fitted[p]:>12.5g}{flag}")
    if args.out_train:
        print(f"calibrated train written to {args.out_train}")
    return code
