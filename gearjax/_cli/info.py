"""``gearjax info`` and ``gearjax mesh``: kinematics, phasing, static loads and the
meshes of a gear."""

from __future__ import annotations

import math

from .._errors import fail
from .outputs import atomic
from .report import EXIT_OK, emit


DEFAULT_INPUT_RPM = 1000.0
"""``info``'s input speed where neither ``--input-rpm`` nor the gear's ``input_rpm`` is
given."""


def info_command(args, train, notes) -> int:
    from .._gear.frequency_groups import MAX_MULTIPLIER
    from .._studies.plan import harmonics_plan, solver_plan
    from .._gear.mesh_report import mesh_report
    from .._gear.kinematics import kinematics
    from .._gear.phasing import phasing_report
    from .._gear.static_loads import static_loads

    g = train.gear(args.gear)
    if args.input_rpm is None:  # the gear's own speed where the file gives one
        args.input_rpm = g.input_rpm if g.input_rpm is not None else DEFAULT_INPUT_RPM
    if not (args.input_rpm > 0 and math.isfinite(args.input_rpm)):
        raise fail("command line", "--input-rpm", args.input_rpm, "must be a positive speed in rpm")
    kin = kinematics(train, g.name)
    loads = static_loads(train, g.name)
    phasing = {}
    for s, sk in zip(train.stages, kin.stages):
        phasing[s.id] = [
            {"h": r.h, "k": r.k, "kind": r.kind, "signs": r.signs, "sun_deg": list(r.sun_deg),
             "ring_deg": list(r.ring_deg)}
            for r in phasing_report(s, sk.sigma, train.phasing, train.stiffness_harmonics)
        ] if sk.turning else []
    out = {
        "train": train.name,
        "gear": g.name,
        "input": g.input,
        "output": g.output,
        "brakes": list(g.brakes),
        "note": g.note,
        "ratio": float(kin.ratio),
        "ratio_exact": str(kin.ratio),
        "mu": list(kin.mu) if kin.mu is not None else None,
        "dof": train.n_dof,
        "model": train.model,
        "input_rpm": args.input_rpm,
        "stages": [
            {"id": s.id, "loaded": s.loaded, "turning": s.turning, "sigma": s.sigma,
             "mesh_frequency_hz": kin.mesh_frequency_hz(s.id, args.input_rpm),
             "planet_speed": float(s.planet_speed), "planet_speed_exact": str(s.planet_speed)}
            for s in kin.stages
        ],
        "member_speeds": {p: float(w) for p, w in kin.speeds.items()},
        "member_speeds_exact": {p: str(w) for p, w in kin.speeds.items()},
        "static": {
            name: {"force": f, "torque": loads.mesh_torque[name]}
            for name, f in loads.mesh_force.items()
        },
        "brake_reactions": loads.brake_reaction,
        "load_sharing": loads.load_sharing,
        "housing_leak": loads.leak,
        "torque_balance": loads.balance,
        "phasing": phasing,
        "harmonics": harmonics_plan(train, g.name, kin),
        "meshes": [m.as_dict() for m in mesh_report(train, g.name)],
        **solver_plan(train, kin, args.input_rpm),
        "warnings": notes,
    }
    if args.json:
        return emit(out)
    print(f"{train.name}: gear {g.name!r} (input {g.input}, output {g.output}, "
          f"brakes {', '.join(g.brakes) or 'none'})" + (f"  [{g.note}]" if g.note else ""))
    mu = "null (no mesh turns)" if kin.mu is None else str(tuple(kin.mu))
    print(f"ratio {kin.ratio} = {float(kin.ratio):.6g}   mu = {mu}   {train.n_dof} DOF "
          f"({train.model} model)")
    print(f"\n{'stage':>6} {'loaded':>7} {'mesh Hz @ %g rpm' % args.input_rpm:>20} {'sigma':>6}"
          f" {'planet/carrier':>15}")
    for s in out["stages"]:
        print(f"{s['id']:>6} {str(s['loaded']):>7} {s['mesh_frequency_hz']:>20.2f} "
              f"{s['sigma']:>6} {s['planet_speed_exact']:>15}")
    print("\nmember speeds per unit input speed:")
    print("  " + "   ".join(f"{p} {w}" for p, w in kin.speeds.items()))
    print("\nstatic mesh forces (N) and torques (N m), mean stiffness, no backlash:")
    for name, v in out["static"].items():
        print(f"  {name:>7} {v['force']:>12.1f} N {v['torque']:>10.2f} N m")
    for path, t in loads.brake_reaction.items():
        print(f"brake {path} reacts {t:.2f} N m")
    print(f"through the free housing springs: {loads.leak:.3g} N m; "
          f"torque balance residual {loads.balance:.2g} N m")
    print("static load-sharing factor (largest planet load / mean): " + ", ".join(
        f"stage {sid} {v:.4f}" if v is not None else f"stage {sid} unloaded"
        for sid, v in loads.load_sharing.items()))
    for sid, rows in phasing.items():
        if rows:
            print(f"\nstage {sid} stiffness phasing (Parker & Lin, k = h Z_s mod N):")
            for r in rows:
                print(f"  h={r['h']}  k={r['k']}  {r['kind']:<15} sun meshes {r['signs']}")
    if out["frequency_groups"]:
        print(f"\nfrequency groups (members multiples <= {MAX_MULTIPLIER} of a group base, "
              f"at {args.input_rpm:g} rpm):")
        for k, grp in enumerate(out["frequency_groups"]):
            print(f"  {k + 1}: base {grp['base_hz']:.2f} Hz: " + ", ".join(
                f"{m} x{mu}" for m, mu in zip(grp["members"], grp["multipliers"])))
    print("\nmeshes (mean stiffness at the static load; harmonics relative to the mean):")
    print_meshes(out["meshes"])
    print(f"solver: {out['solver_plan']}")
    h = out["harmonics"]
    if h is not None:
        print(f"\nharmonic balance: at least K = {h['floor']} harmonics of the base "
              f"({h['floor_rule']}); the first choice of K reaches {h['cutoff_hz']:.0f} Hz "
              f"(5/3 of the highest mesh mode, {h['mesh_mode_hz']:.0f} Hz); a sweep checks "
              "it against 2K")
    return EXIT_OK


