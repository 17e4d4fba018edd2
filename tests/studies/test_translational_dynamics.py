"""Harmonic balance, bearing forces and verification on the translational-rotational
model (Lin & Parker 1999, model.md).

The bearing forces are checked against each planet's and the sun's force balance
(the mean of each equation of motion: inertia averages out, so the mean bearing
force equals the resultant of the mean mesh forces along their lines of action),
against the cancellation equally spaced planets give, and the harmonic balance
against the project's time integration (model.md's 1% linear, 2% with backlash).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import gearjax as gj
from gearjax import loads_train
from train_refusals import mutate

DATA = Path(__file__).parent.parent / "data"


def _translational(name: str, **stage) -> gj.Train:
    def change(raw):
        raw["model"] = "translational"
        s = raw["stages"][0]
        s["mass"] = {"sun": 2.1, "ring": 9.0, "carrier": 12.0}
        s["bearing_stiffness"] = {"sun": 5e8, "ring": 1e9, "carrier": 1e9, "planet": 5e8}
        s.update(stage)
    text = mutate((DATA / name).read_text(), change)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return loads_train(text, source=name)


def _line_of_action(psi, alpha, side: str) -> np.ndarray:
    """``(-sin, cos)`` of ``psi -+ alpha``: where a mesh's deflection row takes the sun's
    (ring's) ``x, y`` (model.md)."""
    a = psi - alpha if side == "sun" else psi + alpha
    return np.array([-np.sin(a), np.cos(a)])


def _sweep(train, gear, lo, hi, points):
    """A short linear sweep at K = 4. The claims checked on it (mean force balances,
    symmetry) hold for the harmonic-balance equations at any K, so the truncation
    warning K = 4 draws is not about them."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.TruncationWarning)
        return gj.sweep(train, gear, lo, hi, linear=True, points=points, harmonics=4).dataset


@pytest.fixture(scope="module")
def helicopter():
    """Five equally spaced planets, linear, 1590-1610 Hz (between its modes)."""
    train = _translational("helicopter_five_planets.toml")
    return train, _sweep(train, "flight", 1590.0, 1610.0, 5)


@pytest.fixture(scope="module")
def unequal():
    """Three planets at 0, 90 and 180 degrees, linear, short band."""
    train = _translational("three_planets.toml")
    return train, _sweep(train, train.gears[0].name, 900.0, 910.0, 3)


def test_pin_forces_balance_each_planets_mean_mesh_forces(helicopter):
    """Mean pin force of planet n = |F_sn (-sin a, -cos a) + F_rn (sin a, -cos a)|
    in its (radial, tangential) frame, the planet's mean force balance."""
    train, ds = helicopter
    a = np.deg2rad(float(train.stages[0].pressure_angle_deg))
    F = ds["mean_force"].to_pandas()
    pins = ds["bearing_mean_force"].to_pandas()
    for n in range(1, 6):
        resultant = (np.outer(F[f"main.sp{n}"], [-np.sin(a), -np.cos(a)])
                     + np.outer(F[f"main.rp{n}"], [np.sin(a), -np.cos(a)]))
        np.testing.assert_allclose(pins[f"main.pin{n}"], np.linalg.norm(resultant, axis=1),
                                   rtol=1e-7)
    assert ds["bearing_mean_force"].attrs["units"] == "N"


def test_equally_spaced_in_phase_planets_leave_the_central_bearings_unloaded(helicopter):
    """Z_s = 40 and Z_r = 100 are multiples of N = 5: every planet meshes in phase, so
    the planets' forces on sun, ring and carrier cancel at every harmonic (Parker & Lin
    phasing): their bearing forces are round-off beside the pins'."""
    _, ds = helicopter
    np.testing.assert_allclose(ds["load_sharing"].values, 1.0, rtol=1e-9)
    pins = float(ds["bearing_rms_force"].sel(bearing="main.pin1").min())
    for member in ("main.sun", "main.ring", "main.carrier"):
        for field in ("mean_force", "rms_force", "max_force"):
            assert float(ds[f"bearing_{field}"].sel(bearing=member).max()) < 1e-9 * pins


def test_unequal_spacing_loads_the_sun_bearing_by_the_mesh_resultant(unequal):
    """Planets at 0, 90, 180 degrees: the mean sun-bearing force is the resultant of the
    mean sun-mesh forces along their lines of action."""
    train, ds = unequal
    s = train.stages[0]
    a = np.deg2rad(float(s.pressure_angle_deg))
    F = ds["mean_force"].to_pandas()
    resultant = sum(np.outer(F[f"{s.id}.sp{n + 1}"], _line_of_action(np.deg2rad(psi), a, "sun"))
                    for n, psi in enumerate(np.asarray(s.planet_angles_deg)))
    sun = ds["bearing_mean_force"].sel(bearing=f"{s.id}.sun").values
    np.testing.assert_allclose(sun, np.linalg.norm(resultant, axis=1), rtol=1e-7)
    assert np.all(sun > 1.0)
    peak = ds["bearing_max_force"].sel(bearing=f"{s.id}.sun").values
    assert np.all(peak >= sun)  # |mean F| <= mean |F| <= max |F|
    assert np.all(ds["load_sharing"].values > 1.0)


def test_points_json_carries_the_bearings(helicopter):
    _, ds = helicopter
    point = gj.points_json(ds)[0]
    names = [b["name"] for b in point["bearings"]]
    assert names == ["main.sun", "main.ring", "main.carrier"] + [f"main.pin{n}"
                                                                for n in range(1, 6)]
    assert set(point["bearings"][3]) == {"name", "stage", "mean_force", "rms_force",
                                         "max_force"}
    assert point["load_sharing"]["main"] == pytest.approx(1.0)


@pytest.mark.slow
@pytest.mark.parametrize("linear, at_hz, tolerance", [(True, 1600.0, 0.01),
                                                     (False, 1400.0, 0.02)])
def test_harmonic_balance_agrees_with_integration(linear, at_hz, tolerance):
    """model.md: within 1% (linear) and 2% (backlash) of the time integration, mesh and
    pin forces, on the translational helicopter stage; at 1400 Hz the backlash run loses
    contact for about a tenth of the period. Slow (about 10 s on 2 cores with
    compilation): two harmonic balances and integrations of a 24-coordinate system."""
    train = _translational("helicopter_five_planets.toml")
    result = gj.verify_gear(train, "flight", [at_hz], linear=linear, harmonics=16)
    assert result.all_ok and float(np.max(result.rel_diff)) < tolerance
    separation = float(result.hb["separation"].max())
    assert separation == 0.0 if linear else separation > 0.01
    for field in ("mean_force", "rms_force", "max_force"):  # bearings: harmonics vs samples
        hb, ni = (r[f"bearing_{field}"].values for r in (result.hb, result.ni))
        pins = slice(3, None)  # the central bearings carry round-off (equal spacing)
        np.testing.assert_allclose(hb[:, pins], ni[:, pins], rtol=tolerance)


def test_plot_draws_the_bearing_forces(helicopter, tmp_path, capsys):
    from gearjax._cli import main

    _, ds = helicopter
    nc, fig = tmp_path / "sweep.nc", tmp_path / "bearings.png"
    gj.save_results(ds, nc)
    assert main(["plot", str(nc), "--what", "bearings", "--out", str(fig)]) == 0
    assert fig.stat().st_size > 10_000
    torsional = tmp_path / "torsional.nc"
    gj.save_results(ds.drop_vars([v for v in ds.variables if str(v).startswith("bearing")]),
                    torsional)
    assert main(["plot", str(torsional), "--what", "bearings"]) == 2
    assert 'model = "translational"' in capsys.readouterr().err


@pytest.mark.long
def test_bearing_forces_on_a_torus_balance_the_meshes():
    """The 43 : 19 : 81 train (mesh frequencies on a 2-torus) in the translational model:
    the bearing forces come from the torus' wave coefficients, and pin 1 of stage 1
    still balances its planet's mean mesh forces. In the `long` step of CI (about 40-70 s
    on 2 cores): a torus sweep compiles its own programs, which no other test of the
    translational model shares."""
    def change(raw):
        raw["model"] = "translational"
        for s in raw["stages"]:
            s["mass"] = {"sun": 0.5, "ring": 1.0, "carrier": 0.7}
            s["bearing_stiffness"] = {"sun": 1e8, "ring": 1e9, "carrier": 1e8, "planet": 1e8}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        train = loads_train(mutate((DATA / "two_stage_43_19_81.toml").read_text(), change))
        ds = gj.sweep(train, "first", 5000.0, 5050.0, linear=True, points=3).dataset
    assert ds.sizes["angle"] == 2
    a = np.deg2rad(float(train.stages[0].pressure_angle_deg))
    F = ds["mean_force"].to_pandas()
    resultant = (np.outer(F["1.sp1"], [-np.sin(a), -np.cos(a)])
                 + np.outer(F["1.rp1"], [np.sin(a), -np.cos(a)]))
    np.testing.assert_allclose(ds["bearing_mean_force"].sel(bearing="1.pin1").values,
                               np.linalg.norm(resultant, axis=1), rtol=1e-7)
    assert float(ds["bearing_rms_force"].sel(bearing="2.sun").min()) > 0.0
