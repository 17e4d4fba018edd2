"""Load sharing among planets with pin position errors (translational model, and the
torsional model's equivalent mean transmission error): the static results of Kahraman
(1994, Mech. Mach. Theory 29, 1151-1165) that follow from the force balance alone,
against closed forms.

With rigid bearings and one stage (sun driven, ring braked), planet ``i``'s sun-mesh
deflection is ``d_si = D - e_i cos(alpha)`` plus the ring mesh's share: its moment
balance gives ``k_s d_si = k_r d_ri``, so

    F_si = sum_j F_sj / N + 2 k_eff cos(alpha) (mean(e) - e_i),
    k_eff = k_s k_r / (k_s + k_r),

``e_i`` the tangential pin error. A floating sun of a three-planet stage (two more
freedoms for three loads that must sum to the torque) shares exactly. With four planets
the sun's force balance pairs opposite planets, whose lines of action are antiparallel:
``F_i = F_{i+2}``, each pair carrying its mean error,

    F_si = sum_j F_sj / N + 2 k_eff cos(alpha) (mean(e) - (e_i + e_{i+2}) / 2),

so a floating sun lowers the factor only where the heaviest planet's error differs from
its opposite's: an error on one planet alone leaves it unchanged.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from gearjax import TrainError, loads_train, static_loads
from train_refusals import mutate, refuse

DATA = Path(__file__).parent.parent / "data"
HELICOPTER = (DATA / "helicopter_five_planets.toml").read_text()
RIGID = 1e15
"""Bearing stiffness (N/m) of the rigid limit: 1e6 times the meshes'."""


def _stage(angles, errors_um, sun_bearing=RIGID, model="translational", radial=None):
    def change(raw):
        raw["model"] = model
        s = raw["stages"][0]
        s["planet_angles_deg"] = list(angles)
        s["mass"] = {"sun": 2.1, "ring": 9.0, "carrier": 12.0}
        s["bearing_stiffness"] = {"sun": sun_bearing, "ring": RIGID, "carrier": RIGID,
                                  "planet": RIGID}
        s["planet_position_error_um"] = {"tangential": list(errors_um)}
        if radial is not None:
            s["planet_position_error_um"]["radial"] = list(radial)
    return mutate(HELICOPTER, change)


def _load(text):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # assembly rule at 120 / 90 degrees
        return loads_train(text, source="bad.toml")


def _sun_forces(train):
    loads = static_loads(train)
    sid = train.stages[0].id
    n = train.stages[0].n_planets
    return np.array([loads.mesh_force[f"{sid}.sp{i + 1}"] for i in range(n)]), loads


def _closed_form(train, forces, errors_um, pair_mean=False):
    """The sun-mesh forces of the closed forms above (``pair_mean``: four planets on a
    floating sun, each error replaced by its opposite pair's mean)."""
    s = train.stages[0]
    k_s, k_r = float(s.mesh_stiffness.sun), float(s.mesh_stiffness.ring)
    k_eff = k_s * k_r / (k_s + k_r)
    cos_a = np.cos(np.deg2rad(float(s.pressure_angle_deg)))
    e = np.asarray(errors_um) * 1e-6
    own = 0.5 * (e + np.roll(e, 2)) if pair_mean else e
    return forces.mean() + 2 * k_eff * cos_a * (e.mean() - own)


def test_equal_spacing_without_errors_shares_equally():
    """Equal to round-off: bearings 1e6 times stiffer than the meshes leave about
    1e-16 * 1e6 * (the static solve's other scales) of relative error, 1e-8 here."""
    forces, loads = _sun_forces(_load(_stage([0, 72, 144, 216, 288], [0.0] * 5)))
    np.testing.assert_allclose(forces, forces.mean(), rtol=1e-7)
    assert loads.load_sharing["main"] == pytest.approx(1.0, abs=1e-7)


@pytest.mark.parametrize("model", ["translational", "torsional"])
def test_a_tangential_pin_error_loads_the_planets_as_the_static_equations_give(model):
    """The torsional model takes the error as a mean transmission error on both meshes
    of the planet (``assembly.pin_te``): the same closed form, without bearings."""
    errors = [25.0, 0.0, 0.0]
    train = _load(_stage([0, 120, 240], errors, model=model))
    forces, loads = _sun_forces(train)
    np.testing.assert_allclose(forces, _closed_form(train, forces, errors), rtol=1e-5)
    assert loads.load_sharing["main"] == pytest.approx(forces.max() / forces.mean())
    assert loads.load_sharing["main"] > 1.1
    assert abs(loads.balance) < 1e-6 * abs(float(train.gears[0].input_torque))


def test_a_floating_sun_equalises_three_planets():
    train = _load(_stage([0, 120, 240], [25.0, 0.0, 0.0], sun_bearing=0.0))
    forces, loads = _sun_forces(train)
    np.testing.assert_allclose(forces, forces.mean(), rtol=1e-6)
    assert loads.load_sharing["main"] == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("errors", [[25.0, 0.0, 0.0, 0.0], [25.0, 10.0, 0.0, 0.0],
                                    [25.0, 10.0, -5.0, 3.0]])
def test_a_floating_sun_shares_between_opposite_planets_of_four(errors):
    """Against the pair closed form to 1e-5 (the rigid limit of the other bearings, as
    above); with errors on more than one planet here the heaviest planet's differs from
    its opposite's and the factor falls below the fixed sun's, and with an error on one
    planet alone it stays (to 1e-6)."""
    angles = [0, 90, 180, 270]
    fixed_train = _load(_stage(angles, errors))
    train = _load(_stage(angles, errors, sun_bearing=0.0))
    forces, loads = _sun_forces(train)
    np.testing.assert_allclose(forces, _closed_form(train, forces, errors, pair_mean=True),
                               rtol=1e-5)
    fixed_forces, fixed = _sun_forces(fixed_train)
    np.testing.assert_allclose(fixed_forces, _closed_form(fixed_train, fixed_forces, errors),
                               rtol=1e-5)
    shared, alone = loads.load_sharing["main"], fixed.load_sharing["main"]
    assert shared > 1.0
    if np.count_nonzero(errors) == 1:
        assert shared == pytest.approx(alone, rel=1e-6)
    else:
        assert shared < alone - 0.05


def test_the_torsional_model_shares_as_the_translational_one_with_rigid_bearings():
    """Five planets, errors on two: the two models' static sun-mesh forces agree to the
    rigid limit's 1e-6 (bearings 1e6 times the meshes' stiffness)."""
    errors = [20.0, -10.0, 0.0, 0.0, 0.0]
    angles = [0, 72, 144, 216, 288]
    translational, _ = _sun_forces(_load(_stage(angles, errors)))
    torsional, loads = _sun_forces(_load(_stage(angles, errors, model="torsional")))
    np.testing.assert_allclose(torsional, translational, rtol=1e-5)
    assert loads.load_sharing["main"] == pytest.approx(torsional.max() / torsional.mean())
    assert loads.load_sharing["main"] > 1.05


def test_radial_pin_errors_need_the_translational_model():
    text = _stage([0, 72, 144, 216, 288], [0.0] * 5, model="torsional",
                  radial=[10.0, 0, 0, 0, 0])
    refuse(_load, text, "main.planet_position_error_um.radial", "10.0", "translational")


def test_one_error_per_planet():
    text = _stage([0, 72, 144, 216, 288], [10.0, 0.0])
    with pytest.raises(TrainError, match="one error per planet"):
        _load(text)
