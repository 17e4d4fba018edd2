"""Compliance of one spur-gear tooth by the potential-energy (PE) method, and of a pair.

A tooth is a cantilever of thin slices normal to its centre line (thin-slice beam),
clamped at the root circle, loaded by a unit force ``F = 1 N`` along the line of
action (normal to the involute) at the flank point of radius ``r1``. The force makes
the angle ``alpha1`` with the normal to the centre line; its components are
``F cos(alpha1)`` (bending and shear) and ``F sin(alpha1)`` (compression, which also
relieves the bending moment through its lever ``h1``, the half thickness at the load).
A section at distance ``s`` from the load, of half thickness ``h``, area ``A = 2 h b``
and second moment ``I = 2 h^3 b / 3``, stores the energy of (Yang & Lin 1987,
J. Mech. Transm. Autom. Des. 109:189; Tian 2004, MSc thesis, University of Alberta)

    bending      1/k_b = int [s cos(alpha1) - h1 sin(alpha1)]^2 / (E I) ds
    shear        1/k_s = int 1.2 cos^2(alpha1) / (G A) ds,    G = E / (2 (1 + nu))
    compression  1/k_a = int sin^2(alpha1) / (E A) ds

from the load to the root circle. The gear body under the tooth (fillet foundation) adds
Sainsot, Velex & Duverger (2004, J. Mech. Des. 126:748):

    1/k_f = cos^2(alpha1) / (E b) {L* (u_f/S_f)^2 + M* (u_f/S_f) + P* (1 + Q* tan^2(alpha1))}

with ``X* = A_i/theta_f^2 + B_i h_f^2 + C_i h_f/theta_f + D_i/theta_f + E_i h_f + F_i``
(:data:`SAINSOT_COEFFICIENTS`, Sainsot's Table), ``h_f = r_f / r_int`` (root over bore
radius), ``theta_f`` the half angle of the tooth where its fillet meets the root circle,
``S_f = 2 r_f theta_f`` and ``u_f`` the distance along the centre line from the root
circle to the point where the load line crosses it. The compliance of one tooth is
``1/k_b + 1/k_s + 1/k_a + 1/k_f`` (:func:`tooth_compliance`); a tooth pair in contact adds
Hertz's ``4 (1 - nu^2) / (pi E b)`` (Yang & Lin 1987, load-independent;
:func:`hertz_compliance`, :func:`pair_compliance`).

**Geometry** (module ``m``, ``z`` teeth, basic-rack pressure angle ``alpha0``, profile
shift ``x``, coefficients of addendum ``h_a*``, dedendum ``h_f*`` and tool tip radius
``rho_f*``): pitch radius ``r = m z / 2``, base radius ``r_b = r cos(alpha0)``.

- External gear: tip ``r + m (h_a* + x)``, root ``r_f = r - m (h_f* - x)``, half tooth
  angle on the base circle ``alpha2 = pi/(2z) + 2 x tan(alpha0)/z + inv(alpha0)``. The
  beam is the involute flank from the load down to the base circle (Tian 2004) or, where
  the root circle lies above the base circle, down to the root circle (Chen & Shao 2011,
  Eng. Fail. Anal. 18:2149). Where the root circle lies below the base circle, the tooth
  goes on below the base circle as Chen & Shao's (2011) straight segment **parallel to
  the centre line** (constant half thickness ``r_b sin(alpha2)``) down to the root
  circle; not a radial line. Sainsot's ``theta_f`` is that of the generated root, the
  end of the rack tool's tip fillet: ``theta_f = [pi/2 + 2 x tan(alpha0) + 2 (h_f* -
  rho_f*) tan(alpha0) + 2 rho_f*/cos(alpha0)] / z`` (the tool tip radius enters the
  model only here). ``u_f`` is Sainsot's (along the centre line to the load line), not
  the radial distance ``r1 - r_f`` some later papers put in its place.
- Internal gear (ring): tip ``r - m (h_a* + x)``, root ``r + m (h_f* - x)`` (ISO 21771,
  negative tooth count: a positive ``x`` moves the teeth towards the axis and thickens
  them at the reference circle, ``s = m (pi/2 + 2 x tan(alpha0))``). The tooth widens
  towards its root, on the outside; the same three energy integrals are taken over
  sections normal to its centre line from the load to the root circle, as Liang, Zuo &
  Pandey (2014, Mech. Mach. Theory 76:20) do for the ring-planet pair. The load line
  meets the ring tooth from the side of its tip and pushes it towards its root, so
  ``alpha1`` is the angle of the line of action's tangent point on the base circle
  from the centre line (``alpha1 = alpha0`` for a rack). As in Liang et al. (2014),
  whose ring-planet pair is Hertz + the planet's four terms + the ring's bending,
  shear and compression, the ring tooth has **no fillet-foundation term**: Sainsot's
  fit is for the body of an external gear with a bore, and a ring's rim flexibility
  (Chen & Shao 2013, Mech. Mach. Theory 69:1) is outside this model.

**Assumptions.** Thin-slice Euler-Bernoulli bending with Timoshenko's shear factor 1.2
of a rectangular section; no fillet in the tooth beam (it is clamped at the root
circle); the load along the line of action, without friction; the tooth's own Young's
modulus ``E`` (plane stress), as Yang & Lin (1987), Tian (2004), Chen & Shao (2011),
Sainsot et al. (2004) and Liang et al. (2014) use it. For a face much wider than the
tooth, plane strain (``E / (1 - nu^2)``, 9.9 % stiffer bending at ``nu = 0.3``) would be
nearer the truth; the PE literature these formulas come from uses ``E``, and so do we,
everywhere (Hertz's term has its own ``1 - nu^2``). Without a bore radius, ``h_f = 2``
(bore ``r_f / 2``) is assumed: the foundation term depends on it strongly (its ``P*``
grows as ``h_f^2``), so pass the gear's bore where it is known.

**Numerics.** The integrals over the involute are taken in the involute's roll angle
``phi = tan(alpha(r))``, in which the section's thickness and position are analytic,
by fixed-order Gauss-Legendre quadrature of :data:`QUADRATURE_NODES` nodes; the straight
segment's integrals are in closed form. Everything is smooth in every float input, so
``jax.grad`` passes through (the root-below-base switch is a ``jnp.where`` and a
``max(., 0)`` of the segment's length, not a Python branch).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._config import require_x64
from .._errors import bad_argument

QUADRATURE_NODES = 24
"""Gauss-Legendre nodes of the integrals over the involute. Against 48 nodes the parts
agree to 1e-13 of their largest value over the flank for ordinary teeth (19 and 48 teeth,
an 81-tooth ring) and to 5e-9 for the hardest integrand tried, a 12-tooth pinion with
``x = 0.4`` and a thin tip (0.36 m thick; 16 nodes: 7e-6); tests/gear/test_tooth_stiffness.py."""

SHEAR_FACTOR = 1.2
"""Timoshenko's shear factor of a rectangular section (Tian 2004)."""

