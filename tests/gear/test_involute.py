"""Involute spur-gear geometry (``gearjax._gear.involute``) against independent numbers.

Published worked examples:

[KHK] KHK Gear Technical Reference (Kohara Gear Industry), "Calculation of profile
      shifted spur gears" (also reproduced with its contact ratio at
      http://bolsover.com/utilitiesforalibre/profile-shifted-external-spur-gears.html):
      m = 3 mm, alpha = 20 deg, z = 12 / 24, x = +0.6 / +0.36, centre distance
      increment factor y = 0.83329 -> inv(alpha_w) = 0.034316, alpha_w = 26.0886 deg,
      a = 56.4999 mm; addenda h_a1 = (1 + y - x2) m = 4.420 mm, h_a2 = (1 + y - x1) m
      = 3.700 mm (tip diameters 44.840 / 79.400 mm); contact ratio 1.202.
[CD]  "Centre distance of profile shifted gear calc", worksheet published at
      https://scribd.com/doc/92821234 (alpha = 20 deg, Newton iteration shown):
      internal z1 = 17, z2 = 96, m = 14, x1 = 0.20, x2 = 0.50 (KHK sign) -> alpha_w =
      21.1251 deg, inv = 0.01766871, a = 557.0887 mm; external z = 30 / 78, m = 16,
      x = 0 / 0.05 -> alpha_w = 20.1446 deg, a = 864.7972 mm; z = 22 / 118, m = 8,
      x = 0 / 0.5 -> alpha_w = 21.0617 deg, a = 563.8999 mm.

The worksheet's ring uses KHK's sign (``inv(alpha_w) = inv(alpha) + 2 tan(alpha) (x2 -
x1) / (z2 - z1)``, ring tip ``d_a = d - 2 m (1 - x2)``); ISO 21771, which gearjax
follows, writes the same ring with ``x2 = -0.50``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from gearjax._errors import ArgumentError
from gearjax._gear.involute import (
    JAM_TOLERANCE_M,
    MeshContact,
    ToothForm,
    involute,
    inverse_involute,
    mesh_contact,
    mesh_violations,
    undercut_limit,
)

ALPHA = math.radians(20.0)


def inv_ref(a):
    """``tan(a) - a`` in NumPy's long double (an independent reference); below 0.01 rad,
    where even long double cancels, the Taylor series ``a^3/3 + 2 a^5/15 + 17 a^7/315 +
    62 a^9/2835`` (truncation below 1e-20 relative)."""
    a = np.asarray(a, dtype=np.longdouble)
    series = a**3 / 3 + 2 * a**5 / 15 + 17 * a**7 / 315 + 62 * a**9 / 2835
    return np.where(np.abs(a) < 0.01, series, np.tan(a) - a)


def ainv_ref(v):
    """Angle (rad) of involute ``v`` by SciPy's bracketing root finder."""
    return brentq(lambda a: math.tan(a) - a - v, 1e-9, 1.5, xtol=1e-15, rtol=1e-15)


def gear(z, x=0.0, m=2.0, **kw):
    return ToothForm(teeth=z, module_mm=m, profile_shift=x, **kw)


def ring(z, x=0.0, m=2.0, **kw):
    return ToothForm(teeth=z, module_mm=m, profile_shift=x, internal=True, **kw)


def rules(violations):
    return [rule for rule, _ in violations]


# ------------------------------------------------------------------ involute function


def test_involute_matches_long_double_and_the_table_value():
    a = np.concatenate([[1e-6, 1e-3, 0.05, 0.0999, 0.1, 0.1001],
                        np.radians(np.linspace(1.0, 80.0, 80))])
    got = np.asarray(involute(a))
    ref = inv_ref(a).astype(float)
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=0)
    # involute tables: inv(20 deg) = 0.014904 (0.0149043839 to ten places)
    assert float(involute(ALPHA)) == pytest.approx(0.0149043839, abs=1e-10)
    assert float(involute(0.0)) == 0.0


