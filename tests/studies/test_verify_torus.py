"""Time integration and verification of a quasi-periodic gear (G = 2): simulate_gear,
verify_gear and their commands on the paper's topology with stage 2 re-toothed 43/19/81
(tests/data/two_stage_43_19_81.toml; mesh frequencies 70 : 81, two frequency groups).

Kept short: windows of 25 beats of the slowest excitation beat (160 base periods) and
one agreement (``FAST``) instead of the defaults (100 beats, 637 periods, two
agreements), at 10.5 and 11 kHz, where the explicit integration is cheapest (its step
is bounded by the train's 418 kHz penalty mode, so its cost grows with the physical
length of a window) and, with backlash, the stage-1 meshes separate (about 28% and 16%
of the time). The torus harmonic balance there has the floor orders (4, 4). Every call
after the first reuses the compiled programs (one per System shape and window plan), so
the module's fixtures and commands share them.
"""

import json
import pathlib
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._cli import main
from gearjax._engine import time_domain as td
from gearjax._gear.case import gear_case
from gearjax._io.verify_file import load_verify
from gearjax._studies import harmonics as _harmonics
from gearjax._studies import simulate as _simulate
from gearjax._studies import verify as _verify

TRAIN = pathlib.Path(__file__).parents[1] / "data" / "two_stage_43_19_81.toml"
FAST = gj.Windowed(n_beats=25, tol=0.04, n_agree=1)
FREQS = [10500.0, 11000.0]


@pytest.fixture(scope="module")
def train():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)  # stage 1 as published
        return gj.load_train(TRAIN)


@pytest.fixture(scope="module")
def simulated(train):
    """One point from the static solution in contact, with backlash."""
    return gj.simulate_gear(train, "first", [10500.0], windowed=FAST)


@pytest.fixture(scope="module")
def verified_linear(train):
    return gj.verify_gear(train, "first", FREQS, linear=True, windowed=FAST)


@pytest.fixture(scope="module")
def verified(train):
    """With backlash: the stage-1 meshes separate at both frequencies."""
    return gj.verify_gear(train, "first", FREQS, windowed=FAST)


def stage_rel(a, b, stages):
    """``|a - b|`` over the largest ``|b|`` of the mesh's stage (verify's measure)."""
    scale = np.array([np.max(np.abs(b[stages == s])) for s in stages])
    return np.abs(a - b) / scale


def test_a_time_shifted_system_is_the_clock_started_later(train):
    """The sweep's phase continuity: the shifted train's excitation at tau is the train's
    at tau + tau0, stiffness and forcing, with a transmission error and forcing columns
    on both angles (a matrix system: the train has neither)."""
    case = gear_case(train, "first", torus=True)
    rng = np.random.default_rng(3)
    matrices = gj.system_from_matrices(
        np.eye(2), 0.1 * np.eye(2), np.eye(2), [[1.0, -1.0], [0.0, 1.0]], [1.0, 2.0],
        k_cos=rng.normal(size=(2, 3)), k_sin=rng.normal(size=(2, 3)), mesh_mu=[7, 8],
        te_cos=rng.normal(size=(2, 2)), te_sin=rng.normal(size=(2, 2)), f_mean=[0.1, 0.2],
        f_cos=rng.normal(size=(2, 2)), f_sin=rng.normal(size=(2, 2)), forcing_mu=[1, 3],
        mesh_angle=[0, 1], forcing_angle=[1, 0], angle_ratio=(1.0, 81 / 70))
    tau = jnp.linspace(0.0, 40.0, 29)
    for system in (case.system, matrices):
        for tau0 in (2 * np.pi * 637 * 4, 1234.5678):
            shifted = _simulate.time_shifted(system, tau0)
            for got, want in zip(td.excitation(shifted, tau), td.excitation(system, tau + tau0)):
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * (1 + np.max(
                    np.abs(np.asarray(want)))))
    assert case.G == 2
    assert _simulate.time_shifted(case.system, 0.0).mesh_angle == case.system.mesh_angle