SAINSOT_COEFFICIENTS = np.array([
    # A_i        B_i         C_i         D_i         E_i      F_i
    [-5.574e-5, -1.9986e-3, -2.3015e-4, 4.7702e-3, 0.0271, 6.8045],   # L*
    [60.111e-5, 28.100e-3, -83.431e-4, -9.9256e-3, 0.1624, 0.9086],   # M*
    [-50.952e-5, 185.50e-3, 0.0538e-4, 53.300e-3, 0.2895, 0.9236],    # P*
    [-6.2042e-5, 9.0889e-3, -4.0964e-4, 7.8297e-3, -0.1472, 0.6904],  # Q*
])
"""Sainsot, Velex & Duverger (2004): rows L*, M*, P*, Q*; columns A_i ... F_i of
``X* = A_i/theta_f^2 + B_i h_f^2 + C_i h_f/theta_f + D_i/theta_f + E_i h_f + F_i``."""

DEFAULT_BODY_RATIO = 2.0
"""``h_f = r_f / r_int`` where no bore radius is given."""

_SLACK = 1e-9  # relative tolerance on the ends of the flank for a load radius


class ToothCompliance(eqx.Module):
    """The four parts of one tooth's compliance (m/N), each of the load radius's shape:
    ``bending``, ``shear``, ``axial`` (compression) and ``foundation`` (the gear body,
    Sainsot et al. 2004; zero for an internal gear)."""

    bending: Float[Array, "..."]
    shear: Float[Array, "..."]
    axial: Float[Array, "..."]
    foundation: Float[Array, "..."]

    @property
    def total(self) -> Float[Array, "..."]:
        return self.bending + self.shear + self.axial + self.foundation