def test_inverse_involute_is_exact_to_1e_14_from_0_to_60_degrees():
    a = np.concatenate([[0.0, 1e-6, 1e-3, 0.05, 0.1], np.radians(np.linspace(0.5, 60, 120))])
    v = inv_ref(a).astype(float)  # the involute, correctly rounded to float64
    got = np.asarray(inverse_involute(v))
    assert np.max(np.abs(got - a)) < 1e-14
    # odd, and good to 80 degrees as well
    np.testing.assert_allclose(np.asarray(inverse_involute(-v)), -a, atol=1e-14)
    big = np.radians([70.0, 80.0])
    np.testing.assert_allclose(np.asarray(inverse_involute(inv_ref(big).astype(float))), big,
                               rtol=1e-14)
    # against a bracketing root finder
    assert float(inverse_involute(0.034316129694867234)) == pytest.approx(
        ainv_ref(0.034316129694867234), abs=1e-14)


def test_inverse_involute_derivative_is_exact():
    for deg in (5.0, 20.0, 45.0):
        a = math.radians(deg)
        v = math.tan(a) - a
        g = float(jax.grad(inverse_involute)(v))
        assert g == pytest.approx(1 / math.tan(a) ** 2, rel=1e-12)
        h = 1e-6 * v
        fd = (ainv_ref(v + h) - ainv_ref(v - h)) / (2 * h)
        assert g == pytest.approx(fd, rel=1e-6)
    # second derivative through the custom rule: d2a/dv2 = -2 / (tan^5 a cos^2 a)
    a = math.radians(25.0)
    g2 = float(jax.grad(jax.grad(inverse_involute))(math.tan(a) - a))
    assert g2 == pytest.approx(-2 / (math.tan(a) ** 5 * math.cos(a) ** 2), rel=1e-10)


# ------------------------------------------------------------------ tooth forms


@pytest.mark.parametrize("x", [-0.4, 0.0, 0.35, 0.8])
def test_external_thickness_at_pitch_and_base_circles(x):
    """Textbook: ``s = m (pi/2 + 2 x tan(alpha))`` on the reference circle and
    ``s_b = d_b (s / d + inv(alpha))`` on the base circle."""
    g = gear(23, x, m=2.5)
    m = 2.5e-3
    s = m * (math.pi / 2 + 2 * x * math.tan(ALPHA))
    assert float(g.thickness(m * 23 / 2)) == pytest.approx(s, rel=1e-13)
    assert float(g.reference_thickness()) == pytest.approx(s, rel=1e-13)
    db = m * 23 * math.cos(ALPHA)
    sb = db * (s / (m * 23) + float(inv_ref(ALPHA)))
    assert float(g.thickness(db / 2)) == pytest.approx(sb, rel=1e-13)
    assert float(g.tip_radius()) == pytest.approx(m * (23 / 2 + 1 + x), rel=1e-14)
    assert float(g.root_circle_radius()) == pytest.approx(m * (23 / 2 - 1.25 + x), rel=1e-14)


def test_ring_follows_the_iso_21771_sign():
    """A ring with ``x = +0.3`` (ISO 21771 / KISSsoft): tip and root diameters
    ``d - 2 m (1 + x)`` and ``d + 2 m (1.25 - x)``, both smaller than at ``x = 0``;
    tooth thickness ``m (pi/2 + 2 x tan(alpha))`` on the reference circle, thicker than
    at ``x = 0``. Its tooth space at any radius is the tooth of an external gear with the
    same teeth and ``-x`` (the shaper's own tooth), so tooth + space = the pitch."""
    m, z, x = 2e-3, 71, 0.3
    r = ring(z, x)
    assert float(r.tip_radius()) == pytest.approx((m * z - 2 * m * (1 + x)) / 2, rel=1e-14)
    assert float(r.root_circle_radius()) == pytest.approx((m * z + 2 * m * (1.25 - x)) / 2,
                                                          rel=1e-14)
    assert float(r.tip_radius()) < float(ring(z).tip_radius())
    assert float(r.thickness(m * z / 2)) == pytest.approx(
        m * (math.pi / 2 + 2 * x * math.tan(ALPHA)), rel=1e-13)
    assert float(r.thickness(m * z / 2)) > float(ring(z).thickness(m * z / 2))
    radii = np.linspace(float(r.base_radius()) * 1.001, float(r.root_circle_radius()), 7)
    space = np.asarray(gear(z, -x).thickness(radii))
    np.testing.assert_allclose(np.asarray(r.thickness(radii)) + space, 2 * np.pi * radii / z,
                               rtol=1e-13)
    # a ring's tooth widens away from the axis, an external gear's narrows
    assert np.all(np.diff(np.asarray(r.thickness(radii))) > 0)