def print_meshes(meshes: list[dict]) -> None:
    for m in meshes:
        amps = " ".join(f"{h['amplitude']:.3f}" for h in m["harmonics"])
        print(f"  {m['stage']}.{m['side']:<4} {m['source']:<22} contact ratio "
              f"{m['contact_ratio']:.3f}  mean {m['mean_stiffness']:.4g} N/m  "
              f"harmonics {amps or '-'} (beyond: {100 * m['truncation']:.1f}% RMS)")
        if m["iso_mesh"] is not None:
            print(f"  {'':>6} operating pressure angle {m['pressure_angle_deg']:.3f} deg, centre "
                  f"distance {m['centre_distance_mm']:.4f} mm, load {m['load']:.1f} N; "
                  f"ISO 6336-1 c_gamma_alpha b {m['iso_mesh']:.4g} N/m "
                  f"({100 * m['iso_difference']:+.1f}% from it)")
        if m["relief_te_um"]:
            print(f"  {'':>6} tip relief transmission error (um per harmonic): "
                  + " ".join(f"{a:.3f}" for a in m["relief_te_um"]))


def mesh_command(args, train, notes) -> int:
    from .._gear.mesh_report import mesh_report

    g = train.gear(args.gear)
    if args.stage is not None and args.stage not in train.stage_ids:
        raise fail("command line", "--stage", args.stage,
                   f"no such stage; stages are {', '.join(train.stage_ids)}")
    if args.plot and args.stage is None and len(train.stages) > 1:
        raise fail("command line", "--plot", args.plot,
                   "name the stage to draw with --stage ID")
    meshes = [m.as_dict() for m in mesh_report(train, g.name)
              if args.stage is None or m.stage == args.stage]
    out = {"train": train.name, "gear": g.name, "meshes": meshes, "warnings": notes}
    if args.plot:
        from .._plot.figures import mesh_cycle_figure

        stage = train.stage(args.stage or train.stage_ids[0])
        loads = {m["side"]: m["load"] for m in meshes if m["stage"] == stage.id}
        with atomic(args.plot) as fig:
            mesh_cycle_figure(stage, loads, title=f"{train.name}: stage {stage.id}, "
                              f"gear {g.name}").savefig(fig, dpi=120)
    if args.json:
        return emit(out)
    print(f"{train.name}: gear {g.name!r}, meshes (mean stiffness at the static load):")
    print_meshes(meshes)
    if args.plot:
        print(f"mesh cycle written to {args.plot}")
    return EXIT_OK
