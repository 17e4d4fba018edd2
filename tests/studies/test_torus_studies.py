"""Sensitivities, batched designs and the phasing optimiser on a quasi-periodic train.

The train is tests/data/two_stage_14_17.toml (mesh frequencies 14 : 17: two
incommensurate frequency groups, one torus angle per stage) with one stiffness harmonic
and orders (2, 2), as in test_torus_train.py: 13 coefficient rows of 14 coordinates, so
these tests check the machinery on the torus, not the train's converged response.

At 8500 Hz the stage-2 meshes are past a resonance: with backlash a mesh separates for
11% of the torus, the point is stable and its nearest multiplier per turn is about 0.2 from
+1, far from a fold.
"""

from __future__ import annotations

import json

import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import gearjax as gj
from gearjax._cli import main
from gearjax._engine import hb as _hb
from gearjax._engine.newton import newton_jit
from gearjax._engine.responses import mesh_responses, static_mesh_forces
from gearjax._gear.case import gear_case
from gearjax._io.results import add_displacement_waves
from gearjax._studies import harmonics as _harmonics
from gearjax._studies import optimize as O
from gearjax._studies.optimize.screen import resonance_frequencies

AT = 8500.0  # Hz, stage 1 (the reference stage): stage-2 meshes separate with backlash
MESH = "2.rp4"  # the largest RMS there
PATHS = ("2.mesh_stiffness.ring", "2.inertia.planet", "2.planet_angles_deg.3")


@pytest.fixture(scope="module")
def train(torus_h1_train):
    return torus_h1_train


def torus_problem(train, linear: bool):
    """The torus balance at orders (2, 2) of ``train``, assembled afresh (``gear_case``,
    no study code): ``(case, problem)``."""
    case = gear_case(train, "first", None, linear, torus=True)
    return case, _hb.hb_problem(case.system, _harmonics.settings_for(case.system, (2, 2)))


def resolved(train, linear: bool, f_hz: float, X0=None):
    """``(rms (m,), separation (m,), X)`` of :func:`torus_problem` at ``f_hz``, solved by
    Newton from ``X0`` (or the linear guess)."""
    case, problem = torus_problem(train, linear)
    w = jnp.asarray(float(case.omega(f_hz)))
    y0 = _hb.linear_guess(problem, w) if X0 is None else (X0 / problem.x_scale).reshape(-1)
    sol = newton_jit(problem, w, y0)
    assert bool(sol.converged)
    r = mesh_responses(problem, sol.X, w, static_mesh_forces(case.system))
    return np.asarray(r.rms_force), np.asarray(r.separation), sol.X


# ----------------------------------------------------------------------- sensitivity


@pytest.mark.slow
@pytest.mark.parametrize("linear", [True, False], ids=["linear", "backlash"])
def test_torus_sensitivity_matches_finite_differences(train, torus_h1_file, linear, capsys):
    """The implicit derivative of mesh 2.rp4's RMS force on the torus against central
    differences of independently re-solved points.

    Steps: 1e-5 of a stiffness or inertia, 1e-6 of a turn (0.00036 deg) of the planet
    angle (normalised sensitivity -38: the response turns fast with it). The central
    difference's truncation error is ``h^2 R''' / 6`` and Newton's converged noise over
    the step (relative 1e-12 or better at these quadratically converged points) adds
    ``1e-12 / (h/p) / |s|`` for a normalised sensitivity ``s`` (|s| >= 1.2 here): both
    below 1e-6. With backlash the sampled residual is piecewise smooth: a step that moves
    an AFT sample across a clearance edge differs from the derivative by the kink (at
    1e-5 of a turn the planet angle's difference is 5e-5 off, at 1e-6 2.5e-8).
    Measured agreement: 1e-9 to 3e-8, linear and with backlash; 1e-4 leaves a margin
    that a wrong derivative (the coupling through the solution left out, or the torus
    basis's bookkeeping wrong) cannot meet.
    """
    if linear:  # the command line, JSON included, for one of the two
        rc = main(["sensitivity", str(torus_h1_file), "--at", str(AT), "--harmonics", "2",
                   "--mesh", MESH, "--vary", *PATHS, "--linear", "--json"])
        assert rc == 0
        out = json.loads(capsys.readouterr().out)
        assert out["harmonics"] == [2, 2] and out["result"] == "ok"
        assert out["torus"]["G"] == 2 and out["torus"]["angle_ratio_exact"] == ["1", "17/14"]
        derivative = {row["path"]: row["derivative"] for row in out["derivatives"]}
        d, value = np.asarray([derivative[p] for p in PATHS]), out["value"]
    else:
        r = gj.sensitivity(train, "first", AT, mesh=MESH, paths=PATHS, harmonics=2)
        assert r.ok, r.message
        assert r.harmonics == (2, 2) and r.torus["G"] == 2
        assert r.stable and r.fold_distance > 0.1
        json.dumps(gj.sensitivity_json(r), allow_nan=False)
        d, value = r.derivative, r.value
    rms, separation, X0 = resolved(train, linear, AT)
    j = list(gj.gear_case(train, "first", torus=True).system.mesh_labels).index(MESH)
    assert value == pytest.approx(rms[j], rel=1e-10)
    if not linear:
        assert separation.max() > 0.05  # the backlash acts at this point
    fd = []
    for p in PATHS:
        v = float(gj.get_path(train, p))
        h = 1e-6 * 360.0 if p.endswith("_deg.3") else 1e-5 * abs(v)
        plus = resolved(gj.set_path(train, p, v + h), linear, AT, X0)[0][j]
        minus = resolved(gj.set_path(train, p, v - h), linear, AT, X0)[0][j]
        fd.append((plus - minus) / (2 * h))
    fd = np.asarray(fd)
    np.testing.assert_allclose(d, fd, rtol=1e-4, err_msg=str(dict(zip(PATHS, zip(d, fd)))))
    values = np.asarray([float(gj.get_path(train, p)) for p in PATHS])
    assert np.all(np.abs(fd * values / value) > 0.5)  # each parameter matters here