# ------------------------------------------------------------------ pairs


def _thickness_play(g1, g2, c):
    """Circumferential play on the operating pitch circles from the teeth themselves:
    ``p_w - s1(r_w1) - s2(r_w2)`` (for a ring, ``s2`` is its tooth: the space left for
    the planet's tooth is ``p_w - s2``)."""
    cw = math.cos(float(c.operating_pressure_angle))
    rw1, rw2 = float(g1.base_radius()) / cw, float(g2.base_radius()) / cw
    return 2 * math.pi * rw1 / g1.teeth - float(g1.thickness(rw1)) - float(g2.thickness(rw2))


@pytest.mark.parametrize("pair", [
    (gear(17, 0.4), gear(41, 0.15)),
    (gear(12, 0.6, m=3), gear(24, 0.36, m=3)),
    (gear(21, 0.25), ring(75, -0.4)),
    (gear(18, -0.2), ring(60, 0.3)),
], ids=["ext", "ext-khk", "int-neg", "int-pos"])
def test_zero_backlash_centre_distance_closes_the_play_between_the_teeth(pair):
    """At the zero-backlash centre distance the teeth, measured on the operating pitch
    circles, leave no play; at another centre distance the play equals the reported
    circumferential backlash (external: more distance, more play; internal: less)."""
    g1, g2 = pair
    c = mesh_contact(g1, g2)
    assert abs(_thickness_play(g1, g2, c)) < 1e-15
    assert float(c.circumferential_backlash) == 0.0
    sign = -1.0 if g2.internal else 1.0
    for delta in (20e-6, -10e-6):
        c2 = mesh_contact(g1, g2, centre_distance_m=c.centre_distance + delta)
        play = _thickness_play(g1, g2, c2)
        assert float(c2.circumferential_backlash) == pytest.approx(play, rel=1e-9, abs=1e-16)
        assert np.sign(play) == np.sign(sign * delta)
        assert float(c2.normal_backlash) == pytest.approx(
            play * math.cos(float(c2.operating_pressure_angle)), rel=1e-9)


def test_khk_worked_example():
    """[KHK]: the tip shortening of the example (h_a = (1 + y - x_mate) m, i.e. ISO 21771's
    tip alteration k = y - (x1 + x2)) enters as ``addendum = 1 + k``."""
    y = 0.83329
    k = y - (0.6 + 0.36)
    g1, g2 = gear(12, 0.6, m=3, addendum=1 + k), gear(24, 0.36, m=3, addendum=1 + k)
    c = mesh_contact(g1, g2)
    assert math.degrees(float(c.operating_pressure_angle)) == pytest.approx(26.0886, abs=5e-5)
    assert float(involute(c.operating_pressure_angle)) == pytest.approx(0.034316, abs=5e-7)
    assert float(c.centre_distance) * 1e3 == pytest.approx(56.4999, abs=1e-4)
    assert 2e3 * float(g1.tip_radius()) == pytest.approx(44.840, abs=5e-4)
    assert 2e3 * float(g2.tip_radius()) == pytest.approx(79.400, abs=5e-4)
    assert float(c.contact_ratio) == pytest.approx(1.202, abs=5e-4)
    assert mesh_violations(g1, g2, c) == []


@pytest.mark.parametrize(("z1", "z2", "m", "x1", "x2", "alpha_w", "a_mm"), [
    (30, 78, 16, 0.0, 0.05, 20.1446, 864.7972),
    (22, 118, 8, 0.0, 0.5, 21.0617, 563.8999),
])
def test_external_operating_pressure_angle_worked_examples(z1, z2, m, x1, x2, alpha_w, a_mm):
    """[CD], external pairs."""
    c = mesh_contact(gear(z1, x1, m=m), gear(z2, x2, m=m))
    assert math.degrees(float(c.operating_pressure_angle)) == pytest.approx(alpha_w, abs=5e-5)
    assert float(c.centre_distance) * 1e3 == pytest.approx(a_mm, abs=5e-5)