def _inv(a):
    return jnp.tan(a) - a


def _check_structure(teeth, internal) -> None:
    if isinstance(teeth, bool) or not isinstance(teeth, (int, np.integer)) or teeth < 3:
        raise bad_argument("teeth", teeth, "a tooth count is a Python int of at least 3")
    if not isinstance(internal, (bool, np.bool_)):
        raise bad_argument("internal", internal, "internal is True (a ring) or False")


def _flank(teeth: int, internal: bool, m, alpha0, x, ha, hf):
    """Radii (m) and the flank's tangent-point constant of one gear.

    **Returns:** ``(r_b, r_a, r_f, c)``: base, tip and root radius, and ``c`` such that
    the tangent point on the base circle of the flank point of roll angle ``phi`` lies at
    ``c - phi`` (external: ``c = alpha2``) or ``c + phi`` (internal) from the centre line.
    """
    r = m * teeth / 2
    rb = r * jnp.cos(alpha0)
    shift = 2 * x * jnp.tan(alpha0) / teeth
    if internal:
        return rb, r - m * (ha + x), r + m * (hf - x), jnp.pi / (2 * teeth) + shift - _inv(alpha0)
    return rb, r + m * (ha + x), r - m * (hf - x), jnp.pi / (2 * teeth) + shift + _inv(alpha0)


def _section(phi, rb, c, internal: bool):
    """Half thickness ``h``, position ``y`` along the centre line (from the gear's
    centre) and ``dy/dphi`` of the flank point of roll angle ``phi`` (all in m)."""
    if internal:
        t = c + phi
        return rb * (jnp.sin(t) - phi * jnp.cos(t)), rb * (jnp.cos(t) + phi * jnp.sin(t)), \
            rb * phi * jnp.cos(t)
    t = c - phi
    return rb * (jnp.sin(t) + phi * jnp.cos(t)), rb * (jnp.cos(t) - phi * jnp.sin(t)), \
        rb * phi * jnp.cos(t)


def _roll(r, rb):
    """Roll angle ``sqrt(r^2/r_b^2 - 1)`` of radius ``r``, 0 at and below the base circle
    (with a gradient that stays finite there)."""
    q = (r / rb) ** 2 - 1
    above = q > 0
    return jnp.where(above, jnp.sqrt(jnp.where(above, q, 1.0)), 0.0)


def _sainsot(h_ratio, theta_f):
    """``(L*, M*, P*, Q*)`` at ``h_f = h_ratio`` and ``theta_f`` (rad)."""
    basis = jnp.stack(jnp.broadcast_arrays(
        1 / theta_f**2, h_ratio**2, h_ratio / theta_f, 1 / theta_f, h_ratio,
        jnp.ones_like(theta_f)), axis=-1)
    return tuple(basis @ jnp.asarray(row) for row in SAINSOT_COEFFICIENTS)


