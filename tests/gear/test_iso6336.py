"""ISO 6336-1 method B stiffness (``gearjax._gear.iso6336``) against hand calculations.

No worked example with stated ``c'`` and ``c_gamma_alpha`` was at hand (ISO/TR 6336-30
has some, not reproduced here), so the numbers below are worked by hand from the
formulas of ISO 6336-1 (quoted in the module docstring), written out in each docstring,
and checked against the standard's own rough values: "``c' = 14 N/(mm um)`` and
``c_gamma = 20 N/(mm um)``" for steel spur gears of ordinary proportions.

Hand calculation, z1 = 20, z2 = 40, x1 = x2 = 0, alpha = 20 deg, h_fP = 1.25 m:

    q'    = 0.04723 + 0.15551/20 + 0.25791/40 = 0.06145325 mm um/N
    c'_th = 1 / q' = 16.27253 N/(mm um)
    C_B   = [1 + 0.5 (1.2 - 1.25)] [1 - 0.02 (20 - 20)] = 0.975
    c'    = 16.27253 * 0.8 * 1 * 0.975 = 12.69258 N/(mm um)
    eps_alpha (standard centre distance 60 m, tips r + m):
          = [sqrt(11^2 - 9.39693^2) + sqrt(21^2 - 18.79385^2) - 30 sin 20] / (pi cos 20)
          = 1.635186
    c_gamma_alpha = 12.69258 (0.75 * 1.635186 + 0.25) = 18.73918 N/(mm um)
"""

from __future__ import annotations

import math

import jax
import pytest

from gearjax._gear.involute import ToothForm, mesh_contact
from gearjax._gear.iso6336 import IsoStiffness, basic_rack_factor, iso_stiffness


def gear(z, x=0.0, **kw):
    return ToothForm(teeth=z, module_mm=2.0, profile_shift=x, **kw)


def stiffness(g1, g2, b=0.02, **kw) -> IsoStiffness:
    return iso_stiffness(g1, g2, mesh_contact(g1, g2), b, **kw)


def test_standard_pair_by_hand():
    """The module docstring's hand calculation, and ISO's rough values: c' near 14 and
    c_gamma near 20 N/(mm um)."""
    s = stiffness(gear(20), gear(40))
    assert float(s.theoretical_single_stiffness) == pytest.approx(16.27253, rel=1e-6)
    assert float(s.basic_rack_factor) == pytest.approx(0.975, rel=1e-14)
    assert float(s.single_stiffness) == pytest.approx(12.69258, rel=1e-6)
    assert float(s.mesh_stiffness) == pytest.approx(18.73918, rel=1e-6)
    assert float(s.load_factor) == 1.0
    assert abs(float(s.single_stiffness) / 14 - 1) < 0.15
    assert abs(float(s.mesh_stiffness) / 20 - 1) < 0.15


def test_per_width_values_are_the_whole_face_width_in_n_per_m():
    """``1 N/(mm um)`` over ``b = 20 mm`` is ``20 N/um = 2e7 N/m``."""
    s = stiffness(gear(20), gear(40), b=0.02)
    assert float(s.single_per_width) == pytest.approx(12.69258 * 20 * 1e6, rel=1e-6)
    assert float(s.mesh_per_width) == pytest.approx(18.73918 * 20 * 1e6, rel=1e-6)


def test_many_teeth_tend_to_c1():
    """z1 = z2 = 1000: q' = 0.04723 + 0.15551/1000 + 0.25791/1000 = 0.04764342,
    c'_th = 20.98926, c' = 20.98926 * 0.8 * 0.975 = 16.37162 (ISO's limit 1/C1 = 21.17
    for c'_th)."""
    s = stiffness(gear(1000), gear(1000))
    assert float(s.theoretical_single_stiffness) == pytest.approx(20.98926, rel=1e-6)
    assert float(s.single_stiffness) == pytest.approx(16.37162, rel=1e-6)