def test_internal_operating_pressure_angle_worked_example():
    """[CD], internal pair: x2 = +0.50 in KHK's sign is x2 = -0.50 in ISO 21771's."""
    c = mesh_contact(gear(17, 0.2, m=14), ring(96, -0.5, m=14))
    assert math.degrees(float(c.operating_pressure_angle)) == pytest.approx(21.1251, abs=5e-5)
    assert float(involute(c.operating_pressure_angle)) == pytest.approx(0.01766871, abs=5e-9)
    assert float(c.centre_distance) * 1e3 == pytest.approx(557.0887, abs=5e-5)
    # and ring diameters in the two signs agree: KHK d_a2 = d2 - 2 m (1 - x2_KHK)
    assert 2e3 * float(ring(96, -0.5, m=14).tip_radius()) == pytest.approx(
        14 * 96 - 2 * 14 * (1 - 0.5), rel=1e-14)


def _closed_form_ratio(g1, g2, c):
    """ISO 21771 in tip pressure angles: ``eps = [z1 (tan a_a1 - tan a_w) +- z2 (tan a_a2
    - tan a_w)] / (2 pi)`` (``-`` for a ring)."""
    tw = math.tan(float(c.operating_pressure_angle))
    t1 = math.tan(math.acos(float(g1.base_radius() / g1.tip_radius())))
    t2 = math.tan(math.acos(float(g2.base_radius() / g2.tip_radius())))
    sign = -1 if g2.internal else 1
    return (g1.teeth * (t1 - tw) + sign * g2.teeth * (t2 - tw)) / (2 * math.pi)


@pytest.mark.parametrize(("g1", "g2", "delta"), [
    (gear(20), gear(40), 0.0),
    (gear(17, 0.4), gear(41, 0.15), 0.0),
    (gear(17, 0.4), gear(41, 0.15), 50e-6),
    (gear(21, 0.25), ring(75, -0.4), 0.0),
    (gear(18, -0.2), ring(60, 0.3), -30e-6),
], ids=["20-40", "shifted", "shifted-wide", "ring", "ring-close"])
def test_contact_ratio_matches_the_closed_form(g1, g2, delta):
    c0 = mesh_contact(g1, g2)
    c = mesh_contact(g1, g2, centre_distance_m=c0.centre_distance + delta)
    assert float(c.contact_ratio) == pytest.approx(_closed_form_ratio(g1, g2, c), rel=1e-12)
    assert float(c.line_of_action_length) == pytest.approx(
        float(c.centre_distance) * math.sin(float(c.operating_pressure_angle)), rel=1e-14)
    assert float(c.base_pitch) == pytest.approx(2e-3 * math.pi * math.cos(ALPHA), rel=1e-14)


@pytest.mark.parametrize("internal", [False, True], ids=["external", "internal"])
def test_contact_points_from_both_centres_are_one_point(internal):
    """Vector geometry, independent of the module's formulas: the line of action through
    the pitch point ``C`` at ``alpha_w``, its tangent points ``T1``, ``T2`` as the feet of
    the perpendiculars from the centres; the point ``s`` from ``T1`` (towards ``C``) lies
    at ``radius1(s)`` from gear 1's centre and ``radius2(s)`` from gear 2's; contact
    starts on gear 2's tip circle and ends on gear 1's."""
    g1 = gear(19, 0.3)
    g2 = ring(67, -0.2) if internal else gear(44, 0.1)
    c = mesh_contact(g1, g2, centre_distance_m=mesh_contact(g1, g2).centre_distance + 40e-6)
    aw, alw = float(c.centre_distance), float(c.operating_pressure_angle)
    rw1 = float(g1.base_radius()) / math.cos(alw)
    o1 = np.array([0.0, 0.0])
    o2 = np.array([-aw, 0.0]) if internal else np.array([aw, 0.0])
    pitch = np.array([rw1, 0.0])
    u = np.array([math.sin(alw), math.cos(alw)])  # along the line of action
    foot = lambda o: pitch + np.dot(o - pitch, u) * u  # noqa: E731
    t1, t2 = foot(o1), foot(o2)
    assert np.linalg.norm(t1 - o1) == pytest.approx(float(c.base_radius1), rel=1e-12)
    assert np.linalg.norm(t2 - o2) == pytest.approx(float(c.base_radius2), rel=1e-12)
    assert np.linalg.norm(t2 - t1) == pytest.approx(float(c.line_of_action_length), rel=1e-12)
    towards_c = (pitch - t1) / np.linalg.norm(pitch - t1)
    assert np.linalg.norm(pitch - t1) == pytest.approx(float(c.pitch_point), rel=1e-12)
    # T2 is beyond C (external), or on the far side of T1 from C (internal)
    assert np.dot(t2 - t1, towards_c) * (-1 if internal else 1) > 0
    s = np.linspace(float(c.start), float(c.end), 9)
    points = t1[None, :] + s[:, None] * towards_c[None, :]
    np.testing.assert_allclose(np.linalg.norm(points - o1, axis=1),
                               np.asarray(c.radius1(s)), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(points - o2, axis=1),
                               np.asarray(c.radius2(s)), rtol=1e-12)
    assert np.linalg.norm(points[0] - o2) == pytest.approx(float(g2.tip_radius()), rel=1e-12)
    assert np.linalg.norm(points[-1] - o1) == pytest.approx(float(g1.tip_radius()), rel=1e-12)


