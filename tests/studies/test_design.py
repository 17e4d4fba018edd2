"""Batched designs (vmapped, sharded), admissible planet sets, the phasing optimiser and
``gearjax optimize``.

Small sizes throughout (K = 8 on the paper train, K = 4 on a three-planet single stage,
a handful of designs and frequencies): the checks are identities (batched = looped,
sharded = unsharded, rotated set = same design), counts against brute force, and
that the optimiser improves a bad design and returns an admissible one."""

import itertools
import json
import math
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import gearjax as gj
from gearjax import _cli
from gearjax._gear import planet_sets as P
from gearjax._gear.validate import overlapping_planets
from gearjax._studies import design as D
from gearjax._studies import optimize as O

K = 8
PATHS = ("1.planet_angles_deg.2", "1.sun_ring_phase_deg", "2.stage_phase_deg")
THETAS = np.array([[90.0, 0.0, 0.0], [86.4, 30.0, 45.0], [93.6, 60.0, 90.0],
                   [82.8, 10.0, 0.0], [97.2, 200.0, 300.0]])
FREQS = (2500.0, 6000.0, 11000.0)

SMALL = (pathlib.Path(__file__).parent.parent / "data" / "three_planets.toml").read_text()
TINY = ["--band", "2000", "9000", "--harmonics", "4", "--points", "6", "--final-points", "8",
        "--proxy-points", "32", "--phase-grid", "4", "--screen", "3", "--nonlinear", "0",
        "--relax-iterations", "2"]
TINY_SETTINGS = O.OptimizeSettings(proxy_points=32, phase_grid=4, screen=3, screen_points=6,
                                   final_points=8, harmonics=4, nonlinear=0,
                                   relax_iterations=2)


@pytest.fixture(scope="module")
def paper(paper_train_h1):
    """One stiffness harmonic: the small K of these tests holds its excitation."""
    return paper_train_h1


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    path = tmp_path_factory.mktemp("small") / "small.toml"
    path.write_text(SMALL)
    return path


@pytest.fixture(scope="module")
def batched(paper):
    return D.design_sweep(paper, "first", PATHS, THETAS, FREQS, harmonics=K)


# ----------------------------------------------------------------------- batching


def test_batched_equals_looped_and_compiles_once(paper, batched):
    assert batched.solver == "linear" and batched.converged.all()
    assert batched.rms_force.shape == (len(THETAS), len(FREQS), 16)
    n_compiled = D._design_jit._cached._cache_size()
    for b in range(len(THETAS)):
        one = D.design_sweep(paper, "first", PATHS, THETAS[b:b + 1], FREQS, harmonics=K)
        rel = np.abs(one.rms_force[0] - batched.rms_force[b]) / batched.rms_force[b]
        assert rel.max() <= 1e-12
    # a batch of 1: one more program, and one for its truncation check at the peaks
    assert D._design_jit._cached._cache_size() == n_compiled + 2
    again = D.design_sweep(paper, "first", PATHS, THETAS[::-1] + 3.6, FREQS, harmonics=K)
    assert D._design_jit._cached._cache_size() == n_compiled + 2  # same shapes: no compile
    assert not np.allclose(again.rms_force[::-1], batched.rms_force)


def test_linear_solver_equals_newton(paper, batched):
    newton = D.design_sweep(paper, "first", PATHS, THETAS[:2], FREQS, harmonics=K,
                            solver="newton")
    assert newton.converged.all()
    np.testing.assert_allclose(newton.rms_force, batched.rms_force[:2], rtol=1e-9)
    with pytest.raises(gj.TrainError, match="argument solver = "):
        D.design_sweep(paper, "first", PATHS, THETAS[:1], FREQS, linear=False, solver="linear")


SHARDED = textwrap.dedent("""
    import os, json
    os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
    import jax
    jax.config.update("jax_enable_x64", True)
    import dataclasses, numpy as np, warnings
    warnings.simplefilter("ignore")
    import gearjax as gj
    from gearjax._studies import design as D
    train = dataclasses.replace(gj.load_train(), stiffness_harmonics=1)
    paths, thetas, freqs = {paths!r}, np.array({thetas!r}), {freqs!r}
    one = D.design_sweep(train, "first", paths, thetas, freqs, harmonics={K})
    four = D.design_sweep(train, "first", paths, thetas, freqs, harmonics={K},
                          devices=jax.devices())
    rel = np.abs(four.rms_force - one.rms_force) / np.abs(one.rms_force)
    print(json.dumps({{"devices": len(jax.devices()), "used": four.devices,
                      "rel": float(rel.max()), "converged": bool(four.converged.all())}}))
""")