# --------------------------------------------------------------------------- designs


@pytest.mark.slow
def test_torus_designs_batched_equal_looped_and_resolved(train):
    """Three designs of the torus train with backlash (Newton), batched, against each
    solved alone and against an independent re-solve; a stage-2 phase, the origin of
    its torus angle, changes nothing but the torus grid's sampling of the contact
    edges."""
    paths = ("2.sun_ring_phase_deg", "2.stage_phase_deg")
    thetas = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 123.0]])
    freqs = [3000.0, AT]
    batch = gj.design_sweep(train, "first", paths, thetas, freqs, linear=False,
                            harmonics=2)
    assert batch.solver == "newton" and batch.harmonics == (2, 2)
    assert batch.torus["G"] == 2 and np.all(batch.converged)
    for b in range(len(thetas)):
        one = gj.design_sweep(train, "first", paths, thetas[b:b + 1], freqs, linear=False,
                              harmonics=2)
        np.testing.assert_allclose(one.rms_force[0], batch.rms_force[b], rtol=1e-12)
    t1 = gj.set_path(train, paths[0], 40.0)
    for k, f in enumerate(freqs):
        np.testing.assert_allclose(batch.rms_force[1, k], resolved(t1, False, f)[0],
                                   rtol=1e-9)
    # the sun-ring phase matters; the phase of a whole torus angle does not (exactly in a
    # linear balance; with backlash up to the sampling of the clearance edges, 3e-4)
    assert np.max(np.abs(batch.rms_force[1] - batch.rms_force[0]) / batch.rms_force[0]) > 0.01
    np.testing.assert_allclose(batch.rms_force[2], batch.rms_force[1], rtol=1e-3)


# ------------------------------------------------------------------------- optimiser


def test_torus_proxy_equals_the_periodic_proxy(train):
    """The 14 : 17 train also has a periodic form (mu = (14, 17)): the first-order proxy
    sums the same tones, so the torus proxy (tones on two angles) equals it to
    rounding; so do the resonance frequencies of the common grid. On the torus the
    stage phase of stage 2, alone on its angle, changes no proxy value."""
    tor = gear_case(train, "first", linear=True, torus=True)
    per = gear_case(train, "first", linear=True)
    assert tor.G == 2 and per.G == 1 and per.mu == (14, 17)
    f = np.geomspace(2000.0, 12000.0, 7)
    ft, fp = O.first_order(tor.system, tor.omega(f)), O.first_order(per.system, per.omega(f))
    assert ft.order_angles == (0, 1) and fp.orders == (14, 17)
    np.testing.assert_allclose(ft.tone_rates, fp.tone_rates / 14, rtol=1e-15)
    np.testing.assert_allclose(O.first_order_rms(ft, tor.system),
                               O.first_order_rms(fp, per.system), rtol=1e-12)
    np.testing.assert_allclose(resonance_frequencies(tor.system, ft.tone_rates, 1.0, 2e3, 12e3),
                               resonance_frequencies(per.system, fp.tone_rates, 14, 2e3, 12e3))
    sets = np.array([[0.0, 90.0, 180.0, 270.0], [0.0, 86.4, 176.4, 270.0]])
    every = np.ones(tor.system.n_meshes, dtype=bool)
    on_torus = O.proxy_screen(train, "first", "1", sets, [0.0, 90.0], tor.omega(f), every,
                              chunk=2, depth=3, layout=tor.layout)
    periodic = O.proxy_screen(train, "first", "1", sets, [0.0, 90.0], per.omega(f), every,
                              chunk=2, depth=3)
    np.testing.assert_allclose(on_torus, periodic, rtol=1e-12)
    phased = O.proxy_screen(train, "first", "2", sets[:1], [0.0], tor.omega(f), every,
                            chunk=2, depth=3, layout=tor.layout, stage_phases_deg=[0.0, 50.0])
    np.testing.assert_allclose(phased[0, 0, 0], phased[0, 0, 1], rtol=1e-12)