# ------------------------------------------------------------------ rules


def test_undercut_limit_is_the_classic_17_teeth():
    """x = 0, 20 degrees, a rack whose straight flank reaches 1 m below the datum line
    (h_a* = 1 of the classic, here h_f* = 1 with a sharp tip, rho_f* = 0): undercut below
    ``z = 2 / sin(alpha)^2 = 17.097``, so 17 teeth are (just) undercut and 18 are not.
    ISO 53 profile A (1.25, 0.38) has its straight flank end at 0.99997 m: the same."""
    for kw in (dict(dedendum=1.0, root_radius=0.0), {}):
        z17, z18 = gear(17, **kw), gear(18, **kw)
        lim17, lim18 = undercut_limit(z17), undercut_limit(z18)
        assert lim17 > 0 > lim18
        crossing = 17 + lim17 / (lim17 - lim18)  # the limit is linear in z
        height = 1.0 if kw else 1.25 - 0.38 * (1 - math.sin(ALPHA))
        assert crossing == pytest.approx(2 * height / math.sin(ALPHA) ** 2, rel=1e-12)
        assert crossing == pytest.approx(17.1, abs=5e-3)
        mate = gear(40, **kw)
        bad = mesh_violations(z17, mate, mesh_contact(z17, mate))
        assert [r for r in rules(bad) if r == "undercut"] == ["undercut"]
        msg = dict(bad)["undercut"]
        assert "gear 1 (z = 17)" in msg and f"{lim17:.4g}" in msg
        assert "undercut" not in rules(mesh_violations(z18, mate, mesh_contact(z18, mate)))
    # a shift of the limit cures it; a ring is never checked against a rack
    cured = gear(12, undercut_limit(gear(12)) + 1e-9)
    assert "undercut" not in rules(mesh_violations(cured, gear(40), mesh_contact(cured, gear(40))))


def test_pointed_and_thin_teeth_of_a_heavily_shifted_pinion():
    """z = 10, x = 0.8: the tip diameter 13.6 m exceeds the pointed-tooth diameter
    ``d_amax = m z cos(alpha) / cos(gamma)``, ``inv(gamma) = pi / (2 z) + 2 x tan(alpha) / z
    + inv(alpha)`` (13.495 m); z = 10, x = 0.6 keeps a tip 0.102 m thick: thin, not
    pointed."""
    z, x = 10, 0.8
    gamma = ainv_ref(math.pi / (2 * z) + 2 * x * math.tan(ALPHA) / z + float(inv_ref(ALPHA)))
    d_amax = z * math.cos(ALPHA) / math.cos(gamma)
    assert d_amax == pytest.approx(13.495, abs=5e-4)
    assert z + 2 + 2 * x > d_amax
    pinion, mate = gear(z, x), gear(30)
    got = mesh_violations(pinion, mate, mesh_contact(pinion, mate))
    assert "pointed teeth" in rules(got)
    assert "gear 1 (z = 10)" in dict(got)["pointed teeth"]
    assert float(pinion.tip_thickness()) < 0
    # the thickness vanishes exactly on the d_amax circle
    assert abs(float(pinion.thickness(2e-3 * d_amax / 2))) < 1e-15
    thin = gear(10, 0.6)
    got = mesh_violations(thin, mate, mesh_contact(thin, mate))
    assert "pointed teeth" not in rules(got)
    assert "warning: thin tip" in rules(got)
    assert float(thin.tip_thickness()) / 2e-3 == pytest.approx(0.10233, abs=1e-5)
    assert "0.2047 mm" in dict(got)["warning: thin tip"]


