"""An independent re-check of a phasing optimisation: fresh complete sweeps with backlash
(the sweep's own harmonics: every stable state the sweep and its completion find), time
integration from their peak orbits and :func:`gearjax.verify_gear` at the peak
frequencies, for the baseline and the optimum, and the verdict: whether the optimum's
fresh peak is below the baseline's, or that no admissible phasing the optimiser tried
beats the baseline (then the recommended design is the baseline)."""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable, Sequence

import jax.numpy as jnp
import numpy as np
import pandas as pd

from ..._engine.time_domain import hb_initial_state
from ..._gear.toml_io import dumps_train, loads_train
from ..._io.results import displacement_coefficients
from ..simulate import simulate_gear
from ..verify import verify_gear
from .nonlinear import NONLINEAR_RTOL, BandSettings, band_of, complete_sweep
from .nonlinear import band_peak as band_peak
from .result import OptimizeResult, verdict
from .settings import check_band


@dataclasses.dataclass(frozen=True)
class Recheck:
    """An independent re-check of a phasing optimisation (:func:`recheck`).

    **Fields:** ``band_hz``: the band swept; ``sweeps``: ``{"baseline", "optimum"}`` ->
    :class:`~gearjax.SweepResult`, fresh complete sweeps with backlash (``settings``, a
    :class:`.nonlinear.BandSettings`: by default the sweep's own frequency-dependent
    harmonics); ``bands``: the same keys -> :class:`.nonlinear.NonlinearBand` (the peak
    over every stable state); ``verdict``: :func:`.result.verdict` of the fresh peaks
    (plus, in its text, an integration that does not confirm a peak); ``trains``: the
    same keys -> the designs' trains; ``orbits``: the same
    keys -> results Dataset of the time integration started from the sweep's peak orbit
    (one point); ``verify``: the same keys -> :class:`~gearjax.VerifyResult` at
    ``verify_hz`` (harmonic balance solved afresh at each point, then integrated);
    ``peaks``: ``pandas.DataFrame``, one row per design: the optimiser's peaks (linear,
    with backlash), the fresh sweep's peak over its stable points (N), where and on which
    mesh, how the peak's branch was found, the peak of the sweep's walk alone, the
    integration's RMS of that mesh from that orbit and their difference, the sweep's
    points, unstable points, branches, restarts, stop and whether it is complete;
    ``points``: ``pandas.DataFrame``,
    one row per design and ``verify_hz`` frequency: the largest RMS mesh force by
    harmonic balance and by integration (N), the largest stage-relative difference, the
    integration result, whether every mesh is within the tolerance; ``seconds``.
    """

    band_hz: tuple[float, float]
    verify_hz: tuple[float, ...]
    sweeps: dict
    orbits: dict
    verify: dict
    peaks: object
    points: object
    seconds: float
    settings: BandSettings = BandSettings()
    bands: dict = dataclasses.field(default_factory=dict)
    verdict: dict = dataclasses.field(default_factory=dict)
    trains: dict = dataclasses.field(default_factory=dict)

    @property
    def recommended(self) -> str:
        """``"optimum"`` where its fresh peak beats the baseline's, else ``"baseline"``."""
        return self.verdict.get("recommended", "baseline")

    @property
    def recommended_train(self):
        """The train of the :attr:`recommended` design."""
        return self.trains[self.recommended]


INTEGRATION_RTOL = 0.02
"""An integration from a peak orbit confirms it where it converges and its RMS of the
peak mesh is within this (relative) of the sweep's (the tolerance with backlash of
:func:`gearjax.verify_gear`)."""