def test_sharded_equals_unsharded():
    # 5 designs on 4 devices: padded to 8, the padding dropped
    code = SHARDED.format(paths=PATHS, thetas=THETAS.tolist(), freqs=FREQS, K=K)
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["devices"] == 4 and out["used"] == 4 and out["converged"]
    assert out["rel"] <= 1e-12


# ------------------------------------------------------------------- planet sets


def brute_force(stage, N):
    """Every set with planet 1 at 0 and the others on distinct slots, by the rule of
    validate_train (no enumeration shortcut)."""
    S = stage.teeth.sun + stage.teeth.ring
    out = []
    for rest in itertools.combinations(range(1, S), N - 1):
        angles = [0.0] + [360.0 * k / S for k in rest]
        if overlapping_planets(stage, angles) is None:
            out.append(tuple(round(a, 9) for a in angles))
    return out


def rotation_classes(sets, S):
    """Sets equal up to a rotation (and relabelling) counted once."""
    seen = set()
    for angles in sets:
        slots = [round(a * S / 360) for a in angles]
        seen.add(min(tuple(sorted((s - r) % S for s in slots)) for r in slots))
    return len(seen)


@pytest.mark.parametrize("teeth, N", [((10, 5, 20), 3), ((12, 4, 20), 4), ((9, 6, 21), 2)])
def test_planet_sets_against_brute_force(small, teeth, N):
    text = SMALL.replace("{ sun = 20, planet = 10, ring = 40 }",
                         "{ sun = %d, planet = %d, ring = %d }" % teeth)
    text = text.replace("[0, 90, 180]", "[" + ", ".join(
        f"{360 * k / N:.12g}" for k in range(N)) + "]")
    stage = gj.loads_train(text, validate=False).stages[0]
    brute = brute_force(stage, N)
    sets = P.admissible_planet_sets(stage, N)
    assert sorted(tuple(round(a, 9) for a in row) for row in sets) == sorted(brute)
    assert P.count_planet_sets(stage, N) == len(brute)
    S = sum(teeth[::2])
    classes = P.admissible_planet_sets(stage, N, modulo_rotation=True)
    assert len(classes) == rotation_classes(brute, S)
    for row in sets:
        q = S * row / 360
        assert np.allclose(q, np.round(q)) and overlapping_planets(stage, row) is None


def test_paper_stage_sets_and_rules(paper):
    st = paper.stage("1")  # 100 slots of 3.6 deg, tip 45 mm, carrier radius 43.5 mm
    assert P.min_gap_slots(st) == 18
    assert overlapping_planets(st, [0.0, 17 * 3.6]) is not None
    assert overlapping_planets(st, [0.0, 18 * 3.6]) is None
    assert math.comb(99, 3) == 156849  # placements of planets 2-4 without the overlap rule
    sets = P.admissible_planet_sets(st)
    assert len(sets) == P.count_planet_sets(st) == 4495 == math.comb(31, 3)
    assert [0, 90, 180, 270] in sets.tolist()
    assert all(P.planet_set_ok(st, row) for row in sets[::97])
    assert not P.planet_set_ok(st, [0, 90, 181, 270])  # off a slot
    assert not P.planet_set_ok(st, [0, 61.2, 180, 270])  # 17 slots: overlap
    assert 1120 <= len(P.admissible_planet_sets(st, modulo_rotation=True)) <= 1130
    # Z_s psi mod 360 takes 10 values on 100 slots: 220 distinct designs, 73 up to rotation
    reps, sizes = P.phasing_classes(st, sets)
    assert len(reps) == 220 and sizes.sum() == 4495
    assert [0, 90, 180, 270] in sets[reps].tolist()  # the balanced member represents
    assert len(P.phasing_classes(st, sets, modulo_shift=True)[0]) == 73
    assert P.planet_imbalance([0, 90, 180, 270]) == pytest.approx(0, abs=1e-15)