def test_a_window_longer_than_allowed_is_refused(train, monkeypatch, capsys):
    """No statistics rather than those of windows that truncate the slowest beat: refused
    before any work, in one line from the command."""
    short = gj.Windowed(max_window_periods=100)
    msg = (r"gears\.first = \['1', '81/70'\]: the frequency groups' angle ratios ask for "
           r"too long a window: .* needs 128 base periods, more than "
           r"Windowed\.max_window_periods = 100")
    with pytest.raises(gj.TrainError, match=msg):
        gj.simulate_gear(train, "first", [10500.0], windowed=short)
    with pytest.raises(gj.TrainError, match=msg):
        gj.verify_gear(train, "first", [10500.0], windowed=short)
    monkeypatch.setattr(_simulate, "WINDOWED", short)
    for command in ("simulate", "verify"):
        assert main([command, str(TRAIN), "--at", "10500"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith("gearjax: error: ") and "128 base periods" in err[-1]
        assert "Traceback" not in "\n".join(err)


def test_verify_linear_within_1_percent(verified_linear):
    r = verified_linear
    assert r.tolerance == 0.01 and r.all_ok and r.ok.shape == (2, 16)
    assert np.nanmax(r.rel_diff) < 0.01
    np.testing.assert_array_equal(r.hb["result"].values, ["converged"] * 2)
    np.testing.assert_array_equal(r.ni["result"].values, ["quasi_periodic"] * 2)
    np.testing.assert_array_equal(r.hb["harmonics"].values, [[4, 4], [4, 4]])
    assert r.hb["stable"].values.tolist() == [1, 1]
    assert r.reference["method"] == "windowed time integration"
    assert r.reference["window_periods"] == 160 and r.reference["agreement_tolerance"] == 0.04
    assert json.loads(r.hb.attrs["solver"])["method"] == "torus harmonic balance"
    assert r.ni.attrs["start"] == "harmonic balance"


def test_verify_with_backlash_within_2_percent(verified, verified_linear):
    r = verified
    assert r.tolerance == 0.02 and r.all_ok and np.nanmax(r.rel_diff) < 0.02
    np.testing.assert_array_equal(r.ni["result"].values, ["quasi_periodic"] * 2)
    assert r.hb["stable"].values.tolist() == [1, 1]
    for ds in (r.hb, r.ni):  # the stage-1 meshes separate in both methods
        assert ds["separation"].sel(mesh="1.sp1").values[0] > 0.2
        assert ds["separation"].sel(mesh="1.sp1").values[1] > 0.1
    # and it matters: contact loss takes more than 10% off the linear RMS at 10.5 kHz
    assert verified_linear.rms_hb[0, 0] > 1.1 * r.rms_hb[0, 0]


def test_a_torus_that_the_integration_does_not_follow_is_never_a_pass(verified):
    """The two outcomes of a locking or chaotic response, put in by hand: windows that do
    not agree (no statistics to compare) and statistics that differ from the torus."""
    r = verified
    ni = r.ni.copy(deep=True)
    ni["result"][1], ni["converged"][1] = "not_stationary", False
    ni["rms_force"][0] = ni["rms_force"][0] * 1.05
    rms_hb, rms_ni, rel, ok = _verify.compare_rms(r.hb, ni, r.tolerance)
    moved = _verify.VerifyResult(hb=r.hb, ni=ni, rms_hb=rms_hb, rms_ni=rms_ni, rel_diff=rel,
                                 ok=ok, tolerance=r.tolerance, seconds=r.seconds,
                                 reference=r.reference)
    assert not moved.all_ok and not ok[0].all() and not ok[1].any()
    out = json.loads(json.dumps(_verify.verify_json(moved)))
    differ, unsettled = out["points"]
    assert not out["all_ok"] and out["reference"] == r.reference
    assert differ["agreement"] == "differ" and not differ["ok"] and differ["converged"]
    assert "locks onto a rational winding" in differ["agreement_reason"]
    # which side fell short: each met its own check here, so neither (the 5% is put in)
    estimate = max(c["change"] for c in differ["truncation"]
                   if c["K"] == differ["harmonics"] and c["change"] is not None)
    assert estimate <= _harmonics.TRUNCATION_TARGET
    assert differ["shortfall"] == "neither" and differ["shortfall_reason"] == (
        f"each side meets its own check (truncation estimate {estimate:.2%}, windows within "
        f"{differ['window_change']:.2%}): the difference is the response's")
    assert unsettled["shortfall"] is None
    assert _verify.shortfall([{"K": [8, 8], "K_check": [16, 8], "change": 0.03}], 1e-4, 1e-3,
                             0.01) == ("harmonic_balance", "the harmonic balance fell short: "
                                       "its truncation estimate 3.00% exceeds the 0.5% target "
                                       "(omit `--harmonics`, or raise it)")
    assert _verify.shortfall([{"K": [8, 8], "K_check": [16, 8], "change": 1e-4}], 0.004, 0.04,
                             0.01)[0] == "integration"
    assert _verify.shortfall([{"K": [8, 8], "K_check": None, "change": None,
                               "skipped": "too big"}], 1e-4, 1e-3, 0.01) == (
        "harmonic_balance", "the harmonic balance's truncation was not checked at this point "
                            "(too big): it may be short")
    assert unsettled["agreement"] == "not_stationary" and not unsettled["ok"]
    assert not unsettled["converged"] and unsettled["result"] == "not_stationary"
    assert all(m["rel_diff"] is None and m["reason"] == "integration not_stationary"
               for m in unsettled["meshes"])
    # the real ones agree
    real = _verify.verify_json(r)
    assert [p["agreement"] for p in real["points"]] == ["agree", "agree"]


def test_simulate_a_point_is_quasi_periodic_and_on_the_torus(simulated, verified):
    """From the static contact state the windows settle on the torus solution (independent:
    the torus harmonic balance of ``verified``) within 1% of each stage's largest RMS."""
    ds = simulated
    assert ds["result"].values.tolist() == ["quasi_periodic"]
    assert ds["converged"].values.tolist() == [True]
    assert ds["period"].values.tolist() == [0] and ds["stable"].values.tolist() == [-1]
    solver = json.loads(ds.attrs["solver"])
    assert solver["method"] == "windowed time integration" and solver["window_periods"] == 160
    assert solver["torus"]["G"] == 2 and solver["torus"]["angle_ratio_exact"] == ["1", "81/70"]
    assert ds.attrs["kind"] == "simulate" and ds.attrs["mode"] == "points"
    windows = int(ds["windows"].values[0])
    assert windows >= 3 and int(ds["periods"].values[0]) == 160 * windows
    # mu_ref = 1: a base period is a stage-1 mesh cycle
    assert ds["window_s"].values[0] == pytest.approx(160 / 10500.0, rel=1e-12)
    assert ds["window_change"].values[0] <= FAST.tol
    stages = ds["stage"].values
    rel = stage_rel(ds["rms_force"].values[0], verified.rms_hb[0], stages)
    assert np.max(rel) < 0.01
    assert ds["separation"].sel(mesh="1.sp1").values[0] > 0.2  # the backlash is active


def test_simulate_sweep_continues_each_point(train, simulated, verified):
    """A run-down 11 -> 10.5 kHz, each point from the previous end state and phase: both
    quasi-periodic, the second on the same torus as the independent point."""
    ds = gj.simulate_gear(train, "first", from_hz=11000.0, to_hz=10500.0, points=2,
                          windowed=FAST)
    assert ds.attrs["mode"] == "sweep"
    np.testing.assert_allclose(ds["mesh_frequency_hz"].values, [11000.0, 10500.0])
    assert ds["result"].values.tolist() == ["quasi_periodic"] * 2
    stages = ds["stage"].values
    assert np.max(stage_rel(ds["rms_force"].values[0], verified.rms_hb[1], stages)) < 0.01
    assert np.max(stage_rel(ds["rms_force"].values[1], simulated["rms_force"].values[0],
                            stages)) < 0.01


def test_simulate_command_json(monkeypatch, capsys, tmp_path, simulated):
    monkeypatch.setattr(_simulate, "WINDOWED", FAST)
    csv = tmp_path / "sim.csv"
    code = main(["simulate", str(TRAIN), "--at", "10500", "--json", "--out", str(csv)])
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert code == 0 and out["mode"] == "points" and out["solver"]["window_periods"] == 160
    # its windows reported as they ran (the first one at least), in the settings' words
    windows = [l for l in captured.err.splitlines() if l.startswith("integration: ")]
    assert windows[0].startswith("integration: point 1 of 1 (10500.0 Hz): window 1 of at "
                                 f"most {FAST.max_windows}, ")
    assert "report" not in out["solver"]
    (p,) = out["points"]
    assert p["result"] == "quasi_periodic" and p["converged"] and p["stable"] is None
    assert p["period"] is None and "quasi-periodic" in p["period_reason"]
    assert p["windows"] == int(simulated["windows"].values[0])
    assert p["periods"] == 160 * p["windows"] and p["window_s"] > 0
    mesh = {m["name"]: m for m in p["meshes"]}
    assert set(mesh["1.sp1"]) >= {"mean_force", "rms_force", "max_force", "dlf",
                                  "separation", "back_contact", "mean_torque"}
    assert mesh["1.sp1"]["rms_force"] == pytest.approx(
        float(simulated["rms_force"].sel(point=0, mesh="1.sp1")), rel=1e-9)
    assert csv.read_text().count("\n") == 1 + 16
    # the table says what the statistics are
    assert main(["simulate", str(TRAIN), "--at", "10500"]) == 0
    text = capsys.readouterr().out
    assert "quasi_periodic" in text and "windows of 160 base periods" in text


def test_verify_command_json(monkeypatch, capsys, tmp_path, verified):
    monkeypatch.setattr(_simulate, "WINDOWED", FAST)
    nc, fig = tmp_path / "verify.nc", tmp_path / "verify.png"
    code = main(["verify", str(TRAIN), "--at", "10500", "--json", "--out", str(nc),
                 "--plot", str(fig)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["all_ok"] and out["tolerance"] == 0.02
    assert out["reference"]["method"] == "windowed time integration"
    assert out["reference"]["window_periods"] == 160 and out["torus"]["G"] == 2
    (p,) = out["points"]
    assert p["result_hb"] == "converged" and p["result_ni"] == "quasi_periodic"
    assert p["harmonics"] == [4, 4] and p["period"] is None and p["agreement"] == "agree"
    assert p["windows"] >= 3 and p["stable"] is True
    for m in p["meshes"]:
        assert m["ok"] and m["rel_diff"] < 0.02
    j = {m["name"]: m for m in p["meshes"]}["1.sp1"]
    assert j["rms_hb"] == pytest.approx(verified.rms_hb[0, 0], rel=1e-6)
    root, hb, ni = load_verify(nc)
    assert json.loads(root.attrs["reference"])["window_periods"] == 160
    assert hb["harmonics"].dims == ("point", "angle") and "windows" in ni
    assert fig.stat().st_size > 10_000
    assert main(["verify", str(TRAIN), "--at", "10500"]) == 0
    text = capsys.readouterr().out
    assert "windows of 160 base periods" in text and "(4, 4)" in text


@pytest.mark.slow
def test_verify_command_default_windows_linear(capsys):
    """The command's own windows (20 beats: 128 base periods, two agreements within
    1e-3)."""
    code = main(["verify", str(TRAIN), "--at", "10500", "--linear", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["all_ok"] and out["tolerance"] == 0.01
    assert out["reference"]["window_periods"] == 128 and out["reference"]["n_agree"] == 2
    assert out["reference"]["n_beats"] == 20 and out["reference"]["agreement_tolerance"] == 1e-3
    assert out["points"][0]["windows"] >= 4 and out["max_rel_diff"] < 0.01


G3 = pathlib.Path(__file__).parents[1] / "data" / "three_stage_incommensurate.toml"


@pytest.mark.slow
@pytest.mark.long
def test_a_three_group_train_verifies_within_1_percent_with_default_settings(capsys):
    """G = 3 (tests/data/three_stage_incommensurate.toml: three stages, three frequency
    groups), linear, 2.2 kHz, every setting the command's own: the torus balance (orders
    chosen and checked a posteriori) and the windowed integration (20-beat windows,
    weighted averages, agreeing within 1e-3) agree within 1% on every mesh. What is left
    is the balance's truncation (its own estimate, 0.38% here, below the 0.5% target),
    not the integration's: its last windows agree to 1e-9. Long: about 3 minutes on 2
    cores (a 3-torus balance with its checks, then four windows of 2908 base periods)."""
    code = main(["verify", str(G3), "--linear", "--at", "2200", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["all_ok"] and out["max_rel_diff"] < 0.01
    (p,) = out["points"]
    assert p["agreement"] == "agree" and p["shortfall"] is None
    estimate = max(c["change"] for c in p["truncation"]
                   if c["K"] == p["harmonics"] and c["change"] is not None)
    assert estimate <= _harmonics.TRUNCATION_TARGET and p["window_change"] < 1e-6
    assert out["max_rel_diff"] <= 2 * estimate  # the difference is the balance's truncation