def test_profile_shift_terms_by_hand():
    """z = 20 / 40, x1 = 0.3, x2 = -0.2:
    q' = 0.04723 + 0.15551/20 + 0.25791/40 - 0.00635*0.3 - 0.11654*0.3/20 - 0.00193*(-0.2)
         - 0.24188*(-0.2)/40 + 0.00529*0.09 + 0.00182*0.04 = 0.05994445,
    c'_th = 16.68211, c' = 13.01205."""
    s = stiffness(gear(20, 0.3), gear(40, -0.2))
    assert float(s.theoretical_single_stiffness) == pytest.approx(16.68211, rel=1e-6)
    assert float(s.single_stiffness) == pytest.approx(13.01205, rel=1e-6)


def test_internal_pair_takes_the_ring_as_infinite():
    """Planet z1 = 20, x1 = 0.3, ring z2 = 80, x2 = -0.2 (ISO 21771 sign), zn2 = infinity:
    q' = 0.04723 + 0.15551/20 - 0.00635*0.3 - 0.11654*0.3/20 - 0.00193*(-0.2)
         + 0.00529*0.09 + 0.00182*0.04 = 0.0522873, c'_th = 19.12510, c' = 14.91758;
    the ring's tooth count does not matter."""
    planet = gear(20, 0.3)
    for z2 in (80, 200):
        ring = gear(z2, -0.2, internal=True)
        s = stiffness(planet, ring)
        assert float(s.theoretical_single_stiffness) == pytest.approx(19.12510, rel=1e-6)
        assert float(s.single_stiffness) == pytest.approx(14.91758, rel=1e-6)
    c = mesh_contact(planet, ring)
    assert float(s.mesh_stiffness) == pytest.approx(
        14.91758 * (0.75 * float(c.contact_ratio) + 0.25), rel=1e-6)


def test_basic_rack_factor():
    """alpha_Pn = 25 deg, h_fP = 1.4 m: C_B = [1 + 0.5 (1.2 - 1.4)] [1 - 0.02 (20 - 25)]
    = 0.9 * 1.1 = 0.99; racks that differ between the gears are averaged (ISO 6336-1:2006)."""
    g = gear(30, dedendum=1.4, pressure_angle_deg=25.0)
    assert float(basic_rack_factor(g)) == pytest.approx(0.99, rel=1e-14)
    s = stiffness(gear(20, dedendum=1.4), gear(40, dedendum=1.2))
    assert float(s.basic_rack_factor) == pytest.approx((0.9 + 1.0) / 2, rel=1e-14)


@pytest.mark.parametrize(("load", "ka", "factor"), [
    (1000.0, 1.0, 0.5),    # 1000 N / 20 mm = 50 N/mm
    (1000.0, 2.0, 1.0),    # K_A lifts it to 100 N/mm
    (3000.0, 1.0, 1.0),    # 150 N/mm: no correction
])
def test_light_load_reduces_the_single_stiffness(load, ka, factor):
    s = stiffness(gear(20), gear(40), b=0.02, tangential_load_n=load, application_factor=ka)
    assert float(s.load_factor) == pytest.approx(factor, rel=1e-14)
    assert float(s.single_stiffness) == pytest.approx(12.69258 * factor, rel=1e-6)


def test_grad_with_respect_to_profile_shift_and_face_width():
    def mesh(x1, b):
        g1, g2 = gear(20, x1), gear(40, 0.1)
        return iso_stiffness(g1, g2, mesh_contact(g1, g2), b).mesh_per_width

    x1, b, h = 0.25, 0.02, 1e-6
    gx, gb = jax.grad(mesh, argnums=(0, 1))(x1, b)
    fd = (float(mesh(x1 + h, b)) - float(mesh(x1 - h, b))) / (2 * h)
    assert float(gx) == pytest.approx(fd, rel=1e-6)
    assert float(gb) == pytest.approx(float(mesh(x1, b)) / b, rel=1e-12)
    assert math.isfinite(float(gx))
