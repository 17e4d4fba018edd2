"""A two-group train end to end: ``gearjax sweep`` on the paper's
topology with stage 2 re-toothed 45/20/85 (tests/data/two_stage_14_17.toml: mesh
frequencies 14 : 17, two incommensurate groups) solves the torus balance, says which
frequencies and truncation it used, keeps the mean transmitted torque, and resumes from
its journal as if never interrupted.

One stiffness harmonic and orders (2, 2) keep the problems small (13 coefficient rows of
14 coordinates): these tests check the machinery, not the train's converged response.
"""

from __future__ import annotations

import json
import pathlib
import warnings

import numpy as np
import pytest
import xarray as xr

import gearjax as gj
from gearjax._cli import main
from gearjax._studies import sweep as _sweep

BAND = dict(from_hz=3000.0, to_hz=3060.0, harmonics=2, max_step_hz=10.0)


@pytest.fixture(scope="module")
def train(torus_h1_train):
    return torus_h1_train


@pytest.fixture(scope="module")
def full(train, tmp_path_factory):
    path = tmp_path_factory.mktemp("full") / "sweep.nc.journal"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.TruncationWarning)
        result = _sweep.sweep(train, "first", journal=path, **BAND)
    return result, path.read_bytes()


def test_a_two_group_sweep_solves_the_torus_and_says_so(full, train):
    result, _ = full
    ds = result.dataset
    assert result.stop == "reached_end" and ds.sizes["point"] > 5
    solver = json.loads(ds.attrs["solver"])
    torus = solver["torus"]
    assert torus["G"] == 2 and torus["angle_ratio_exact"] == ["1", "17/14"]
    assert torus["truncation"] == "diamond" and torus["stage_angle"] == {"1": [0, 1], "2": [1, 1]}
    assert [seg[2] for seg in solver["segments"]] == [[2, 2]]
    # the stages' mesh frequencies stand in the exact ratio of the kinematics
    hz = ds["stage_mesh_frequency_hz"].values
    np.testing.assert_allclose(hz[:, 1] / hz[:, 0], 17 / 14, rtol=1e-14)
    # the solution is stored per wave vector of the diamond of orders (2, 2)
    waves = {tuple(int(v) for v in k) for k in ds["wave_vector"].values}
    assert waves == {(0, 0), (1, 0), (2, 0), (0, 1), (0, 2), (1, 1), (1, -1)}
    assert np.all(ds["harmonics"].values == 2) and ds["harmonics"].dims == ("point", "angle")
    # equilibrium of the mean, whatever the dynamics: the input sun's mean torque, its
    # stage-1 sun meshes' mean forces times their lever plus its housing spring (the free
    # one) times its mean rotation, is the input torque
    system = gj.assemble(train, "first")
    sun = [i for i, (g, side) in enumerate(zip(system.mesh_group, system.mesh_side))
           if g == "1" and side == "sun"]
    lever = np.asarray(system.mesh_radius)[sun]
    x_mean = ds["displacement_cos"].sel(dof="1.sun").values[:, 0]
    torque = ds["mean_force"].values[:, sun] @ lever + train.housing.free * x_mean
    np.testing.assert_allclose(torque, float(train.gear("first").input_torque), rtol=1e-9)


@pytest.mark.parametrize("keep", [2, -1])
def test_a_resumed_torus_sweep_equals_the_uninterrupted_one(train, full, tmp_path, keep):
    """Interrupted after ``keep`` points (-1: all but the segment's end record), a torn
    record after them: the resumed sweep is identical and its journal unchanged."""
    result, data = full
    lines = data.splitlines(keepends=True)
    kept = lines[:-1] if keep == -1 else lines[:1 + keep]
    torn = lines[len(kept)][: len(lines[len(kept)]) // 2]
    path = tmp_path / "sweep.nc.journal"
    path.write_bytes(b"".join(kept) + torn)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.TruncationWarning)
        resumed = _sweep.sweep(train, "first", journal=path, resume=True, **BAND)
    a, b = resumed.dataset.copy(), result.dataset.copy()
    for ds in (a, b):
        ds.attrs.pop("created", None)
    xr.testing.assert_identical(a, b)
    assert path.read_bytes() == data


def test_cli_sweep_json_of_a_two_group_train(torus_h1_file, capsys):
    code = main(["sweep", str(torus_h1_file), "--from", "3000", "--to", "3020", "--harmonics", "2",
                 "--max-step", "10", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["solver"]["torus"]["G"] == 2
    assert out["segments"][0][2] == [2, 2]
    assert all(p["converged"] for p in out["points"])
    assert all(len(p["stage_mesh_frequency_hz"]) == 2 for p in out["points"])


def test_a_second_torus_sweep_compiles_nothing(train, full):
    """Shapes and static settings are compile keys (orders, grid, chunks, steps): the same
    sweep again, from a fresh gear case and fresh problems in the same process, reuses
    every compiled program of the first (nothing of a run leaks into a compile key; the
    persistent cache of a second process relies on the same)."""
    import jax

    compiles = []

    def listener(event, duration, **kwargs):  # noqa: ARG001
        if event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", gj.TruncationWarning)
            other = _sweep.sweep(train, "first", **BAND)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert other.stop == "reached_end"
    assert len(compiles) == 0


def test_cli_sweep_of_a_three_group_train(tmp_path, capsys):
    """A 3-torus from the command line with the same flags: three stages whose mesh
    frequencies share no small common base (tests/data/three_stage_incommensurate.toml,
    one stiffness harmonic per mesh here), two orders per angle. The JSON names the three
    angles and their exact ratios, every point converges, and the mean mesh forces of the
    linear sweep are the static ones (the torus average of the equations of motion)."""
    path = tmp_path / "three_h1.toml"
    path.write_text((pathlib.Path(__file__).parent.parent / "data" /
                     "three_stage_incommensurate.toml").read_text().replace(
        "stiffness_harmonics = 4", "stiffness_harmonics = 1", 1))
    code = main(["sweep", str(path), "--from", "3000", "--to", "3020", "--harmonics", "2",
                 "--max-step", "10", "--linear", "--points", "3", "--json"])
    out = json.loads(capsys.readouterr().out)
    torus = out["solver"]["torus"]
    assert code == 0 and torus["G"] == 3 and len(torus["angle_ratio_exact"]) == 3
    assert out["segments"][0][2] == [2, 2, 2]
    assert len(out["points"]) >= 3 and all(p["converged"] for p in out["points"])
    assert all(len(p["stage_mesh_frequency_hz"]) == 3 for p in out["points"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        static = gj.static_mesh_forces(gj.gear_case(gj.load_train(path), torus=True).system)
    for p in out["points"]:
        mean = [m["mean_force"] for m in p["meshes"]]
        np.testing.assert_allclose(mean, np.asarray(static), rtol=1e-6)