def point_state(ds, i: int):
    """``(x0, v0)`` ``(n,)``: the state at ``t = 0`` of point ``i`` of a sweep Dataset
    (its ``displacement_cos`` / ``displacement_sin`` harmonics), to start an integration
    on that orbit (:func:`~gearjax.hb_initial_state`). On a torus (coordinate
    ``wave_vector``) ``x(t) = sum_k cos_k cos(nu_k Omega t) + sin_k sin(nu_k Omega t)``
    with ``nu_k`` the ``wave_frequency``: ``x0 = sum_k cos_k``, ``v0 = Omega sum_k nu_k
    sin_k``, a state on the torus solution for the windowed integration."""
    if "wave_vector" in ds.coords:
        cos = np.asarray(ds["displacement_cos"].values[i], dtype=float)  # (n, waves)
        sin = np.asarray(ds["displacement_sin"].values[i], dtype=float)
        nu = np.asarray(ds["wave_frequency"].values, dtype=float)
        return cos.sum(axis=1), float(ds["omega"].values[i]) * (sin @ nu)
    X = displacement_coefficients(ds, i)
    eta = (ds["eta"].values[i] if "eta" in ds.variables  # per point: a doubled branch's 2
           else json_solver(ds).get("eta", 1))
    return hb_initial_state(jnp.asarray(X), float(ds["omega"].values[i]), int(eta))


def json_solver(ds) -> dict:
    """The ``solver`` attribute of a results Dataset, decoded (``{}`` where absent or
    not JSON)."""
    try:
        return json.loads(ds.attrs.get("solver", "{}"))
    except ValueError:
        return {}


def recheck_designs(result) -> tuple[str, str, tuple, dict]:
    """``(gear, reference stage, band (Hz), {name: (train, linear peak, backlash peak)})``
    (peaks in N) of an :class:`OptimizeResult` or of its Dataset.

    **Raises:** ``ValueError`` for anything else.
    """
    if isinstance(result, OptimizeResult):
        return result.gear, result.reference_stage, result.band_hz, {
            "baseline": (result.baseline_train, result.baseline.linear_peak,
                         result.baseline.nonlinear_peak),
            "optimum": (result.train, result.optimum.linear_peak,
                        result.optimum.nonlinear_peak)}
    attrs = getattr(result, "attrs", {})
    if attrs.get("kind") != "optimize":
        raise ValueError("recheck needs an OptimizeResult or its Dataset (kind 'optimize'), "
                         f"not {type(result).__name__} of kind {attrs.get('kind')!r}")
    band = attrs["band_hz"]
    band = json.loads(band) if isinstance(band, str) else list(band)
    peak = lambda key: float(attrs.get(key, math.nan))
    return str(attrs["gear"]), str(attrs["reference_stage"]), tuple(band), {
        "baseline": (loads_train(attrs["baseline_train_toml"]), peak("baseline_peak_linear"),
                     peak("baseline_peak_nonlinear")),
        "optimum": (loads_train(attrs["train_toml"]), peak("optimum_peak_linear"),
                    peak("optimum_peak_nonlinear"))}


