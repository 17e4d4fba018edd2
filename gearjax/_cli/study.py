"""``gearjax study``: a design study on a Dask cluster."""

from __future__ import annotations

from .._errors import fail
from .outputs import study_store
from .report import EXIT_OK, brief, emit, to_stderr


def study_command(args, train, notes) -> int:
    from .._studies.study import load_study, study
    from .._studies.study.report import study_json

    spec = load_study(args.study)
    store = study_store(args)
    client = None
    if args.scheduler is not None:
        if args.workers is not None:
            raise fail("command line", "--workers", args.workers,
                       "is for the local cluster; --scheduler names a cluster with its own "
                       "workers")
        from dask.distributed import Client

        try:
            client = Client(args.scheduler, timeout=30)
        except OSError as e:
            raise fail("command line", "--scheduler", args.scheduler,
                       f"no Dask scheduler answers there ({brief(e, 120)})") from None
    try:
        result = study(spec, store, client=client, workers=args.workers, resume=args.resume,
                       say=to_stderr)
    finally:
        if client is not None:
            client.close()
    out = study_json(result)
    out["warnings"] = notes
    if args.json:
        return emit(out)
    print(f"study {spec.source}: {out['candidates']} candidates ({out['design']}) in "
          f"{store}: {out['ran']} run now, {out['skipped']} before, {out['refused']} "
          f"refused, {out['failed']} failed, {out['missing']} missing "
          f"({out['seconds']:.0f} s)")
    for rec in out["results"]:
        values = "; ".join(f"{p} = {v:g}" if isinstance(v, float) else f"{p} = {v}"
                           for p, v in rec["values"].items())
        merits = [f"first mode {rec['first_elastic_hz']:.1f} Hz"
                  if rec["first_elastic_hz"] is not None else ""]
        for kind in ("linear", "backlash"):
            if rec[kind] is not None:
                peaks = ", ".join(f"{s} {_kilo(f)}" for s, f in
                                  rec[kind]["peak_rms_force"].items())
                merits.append(f"{kind} peak RMS {peaks}")
        check = rec["verify"]
        if check is not None and check["max_rel_diff"] is not None:
            merits.append(f"verify {check['max_rel_diff']:.2%} "
                          f"({'within' if check['ok'] else 'beyond'} {check['tolerance']:.0%})")
        tail = rec["reason"] if rec["status"] != "done" else "; ".join(m for m in merits if m)
        print(f"{rec['candidate']:>6} {rec['status']:<8} {values}: {tail}")
    return EXIT_OK


def _kilo(force: float | None) -> str:
    return "-" if force is None else f"{force / 1e3:.2f} kN"
