"""Time-domain verification surface: simulate_gear, verify_gear and their commands.

Kept fast: the paper's first gear at 2 points per call, all of them in one harmonics
segment (K = 48 for 3-4.3 kHz), so every call after the first reuses the compiled
harmonic balance and integrator.
"""

import json
import pathlib

import numpy as np
import pytest

import gearjax as gj
from gearjax._studies import simulate as _simulate
from gearjax._cli import main


@pytest.fixture(scope="module")
def train(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


@pytest.fixture(scope="module")
def simulated(train):
    """Independent points from the static solution, with backlash."""
    return gj.simulate_gear(train, "first", [4000.0, 4300.0])


@pytest.fixture(scope="module")
def verified(train):
    """With backlash at 4 kHz (meshes separate ~15% of the period) and 4.3 kHz, off the jumps."""
    return gj.verify_gear(train, "first", [4000.0, 4300.0])


@pytest.mark.parametrize("argv, message", [
    (["simulate"], "--from = (missing): give --at HZ"),
    (["simulate", "--at", "-5"], "--at = -5.0: must be a positive mesh frequency"),
    (["simulate", "--at", "3000", "--from", "2000", "--to", "3000"], "not both"),
    (["simulate", "--from", "3000", "--to", "3000"], "--to = 3000.0: must differ from --from"),
    (["simulate", "--from", "2000", "--to", "3000", "--points", "1"],
     "--points = 1: must be an integer >= 2"),
    (["simulate", "--at", "3000", "--out", "x.txt"], "--out = 'x.txt': must end in .nc or .csv"),
    (["simulate", "--at", "3000", "--stage", "9"], "--stage = '9': no such stage"),
    (["verify", "--at", "3000", "--tol-linear", "0"], "--tol-linear = 0.0: must be a relative"),
    (["verify", "--at", "3000", "--harmonics", "0"], "--harmonics = 0: must be an integer"),
    (["verify", "--at", "3000", "--curve", "missing.nc"], "--curve = 'missing.nc': cannot be read"),
    (["verify", "--gear", "second", "--at", "3000"], "gears.second.drag_torque = 0.0"),
])
def test_bad_input_exits_2_with_one_line(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and err[-1].startswith("gearjax: error: ")
    assert "Traceback" not in "\n".join(err)


@pytest.mark.slow
def test_verify_linear_paper_first_gear_within_1_percent(capsys, tmp_path):
    fig, nc = tmp_path / "verify.png", tmp_path / "verify.nc"
    code = main(["verify", "--linear", "--at", "3000", "3300", "--json", "--plot", str(fig),
                 "--out", str(nc)])
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert code == 0 and "verify: harmonic balance" in captured.err
    assert out["tolerance"] == 0.01 and out["all_ok"] and len(out["points"]) == 2
    for p in out["points"]:
        assert p["result_hb"] == "converged" and p["result_ni"] == "converged"
        assert p["converged"] and p["ok"] and p["period"] == 1 and p["harmonics"] == 64
        (check,) = p["truncation"]  # the first choice checked against K = 128, and kept
        assert check["K"] == 64 and check["K_check"] == 128 and check["change"] < 0.005
        assert len(p["meshes"]) == 16
        for m in p["meshes"]:
            assert {"name", "rms_hb", "rms_ni", "rel_diff", "ok"} <= set(m)
            assert m["ok"] and m["rel_diff"] < 0.01 and m["rms_hb"] > 100
    assert out["points"][0]["mesh_frequency_hz"] == 3000.0
    # the saved verification redraws without recomputing
    assert main(["plot", str(nc), "--what", "dlf"]) == 0
    assert "verify results" in capsys.readouterr().out
    assert nc.with_suffix(".png").stat().st_size > 10_000
    assert fig.stat().st_size > 10_000


def test_verify_with_backlash_off_the_jumps_within_2_percent(verified):
    r = verified
    assert r.tolerance == 0.02 and r.all_ok and r.ok.shape == (2, 16)
    assert np.nanmax(r.rel_diff) < 0.02
    np.testing.assert_array_equal(r.hb["result"].values, ["converged"] * 2)
    np.testing.assert_array_equal(r.ni["result"].values, ["converged"] * 2)
    assert r.hb["stable"].values.tolist() == [1, 1]
    # the backlash is active: the ring meshes of stage 1 separate at 4 kHz in both methods
    for ds in (r.hb, r.ni):
        assert ds["separation"].values[0].max() > 0.05


@pytest.mark.slow
def test_simulate_from_static_lands_on_the_verified_orbit(simulated, verified):
    """Off the jumps the orbit is unique: the static start settles on the HB orbit."""
    ds = simulated
    assert ds["converged"].values.all() and ds["period"].values.tolist() == [1, 1]
    assert ds["stable"].values.tolist() == [-1, -1]  # unknown for integration
    assert ds.attrs["mode"] == "points" and ds.attrs["start"] == "static contact"
    np.testing.assert_allclose(ds["rms_force"].values, verified.rms_ni, rtol=1e-3)
    assert np.all(ds["periods"].values > verified.ni["periods"].values)  # HB start: faster


@pytest.mark.slow
def test_simulate_cli_json_and_csv(capsys, tmp_path, simulated):
    csv = tmp_path / "sim.csv"
    code = main(["simulate", "--at", "4000", "4300", "--json", "--out", str(csv)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["mode"] == "points" and len(out["points"]) == 2
    p = out["points"][1]
    assert {"mesh_frequency_hz", "stage_mesh_frequency_hz", "input_rpm", "result", "converged",
            "stable", "period", "meshes", "periods", "num_steps"} <= set(p)
    assert p["result"] == "converged" and p["stable"] is None and p["period"] == 1
    assert p["stage_mesh_frequency_hz"][1] == pytest.approx(4300 * 8 / 7)
    mesh = {m["name"]: m for m in p["meshes"]}
    assert mesh["1.sp1"]["rms_force"] == pytest.approx(
        float(simulated["rms_force"].sel(point=1, mesh="1.sp1")), rel=1e-6)
    assert out["solver"]["solver"] == "Dopri8"
    assert csv.read_text().count("\n") == 1 + 2 * 16


@pytest.mark.slow
def test_simulate_sweep_continues_in_order(train, simulated):
    """A run-down 4.3 -> 4 kHz: points in sweep order, each started from the previous end."""
    ds = gj.simulate_gear(train, "first", from_hz=4300.0, to_hz=4000.0, points=2)
    assert ds.attrs["mode"] == "sweep"
    np.testing.assert_allclose(ds["mesh_frequency_hz"].values, [4300.0, 4000.0])
    assert ds["converged"].values.all()
    np.testing.assert_allclose(ds["rms_force"].values, simulated["rms_force"].values[::-1],
                               rtol=1e-3)


def test_no_converged_point_exits_3(capsys, monkeypatch, simulated):
    failed = simulated.copy(deep=True)
    failed["converged"][:] = False
    failed["result"][:] = "max_steps"
    failed["rms_force"][:] = np.nan
    monkeypatch.setattr(_simulate, "simulate_gear", lambda *a, **k: failed)
    assert main(["simulate", "--at", "4000", "4300", "--json"]) == 3
    out = json.loads(capsys.readouterr().out)  # valid JSON: no NaN
    m = out["points"][0]["meshes"][0]
    assert m["rms_force"] is None and m["reason"] == "point not converged (max_steps)"


@pytest.mark.long
@pytest.mark.slow
def test_verify_raises_K_where_the_first_choice_is_short(capsys):
    """tests/data/three_stage.toml at 1 kHz (stage-A mesh frequency), default settings:
    the first choice K = 64 is 5% off in the RMS forces against K = 128, so verify
    raises K as a sweep would, checks 128 against 256, and agrees with the independent
    integration within 1% (at K = 64 it was 4.8% off). Long: three solves up to
    K = 256 of a 3-stage train and the integration (about a minute on 2 cores)."""
    train = pathlib.Path(__file__).parents[1] / "data" / "three_stage.toml"
    code = main(["verify", str(train), "--at", "1000", "--json"])
    out = json.loads(capsys.readouterr().out)
    (p,) = out["points"]
    first, second = p["truncation"]
    assert first["K"] == 64 and first["K_check"] == 128 and first["change"] > 0.005
    assert second["K"] == 128 and second["K_check"] == 256 and second["change"] < 0.005
    assert code == 0 and p["harmonics"] == 128 and out["all_ok"]
    assert out["max_rel_diff"] < 0.01