def recheck(
    result,
    band_hz: tuple[float, float] | None = None,
    *,
    verify_hz: Sequence[float] | None = None,
    harmonics: int | None = None,
    max_step_hz: float | None = None,
    max_points: int = 3000,
    seeds: int = 0,
    progress: Callable[[str], None] | None = None,
) -> Recheck:
    """Re-check the baseline and the optimum of ``result`` independently of the optimiser.

    ``result``: an :class:`OptimizeResult`, or the Dataset of a saved one
    (:func:`optimize_dataset`, ``gearjax optimize --out``; ``gj.load_results``).

    For each design: (1) a fresh complete sweep with backlash over ``band_hz`` (default
    the optimisation's band; a part of it around the peaks is cheaper) by
    :func:`gearjax.sweep` (``complete=True``) with its own frequency-dependent harmonics
    (``harmonics``: a fixed K instead), ``max_step_hz``, ``max_points`` and ``seeds``;
    its peak over every stable state (:func:`.nonlinear.band_peak`: ``stable == 1``,
    result ``converged``, runaway points left out); (2) time integration (diffrax)
    started from the sweep's peak
    orbit: a stable orbit is what the integration settles on, with the same RMS; (3)
    :func:`gearjax.verify_gear` at ``verify_hz`` (default: the fresh peak frequencies of
    both designs), the harmonic balance solved afresh there and integrated. On a torus
    (``G > 1`` incommensurate groups) the sweeps are torus continuations and both
    integrations are windowed ones (:func:`gearjax.simulate_gear`,
    :func:`gearjax.verify_gear`). Then the verdict (:func:`.result.verdict` on the fresh
    peaks, :data:`.nonlinear.NONLINEAR_RTOL`): the optimum's fresh peak is below the
    baseline's by so much, or no admissible phasing the optimiser tried beats the
    baseline and the recommended design is the baseline.

    **Returns:** :class:`Recheck` (tables ``peaks`` and ``points``, ``verdict``).
    **Raises:**
    ``ArgumentError`` naming ``band_hz`` for a bad band; ``ValueError`` for a
    ``result`` of another kind; ``TrainError`` as :func:`gearjax.sweep`.
    """
    t0 = time.perf_counter()
    say = progress or (lambda message: None)
    gear, ref, band, designs = recheck_designs(result)
    lo, hi = check_band(band if band_hz is None else band_hz)
    settings = BandSettings(harmonics=harmonics, max_step_hz=max_step_hz,
                            max_points=max_points, seeds=seeds)
    same = dumps_train(designs["baseline"][0]) == dumps_train(designs["optimum"][0])
    sweeps, bands, orbits, peak_rows, peak_at = {}, {}, {}, [], {}
    for name, (train, linear_peak, nonlinear_peak) in designs.items():
        if name == "optimum" and same:  # the optimiser kept the baseline: one design
            say("recheck: the optimum is the baseline design: its re-check is the baseline's")
            sweeps[name], bands[name] = sweeps["baseline"], bands["baseline"]
            if "baseline" in orbits:
                orbits[name] = orbits["baseline"]
            peak_rows.append({**peak_rows[0], "design": name,
                              "optimiser linear peak (N)": linear_peak,
                              "optimiser backlash peak (N)": nonlinear_peak})
            continue
        say(f"recheck: {name}, {settings.text()} with backlash {lo:g}-{hi:g} Hz")
        sw = complete_sweep(train, gear, lo, hi, ref, settings)
        sweeps[name] = sw
        ds = sw.dataset
        band = bands[name] = band_of(sw, lo, hi, settings)
        peak, f_peak, mesh, i = band_peak(ds)
        row = {"design": name, "optimiser linear peak (N)": linear_peak,
               "optimiser backlash peak (N)": nonlinear_peak,
               "sweep peak (N)": peak, "at (Hz)": f_peak, "mesh": mesh,
               "branch found by": band.peak_found, "walk peak (N)": band.walk_peak}
        if i >= 0:
            peak_at[name] = f_peak
            say(f"recheck: {name}, {ds.sizes['point']} points on {len(band.branches)} "
                f"branches in {sw.seconds:.0f} s, peak {peak:.1f} N at {f_peak:.1f} Hz "
                f"({mesh}, branch found by {band.peak_found}); integrating from that orbit")
            x0, v0 = point_state(ds, i)
            ni = simulate_gear(train, gear, [f_peak], stage=ref, x0=x0, v0=v0)
            orbits[name] = ni
            j = list(ds["mesh"].values).index(mesh)
            rms_ni = float(ni["rms_force"].values[0, j])
            row.update({"integrated (N)": rms_ni, "rel diff": abs(rms_ni - peak) / peak,
                        "integration": str(ni["result"].values[0])})
        else:
            row.update({"integrated (N)": math.nan, "rel diff": math.nan,
                        "integration": "no stable point"})
        row.update({"points": band.points, "unstable": band.unstable,
                    "runaway": band.runaway, "branches": len(band.branches),
                    "restarts": len(sw.restarts), "stop": sw.stop, "complete": band.complete,
                    "sweep seconds": sw.seconds})
        peak_rows.append(row)
    outcome = _fresh_verdict(same, bands, peak_rows, settings)
    say(f"recheck: {outcome['text']}")
    if verify_hz is None:
        verify_hz = sorted({round(f, 3) for f in peak_at.values()})
    verify_hz = tuple(float(f) for f in verify_hz)
    checks, point_rows = {}, []
    if verify_hz:
        for name, (train, *_) in designs.items():
            if name == "optimum" and same:
                checks[name] = checks["baseline"]
                point_rows += [{**r, "design": name} for r in point_rows]
                continue
            say(f"recheck: {name}, harmonic balance and time integration at "
                f"{', '.join(f'{f:g}' for f in verify_hz)} Hz")
            v = verify_gear(train, gear, list(verify_hz), stage=ref, harmonics=harmonics)
            checks[name] = v
            for k, f in enumerate(verify_hz):
                hb_row, ni_row = v.rms_hb[k], v.rms_ni[k]
                j = int(np.nanargmax(hb_row)) if np.any(np.isfinite(hb_row)) else 0
                point_rows.append({
                    "design": name, "Hz": f, "mesh": str(v.hb["mesh"].values[j]),
                    "harmonic balance (N)": float(hb_row[j]),
                    "integration (N)": float(ni_row[j]),
                    "max rel diff": float(np.nanmax(v.rel_diff[k]))
                    if np.any(np.isfinite(v.rel_diff[k])) else math.nan,
                    "hb stable": bool(v.hb["stable"].values[k] == 1),
                    "integration": str(v.ni["result"].values[k]),
                    "all meshes ok": bool(np.all(v.ok[k]))})
    return Recheck(band_hz=(lo, hi), verify_hz=verify_hz, sweeps=sweeps, orbits=orbits,
                   verify=checks, peaks=pd.DataFrame(peak_rows).set_index("design"),
                   points=pd.DataFrame(point_rows), seconds=time.perf_counter() - t0,
                   settings=settings, bands=bands, verdict=outcome,
                   trains={name: d[0] for name, d in designs.items()})


