"""The optimiser: stage by stage, proxy -> linear screen -> complete sweeps with backlash.

Stages are optimised one at a time, in file order (``passes`` times). For each, every
distinct planet set (:func:`gearjax._gear.planet_sets.phasing_classes`: one set per class
the torsional model cannot tell apart, the best-balanced one) x a grid of sun-ring (and
stage) phases is ranked by the first-order proxy (:mod:`.proxy`); the ``screen`` best
are solved by the linear, time-varying harmonic balance (:mod:`.screen`), and the
``nonlinear`` best of those that beat the incumbent by complete sweeps with backlash
(:mod:`.nonlinear`: the peak over every stable state the sweep and its completion find,
the baseline's too, with the same settings). A candidate replaces the incumbent only
where its peak with backlash is lower by more than :data:`NONLINEAR_RTOL` and its sweep
is as trustworthy (:func:`trusted`); so no step makes the objective worse on the model
that decides it, and where no candidate beats the baseline the optimum *is* the baseline
(:func:`.result.verdict` says so). Ties of the linear screen go to the better-balanced
planet set, then to the incumbent (:mod:`.ranking`).

A gear whose mesh frequencies fall in ``G > 1`` incommensurate groups is optimised on its
torus (model.md, "Incommensurate stages"): the proxy sums the tones of every angle, the
linear screen is the torus harmonic balance at each angle's excitation floor (or
``harmonics`` on every angle), the sweeps with backlash are the sweep's torus
continuation, and each group's first stage phase is an origin, not a variable
(:func:`.variables.phase_origins`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..._gear.case import gear_case, torus_fields
from ..._gear.paths import get_path
from ..._gear.planet_sets import (
    admissible_planet_sets,
    phasing_classes,
    planet_imbalance,
    planet_set_ok,
)
from ..._gear.train import Train
from .. import harmonics as _harmonics
from ..design import orders_of, peak_of, peak_truncation, truncation_json, warn_truncation
from ..sweep.default_band import default_band
from .nonlinear import NONLINEAR_RTOL, BandSettings, NonlinearBand, nonlinear_band
from .proxy import proxy_screen
from .ranking import RANK_RTOL, band_profile, leximax_order
from .relaxation import relax
from .result import Design, OptimizeResult, verdict
from .screen import Screen, peak_indices, resonance_frequencies
from .settings import OptimizeSettings, check_band, check_settings
from .variables import StageVariables, phasing_variables, theta_of, with_stage


@dataclasses.dataclass(frozen=True)
class StageStudy:
    """What every stage step of one optimisation shares.

    **Fields:** ``gear``; ``paths``: the design vector's TOML paths; ``screen``: the
    models over it (:class:`.screen.Screen`); ``settings``; ``mesh_stage`` ``(m,)``: the
    stage id of every mesh; ``sweep_band(train)``: the band swept with backlash
    (:class:`.nonlinear.NonlinearBand`); ``say(message)``: progress; ``layout``: the
    gear's torus layout (``None``: periodic).
    """

    gear: str
    paths: tuple[str, ...]
    screen: Screen
    settings: OptimizeSettings
    mesh_stage: np.ndarray
    sweep_band: Callable[[Train], NonlinearBand]
    say: Callable[[str], None]
    layout: object = None


def optimize(
    train: Train,
    gear: str | None = None,
    band_hz: tuple[float, float] | None = None,
    vary: Sequence[str] | None = None,
    *,
    stage: str | None = None,
    settings: OptimizeSettings = OptimizeSettings(),
    progress: Callable[[str], None] | None = None,
) -> OptimizeResult:
    """Planet sets and phases of ``gear`` that minimise the peak RMS mesh force over a band.

    **Arguments:** ``band_hz``: ``(lo, hi)`` reference-stage mesh frequencies (Hz);
    ``None``: the band a sweep of the gear chooses from its modes and excitation orders
    (:mod:`~gearjax._studies.sweep.default_band`), said through ``progress``;
    ``vary``: phasing paths (:mod:`.variables`; default
    :func:`.variables.default_vary`); ``stage``: the reference stage of the frequencies
    (default: the first turning one); ``settings``: :class:`OptimizeSettings`;
    ``progress(message)``: called per step.

    **Returns:** :class:`OptimizeResult`; the baseline's, optimum's and relaxation's
    linear peaks are on one common grid (``final_points`` geometric points plus the
    proxy peaks of each), the candidates' on their screen grids. **Raises:**
    ``TrainError`` for a bad gear or stage, or backlash on an unloaded stage (with
    ``settings.nonlinear``); ``ArgumentError`` naming ``band_hz``, ``vary`` or the
    :class:`OptimizeSettings` field for a bad band, paths or settings out of range.
    """
    t_start = time.perf_counter()
    say = progress or (lambda message: None)
    case = gear_case(train, gear, stage, linear=not settings.nonlinear, torus=True)
    g, ref, mu_ref, nominal = case.gear, case.stage, case.mu_ref, case.system
    band = None if band_hz is None else check_band(band_hz)
    check_settings(settings)
    variables = phasing_variables(train, g.name, vary)
    if band is None:  # the inputs are valid: choose the band, and say it
        chosen = default_band(case)
        say(f"optimize: no band given: {chosen.from_hz:.1f}-{chosen.to_hz:.1f} Hz, chosen "
            f"{chosen.reason}")
        band = check_band((chosen.from_hz, chosen.to_hz))
    lo, hi = band
    paths = tuple(p for v in variables for p in v.paths)
    K = orders_of(nominal, settings.harmonics)  # a tuple of orders per angle on a torus
    # the sweeps take one K for every angle
    K_nl = settings.nonlinear_harmonics or (max(K) if isinstance(K, tuple) else K)
    for k in dict.fromkeys([K, (int(K_nl),) * case.G if case.G > 1 else int(K_nl)]):
        _harmonics.require_harmonics(nominal, max(k) if isinstance(k, tuple) else k)
        _harmonics.require_size(nominal, k, mu=case.mu)
    hb_settings = _harmonics.settings_for(nominal, K)
    n_peaks = settings.screen_points // 2
    f_shared = np.geomspace(lo, hi, settings.screen_points - n_peaks)
    f_proxy = np.geomspace(lo, hi, settings.proxy_points)
    screen = Screen(train, g.name, paths, f_proxy, f_shared, n_peaks, case.omega, hb_settings,
                    settings.devices, settings.screen + 1, layout=case.layout)
    groups = np.asarray(nominal.mesh_group)

    band_settings = BandSettings(harmonics=int(K_nl), max_step_hz=settings.max_step_hz,
                                 max_points=settings.max_points, seeds=settings.seeds)

    def sweep_band(t):
        return nonlinear_band(t, g.name, lo, hi, stage=ref, settings=band_settings,
                              progress=say)

    study = StageStudy(gear=g.name, paths=paths, screen=screen, settings=settings,
                       mesh_stage=groups, sweep_band=sweep_band, say=say, layout=case.layout)
    torus = (f"; {case.G} incommensurate frequency groups: the torus harmonic balance"
             if case.G > 1 else "")
    say(f"optimize: gear {g.name!r}, band {lo:g}-{hi:g} Hz (stage {ref}), varying "
        f"{', '.join(n for v in variables for n in v.names)}; linear screen K = "
        f"{_harmonics.orders_text(K)}, {settings.screen_points} frequencies per candidate"
        + torus)
    models = _models(settings, K, band_settings if settings.nonlinear else None)
    base_nl = None
    if settings.nonlinear:
        say(f"optimize: baseline, with backlash: {band_settings.text()}")
        base_nl = sweep_band(train)
        say(f"optimize: baseline peak {base_nl.peak:.1f} N (backlash, every stable state)")
    current, cur_nl = train, base_nl
    rows: list[dict] = []
    stages_info = []
    for k in range(settings.passes):
        for v in variables:
            current, cur_nl, info = _optimise_stage(study, current, v, cur_nl, rows)
            stages_info.append({"pass": k + 1, **info})
    relaxation, relaxed_theta = None, None
    theta_opt = theta_of(current, paths)
    # where the linear peaks of any phasing sit: in the relaxation's grid and the common one
    f_res = resonance_frequencies(nominal, screen.fo.tone_rates, mu_ref, lo, hi)
    if settings.relax_iterations:
        f_relax = np.unique(np.concatenate([f_res, screen.grids(theta_opt[None])[0]]))
        say(f"optimize: continuous relaxation (L-BFGS on the linear model at {f_relax.size} "
            "frequencies: the resonances and the optimum's screen grid)")
        t0 = time.perf_counter()
        relaxation, relaxed_theta = relax(current, variables, paths, screen, f_relax, settings)
        say(f"optimize: relaxation: {relaxation.iterations} iterations in "
            f"{time.perf_counter() - t0:.1f} s ({relaxation.message})")
    # the common grid of the reported linear peaks
    finals = [theta_of(train, paths), theta_opt] + (
        [relaxed_theta] if relaxed_theta is not None else [])
    per_f = np.max(screen.proxy(np.asarray(finals)), axis=-1)
    peaks = np.concatenate([screen.f_proxy[peak_indices(row, n_peaks)] for row in per_f])
    f_final = np.unique(np.concatenate([np.geomspace(lo, hi, settings.final_points), peaks,
                                        f_res]))
    models["final"]["frequencies"] = int(f_final.size)
    say(f"optimize: baseline and optimum{' and relaxation' if relaxation else ''} on a "
        f"common grid of {f_final.size} frequencies")
    final_rms = screen.rms(np.asarray(finals), np.broadcast_to(f_final, (len(finals),
                                                                          f_final.size)),
                           batch=len(finals))
    truncation = peak_truncation(screen.family, nominal, np.asarray(finals),
                                 case.omega(f_final), final_rms, K, devices=settings.devices)
    models["final"]["truncation"] = truncation_json(truncation)
    say("optimize: truncation check at each design's linear peak, K = "
        f"{_harmonics.orders_text(K)}: " + "; ".join(
            f"against {_harmonics.orders_text(c['K_check'])}: "
            + (f"{c['change']:.2%}" if c["change"] is not None else c.get("skipped", "failed"))
            for c in truncation["checks"]) + f" (target {truncation['target']:.1%})")
    warn_truncation(truncation, "optimize", "the linear screen ranked its candidates at this "
                    "K: give a larger `harmonics`")
    baseline = _design(study, variables, train, final_rms[0], base_nl)
    optimum = _design(study, variables, current, final_rms[1], cur_nl)
    if relaxation is not None:
        relaxation = dataclasses.replace(relaxation, linear_peak=float(np.nanmax(final_rms[2])),
                                         linear_rms=final_rms[2])
        say(f"optimize: relaxed peak {relaxation.linear_peak:.1f} N (linear; not "
            f"assemblable: {relaxation.assembly_violations} planets off a slot, up to "
            f"{relaxation.max_slot_offset:.2f} slot)")
    say(f"optimize: peak {baseline.linear_peak:.1f} -> {optimum.linear_peak:.1f} N (linear)"
        + (f", {baseline.nonlinear_peak:.1f} -> {optimum.nonlinear_peak:.1f} N (backlash)"
           if base_nl is not None else ""))
    outcome = _verdict(settings, baseline, optimum, current is train, models)
    say(f"optimize: {outcome['text']}")
    return OptimizeResult(
        gear=g.name, reference_stage=ref, band_hz=(lo, hi),
        vary=tuple(n for v in variables for n in v.names), paths=paths, baseline=baseline,
        optimum=optimum, train=current, baseline_train=train, relaxation=relaxation,
        candidates=_columns(rows, max(v.n_planets for v in variables)), stages=stages_info,
        frequencies_hz=f_final, meshes=tuple(nominal.mesh_labels),
        mesh_stage=tuple(nominal.mesh_group), mesh_side=tuple(nominal.mesh_side),
        mesh_planet=tuple(nominal.mesh_planet), settings=settings,
        seconds=time.perf_counter() - t_start, harmonics=K, torus=torus_fields(case),
        models=models, verdict=outcome)


def _models(settings: OptimizeSettings, K, band: BandSettings | None) -> dict:
    """Which model and settings each step of the optimisation used (JSON values):
    ``proxy``, ``linear`` (the screen), ``backlash`` (the complete sweeps; ``None``
    where ``nonlinear = 0``), ``final`` (the common grid) and ``relaxation``."""
    K = list(K) if isinstance(K, tuple) else K
    return {
        "proxy": {"model": "first order in the stiffness variation (linear)",
                  "frequencies": settings.proxy_points, "phase_grid": settings.phase_grid},
        "linear": {"model": "linear time-varying harmonic balance (no backlash)",
                   "harmonics": K, "frequencies_per_candidate": settings.screen_points,
                   "candidates_per_stage": settings.screen},
        "backlash": None if band is None else {
            "model": "complete sweeps with backlash: the largest RMS mesh force over every "
                     "stable state (stable == 1, result converged; runaway points left out)",
            "candidates_per_stage": settings.nonlinear, "text": band.text(), **band.as_dict()},
        "final": {"model": "linear time-varying harmonic balance (no backlash)",
                  "harmonics": K, "geometric_frequencies": settings.final_points},
        "relaxation": {"model": "linear time-varying harmonic balance, L-BFGS",
                       "iterations": settings.relax_iterations},
    }


def _verdict(settings: OptimizeSettings, baseline: Design, optimum: Design, same: bool,
             models: dict) -> dict:
    """:func:`.result.verdict` of the optimum against the baseline on the model that
    decided: the complete sweeps with backlash, or (``nonlinear = 0``) the linear one."""
    if settings.nonlinear and baseline.nonlinear is not None:
        b, o = baseline.nonlinear, optimum.nonlinear
        return verdict(b.peak, o.peak, same=same, rtol=NONLINEAR_RTOL,
                       model="complete-sweep peak with backlash",
                       settings=models["backlash"]["text"],
                       incomplete=[name for name, nl in (("baseline", b), ("optimum", o))
                                   if not nl.complete])
    return verdict(baseline.linear_peak, optimum.linear_peak, same=same, rtol=RANK_RTOL,
                   model="linear peak", settings="linear time-varying model, no backlash "
                   "(nonlinear = 0): a design that must hold with backlash needs the sweeps")


def _design(study: StageStudy, variables, t: Train, rms, nl) -> Design:
    """The :class:`Design` of train ``t`` with linear RMS ``rms`` ``(F, m)`` (N) and band
    with backlash ``nl`` (or ``None``)."""
    values = {p: float(get_path(t, p, "vary")) for p in study.paths}
    sets = {v.stage: np.asarray(t.stage(v.stage).planet_angles_deg, float)
            for v in variables if v.planets}
    adm = all(planet_set_ok(t.stage(sid), a) for sid, a in sets.items())
    groups = study.mesh_stage
    stage_peaks = {sid: float(peak_of(rms[None], groups == sid)[0])
                   for sid in dict.fromkeys(groups.tolist())}
    return Design(values=values, planet_sets=sets, linear_peak=float(peak_of(rms[None])[0]),
                  linear_stage_peaks=stage_peaks, linear_rms=rms, nonlinear=nl,
                  admissible=adm)


@dataclasses.dataclass(frozen=True)
class _ProxyRanking:
    """The proxy's ranking of one stage's candidates: planet ``sets`` ``(S, N)`` (deg),
    each with its best sun-ring phase ``gamma_of`` and stage phase ``phase_of`` (deg) and
    band profile ``best`` ``(S, depth)`` (N); ``order``: best first; ``n_all``:
    admissible sets before grouping; ``shift``: grouped up to a rotation; ``gammas``,
    ``phases``: the phase grids tried (deg)."""

    sets: np.ndarray
    gamma_of: np.ndarray
    phase_of: np.ndarray
    best: np.ndarray
    order: np.ndarray
    n_all: int
    shift: bool
    gammas: np.ndarray
    phases: np.ndarray


def _proxy_ranking(study: StageStudy, current: Train, v: StageVariables) -> _ProxyRanking:
    """Planet sets x sun-ring phases x stage phases of stage ``v.stage`` ranked by the
    first-order proxy (the proxy picks the phases per set); one set per class of sets
    the model cannot tell apart."""
    settings = study.settings
    sid = v.stage
    st = current.stage(sid)
    everywhere = np.ones(len(study.mesh_stage), dtype=bool)
    shift = bool(v.planets and v.stage_phase and current.phasing == "physical")
    if v.planets:
        every = admissible_planet_sets(st)
        reps, _ = phasing_classes(st, every, modulo_shift=shift)
        sets = every[reps]
        n_all = len(every)
    else:
        sets = np.asarray(st.planet_angles_deg, float)[None]
        n_all = 1
    grid = 360.0 * np.arange(settings.phase_grid) / settings.phase_grid
    gamma0, phase0 = float(st.sun_ring_phase_deg), float(st.stage_phase_deg)
    gammas = (gamma0 + grid if v.sun_ring else np.array([gamma0])) % 360.0
    phases = (phase0 + grid if v.stage_phase else np.array([phase0])) % 360.0
    t0 = time.perf_counter()
    proxy = proxy_screen(current, study.gear, sid, sets, gammas,
                         study.screen.to_omega(study.screen.f_proxy), everywhere,
                         settings.chunk, stage_phases_deg=phases if v.stage_phase else None,
                         layout=study.layout)
    proxy = proxy.reshape(len(sets), len(gammas) * len(phases), -1)  # (S, G P, depth)
    best_g = np.asarray([leximax_order(p)[0] for p in proxy])
    proxy_best = proxy[np.arange(len(sets)), best_g]  # (S, depth)
    balance = np.asarray([planet_imbalance(a) for a in sets])
    order = leximax_order(proxy_best, RANK_RTOL, tie=np.round(balance, 6))
    study.say(f"optimize: stage {sid}: {n_all} planet sets, {len(sets)} distinct phasings"
              + (" up to a rotation" if shift else "") + f", x {len(gammas)} sun-ring"
              + (f" x {len(phases)} stage" if v.stage_phase else "")
              + f" phases by the first-order proxy in {time.perf_counter() - t0:.1f} s; best "
              f"peak {proxy_best[order[0], 0]:.1f} N")
    return _ProxyRanking(sets=sets, gamma_of=gammas[best_g // len(phases)],
                         phase_of=phases[best_g % len(phases)], best=proxy_best, order=order,
                         n_all=n_all, shift=shift, gammas=gammas, phases=phases)


def _optimise_stage(study: StageStudy, current: Train, v: StageVariables,
                    cur_nl: NonlinearBand | None, rows: list[dict]
                    ) -> tuple[Train, NonlinearBand | None, dict]:
    """Screen, rank and choose stage ``v.stage``'s variables, from the incumbent
    ``current`` (its band with backlash ``cur_nl``, or ``None``); one row per candidate
    is appended to ``rows``.

    **Returns:** ``(train, NonlinearBand or None, summary)`` of the new incumbent.
    """
    settings, screen, say = study.settings, study.screen, study.say
    sid = v.stage
    st = current.stage(sid)
    ranked = _proxy_ranking(study, current, v)
    sets, gamma_of, phase_of, proxy_best = (ranked.sets, ranked.gamma_of, ranked.phase_of,
                                            ranked.best)
    top = ranked.order[:settings.screen]
    cands = [with_stage(current, v, sets[c], gamma_of[c], phase_of[c]) for c in top]
    t0 = time.perf_counter()
    thetas = np.asarray([theta_of(t, study.paths) for t in [current] + cands])
    rms = screen.rms(thetas, screen.grids(thetas))
    profile = band_profile(rms)
    lin_stage = peak_of(rms, study.mesh_stage == sid)
    lin_all = peak_of(rms)
    ranking = leximax_order(  # 0 is the incumbent; a tie goes to the better-balanced set
        profile, RANK_RTOL, tie=np.round([planet_imbalance(t.stage(sid).planet_angles_deg)
                                          for t in [current] + cands], 6))
    say(f"optimize: stage {sid}: {len(top)} candidates by the linear harmonic balance in "
        f"{time.perf_counter() - t0:.1f} s; best peak {lin_all[ranking[0]]:.1f} N "
        f"(incumbent {lin_all[0]:.1f} N)")
    rows.append(_row(sid, st.planet_angles_deg, float(st.sun_ring_phase_deg),
                     float(st.stage_phase_deg), math.nan, lin_stage[0], lin_all[0],
                     incumbent=True))
    row_of = [len(rows) - 1]
    for rank, c in enumerate(ranked.order):
        lin = (lin_stage[1 + rank], lin_all[1 + rank]) if rank < len(top) else (math.nan,) * 2
        rows.append(_row(sid, sets[c], gamma_of[c], phase_of[c], proxy_best[c, 0], *lin))
        if rank < len(top):
            row_of.append(len(rows) - 1)
    better = [int(i) for i in ranking[:int(np.flatnonzero(ranking == 0)[0])]
              if np.isfinite(lin_all[i])]  # candidates ranked above the incumbent
    pick = 0
    swept = 0
    if settings.nonlinear and cur_nl is not None and better:
        rows[row_of[0]].update(_nonlinear_fields(cur_nl, sid))
        results = {0: cur_nl}
        for i in better[:settings.nonlinear]:
            t = cands[i - 1]
            say(f"optimize: stage {sid}: candidate {_show_set(t.stage(sid).planet_angles_deg)}"
                f", sun-ring {float(t.stage(sid).sun_ring_phase_deg):.1f} deg, complete sweep "
                "with backlash")
            nl = study.sweep_band(t)
            swept += 1
            results[i] = nl
            rows[row_of[i]].update(_nonlinear_fields(nl, sid))
            say(f"optimize: stage {sid}: peak {nl.peak:.1f} N with backlash (incumbent "
                f"{cur_nl.peak:.1f} N), band coverage {nl.coverage:.3f}"
                + ("" if nl.complete else ", sweep not complete"))
        rank_of = {int(i): k for k, i in enumerate(ranking)}
        pick = pick_nonlinear(results, rank_of)
        new_nl = results[pick]
    else:
        pick = int(ranking[0]) if np.isfinite(lin_all[ranking[0]]) else 0
        new_nl = cur_nl if pick == 0 else None
    rows[row_of[pick]]["selected"] = True
    if pick == 0:
        chosen = "incumbent kept"
        new = (current, cur_nl)
    else:
        t = cands[pick - 1]
        chosen = (f"{_show_set(t.stage(sid).planet_angles_deg)}, sun-ring "
                  f"{float(t.stage(sid).sun_ring_phase_deg):.1f} deg"
                  + (f", stage phase {float(t.stage(sid).stage_phase_deg):.1f} deg"
                     if v.stage_phase else ""))
        new = (t, new_nl)
    say(f"optimize: stage {sid}: {chosen}")
    info = {"stage": sid, "planet_sets": int(ranked.n_all), "screened_sets": len(sets),
            "modulo_rotation": ranked.shift, "sun_ring_phases": len(ranked.gammas),
            "stage_phases": len(ranked.phases),
            "linear_screened": len(top), "nonlinear_swept": swept, "chosen": chosen}
    return (*new, info)


def trusted(nl: NonlinearBand, incumbent: NonlinearBand) -> bool:
    """Whether the complete sweep ``nl`` of a candidate may replace the ``incumbent``'s:
    a finite peak, as much of the band traced (coverage at least the incumbent's, or
    0.95), and complete wherever the incumbent's is (a sweep stopped by its budget may
    miss the stable state that would set its peak)."""
    return (bool(np.isfinite(nl.peak)) and nl.coverage >= min(0.95, incumbent.coverage)
            and (nl.complete or not incumbent.complete))


def pick_nonlinear(results: dict, rank_of: dict) -> int:
    """The key of ``results`` (``{0: incumbent band, i: candidate band}``,
    :class:`NonlinearBand`) that the stage keeps: among the :func:`trusted` candidates
    whose peak is below the incumbent's by more than :data:`NONLINEAR_RTOL` (any trusted
    one where the incumbent has no finite peak), the lowest peak, those within
    :data:`NONLINEAR_RTOL` of it ranked by the linear screen (``rank_of``); ``0`` (the
    incumbent) where none is."""
    cur = results[0]
    bar = cur.peak * (1 - NONLINEAR_RTOL) if np.isfinite(cur.peak) else math.inf
    beating = [i for i, nl in results.items()
               if i != 0 and trusted(nl, cur) and nl.peak < bar]
    if not beating:
        return 0
    low = min(results[i].peak for i in beating)
    near = [i for i in beating if results[i].peak <= low * (1 + NONLINEAR_RTOL)]
    return min(near, key=lambda i: rank_of[i])


def _nonlinear_fields(nl: NonlinearBand, sid: str) -> dict:
    """A candidate row's fields from its complete sweep with backlash ``nl``."""
    return {"nonlinear_stage_peak": nl.stage_peaks.get(sid, math.nan),
            "nonlinear_peak": nl.peak, "nonlinear_walk_peak": nl.walk_peak,
            "nonlinear_peak_hz": nl.peak_hz, "nonlinear_coverage": nl.coverage,
            "nonlinear_complete": float(nl.complete)}


def _row(stage, angles, gamma, phase, proxy, lin_stage, lin_all, incumbent=False) -> dict:
    return {"stage": stage, "planet_angles_deg": np.asarray(angles, float),
            "sun_ring_phase_deg": float(gamma), "stage_phase_deg": float(phase),
            "proxy_peak": float(proxy), "linear_stage_peak": float(lin_stage),
            "linear_peak": float(lin_all), "nonlinear_stage_peak": math.nan,
            "nonlinear_peak": math.nan, "nonlinear_walk_peak": math.nan,
            "nonlinear_peak_hz": math.nan, "nonlinear_coverage": math.nan,
            "nonlinear_complete": math.nan, "incumbent": incumbent, "selected": False}


def _columns(rows, n_max) -> dict:
    out = {k: [] for k in rows[0]} if rows else {}
    for r in rows:
        for k, val in r.items():
            if k == "planet_angles_deg":
                pad = np.full(n_max, np.nan)
                pad[:len(val)] = val
                val = pad
            out[k].append(val)
    return {k: np.asarray(v) for k, v in out.items()}


def _show_set(angles) -> str:
    return "[" + ", ".join(f"{a:g}" for a in np.asarray(angles, float)) + "] deg"