def test_sets_of_one_phasing_class_are_the_same_design(paper):
    # stage 2: 124 slots, Z_s = 44: the residues 44 k mod 124 repeat every 31 slots, so
    # planets on slots (20, 55, 89) and (27, 51, 86) = (89 - 62, 20 + 31, 55 + 31) have the
    # same mesh phases, relabelled
    S = 124
    a = 360 * np.array([0, 20, 55, 89]) / S
    b = 360 * np.array([0, 27, 51, 86]) / S
    c = 360 * np.array([0, 21, 55, 89]) / S  # another class
    st = paper.stage("2")
    assert all(P.planet_set_ok(st, x) for x in (a, b, c))
    reps, sizes = P.phasing_classes(st, np.array([a, b, c]))
    assert sorted(sizes.tolist()) == [1, 2]
    paths = ("2.planet_angles_deg.2", "2.planet_angles_deg.3", "2.planet_angles_deg.4")
    r = D.design_sweep(paper, "first", paths, np.array([a[1:], b[1:], c[1:]]), FREQS[:2],
                       harmonics=K)
    np.testing.assert_allclose(np.sort(r.rms_force[0], axis=-1),
                               np.sort(r.rms_force[1], axis=-1), rtol=1e-9)
    assert not np.allclose(r.rms_force[0], r.rms_force[2], rtol=1e-3)


def test_rotated_set_is_the_same_design_with_another_stage_phase(paper):
    # rotate a stage-2 set so that planet 2 becomes planet 1: every mesh of the stage then
    # moves by sigma Z_s psi_2 (the ring too, by the assembly rule), which the stage phase
    # takes back
    S, z_s = 124, 44
    sigma = gj.kinematics(paper, "first").stage("2").sigma
    gaps = [20, 31, 35, 38]
    a = 360 * np.cumsum([0] + gaps[:-1]) / S
    b = 360 * np.cumsum([0] + gaps[1:] + gaps[:1])[:-1] / S
    phase = (-sigma * z_s * a[1]) % 360  # Phi_s = -sigma Z_s psi + Gamma
    paths = ("2.planet_angles_deg.2", "2.planet_angles_deg.3", "2.planet_angles_deg.4",
             "2.stage_phase_deg")
    thetas = np.array([[*a[1:], 0.0], [*b[1:], phase]])
    r = D.design_sweep(paper, "first", paths, thetas, FREQS[:2], harmonics=K)
    stage2 = np.asarray([m.startswith("2.") for m in r.meshes])
    one, two = r.rms_force[0], r.rms_force[1]
    # the same forces, planets relabelled
    np.testing.assert_allclose(np.sort(one[:, stage2]), np.sort(two[:, stage2]), rtol=1e-9)
    np.testing.assert_allclose(one[:, ~stage2], two[:, ~stage2], rtol=1e-9)


# ---------------------------------------------------------------------- optimiser


def test_proxy_screen_matches_first_order_forces(paper):
    f = np.geomspace(2000, 15000, 12)
    w = 2 * np.pi * f / 7
    sets = np.array([[0, 90, 180, 270], [0, 72, 180, 252.0]])
    gammas = np.array([0.0, 120.0])
    every = np.ones(16, dtype=bool)
    prof = O.proxy_screen(paper, "first", "1", sets, gammas, w, every, chunk=2, depth=3)
    for i, s in enumerate(sets):
        for j, g in enumerate(gammas):
            t = O.train_at(paper, ("1.planet_angles_deg.2", "1.planet_angles_deg.3",
                                   "1.planet_angles_deg.4", "1.sun_ring_phase_deg"),
                           [*s[1:], g])
            system = gj.assemble(t, "first")
            rms = np.asarray(O.first_order_rms(O.first_order(system, w), system))
            top = np.sort(rms.max(axis=1))[::-1][:3]
            np.testing.assert_allclose(prof[i, j], top, rtol=1e-10)
    # stage 2 with its stage phase screened as well
    sets2 = np.array([[0, 90, 180, 270], [0, 58.064516129032256, 159.67741935483872,
                                           258.38709677419354]])
    phases = np.array([0.0, 100.0])
    prof = O.proxy_screen(paper, "first", "2", sets2, gammas, w, every, chunk=2, depth=3,
                          stage_phases_deg=phases)
    assert prof.shape == (2, 2, 2, 3)
    for i, s in enumerate(sets2):
        for j, g in enumerate(gammas):
            for k, ph in enumerate(phases):
                t = O.train_at(paper, ("2.planet_angles_deg.2", "2.planet_angles_deg.3",
                                       "2.planet_angles_deg.4", "2.sun_ring_phase_deg",
                                       "2.stage_phase_deg"), [*s[1:], g, ph])
                system = gj.assemble(t, "first")
                rms = np.asarray(O.first_order_rms(O.first_order(system, w), system))
                top = np.sort(rms.max(axis=1))[::-1][:3]
                np.testing.assert_allclose(prof[i, j, k], top, rtol=1e-10)