@functools.partial(jax.jit, static_argnames=("teeth", "internal", "quadrature_nodes"))
def tooth_compliance_terms(teeth: int, module_m: ArrayLike, pressure_angle_rad: ArrayLike,
                           profile_shift: ArrayLike, addendum: ArrayLike, dedendum: ArrayLike,
                           root_radius: ArrayLike, face_width_m: ArrayLike,
                           youngs_modulus_pa: ArrayLike, poisson_ratio: ArrayLike,
                           load_radius_m: ArrayLike, internal: bool = False, *,
                           bore_radius_m: ArrayLike | None = None,
                           quadrature_nodes: int = QUADRATURE_NODES) -> ToothCompliance:
    """The bending, shear, compression and fillet-foundation parts of one tooth's
    compliance under a unit normal load at radius ``load_radius_m`` (the module
    docstring gives the formulas and their sources).

    **Arguments:** as :func:`tooth_compliance`; ``quadrature_nodes``: Gauss-Legendre
    nodes over the involute (static).

    **Returns:** a :class:`ToothCompliance`, each part in m/N and of
    ``load_radius_m``'s shape.

    **Raises:** ``ArgumentError`` (a ``ValueError``) for a ``teeth`` that is not an int of
    at least 3 or an ``internal`` that is not a bool; at run time (``eqx.error_if``) for
    a load radius off the involute flank, or a face width, Young's modulus, Poisson
    ratio or bore radius out of range.
    """
    _check_structure(teeth, internal)
    require_x64()
    f = lambda v: jnp.asarray(v, dtype=float)  # noqa: E731
    m, alpha0, x, ha, hf, rho = map(f, (module_m, pressure_angle_rad, profile_shift,
                                        addendum, dedendum, root_radius))
    b, E, nu, r1 = map(f, (face_width_m, youngs_modulus_pa, poisson_ratio, load_radius_m))
    b = eqx.error_if(b, b <= 0, "tooth_compliance: face_width_m must be positive (m)")
    E = eqx.error_if(E, E <= 0, "tooth_compliance: youngs_modulus_pa must be positive (Pa)")
    nu = eqx.error_if(nu, (nu <= -1) | (nu >= 0.5),
                      "tooth_compliance: poisson_ratio must lie in (-1, 0.5)")
    G = E / (2 * (1 + nu))

    rb, ra, rf, c = _flank(teeth, internal, m, alpha0, x, ha, hf)
    if internal:
        lo, hi = jnp.maximum(ra, rb), rf
    else:
        lo, hi = jnp.maximum(rf, rb), ra
    r1 = eqx.error_if(r1, (r1 < lo * (1 - _SLACK)) | (r1 > hi * (1 + _SLACK)),
                      "tooth_compliance: load_radius_m is off the involute flank (external: "
                      "from max(root, base radius) to the tip radius; internal: from "
                      "max(tip, base radius) to the root radius)")

    phi1 = _roll(r1, rb)
    h1, y1, _ = _section(phi1, rb, c, internal)
    alpha1 = c + phi1 if internal else phi1 - c
    cos1, sin1 = jnp.cos(alpha1), jnp.sin(alpha1)

    # Involute part: phi from the root end to the load (external) or load to root (ring).
    phi_root = _roll(rf, rb)
    a, z_ = (phi1, phi_root) if internal else (phi_root, phi1)
    nodes, weights = np.polynomial.legendre.leggauss(quadrature_nodes)
    half = ((z_ - a) / 2)[..., None]
    phi = (z_ + a)[..., None] / 2 + half * nodes
    h, y, dy = _section(phi, rb, c, internal)
    w = half * weights * dy
    lever = y - y1[..., None] if internal else y1[..., None] - y
    moment = lever * cos1[..., None] - (h1 * sin1)[..., None]
    bending = jnp.sum(w * moment**2 * 1.5 / h**3, axis=-1) / (E * b)
    per_area = jnp.sum(w / (2 * h), axis=-1) / b
    shear = SHEAR_FACTOR * cos1**2 * per_area / G
    axial = sin1**2 * per_area / E
    if internal:
        return ToothCompliance(bending, shear, axial, jnp.zeros_like(bending))

    # Straight segment below the base circle (Chen & Shao 2011), length 0 if none.
    hb, yb, _ = _section(jnp.zeros_like(rb), rb, c, internal)
    length = jnp.maximum(yb - jnp.sqrt(jnp.maximum(rf**2 - hb**2, 0.0)), 0.0)
    u0 = (y1 - yb) * cos1 - h1 * sin1
    u1 = u0 + length * cos1
    bending = bending + (u1**3 - u0**3) / (3 * cos1) * 1.5 / (hb**3 * E * b)
    shear = shear + SHEAR_FACTOR * cos1**2 * length / (2 * hb * b * G)
    axial = axial + sin1**2 * length / (2 * hb * b * E)

    # Fillet foundation (Sainsot et al. 2004) with the generated root's theta_f.
    theta_f = (jnp.pi / 2 + 2 * x * jnp.tan(alpha0) + 2 * (hf - rho) * jnp.tan(alpha0)
               + 2 * rho / jnp.cos(alpha0)) / teeth
    if bore_radius_m is None:
        r_int = rf / DEFAULT_BODY_RATIO
    else:
        r_int = f(bore_radius_m)
        r_int = eqx.error_if(r_int, (r_int <= 0) | (r_int >= rf),
                             "tooth_compliance: bore_radius_m must lie between 0 and the root "
                             "radius")
    L, M, P, Q = _sainsot(rf / r_int, theta_f)
    ratio = (y1 - h1 * jnp.tan(alpha1) - rf) / (2 * rf * theta_f)
    foundation = cos1**2 / (E * b) * (L * ratio**2 + M * ratio
                                      + P * (1 + Q * jnp.tan(alpha1) ** 2))
    return ToothCompliance(bending, shear, axial, foundation)