def test_involute_interference():
    """External: a 10-tooth pinion with a 60-tooth gear (standard) - the gear's tip cuts
    the line before T1; the other way round, contact ends beyond T2. Internal: a 24-tooth
    ring's tip circle (11 m) lies inside its base circle (11.28 m); a 14-tooth planet
    (x = 0.25) in an 80-tooth ring with x = +0.3 (its tips moved towards the axis, ISO
    21771 sign) starts contact before T1."""
    small, big = gear(10, 0.3), gear(60)  # x = 0.3 keeps the pinion free of undercut
    c = mesh_contact(small, big)
    assert float(c.start) < 0
    msg = dict(mesh_violations(small, big, c))["involute interference"]
    assert "before T1" in msg and f"{-float(c.start) * 1e3:.4g} mm" in msg
    c = mesh_contact(big, small)
    assert float(c.end) > float(c.line_of_action_length)
    assert "beyond T2" in dict(mesh_violations(big, small, c))["involute interference"]
    planet, r24 = gear(18, 0.5), ring(24)
    got = mesh_violations(planet, r24, mesh_contact(planet, r24))
    assert any("not outside its base circle" in m for r, m in got
               if r == "involute interference")
    planet, r80 = gear(14, 0.25), ring(80, 0.3)
    c = mesh_contact(planet, r80)
    assert float(c.start) < 0
    assert "before T1" in dict(mesh_violations(planet, r80, c))["involute interference"]
    sound = mesh_contact(gear(21, 0.25), ring(75, -0.4))
    assert mesh_violations(gear(21, 0.25), ring(75, -0.4), sound) == []


def test_contact_ratio_below_one():
    g1, g2 = gear(20, addendum=0.55), gear(30, addendum=0.55)
    c = mesh_contact(g1, g2)
    assert float(c.contact_ratio) < 1
    assert f"{float(c.contact_ratio):.4g}" in dict(mesh_violations(g1, g2, c))["contact ratio"]


@pytest.mark.parametrize("internal", [False, True], ids=["external", "internal"])
def test_jamming_side_of_the_centre_distance(internal):
    """An external pair jams when closer than the zero-backlash distance, an internal one
    when farther apart; within :data:`JAM_TOLERANCE_M` it is forgiven."""
    g1, g2 = gear(21, 0.25), (ring(75, -0.4) if internal else gear(40, 0.1))
    a0 = float(mesh_contact(g1, g2).centre_distance)
    jam = 1.0 if internal else -1.0
    c = mesh_contact(g1, g2, centre_distance_m=a0 + jam * 10e-6)
    got = dict(mesh_violations(g1, g2, c))
    assert float(c.normal_backlash) < 0
    assert "0.01 mm " + ("larger" if internal else "smaller") in got["jamming"]
    for delta in (jam * 0.5 * JAM_TOLERANCE_M, -jam * 10e-6):
        c = mesh_contact(g1, g2, centre_distance_m=a0 + delta)
        assert "jamming" not in rules(mesh_violations(g1, g2, c))


# ------------------------------------------------------------------ derivatives


def _ratio(x1, x2, internal=False, centre=None):
    g2 = ring(70, x2) if internal else gear(43, x2)
    return mesh_contact(gear(19, x1), g2, centre_distance_m=centre).contact_ratio


@pytest.mark.parametrize("internal", [False, True], ids=["external", "internal"])
def test_grad_of_contact_ratio_matches_central_differences(internal):
    x1, x2, h = 0.3, -0.15, 1e-5
    g1, g2 = jax.grad(_ratio, argnums=(0, 1))(x1, x2, internal)
    fd1 = (_ratio(x1 + h, x2, internal) - _ratio(x1 - h, x2, internal)) / (2 * h)
    fd2 = (_ratio(x1, x2 + h, internal) - _ratio(x1, x2 - h, internal)) / (2 * h)
    assert float(g1) == pytest.approx(float(fd1), rel=1e-6)
    assert float(g2) == pytest.approx(float(fd2), rel=1e-6)
    a0 = float(mesh_contact(gear(19, x1), ring(70, x2) if internal else gear(43, x2))
               .centre_distance)
    a = a0 + (-20e-6 if internal else 20e-6)
    ga = jax.grad(lambda c: _ratio(x1, x2, internal, c))(a)
    ha = 1e-8
    fda = (_ratio(x1, x2, internal, a + ha) - _ratio(x1, x2, internal, a - ha)) / (2 * ha)
    assert float(ga) == pytest.approx(float(fda), rel=1e-6)