def test_optimiser_improves_and_returns_an_admissible_design(small):
    train = gj.load_train(small)
    result = O.optimize(train, "low", (2000.0, 9000.0), settings=TINY_SETTINGS)
    assert result.vary == ("a.planet_angles_deg", "a.sun_ring_phase_deg")
    assert result.optimum.linear_peak < 0.9 * result.baseline.linear_peak
    assert result.optimum.admissible and result.baseline.admissible
    angles = np.asarray(result.train.stage("a").planet_angles_deg)
    assert P.planet_set_ok(result.train.stage("a"), angles)
    gj.validate_train(result.train)
    c = result.candidates
    assert c["incumbent"][0] and c["selected"].sum() == 1
    assert np.isfinite(c["proxy_peak"][1:]).all() and np.isfinite(c["linear_peak"]).sum() == 4
    r = result.relaxation
    assert r is not None and r.smooth_end <= r.smooth_start
    ds = O.optimize_dataset(result)
    assert ds.attrs["kind"] == "optimize" and ds["linear_rms"].dims == (
        "design", "frequency", "mesh")


def test_optimiser_without_a_band_takes_the_one_a_sweep_of_the_gear_chooses(small,
                                                                            monkeypatch):
    """No band: the band a sweep of this gear chooses from its modes (not the paper's
    2-15 kHz), said before the work (stopped where the band is checked: the rest of the
    optimisation is that of a given band)."""
    from gearjax._studies.optimize import driver as _driver
    from gearjax._studies.sweep.default_band import default_band

    class Checked(Exception):
        pass

    def check_band(band_hz):
        raise Checked(band_hz)

    monkeypatch.setattr(_driver, "check_band", check_band)
    train, said = gj.load_train(small), []
    with pytest.raises(Checked) as band:
        O.optimize(train, "low", None, settings=TINY_SETTINGS, progress=said.append)
    chosen = default_band(gj.gear_case(train, "low", None, True, torus=True))
    assert band.value.args[0] == pytest.approx((chosen.from_hz, chosen.to_hz))
    assert band.value.args[0] != pytest.approx((2000.0, 15000.0))
    assert said == [f"optimize: no band given: {chosen.from_hz:.1f}-{chosen.to_hz:.1f} Hz, "
                    f"chosen {chosen.reason}"]


def test_nonlinear_tier_never_makes_the_peak_with_backlash_worse(small):
    train = gj.load_train(small)
    settings = O.OptimizeSettings(proxy_points=32, phase_grid=4, screen=2, screen_points=6,
                                  final_points=6, harmonics=4, nonlinear=1,
                                  relax_iterations=0)
    result = O.optimize(train, "low", (3000.0, 4000.0), settings=settings)
    b, o = result.baseline.nonlinear, result.optimum.nonlinear
    assert b is not None and o is not None and b.frequencies_hz.size and o.frequencies_hz.size
    assert o.peak <= b.peak * (1 + O.NONLINEAR_RTOL)
    swept = np.isfinite(result.candidates["nonlinear_peak"])
    assert swept[0] and swept.sum() == 2  # the incumbent and the best linear candidate
    ds = O.optimize_dataset(result)
    assert ds["optimum_nonlinear_rms"].dims == ("optimum_point", "mesh")
    assert ds.attrs["baseline_peak_nonlinear"] == pytest.approx(b.peak)