def tooth_compliance(teeth: int, module_m: ArrayLike, pressure_angle_rad: ArrayLike,
                     profile_shift: ArrayLike, addendum: ArrayLike, dedendum: ArrayLike,
                     root_radius: ArrayLike, face_width_m: ArrayLike,
                     youngs_modulus_pa: ArrayLike, poisson_ratio: ArrayLike,
                     load_radius_m: ArrayLike, internal: bool = False, *,
                     bore_radius_m: ArrayLike | None = None) -> Float[Array, "..."]:
    """Compliance (m/N) of ONE spur-gear tooth under a unit load along the line of action
    at the flank point of radius ``load_radius_m``: bending + shear + compression (Yang
    & Lin 1987; Tian 2004; Chen & Shao 2011) + fillet foundation (Sainsot et al. 2004;
    none for an internal gear, as Liang et al. 2014). Formulas and assumptions: the
    module docstring.

    **Arguments:**

    - ``teeth``: tooth count (Python int, static).
    - ``module_m``: module (m); ``pressure_angle_rad``: basic-rack pressure angle (rad).
    - ``profile_shift``: profile shift coefficient ``x`` (internal gears: ISO 21771's
      sign, positive towards the axis).
    - ``addendum``, ``dedendum``: coefficients ``h_a*`` (1.0), ``h_f*`` (1.25).
    - ``root_radius``: the tool's tip radius coefficient ``rho_f*`` (0.38), which sets the
      generated root's ``theta_f`` of the fillet-foundation term (unused for a ring).
    - ``face_width_m`` (m), ``youngs_modulus_pa`` (Pa), ``poisson_ratio``.
    - ``load_radius_m``: radius of the load point (m), any shape, on the flank: external
      from ``max(root, base radius)`` to the tip radius, internal from
      ``max(tip, base radius)`` to the root radius.
    - ``internal``: ``True`` for a ring's tooth (static).
    - ``bore_radius_m``: the bore ``r_int`` of Sainsot's ``h_f = r_f / r_int`` (m);
      ``None``: ``r_f / 2``.

    **Returns:** the compliance, of ``load_radius_m``'s shape (m/N).

    **Raises:** as :func:`tooth_compliance_terms`.
    """
    return tooth_compliance_terms(
        teeth, module_m, pressure_angle_rad, profile_shift, addendum, dedendum,
        root_radius, face_width_m, youngs_modulus_pa, poisson_ratio, load_radius_m,
        internal, bore_radius_m=bore_radius_m).total


