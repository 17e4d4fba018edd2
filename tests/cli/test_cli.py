"""The command line: JSON keys of interface.md, exit codes, one-line errors."""

import json
import subprocess
import sys

import pytest

from gearjax._cli import main

INFO_KEYS = {"ratio", "ratio_exact", "mu", "dof", "stages", "member_speeds", "static", "warnings"}


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_info_json_has_interface_keys(capsys):
    code, out, err = run(capsys, "info", "--json")
    assert code == 0
    data = json.loads(out)
    assert INFO_KEYS <= set(data)
    assert data["ratio_exact"] == "17/6"
    assert data["mu"] == [7, 8]
    assert data["dof"] == 14
    stage = {s["id"]: s for s in data["stages"]}
    assert set(stage["1"]) >= {"id", "loaded", "mesh_frequency_hz"}
    assert stage["1"]["mesh_frequency_hz"] == pytest.approx(226.47, abs=0.005)
    assert stage["2"]["mesh_frequency_hz"] == pytest.approx(258.82, abs=0.005)
    assert data["member_speeds"]["2.sun"] == 0.0
    assert data["static"]["1.sp1"]["force"] == pytest.approx(8942.2, abs=0.1)
    # the published stage-1 teeth break concentricity: warned, in JSON and on stderr
    assert any("concentricity" in w for w in data["warnings"])
    assert "concentricity" in err


def test_info_third_gear_has_null_mu(capsys):
    code, out, _ = run(capsys, "info", "--gear", "third", "--json")
    data = json.loads(out)
    assert code == 0 and data["mu"] is None and data["ratio_exact"] == "1"


def test_info_input_rpm_scales_mesh_frequencies(capsys):
    _, out, _ = run(capsys, "info", "--json", "--input-rpm", "3000")
    stage = json.loads(out)["stages"][0]
    assert stage["mesh_frequency_hz"] == pytest.approx(3 * 226.47, abs=0.02)


def test_modes_json_and_plot(capsys, tmp_path):
    fig = tmp_path / "modes.png"
    code, out, _ = run(capsys, "modes", "--json", "--plot", str(fig))
    assert code == 0 and fig.stat().st_size > 10_000
    data = json.loads(out)
    assert len(data["elastic_hz"]) == 12
    assert {"hz", "multiplicity", "class", "family", "stage", "shape"} <= set(data["modes"][0])
    classes = [m["class"] for m in data["modes"]]
    assert classes.count("rigid") == 1 and classes.count("penalty") == 1
    planet = [m for m in data["modes"] if m["family"] == "planet"]
    assert sorted({m["stage"] for m in planet}) == ["1", "2"] and len(planet) == 6


def test_human_output(capsys):
    code, out, _ = run(capsys, "info", "--gear", "fourth")
    assert code == 0 and "ratio 7/10" in out
    code, out, _ = run(capsys, "modes")
    assert code == 0 and "planet 1" in out


@pytest.mark.parametrize(
    "argv, words",
    [
        (["info", "--gear", "sixth"], ["--gear", "'sixth'", "no such gear"]),
        (["info", "missing.toml"], ["missing.toml", "cannot be read"]),
        (["info", "--input-rpm", "0"], ["--input-rpm", "0.0", "positive"]),
    ],
)
def test_bad_input_exits_2_with_one_line(capsys, argv, words):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == ""
    line = [l for l in err.splitlines() if l.startswith("gearjax: error:")]
    assert len(line) == 1 and "Traceback" not in err
    for w in words:
        assert w in line[0]


def test_bad_train_file_exits_2(capsys, tmp_path):
    from gearjax import bundled_example_path

    bad = tmp_path / "bad.toml"
    bad.write_text(bundled_example_path().read_text().replace("sun = 1.25", "sun = 0.9"))
    code, out, err = run(capsys, "modes", str(bad), "--json")
    assert code == 2 and out == ""
    assert "bad.toml: 1.contact_ratio.sun = 0.9: must be >= 1" in err


