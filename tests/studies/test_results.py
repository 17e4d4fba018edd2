"""Results as data: the Dataset layout, NetCDF round trip, CSV rows, JSON points."""

import json
import warnings

import numpy as np
import pandas as pd
import pytest
import xarray as xr

import gearjax as gj
from gearjax._engine.responses import RESPONSE_FIELDS, MeshResponses

P = 3


@pytest.fixture(scope="module")
def paper_meshes():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.mesh_coordinates(gj.assemble(gj.load_train()))


def make_dataset(coords, *, period=None, stable=(True, False, None)):
    m = len(coords["mesh_labels"])
    rng = np.random.default_rng(0)
    fields = {name: rng.uniform(0.0, 1.0, (P, m)) for name in RESPONSE_FIELDS}
    for name in RESPONSE_FIELDS:
        fields[name][2] = np.nan  # the third point failed
    fields["dlf"][0, 0] = np.inf
    rpm = np.array([1000.0, 1100.0, 1200.0])
    hz = rpm / 60 * 70 * 3  # any numbers: the layout is under test
    return gj.sweep_dataset(
        MeshResponses(**fields), **coords,
        mesh_frequency_hz=hz, stage_mesh_frequency_hz=np.stack([hz, hz * 8 / 7], axis=1),
        input_rpm=rpm, omega=2 * np.pi * hz / 7, result=["converged", "converged", "max_steps"],
        stable=stable, period=period, static_force=np.linspace(1.0, 2.0, m),
        train_toml=gj.bundled_example_path().read_text(), gear="first",
        solver={"method": "hb", "n_harmonics": 16, "rtol": 1e-9}, attrs={"reference_stage": "1"})


def test_layout_units_and_attributes(paper_meshes):
    ds = make_dataset(paper_meshes)
    assert dict(ds.sizes) == {"point": 3, "mesh": 16, "stage_id": 2}
    assert ds["mesh"].values.tolist()[:2] == ["1.sp1", "1.sp2"]
    assert ds["stage"].values.tolist() == ["1"] * 8 + ["2"] * 8
    assert ds["side"].values.tolist()[3:5] == ["sun", "ring"]
    assert ds["planet"].values.tolist()[:5] == [1, 2, 3, 4, 1]
    assert ds["stage_mesh_frequency_hz"].dims == ("point", "stage_id")
    assert ds["converged"].values.tolist() == [True, True, False]
    assert ds["stable"].values.tolist() == [1, 0, -1] and ds["stable"].dtype == np.int8
    for name in RESPONSE_FIELDS:
        assert ds[name].dims == ("point", "mesh")
    units = {name: ds[name].attrs["units"] for name in ds.data_vars}
    assert units["mean_force"] == "N" and units["mean_torque"] == "N m"
    assert units["mesh_frequency_hz"] == "Hz" and units["omega"] == "rad/s"
    assert units["input_rpm"] == "rpm" and units["dlf"] == "1"
    assert "period" not in ds
    assert json.loads(ds.attrs["solver"])["n_harmonics"] == 16
    assert ds.attrs["gear"] == "first" and ds.attrs["gearjax_version"] == gj.__version__
    assert "[[stages]]" in ds.attrs["train_toml"] and ds.attrs["created"].endswith("+00:00")


def test_netcdf_round_trip_is_identical(paper_meshes, tmp_path):
    for period in (None, [1.0, 2.0, np.nan]):
        ds = make_dataset(paper_meshes, period=period)
        path = gj.save_results(ds, tmp_path / "sweep.nc")
        back = gj.load_results(path)
        xr.testing.assert_identical(back, ds)
        assert back.attrs == ds.attrs and back["stable"].dtype == np.int8
        assert back["converged"].dtype == bool


def test_csv_has_one_row_per_point_and_mesh(paper_meshes, tmp_path):
    ds = make_dataset(paper_meshes, period=[1.0, 1.0, 1.0])
    path = gj.save_results(ds, tmp_path / "sweep.csv")
    df = pd.read_csv(path)
    assert len(df) == 3 * 16
    assert list(df.columns) == [
        "point", "mesh", "stage", "side", "planet", "mesh_frequency_hz",
        "stage_mesh_frequency_hz", "input_rpm", "omega", "result", "converged", "stable",
        "period", "static_force", *RESPONSE_FIELDS]
    row = df[(df.point == 1) & (df.mesh == "2.rp3")].iloc[0]
    assert (row.stage, row.side, row.planet) == (2, "ring", 3)
    assert row.stage_mesh_frequency_hz == pytest.approx(ds.stage_mesh_frequency_hz[1, 1])
    assert row.rms_force == pytest.approx(float(ds.rms_force.sel(mesh="2.rp3")[1]))
    assert df.stable.isna().sum() == 16 and df.stable[df.point == 0].all()