def hertz_compliance(face_width_m: ArrayLike, youngs_modulus_pa: ArrayLike,
                     poisson_ratio: ArrayLike) -> Float[Array, "..."]:
    """Hertzian contact compliance (m/N) of a tooth pair of one material,
    ``4 (1 - nu^2) / (pi E b)`` (Yang & Lin 1987; independent of load and of the
    contact's radii of curvature).

    **Arguments:** ``face_width_m``: contact width (m); ``youngs_modulus_pa`` (Pa);
    ``poisson_ratio``. Broadcast together.
    """
    b, E, nu = (jnp.asarray(v, dtype=float) for v in
                (face_width_m, youngs_modulus_pa, poisson_ratio))
    return 4 * (1 - nu**2) / (jnp.pi * E * b)


def _as_float(value):
    return jnp.asarray(value, dtype=float)


def _as_float_or_none(value):
    return None if value is None else jnp.asarray(value, dtype=float)


class GearTooth(eqx.Module):
    """One gear's tooth for :func:`pair_compliance`: the arguments of
    :func:`tooth_compliance` less the load radius (same names and units). ``teeth`` and
    ``internal`` are static; the rest are float arrays (traced by ``jit`` and ``grad``).

    **Raises:** ``ArgumentError`` (a ``ValueError``) at construction for a ``teeth`` that
    is not an int of at least 3 or an ``internal`` that is not a bool.
    """

    teeth: int = eqx.field(static=True)
    module_m: Float[Array, ""] = eqx.field(converter=_as_float)
    pressure_angle_rad: Float[Array, ""] = eqx.field(converter=_as_float)
    face_width_m: Float[Array, ""] = eqx.field(converter=_as_float)
    youngs_modulus_pa: Float[Array, ""] = eqx.field(converter=_as_float)
    poisson_ratio: Float[Array, ""] = eqx.field(converter=_as_float)
    profile_shift: Float[Array, ""] = eqx.field(converter=_as_float, default=0.0)
    addendum: Float[Array, ""] = eqx.field(converter=_as_float, default=1.0)
    dedendum: Float[Array, ""] = eqx.field(converter=_as_float, default=1.25)
    root_radius: Float[Array, ""] = eqx.field(converter=_as_float, default=0.38)
    internal: bool = eqx.field(static=True, default=False)
    bore_radius_m: Float[Array, ""] | None = eqx.field(converter=_as_float_or_none,
                                                      default=None)

    def __check_init__(self):
        _check_structure(self.teeth, self.internal)

    def compliance(self, load_radius_m: ArrayLike) -> Float[Array, "..."]:
        """:func:`tooth_compliance` of this tooth at ``load_radius_m`` (m/N)."""
        return tooth_compliance(
            self.teeth, self.module_m, self.pressure_angle_rad, self.profile_shift,
            self.addendum, self.dedendum, self.root_radius, self.face_width_m,
            self.youngs_modulus_pa, self.poisson_ratio, load_radius_m, self.internal,
            bore_radius_m=self.bore_radius_m)


def pair_compliance(gear1: GearTooth, gear2: GearTooth, load_radius1_m: ArrayLike,
                    load_radius2_m: ArrayLike) -> Float[Array, "..."]:
    """Compliance (m/N) of one pair of teeth in contact: Hertz + tooth 1 at
    ``load_radius1_m`` + tooth 2 at ``load_radius2_m`` (Yang & Lin 1987; Tian 2004).

    Hertz's term takes the narrower face width and, for two materials, the usual
    ``2/(pi b) [(1 - nu1^2)/E1 + (1 - nu2^2)/E2]``, which is
    :func:`hertz_compliance` for one material.

    **Arguments:** ``gear1``, ``gear2``: :class:`GearTooth`; ``load_radius1_m``,
    ``load_radius2_m``: the contact point's radius on each gear (m), broadcast together.

    **Returns:** the pair's compliance, of the broadcast shape of the radii (m/N).
    """
    b = jnp.minimum(gear1.face_width_m, gear2.face_width_m)
    hertz = 2 / (jnp.pi * b) * ((1 - gear1.poisson_ratio**2) / gear1.youngs_modulus_pa
                                + (1 - gear2.poisson_ratio**2) / gear2.youngs_modulus_pa)
    return hertz + gear1.compliance(load_radius1_m) + gear2.compliance(load_radius2_m)
