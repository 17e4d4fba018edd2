"""Static loads against rigid-body statics worked out by hand.

The static solution (mean stiffness, no backlash) differs from rigid-body statics
only by the torque that leaks through the 1e2 N m/rad housing springs of free
members; every check below allows exactly that leak and no more.
"""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

import gearjax as gj

T_IN = 750.0
M = 1.5e-3
ALPHA = math.radians(21.3)
R_S1 = M * 30 * math.cos(ALPHA) / 2  # base radius of sun 1 (m)
R_S2 = M * 44 * math.cos(ALPHA) / 2
R_R2 = M * 80 * math.cos(ALPHA) / 2
K_FREE = 1e2


@pytest.fixture(scope="module")
def train(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


@pytest.fixture(scope="module")
def first(train):
    return gj.static_loads(train, "first")


def forces(loads, stage, side=None):
    return [f for name, f in loads.mesh_force.items()
            if name.startswith(f"{stage}.") and (side is None or name[len(stage) + 1] == side)]


def test_first_gear_mesh_forces(first):
    assert len(first.mesh_force) == 16
    for f in forces(first, "1"):
        assert f == pytest.approx(8942.2, rel=1e-4)
    for f in forces(first, "2"):
        assert f == pytest.approx(11178.5, rel=1e-4)


def test_first_gear_rigid_body_estimate(first):
    """Rigid statics: 4 planets share the input torque on sun 1, F = T / (4 r_s)."""
    rigid_1 = T_IN / (4 * R_S1)
    # stage 2: its ring carries carrier 1's torque (Z_s1 + Z_r1) / Z_s1 * T_in
    rigid_2 = T_IN * (30 + 70) / 30 / (4 * R_R2)
    for f in forces(first, "1"):
        assert f == pytest.approx(rigid_1, rel=1e-3)
        assert f < rigid_1  # the leak through sun 1's housing spring unloads it slightly
    for f in forces(first, "2"):
        assert f == pytest.approx(rigid_2, rel=1e-3)


def test_planet_moment_balance(first):
    """Planet equation at rest: r_p (F_s - F_r) = 0, so sun and ring mesh forces are equal."""
    for stage in ("1", "2"):
        for i in range(1, 5):
            assert first.mesh_force[f"{stage}.sp{i}"] == pytest.approx(
                first.mesh_force[f"{stage}.rp{i}"], rel=1e-9)


def test_stage_one_sun_torque_is_input_minus_its_leak(first):
    """Sun equation at rest: r_s sum_i F_si = T_in - k_free theta_s."""
    theta_s = first.coordinates["1.sun"]
    leak_sun = K_FREE * theta_s
    assert abs(leak_sun) < 0.5
    assert R_S1 * sum(forces(first, "1", "s")) == pytest.approx(T_IN - leak_sun, rel=1e-9)


def test_mesh_torque_is_base_radius_times_force(first):
    assert first.mesh_torque["1.sp1"] == pytest.approx(R_S1 * first.mesh_force["1.sp1"], rel=1e-12)
    assert first.mesh_torque["2.sp3"] == pytest.approx(R_S2 * first.mesh_force["2.sp3"], rel=1e-12)
    assert first.mesh_torque["2.rp2"] == pytest.approx(R_R2 * first.mesh_force["2.rp2"], rel=1e-12)


def test_first_gear_brake_reaction_leak_and_balance(first):
    """Output load -T_in * 17/6 = -2125 N m; rigid brake reaction 2125 - 750 = 1375 N m,
    less the ~0.23 N m that leaks through the five free 1e2 housing springs."""
    assert first.external["1.sun"] == pytest.approx(T_IN, rel=1e-12)
    assert first.external["2.carrier"] == pytest.approx(-T_IN * 17 / 6, rel=1e-12)
    assert set(first.brake_reaction) == {"2.sun"}
    reaction = first.brake_reaction["2.sun"]
    assert abs(abs(reaction) - 1374.8) < 0.5
    assert abs(abs(reaction) - 1375.0) < 0.5
    # leak recomputed from the static rotations of the free members
    leak = sum(-K_FREE * first.coordinates[p]
               for p in ("1.sun", "1.ring", "1.carrier", "2.ring", "2.carrier"))
    assert first.leak == pytest.approx(leak, rel=1e-9)
    assert first.leak == pytest.approx(0.23, abs=0.02)
    # external torques plus housing reactions balance: 750 - 2125 + reaction + leak = 0
    assert reaction + first.leak == pytest.approx(2125.0 - 750.0, abs=1e-6)
    assert abs(first.balance) < 1e-6


def test_fourth_gear_stage_one_loaded_on_negative_flank(train):
    loads = gj.static_loads(train, "fourth")
    stage1 = forces(loads, "1")
    assert len(stage1) == 8
    assert all(f < 0 for f in stage1)
    # stage 2 is unloaded (sun 2 free): only the leak through housing springs reaches it
    assert all(abs(f) < 1e-3 * abs(stage1[0]) for f in forces(loads, "2"))
    assert abs(loads.balance) < 1e-6


@pytest.mark.parametrize("gear", ["first", "second", "third", "fourth", "reverse"])
def test_static_equals_exact_rigid_statics(train, gear):
    """kin.load is sum_i F_i m cos(alpha) / 2 per unit input torque (exact fractions)."""
    kin = gj.kinematics(train, gear)
    loads = gj.static_loads(train, gear)
    t_in = float(train.gear(gear).input_torque)
    n_loaded = 0
    for s, st in zip(train.stages, kin.stages):
        assert isinstance(st.load, Fraction)
        if not st.loaded:
            continue
        n_loaded += 1
        m = float(s.module_mm) * 1e-3
        alpha = math.radians(float(s.pressure_angle_deg))
        per_mesh = t_in * float(st.load) * 2 / (m * math.cos(alpha)) / s.n_planets
        got = forces(loads, s.id)
        assert len(got) == 2 * s.n_planets
        for f in got:
            assert f == pytest.approx(per_mesh, rel=1e-3)
    assert n_loaded >= 1