def _fresh_verdict(same: bool, bands: dict, rows: list, settings: BandSettings) -> dict:
    """:func:`.result.verdict` of the fresh complete-sweep peaks (``same``: the optimum is
    the baseline design), with a note where an integration from a peak orbit does not
    confirm it (:data:`INTEGRATION_RTOL`)."""
    unconfirmed = [f"{r['design']} ({r['integration']}, rel diff {r['rel diff']:.2g})"
                   for r in rows if not (r["integration"] == "converged"
                                         and r["rel diff"] <= INTEGRATION_RTOL)]
    out = verdict(bands["baseline"].peak, bands["optimum"].peak, same=same,
                  rtol=NONLINEAR_RTOL, model="fresh complete-sweep peak with backlash",
                  settings=f"re-check: {settings.text()}",
                  incomplete=[n for n in ("baseline", "optimum") if not bands[n].complete],
                  notes=["time integration from the peak orbit does not confirm the peak "
                         f"of the {', '.join(unconfirmed)}"] if unconfirmed else [])
    out["integration_confirms"] = not unconfirmed
    return out


def recheck_json(check: Recheck) -> dict:
    """A :class:`Recheck` as JSON: ``band_hz``, ``settings`` (the fresh sweeps'),
    ``verdict``, ``recommended``, ``peaks`` (one record per design), ``points`` (the
    verification points), ``verify_hz``, ``seconds``."""
    def records(frame):
        return json.loads(frame.reset_index().to_json(orient="records")) if len(frame) else []

    return {"band_hz": list(check.band_hz), "settings": check.settings.as_dict(),
            "verdict": check.verdict, "recommended": check.recommended,
            "peaks": records(check.peaks), "points": records(check.points),
            "verify_hz": list(check.verify_hz), "seconds": check.seconds}