def test_json_points_have_interface_keys_and_no_nan(paper_meshes):
    ds = make_dataset(paper_meshes)
    points = gj.points_json(ds)
    text = json.dumps({"points": points}, allow_nan=False)  # raises on NaN or Infinity
    assert len(points) == 3 and "NaN" not in text
    first = points[0]
    assert set(first) >= {"mesh_frequency_hz", "stage_mesh_frequency_hz", "input_rpm", "result",
                          "converged", "stable", "period", "meshes"}
    assert len(first["stage_mesh_frequency_hz"]) == 2 and first["period"] is None
    assert [p["stable"] for p in points] == [True, False, None]
    mesh = first["meshes"][0]
    assert set(mesh) >= {"name", "stage", "side", "planet", *RESPONSE_FIELDS}
    assert (mesh["name"], mesh["stage"], mesh["side"], mesh["planet"]) == ("1.sp1", "1", "sun", 1)
    assert mesh["dlf"] is None and mesh["reason"] == "not finite"  # the inf
    assert "reason" not in first["meshes"][1]
    failed = points[2]["meshes"][5]
    assert failed["rms_force"] is None and failed["reason"] == "point not converged (max_steps)"
    assert points[1]["meshes"][7]["mean_force"] == pytest.approx(float(ds.mean_force[1, 7]))


def test_unsupported_suffix_and_bad_shapes_are_refused(paper_meshes, tmp_path):
    ds = make_dataset(paper_meshes)
    with pytest.raises(ValueError, match=r"sweep\.txt.*'\.txt'.*\.nc, \.csv"):
        gj.save_results(ds, tmp_path / "sweep.txt")
    with pytest.raises(ValueError, match=r"only NetCDF \(\.nc\)"):
        gj.load_results(tmp_path / "sweep.csv")
    with pytest.raises(FileNotFoundError, match="missing.nc"):
        gj.load_results(tmp_path / "missing.nc")
    bad = {name: np.zeros((P, 15)) for name in RESPONSE_FIELDS}
    with pytest.raises(ValueError, match=r"responses must have fields of shape .*\(P, 16\)"):
        gj.sweep_dataset(MeshResponses(**bad), **paper_meshes, mesh_frequency_hz=np.zeros(P),
                         stage_mesh_frequency_hz=np.zeros((P, 2)), input_rpm=np.zeros(P),
                         omega=np.zeros(P), result=["converged"] * P)
    good = {name: np.zeros((P, 16)) for name in RESPONSE_FIELDS}
    with pytest.raises(ValueError, match=r"stage_mesh_frequency_hz must have shape \(3, 2\)"):
        gj.sweep_dataset(MeshResponses(**good), **paper_meshes, mesh_frequency_hz=np.zeros(P),
                         stage_mesh_frequency_hz=np.zeros(P), input_rpm=np.zeros(P),
                         omega=np.zeros(P), result=["converged"] * P)


def test_json_period_is_null_with_a_reason_when_no_repeat_was_found(paper_meshes):
    points = gj.points_json(make_dataset(paper_meshes, period=[1.0, 2.0, 0.0]))
    assert [p["period"] for p in points] == [1.0, 2.0, None]
    assert "period_reason" not in points[0] and "did not repeat" in points[2]["period_reason"]


def test_simulation_results_are_labelled_data_and_read_back_identical(tmp_path):
    """A real (short, loose) time integration: the same layout as a sweep, its kind and
    integration statistics with units, an identical NetCDF round trip, CSV rows."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train()
    settings = gj.TimeDomain(max_periods=3, rtol=1e-6, atol=1e-6)
    ds = gj.simulate_gear(train, "first", [4000.0], linear=True, settings=settings)
    assert ds.attrs["kind"] == "simulate" and ds.attrs["gear"] == "first"
    assert {"train_toml", "solver", "gearjax_version"} <= set(ds.attrs)
    assert {"stage", "side", "planet"} <= set(ds["mesh"].coords)
    assert all("units" in ds[v].attrs for v in ds.data_vars)
    assert {"period", "periods", "num_steps"} <= set(ds.data_vars)
    back = gj.load_results(gj.save_results(ds, tmp_path / "sim.nc"))
    xr.testing.assert_identical(back, ds)
    df = pd.read_csv(gj.save_results(ds, tmp_path / "sim.csv"))
    assert len(df) == 16 and "period" in df.columns and df.stable.isna().all()