def test_grad_with_respect_to_every_float_input():
    """``eqx.filter_grad`` through a scalar of the pair's geometry against central
    differences field by field (module, pressure angle, shift, addendum, dedendum, root
    radius; the last has no part in these values: zero)."""
    def value(g1: ToothForm) -> jax.Array:
        g2 = ToothForm(teeth=70, module_mm=g1.module_mm, pressure_angle_deg=g1.pressure_angle_deg,
                       profile_shift=-0.1, internal=True)  # the pair shares m and alpha
        c = mesh_contact(g1, g2)
        return (c.contact_ratio + 1e3 * c.centre_distance + 1e3 * g1.tip_thickness()
                + 1e3 * g1.root_circle_radius() + 1e3 * c.radius2(0.5 * (c.start + c.end)))

    g1 = gear(19, 0.3)
    grad = eqx.filter_grad(value)(g1)
    for name in ("module_mm", "pressure_angle_deg", "profile_shift", "addendum", "dedendum",
                 "root_radius"):
        base = float(getattr(g1, name))
        h = 1e-6 * max(abs(base), 1.0)
        up = eqx.tree_at(lambda g: getattr(g, name), g1, jnp.asarray(base + h))
        dn = eqx.tree_at(lambda g: getattr(g, name), g1, jnp.asarray(base - h))
        fd = (float(value(up)) - float(value(dn))) / (2 * h)
        got = float(getattr(grad, name))
        assert np.isfinite(got)
        assert got == pytest.approx(fd, rel=1e-6, abs=1e-9), name


def test_jit_and_vmap_over_profile_shifts():
    f = jax.jit(jax.vmap(lambda x: _ratio(x, 0.1)))
    xs = jnp.array([0.0, 0.2, 0.4])
    np.testing.assert_allclose(np.asarray(f(xs)), [float(_ratio(x, 0.1)) for x in xs],
                               rtol=1e-13)


# ------------------------------------------------------------------ errors


@pytest.mark.parametrize(("kwargs", "needle"), [
    (dict(teeth=2, module_mm=2.0), "argument teeth = 2: a gear has a whole number of teeth"),
    (dict(teeth=17.0, module_mm=2.0), "argument teeth = 17.0"),
    (dict(teeth=17, module_mm=0.0), "argument module_mm = 0.0: the module is positive"),
    (dict(teeth=17, module_mm=2.0, pressure_angle_deg=50.0),
     "argument pressure_angle_deg = 50.0: the pressure angle lies between 0 and 45"),
])
def test_tooth_form_refusals(kwargs, needle):
    with pytest.raises(ArgumentError) as err:
        ToothForm(**kwargs)
    assert needle in str(err.value)


def test_pair_refusals():
    with pytest.raises(ArgumentError, match="gear 1 is the external gear"):
        mesh_contact(ring(70), gear(20))
    with pytest.raises(ArgumentError, match=r"a ring has more teeth than the planet .*\(30\)"):
        mesh_contact(gear(30), ring(30))
    with pytest.raises(ArgumentError, match=r"gear2.module_mm = 2.5: both gears .* \(2.0\)"):
        mesh_contact(gear(20), gear(40, m=2.5))
    with pytest.raises(ArgumentError, match="gear2.pressure_angle_deg = 25.0"):
        mesh_contact(gear(20), gear(40, pressure_angle_deg=25.0))
    with pytest.raises(ArgumentError, match=r"exceeds a cos\(alpha\) = 56.38"):
        mesh_contact(gear(20), gear(40), centre_distance_m=0.05)


def test_mesh_contact_is_a_pytree_of_arrays():
    c = mesh_contact(gear(20), ring(50))
    assert isinstance(c, MeshContact) and c.internal
    leaves = jax.tree_util.tree_leaves(c)
    assert all(isinstance(v, jax.Array) and v.dtype == jnp.float64 for v in leaves)