@pytest.mark.slow
def test_recheck_sweeps_and_integrates_baseline_and_optimum(small):
    train = gj.load_train(small)
    result = O.optimize(train, "low", (2000.0, 9000.0), settings=TINY_SETTINGS)
    frame = O.optimize_frame(result)
    assert list(frame.index) == ["baseline", "optimum", "relaxed"]
    assert frame.loc["optimum", "assemblable"] and not frame.loc["relaxed", "assemblable"]
    assert frame.loc["optimum", "linear peak (N)"] == pytest.approx(result.optimum.linear_peak)
    # from the result and from its saved Dataset: the same designs
    assert O.recheck_designs(O.optimize_dataset(result))[3]["optimum"][0].stage(
        "a").planet_angles_deg.tolist() == pytest.approx(
        result.train.stage("a").planet_angles_deg.tolist())
    rc = O.recheck(result, (3000.0, 3600.0), verify_hz=[3300.0], harmonics=4,
                   max_step_hz=50.0, max_points=200)
    assert set(rc.sweeps) == set(rc.verify) == {"baseline", "optimum"}
    assert list(rc.peaks.index) == ["baseline", "optimum"]
    for name, row in rc.peaks.iterrows():
        ds = rc.sweeps[name].dataset
        stable = (ds["stable"].values == 1) & ds["converged"].values
        assert row["sweep peak (N)"] == pytest.approx(np.nanmax(ds["rms_force"].values[stable]))
        assert 3000.0 <= row["at (Hz)"] <= 3600.0
        # the integration started on the stable peak orbit stays on it
        assert row["integration"] == "converged" and row["rel diff"] < 0.02
    assert len(rc.points) == 2 and rc.points["all meshes ok"].all()
    with pytest.raises(ValueError, match="OptimizeResult"):
        O.recheck(rc.sweeps["optimum"].dataset)


def test_cli_optimize_writes_a_train_every_command_loads(capsys, small, tmp_path):
    out_train, out = tmp_path / "opt.toml", tmp_path / "opt.nc"
    code = _cli.main(["optimize", str(small), *TINY, "--out-train", str(out_train),
                      "--out", str(out), "--json"])
    text, err = capsys.readouterr()
    assert code == 0
    data = json.loads(text)
    for key in ("baseline", "optimum", "improvement", "relaxation", "stages", "candidates"):
        assert key in data
    # the linear screen's K checked at the baseline's, optimum's and relaxation's peaks
    check = data["models"]["final"]["truncation"]
    assert [(c["K"], c["K_check"]) for c in check["checks"]] == [(4, 8)]
    assert len(check["change"]) == 3 and check["checks"][0]["change"] == max(check["change"])
    assert ("optimize: truncation check at each design's linear peak, K = 4: against 8: "
            f"{max(check['change']):.2%} (target 0.5%)") in err
    assert ("warning: optimize: K = 4: truncation estimate" in err) == (
        max(check["change"]) > check["target"])
    assert data["optimum"]["linear_peak"] < data["baseline"]["linear_peak"]
    assert data["optimum"]["admissible"] and data["relaxation"]["assemblable"] is False
    loaded = gj.load_train(out_train)
    assert np.asarray(loaded.stage("a").planet_angles_deg).tolist() == pytest.approx(
        data["optimum"]["planet_angles_deg"]["a"])
    assert _cli.main(["info", str(out_train), "--json"]) == 0
    capsys.readouterr()
    ds = gj.load_results(out)
    assert ds.attrs["kind"] == "optimize" and ds.sizes["candidate"] > 3
    assert ds.attrs["optimum_peak_linear"] == pytest.approx(data["optimum"]["linear_peak"])
    assert gj.loads_train(ds.attrs["train_toml"]).stage("a").planet_angles_deg.tolist() == \
        pytest.approx(data["optimum"]["planet_angles_deg"]["a"])


@pytest.mark.parametrize("argv, words", [
    (["--vary", "1.inertia.sun"], ["--vary", "phasing only"]),
    (["--vary", "1.planet_angles_deg.2"], ["--vary", "together"]),
    (["--vary", "1.stage_phase_deg"], ["--vary", "time origin"]),
    (["--vary", "9.sun_ring_phase_deg"], ["--vary", "no stage"]),
    (["--vary", "1.sun_ring_phase_deg", "1.sun_ring_phase_deg"], ["--vary", "twice"]),
    (["--band", "5000", "2000"], ["--band", "LO < HI"]),
    (["--out", "x.csv"], ["--out", ".nc"]),
    (["--screen", "0"], ["--screen", ">= 1"]),
])
def test_cli_optimize_bad_input(capsys, argv, words):
    code = _cli.main(["optimize", *argv, "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    errors = [line for line in err.splitlines() if not line.startswith("warning:")]
    assert len(errors) == 1 and "Traceback" not in err
    assert all(w in errors[0] for w in words), errors[0]


def test_cli_optimize_refuses_a_gear_where_no_mesh_turns(capsys):
    code = _cli.main(["optimize", "--gear", "third", "--vary", "1.sun_ring_phase_deg"])
    _, err = capsys.readouterr()
    assert code == 2 and "no mesh turns" in err