def test_torus_stage_phase_origins(train, torus_h1_file, capsys):
    """Each frequency group's first stage phase is its angle's origin: left out of the
    default variables and refused, with the reason, from the command line."""
    assert O.default_vary(train, "first") == [
        "1.planet_angles_deg", "1.sun_ring_phase_deg", "2.planet_angles_deg",
        "2.sun_ring_phase_deg"]
    rc = main(["optimize", str(torus_h1_file), "--band", "3000", "3300",
               "--vary", "2.stage_phase_deg", "--json"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert "torus angle 1" in err and "changes no RMS" in err


@pytest.mark.slow
def test_torus_optimize_from_the_command_line(train, torus_h1_file, tmp_path, capsys):
    """``gearjax optimize --json`` on the torus train with a tiny budget: a valid result
    that names the torus and its orders, an optimum no worse than the baseline on the
    linear model, and linear forces on the common grid that an independent re-solve of
    the optimum train reproduces."""
    saved = tmp_path / "optimize.nc"
    rc = main(["optimize", str(torus_h1_file), "--band", "3000", "3300",
               "--vary", "1.sun_ring_phase_deg", "2.sun_ring_phase_deg", "--harmonics", "2",
               "--points", "4", "--final-points", "3", "--proxy-points", "8",
               "--phase-grid", "2", "--screen", "1", "--nonlinear", "0",
               "--relax-iterations", "0", "--out", str(saved), "--json"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "Traceback" not in captured.err and "torus harmonic balance" in captured.err
    out = json.loads(captured.out)
    assert out["harmonics"] == [2, 2] and out["torus"]["G"] == 2
    assert out["vary"] == ["1.sun_ring_phase_deg", "2.sun_ring_phase_deg"]
    b, o = out["baseline"], out["optimum"]
    assert np.isfinite(b["linear_peak"]) and o["linear_peak"] <= b["linear_peak"]
    assert o["nonlinear_peak"] is None and out["improvement"]["linear"] <= 1.0
    assert [s["stage"] for s in out["stages"]] == ["1", "2"]
    assert all(np.isfinite(c["linear_peak"]) for c in out["candidates"])
    ds = gj.load_results(saved)
    assert json.loads(ds.attrs["harmonics"]) == [2, 2]
    rms = ds["linear_rms"].sel(design="optimum").values  # (frequency, mesh)
    assert o["linear_peak"] == pytest.approx(float(np.nanmax(rms)), rel=1e-12)
    optimum = train
    for path, value in o["values"].items():
        optimum = gj.set_path(optimum, path, value)
    for k, f in enumerate(ds["frequency"].values):
        np.testing.assert_allclose(rms[k], resolved(optimum, True, float(f))[0], rtol=1e-9)


def test_recheck_starts_integration_on_the_torus_solution(train):
    """The re-check integrates from a saved sweep point's state at ``t = 0``: on a torus
    it is read from the wave-vector coefficients and equals the state of the solution
    on its basis (:func:`gearjax.hb_initial_state`)."""
    case, problem = torus_problem(train, True)
    _, _, X = resolved(train, True, 3000.0)
    w = float(case.omega(3000.0))
    ds = xr.Dataset({"omega": ("point", [w])})
    ds = add_displacement_waves(ds, [np.asarray(X)], case.system.dof_labels, [(2, 2)],
                                [problem.basis.orders], case.system.angle_ratio)
    x0, v0 = O.rechecking.point_state(ds, 0)
    x_ref, v_ref = gj.hb_initial_state(X, w, 1, problem.basis)
    np.testing.assert_allclose(x0, x_ref, rtol=1e-13, atol=1e-13 * np.max(np.abs(x_ref)))
    np.testing.assert_allclose(v0, v_ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(v_ref)))
    assert np.max(np.abs(v_ref)) > 0