def test_console_script_runs():
    """The installed entry point, as a user runs it (usage errors exit 2 too)."""
    done = subprocess.run([sys.executable, "-m", "gearjax._cli", "info", "--json"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and json.loads(done.stdout)["ratio"] == pytest.approx(17 / 6)
    usage = subprocess.run([sys.executable, "-m", "gearjax._cli", "info", "--bogus"],
                           capture_output=True, text=True, timeout=120)
    assert usage.returncode == 2


def test_calibrate_json_writes_a_train_that_loads(capsys, tmp_path):
    out_train = tmp_path / "fitted.toml"
    code, out, _ = run(capsys, "calibrate", "--json", "--targets-hz", "3880", "8600",
                       "--free", "1.inertia.sun", "2.inertia.carrier",
                       "--out-train", str(out_train))
    data = json.loads(out)
    assert code == 0 and data["converged"]
    assert {"fitted", "initial", "targets_hz", "model_hz", "residual_rel"} <= set(data)
    assert max(abs(r) for r in data["residual_rel"]) < 1e-8
    code, out, _ = run(capsys, "modes", str(out_train), "--json")
    elastic = json.loads(out)["elastic_hz"]
    assert code == 0
    assert elastic[0] == pytest.approx(3880, rel=1e-8)
    assert elastic[1] == pytest.approx(8600, rel=1e-8)


def test_calibrate_bad_path_exits_2(capsys):
    code, out, err = run(capsys, "calibrate", "--targets-hz", "3880", "--free", "1.teeth.sun")
    assert code == 2 and out == ""
    assert "--free" in err and "1.teeth.sun" in err


# ----------------------------------------------------------------------------- plot


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """Small results files of every kind gearjax plot draws (made up numbers: the
    figures, not the solvers, are under test)."""
    import warnings

    import numpy as np
    import xarray as xr

    import gearjax as gj
    from gearjax._engine.responses import RESPONSE_FIELDS, MeshResponses
    from gearjax._io.verify_file import save_verify
    from gearjax._studies.verify import VerifyResult

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train()
    coords = gj.mesh_coordinates(gj.assemble(train))
    m, P = len(coords["mesh_labels"]), 6
    hz = np.linspace(2400.0, 2500.0, P)
    rng = np.random.default_rng(1)

    def dataset(kind, **kw):
        resp = MeshResponses(**{k: rng.uniform(1.0, 2.0, (P, m)) for k in RESPONSE_FIELDS})
        return gj.sweep_dataset(
            resp, **coords, mesh_frequency_hz=hz,
            stage_mesh_frequency_hz=np.stack([hz, hz * 8 / 7], 1), input_rpm=hz / 0.2264,
            omega=2 * np.pi * hz / 7, result=["converged"] * (P - 1) + ["max_steps"],
            train_toml=gj.dumps_train(train), gear="first", solver={"linear": False},
            attrs={"kind": kind, "reference_stage": "1"}, **kw)

    root = tmp_path_factory.mktemp("saved")
    files = {}
    files["sweep"] = gj.save_results(dataset("sweep", stable=[1, 1, 0, 0, 1, 1]),
                                     root / "sweep.nc")
    sim = dataset("simulate", period=np.ones(P))
    sim["num_steps"] = ("point", np.full(P, 100), {"units": "1"})
    files["simulate"] = gj.save_results(sim, root / "sim.nc")
    hb, ni = dataset("sweep", stable=[1] * P), dataset("simulate", period=np.ones(P))
    rel = np.abs(ni.rms_force.values - hb.rms_force.values) / 2
    files["verify"] = save_verify(VerifyResult(
        hb=hb, ni=ni, rms_hb=hb.rms_force.values, rms_ni=ni.rms_force.values, rel_diff=rel,
        ok=rel < 0.3, tolerance=0.02, seconds={}), root / "verify.nc")
    files["design"] = gj.save_results(dataset("design"), root / "design.nc")
    files["foreign"] = root / "foreign.nc"
    xr.Dataset({"a": ("x", np.arange(3.0))}).to_netcdf(files["foreign"], engine="h5netcdf")
    files["text"] = root / "notes.nc"
    files["text"].write_text("not a results file\n")
    return files


@pytest.mark.parametrize("kind", ["sweep", "simulate", "verify"])
def test_plot_redraws_saved_results(capsys, saved, tmp_path, kind):
    for what in ("rms", "dlf", "separation", "torque"):
        fig = tmp_path / f"{kind}-{what}.png"
        code, out, err = run(capsys, "plot", str(saved[kind]), "--what", what, "--out", str(fig))
        assert code == 0 and fig.stat().st_size > 10_000, err
        assert f"{kind} results" in out and str(fig) in out


def test_plot_default_figure_and_json(capsys, saved):
    fig = saved["sweep"].with_suffix(".png")
    code, out, _ = run(capsys, "plot", str(saved["sweep"]), "--json")
    data = json.loads(out)
    assert code == 0 and data == {"results": str(saved["sweep"]), "kind": "sweep",
                                  "what": "rms", "figure": str(fig)}
    assert fig.stat().st_size > 10_000


def test_saved_verify_results_read_back(saved):
    import xarray as xr

    from gearjax._io.verify_file import load_verify

    root, hb, ni = load_verify(saved["verify"])
    assert root.attrs["kind"] == "verify" and root.attrs["tolerance"] == 0.02
    assert root["rel_diff"].dims == ("point", "mesh") and root["ok"].dtype == bool
    assert hb.attrs["kind"] == "sweep" and ni.sizes == hb.sizes
    xr.testing.assert_identical(hb["mesh"], root["mesh"])


@pytest.mark.parametrize("name, words", [
    ("missing", ["missing.nc", "no such results file"]),
    ("text", ["notes.nc", "not a NetCDF results file"]),
    ("foreign", ["foreign.nc", "not a gearjax results file"]),
    ("design", ["design.nc", "kind = 'design'", "cannot draw", "sweep, simulate, verify"]),
])
def test_plot_of_a_file_it_cannot_draw_exits_2(capsys, saved, tmp_path, name, words):
    path = saved.get(name, tmp_path / "missing.nc")
    code, out, err = run(capsys, "plot", str(path))
    line = [l for l in err.splitlines() if l.startswith("gearjax: error:")]
    assert code == 2 and out == "" and len(line) == 1 and "Traceback" not in err
    for w in words:
        assert w in line[0]


@pytest.mark.parametrize("kind", ["sweep", "verify"])
def test_a_value_changed_after_writing_is_refused_by_its_checksum(capsys, saved, tmp_path,
                                                                   kind):
    """One byte of a stored array flipped (the RMS forces of a sweep, of a verification's
    harmonic balance): `plot` and `gj.load_results` refuse the file in one line instead
    of drawing or returning a wrong value."""
    import numpy as np
    import xarray as xr

    import gearjax as gj
    from gearjax._io.verify_file import load_verify

    path = saved[kind]
    group = "hb" if kind == "verify" else None
    values = xr.load_dataset(path, group=group, engine="h5netcdf")["rms_force"].values
    data = bytearray(path.read_bytes())
    at = data.find(np.ascontiguousarray(values).tobytes())
    assert at > 0  # the array is stored as written (no compression)
    data[at + 3] ^= 0xFF
    damaged = tmp_path / f"damaged_{kind}.nc"
    damaged.write_bytes(bytes(data))
    code, out, err = run(capsys, "plot", str(damaged))
    line = [l for l in err.splitlines() if l.startswith("gearjax: error:")]
    assert code == 2 and out == "" and len(line) == 1 and "Traceback" not in err
    assert f"{damaged}: damaged: the checksum of a stored array does not match" in line[0]
    with pytest.raises(gj.TrainError, match="damaged: the checksum"):
        load_verify(damaged) if kind == "verify" else gj.load_results(damaged)


def test_verify_out_must_be_netcdf(capsys):
    code, out, err = run(capsys, "verify", "--at", "3000", "--out", "v.csv")
    assert code == 2 and "--out = 'v.csv': must end in .nc" in err
