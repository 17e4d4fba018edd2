"""Involute spur-gear geometry: tooth forms, the contact along the line of action, and
the rules a real gear pair must meet.

Everything but :func:`mesh_violations` is ``jax.numpy`` in float64 and differentiable
with respect to every float input (module, pressure angle, profile shifts, addendum,
centre distance): no Python branch depends on a traced value.

Conventions (ISO 21771, the same as DIN 3960 and KISSsoft):

- Lengths of the methods and of :class:`MeshContact` are SI (m), angles radians; the
  fields of :class:`ToothForm` keep the train file's units (``module_mm`` in mm,
  ``pressure_angle_deg`` in degrees, the rest coefficients of the module).
- Profile shift of an **internal** gear: a positive ``x`` moves the ring's basic-rack
  datum line towards the ring's tooth tips, that is towards the gear axis. The ring's
  teeth get *thicker* at the reference circle, ``s = m (pi/2 + 2 x tan(alpha))`` as for
  an external gear, and its tip and root diameters get *smaller*:
  ``d_a = d - 2 m (h_a* + x)``, ``d_f = d + 2 m (h_f* - x)``. This is ISO 21771's sign
  (formulas written with ``z_2 < 0``), so a ring's ``x`` read from KISSsoft means the same
  here. KHK's technical data and other JIS-based texts use the opposite sign for internal
  gears: ``x_here = -x_KHK``.
- Zero-backlash operating pressure angle (both pairs in one formula, ISO 21771 with
  ``z_2 < 0`` for a ring):

      external: inv(alpha_w) = inv(alpha) + 2 tan(alpha) (x1 + x2) / (z2 + z1)
      internal: inv(alpha_w) = inv(alpha) - 2 tan(alpha) (x1 + x2) / (z2 - z1)

  derived from ``s1(r_w1) + s2(r_w2) = p_w`` (external) and ``s1(r_w1) = e2(r_w2)`` (the
  planet's tooth fills the ring's space), with ``r_w1 / z1 = r_w2 / z2``.

Line of action (transverse plane). ``T1``, ``T2`` are the points where it touches the
base circles of gear 1 and gear 2, ``L = |T1 T2| = a_w sin(alpha_w)``; a contact point is
given by its distance ``s`` from ``T1``, positive towards the pitch point ``C`` (at
``s = r_b1 tan(alpha_w)``). Gear 1's roll distance (``sqrt(r^2 - r_b^2)``) is ``s``.

- External pair: ``T2`` lies beyond ``C``, gear 2's roll distance is ``L - s``; contact
  begins where gear 2's tip circle cuts the line, ``s = L - sqrt(r_a2^2 - r_b2^2)``, and
  ends on gear 1's tip circle, ``s = sqrt(r_a1^2 - r_b1^2)``.
- Internal pair (planet = gear 1, ring = gear 2): both centres lie on the same side of
  ``C`` and ``T2`` lies on the far side of ``T1`` from ``C``
  (``L = (r_b2 - r_b1) tan(alpha_w) = a_w sin(alpha_w)``), so the ring's roll distance is
  ``s + L``. The ring's material lies *outside* its tip circle, so contact needs
  ``s + L >= sqrt(r_a2^2 - r_b2^2)``: it begins at ``s = sqrt(r_a2^2 - r_b2^2) - L`` and
  ends on the planet's tip circle. The contact ratio is the textbook
  ``(sqrt(r_a1^2 - r_b1^2) - sqrt(r_a2^2 - r_b2^2) + a_w sin(alpha_w)) / p_b``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import bad_argument

THIN_TIP = 0.2
"""Tip thickness (in modules) below which :func:`mesh_violations` warns ('thin tip')."""

JAM_TOLERANCE_M = 1e-9
"""Centre-distance error (m) on the jamming side that :func:`mesh_violations` forgives."""

_SERIES_LIMIT = 0.1
"""Below this angle (rad) the involute is summed as a series (``tan a - a`` cancels)."""

_TAN_SERIES = (1 / 3, 2 / 15, 17 / 315, 62 / 2835, 1382 / 155925, 21844 / 6081075,
               929569 / 638512875)
"""``tan(a) - a = a^3 sum_k c_k a^(2k)``: the Taylor coefficients of ``tan`` from ``a^3``."""

_NEWTON_STEPS = 8


def _float(x) -> Array:
    return jnp.asarray(x, dtype=jnp.result_type(float))


def _safe_sqrt(q):
    """``sqrt(max(q, 0))`` with a finite derivative (zero) where ``q <= 0``."""
    positive = q > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, q, 1.0)), 0.0)


def _concrete(x):
    """``x`` as a NumPy array, or ``None`` when it is traced (no value to check)."""
    try:
        return np.asarray(x)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return None


def involute(alpha: ArrayLike) -> Float[Array, "*shape"]:
    """The involute function ``inv(alpha) = tan(alpha) - alpha``.

    **Arguments:** ``alpha``: angle (rad), any shape, ``|alpha| < pi/2``.

    **Returns:** ``inv(alpha)`` (rad), same shape; below 0.1 rad summed as a series, so
    small angles keep their full relative precision.
    """
    alpha = _float(alpha)
    small = jnp.abs(alpha) < _SERIES_LIMIT
    a = jnp.where(small, alpha, 0.0)
    a2 = a * a
    poly = jnp.zeros_like(a)
    for c in reversed(_TAN_SERIES):
        poly = poly * a2 + c
    return jnp.where(small, a * a2 * poly, jnp.tan(alpha) - alpha)


@jax.custom_jvp
def inverse_involute(inv: ArrayLike) -> Float[Array, "*shape"]:
    """The angle whose involute is ``inv``: ``alpha`` with ``tan(alpha) - alpha = inv``.

    Newton's method from an upper bound of the root (``alpha <= (3 inv)^(1/3)`` and
    ``tan(alpha) = inv + alpha``), on which the convex residual converges monotonically;
    a fixed number of steps (converged after five), accurate to 1e-15 rad for angles
    0 to 85 degrees.
    The derivative is exact (``d alpha / d inv = 1 / tan(alpha)^2``, infinite at 0).

    **Arguments:** ``inv``: involute value (rad), any shape (odd: negative values give
    negative angles).

    **Returns:** ``alpha`` (rad), same shape.
    """
    v = _float(inv)
    sign = jnp.where(v < 0, -1.0, 1.0)
    v = jnp.abs(v)
    alpha = jnp.arctan(v + jnp.minimum(jnp.cbrt(3 * v), jnp.pi / 2))
    for _ in range(_NEWTON_STEPS):
        t2 = jnp.tan(alpha) ** 2
        step = (involute(alpha) - v) / jnp.where(t2 > 0, t2, 1.0)
        alpha = alpha - jnp.where(t2 > 0, step, 0.0)
    return sign * alpha


@inverse_involute.defjvp
def _inverse_involute_jvp(primals, tangents):
    alpha = inverse_involute(primals[0])
    return alpha, _float(tangents[0]) / jnp.tan(alpha) ** 2


class ToothForm(eqx.Module):
    """One gear's teeth: a spur gear cut by the ISO 53 basic rack (external) or its
    internal counterpart (a ring).

    **Fields:**

    - ``teeth``: number of teeth ``z`` (static).
    - ``module_mm``: module ``m`` (mm).
    - ``pressure_angle_deg``: reference (rack) pressure angle ``alpha`` (degrees).
    - ``profile_shift``: profile shift coefficient ``x``. For a ring (``internal``) the
      ISO 21771 / KISSsoft sign: positive ``x`` moves the teeth towards the gear axis,
      making them thicker at the reference circle and the tip and root diameters
      *smaller* (KHK and JIS texts use ``-x``); see the module docstring.
    - ``addendum``: tip height coefficient ``h_a*`` (1.0); a tip alteration ``k`` of
      ISO 21771 (``h_a = m (h_a* + x + k)``) is included here.
    - ``dedendum``: root depth coefficient ``h_f*`` (1.25), the basic rack's dedendum
      ``h_fP*`` and the cutter's addendum.
    - ``root_radius``: the basic rack's root fillet radius coefficient ``rho_fP*`` (the
      cutter's tip radius, 0.38 for ISO 53 profile A), in modules; not the radius of
      the root circle (:meth:`root_circle_radius`).
    - ``internal``: ``True`` for a ring gear (static).

    **Raises:** ``ArgumentError`` (a ``ValueError``) at construction for fewer than
    3 teeth, or, where the values are not traced, a module that is not positive or a
    pressure angle outside (0, 45) degrees.
    """

    teeth: int = eqx.field(static=True)
    module_mm: Float[Array, ""] = eqx.field(converter=_float)
    pressure_angle_deg: Float[Array, ""] = eqx.field(converter=_float, default=20.0)
    profile_shift: Float[Array, ""] = eqx.field(converter=_float, default=0.0)
    addendum: Float[Array, ""] = eqx.field(converter=_float, default=1.0)
    dedendum: Float[Array, ""] = eqx.field(converter=_float, default=1.25)
    root_radius: Float[Array, ""] = eqx.field(converter=_float, default=0.38)
    internal: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        if isinstance(self.teeth, bool) or not isinstance(self.teeth, (int, np.integer)) \
                or self.teeth < 3:
            raise bad_argument("teeth", self.teeth, "a gear has a whole number of teeth, "
                                                    "at least 3")
        m = _concrete(self.module_mm)
        if m is not None and not np.all(m > 0):
            raise bad_argument("module_mm", m.tolist(), "the module is positive (mm)")
        a = _concrete(self.pressure_angle_deg)
        if a is not None and not np.all((a > 0) & (a < 45)):
            raise bad_argument("pressure_angle_deg", a.tolist(),
                               "the pressure angle lies between 0 and 45 degrees")

    def module(self) -> Float[Array, ""]:
        """Module ``m`` (m)."""
        return self.module_mm * 1e-3

    def pressure_angle(self) -> Float[Array, ""]:
        """Reference pressure angle ``alpha`` (rad)."""
        return jnp.deg2rad(self.pressure_angle_deg)

    def pitch_radius(self) -> Float[Array, ""]:
        """Reference (pitch) circle radius ``m z / 2`` (m)."""
        return self.module() * self.teeth / 2

    def base_radius(self) -> Float[Array, ""]:
        """Base circle radius ``m z cos(alpha) / 2`` (m)."""
        return self.pitch_radius() * jnp.cos(self.pressure_angle())

    def tip_radius(self) -> Float[Array, ""]:
        """Tip circle radius (m): ``r + m (h_a* + x)``; a ring's ``r - m (h_a* + x)``."""
        height = self.module() * (self.addendum + self.profile_shift)
        return self.pitch_radius() + (-height if self.internal else height)

    def root_circle_radius(self) -> Float[Array, ""]:
        """Root circle radius (m): ``r - m (h_f* - x)``; a ring's ``r + m (h_f* - x)``."""
        depth = self.module() * (self.dedendum - self.profile_shift)
        return self.pitch_radius() + (depth if self.internal else -depth)

    def reference_thickness(self) -> Float[Array, ""]:
        """Arc tooth thickness at the reference circle, ``m (pi/2 + 2 x tan(alpha))`` (m),
        for external and internal teeth alike (ISO 21771 sign of ``x``)."""
        return self.module() * (jnp.pi / 2 + 2 * self.profile_shift
                                * jnp.tan(self.pressure_angle()))

    def thickness(self, radius: ArrayLike) -> Float[Array, "*shape"]:
        """Arc tooth thickness (m) at ``radius`` (m, any shape), from the involute:

            external: s(r) = 2 r (s / d + inv(alpha) - inv(alpha_r))
            internal: s(r) = 2 r (s / d - inv(alpha) + inv(alpha_r))

        with ``cos(alpha_r) = r_b / r``, ``s`` :meth:`reference_thickness`, ``d = m z``
        (a ring's tooth widens away from the axis: its space is an external tooth's
        shape). Radii inside the base circle are taken at the base circle (no involute
        there). Negative where the flanks have crossed (a pointed tooth).
        """
        r = _float(radius)
        rb = self.base_radius()
        alpha_r = jnp.arctan(_safe_sqrt(r * r - rb * rb) / rb)
        half = self.reference_thickness() / (2 * self.pitch_radius())
        turn = involute(self.pressure_angle()) - involute(alpha_r)
        return 2 * r * (half - turn if self.internal else half + turn)

    def tip_thickness(self) -> Float[Array, ""]:
        """Arc tooth thickness (m) on the tip circle; zero or negative for a pointed
        tooth."""
        return self.thickness(self.tip_radius())


class MeshContact(eqx.Module):
    """The contact of a gear pair along its line of action (SI units, radians).

    **Fields:**

    - ``operating_pressure_angle``: ``alpha_w`` (rad).
    - ``centre_distance``: ``a_w`` (m), as given or the zero-backlash one.
    - ``zero_backlash_centre_distance``: ``a_w0`` (m), from the profile shifts.
    - ``circumferential_backlash``: ``j_wt`` (m), the arc of play on the operating
      pitch circle that ``a_w`` adds over ``a_w0``:
      ``+-2 a_w (inv(alpha_w) - inv(alpha_w0))`` (``+`` external, ``-`` internal);
      negative: the teeth would jam. Zero without a given centre distance.
    - ``normal_backlash``: ``j_bn = j_wt cos(alpha_w)`` (m), along the line of action.
    - ``base_pitch``: ``p_b = pi m cos(alpha)`` (m).
    - ``line_of_action_length``: ``L = |T1 T2| = a_w sin(alpha_w)`` (m).
    - ``pitch_point``: position of the pitch point ``C``, ``r_b1 tan(alpha_w)`` (m).
    - ``start``, ``end``: positions (m, from ``T1``) where contact begins (gear 2's tip)
      and ends (gear 1's tip); purely geometric, so ``start < 0`` (interference) is kept
      as it is and reported by :func:`mesh_violations`.
    - ``contact_ratio``: ``(end - start) / p_b``.
    - ``base_radius1``, ``base_radius2``: (m).
    - ``internal``: whether gear 2 is a ring (static).
    """

    operating_pressure_angle: Float[Array, ""]
    centre_distance: Float[Array, ""]
    zero_backlash_centre_distance: Float[Array, ""]
    circumferential_backlash: Float[Array, ""]
    normal_backlash: Float[Array, ""]
    base_pitch: Float[Array, ""]
    line_of_action_length: Float[Array, ""]
    pitch_point: Float[Array, ""]
    start: Float[Array, ""]
    end: Float[Array, ""]
    contact_ratio: Float[Array, ""]
    base_radius1: Float[Array, ""]
    base_radius2: Float[Array, ""]
    internal: bool = eqx.field(static=True, default=False)

    def radius1(self, s: ArrayLike) -> Float[Array, "*shape"]:
        """Radius (m) on gear 1 of the contact point at ``s`` (m, any shape):
        ``sqrt(r_b1^2 + s^2)``."""
        s = _float(s)
        return jnp.sqrt(self.base_radius1**2 + s * s)

    def radius2(self, s: ArrayLike) -> Float[Array, "*shape"]:
        """Radius (m) on gear 2 of the contact point at ``s`` (m, any shape):
        ``sqrt(r_b2^2 + (L - s)^2)``, for a ring ``sqrt(r_b2^2 + (s + L)^2)``."""
        s = _float(s)
        roll = s + self.line_of_action_length if self.internal \
            else self.line_of_action_length - s
        return jnp.sqrt(self.base_radius2**2 + roll * roll)


def mesh_contact(gear1: ToothForm, gear2: ToothForm,
                 centre_distance_m: ArrayLike | None = None) -> MeshContact:
    """The contact of an external pair (sun = ``gear1``, planet = ``gear2``) or an
    internal one (planet = ``gear1``, ring = ``gear2`` with ``internal=True``).

    **Arguments:**

    - ``gear1``, ``gear2``: the tooth forms; they share module and pressure angle.
    - ``centre_distance_m``: operating centre distance (m). ``None``: the zero-backlash
      one from the profile shifts (module docstring). Given: ``cos(alpha_w) = a cos(alpha)
      / a_w`` with ``a = m (z2 +- z1) / 2``, and the backlash it adds.

    **Returns:** a :class:`MeshContact`.

    **Raises:** ``ArgumentError`` (a ``ValueError``) when ``gear1`` is a ring, a ring has
    no more teeth than its planet, the modules or pressure angles differ (checked where
    not traced), or a centre distance is not more than ``a cos(alpha)`` (the base circles
    would have no common tangent); the last is checked in traced code too
    (``eqx.error_if``).
    """
    if gear1.internal:
        raise bad_argument("gear1", f"ToothForm(teeth={gear1.teeth}, internal=True)",
                           "gear 1 is the external gear of the pair (the sun, or the planet "
                           "of a ring-planet mesh); pass the ring as `gear2`")
    internal = gear2.internal
    if internal and gear2.teeth <= gear1.teeth:
        raise bad_argument("gear2", f"ToothForm(teeth={gear2.teeth}, internal=True)",
                           f"a ring has more teeth than the planet it meshes with "
                           f"({gear1.teeth})")
    for name in ("module_mm", "pressure_angle_deg"):
        v1, v2 = _concrete(getattr(gear1, name)), _concrete(getattr(gear2, name))
        if v1 is not None and v2 is not None and not np.allclose(v1, v2, rtol=1e-12, atol=0):
            raise bad_argument(f"gear2.{name}", v2.tolist(),
                               f"both gears of a pair share the {name} of `gear1` "
                               f"({v1.tolist()})")
    z1, z2 = gear1.teeth, gear2.teeth
    sigma = -1.0 if internal else 1.0
    zsum = z2 + sigma * z1
    m = gear1.module()
    alpha = gear1.pressure_angle()
    reference = m * zsum / 2
    shifts = gear1.profile_shift + gear2.profile_shift
    inv0 = involute(alpha) + sigma * 2 * jnp.tan(alpha) * shifts / zsum
    alpha_w0 = inverse_involute(inv0)
    a_w0 = reference * jnp.cos(alpha) / jnp.cos(alpha_w0)
    if centre_distance_m is None:
        a_w, alpha_w = a_w0, alpha_w0
        backlash = jnp.zeros_like(a_w0)
    else:
        a_w = _float(centre_distance_m)
        floor = reference * jnp.cos(alpha)
        a_c, f_c = _concrete(a_w), _concrete(floor)
        if a_c is not None and f_c is not None and not np.all(a_c > f_c):
            raise bad_argument("centre_distance_m", a_c.tolist(),
                               f"the centre distance exceeds a cos(alpha) = "
                               f"{float(np.max(f_c)) * 1e3:.6g} mm (the sum of the base "
                               f"radii, for a ring their difference): at or below it the "
                               f"base circles have no common tangent")
        a_w = eqx.error_if(a_w, a_w <= floor,
                           "centre_distance_m: the centre distance must exceed a cos(alpha)")
        alpha_w = jnp.arccos(floor / a_w)
        backlash = sigma * 2 * a_w * (involute(alpha_w) - inv0)
    rb1, rb2 = gear1.base_radius(), gear2.base_radius()
    length = a_w * jnp.sin(alpha_w)
    roll1 = _safe_sqrt(gear1.tip_radius() ** 2 - rb1**2)
    roll2 = _safe_sqrt(gear2.tip_radius() ** 2 - rb2**2)
    start = roll2 - length if internal else length - roll2
    pitch = jnp.pi * m * jnp.cos(alpha)
    return MeshContact(
        operating_pressure_angle=alpha_w, centre_distance=a_w,
        zero_backlash_centre_distance=a_w0, circumferential_backlash=backlash,
        normal_backlash=backlash * jnp.cos(alpha_w), base_pitch=pitch,
        line_of_action_length=length, pitch_point=rb1 * jnp.tan(alpha_w), start=start,
        end=roll1, contact_ratio=(roll1 - start) / pitch, base_radius1=rb1,
        base_radius2=rb2, internal=internal)


def undercut_limit(gear: ToothForm) -> float:
    """The smallest profile shift (ISO 53 rule) at which the rack that generates an
    external gear does not undercut it: ``x_min = h_f* - rho_f* (1 - sin(alpha)) -
    z sin(alpha)^2 / 2`` (the straight flank of the cutter, of height ``h_f* - rho_f*
    (1 - sin(alpha))`` above its datum line, reaches the interference point ``T``).
    NumPy on concrete values. With ``h_f* - rho_f* (1 - sin(alpha)) = 1`` and
    ``x = 0`` the limit is the classic ``z = 2 / sin(alpha)^2`` (17.1 at 20 degrees)."""
    alpha = math.radians(float(gear.pressure_angle_deg))
    return (float(gear.dedendum) - float(gear.root_radius) * (1 - math.sin(alpha))
            - gear.teeth * math.sin(alpha) ** 2 / 2)


def mesh_violations(gear1: ToothForm, gear2: ToothForm,
                    contact: MeshContact) -> list[tuple[str, str]]:
    """The geometry rules of a real gear pair that ``gear1``, ``gear2`` meshing as
    ``contact`` (from :func:`mesh_contact`) break.

    Evaluated with NumPy on concrete values (not inside ``jit`` or ``grad``). Rules, in
    this order:

    - ``contact ratio``: below 1;
    - ``involute interference``: contact starts before ``T1`` (``start < 0``: gear 2's
      tip meets gear 1 below its base circle); external pair: contact ends beyond ``T2``;
      internal pair: the ring's tip circle not outside its base circle;
    - ``undercut``: an external gear's ``x`` below :func:`undercut_limit` (rack cutting);
    - ``pointed teeth``: tip thickness zero or negative;
    - ``warning: thin tip``: tip thickness below :data:`THIN_TIP` modules (a warning);
    - ``jamming``: the centre distance on the jamming side of the zero-backlash one
      (smaller for an external pair, larger for an internal one) by more than
      :data:`JAM_TOLERANCE_M`.

    **Returns:** ``[(rule, message), ...]``, each message one sentence with the numbers
    (mm, degrees, dimensionless); empty when the pair is sound.

    **Raises:** ``jax.errors.TracerArrayConversionError`` on traced values.
    """
    val = lambda x: float(np.asarray(x))  # noqa: E731
    mm = lambda x: f"{val(x) * 1e3:.4g} mm"  # noqa: E731
    out: list[tuple[str, str]] = []
    gears = ((1, gear1), (2, gear2))
    eps = val(contact.contact_ratio)
    if eps < 1:
        out.append(("contact ratio", f"the contact ratio {eps:.4g} is below 1, so one tooth "
                    f"pair leaves contact before the next one enters"))
    start, end, length = val(contact.start), val(contact.end), val(contact.line_of_action_length)
    if start < 0:
        out.append(("involute interference",
                    f"contact starts {mm(-start)} before T1 on the line of action: gear 2's "
                    f"tip (radius {mm(gear2.tip_radius())}) meets gear 1 below its base "
                    f"circle (radius {mm(contact.base_radius1)})"))
    if not contact.internal and end > length:
        out.append(("involute interference",
                    f"contact ends {mm(end - length)} beyond T2 on the line of action: gear "
                    f"1's tip (radius {mm(gear1.tip_radius())}) meets gear 2 below its base "
                    f"circle (radius {mm(contact.base_radius2)})"))
    if contact.internal and val(gear2.tip_radius()) <= val(contact.base_radius2):
        out.append(("involute interference",
                    f"the ring's tip circle (radius {mm(gear2.tip_radius())}) is not outside "
                    f"its base circle (radius {mm(contact.base_radius2)}), so its teeth have "
                    f"no involute at the tip"))
    for i, g in gears:
        if not g.internal:
            limit = undercut_limit(g)
            x = val(g.profile_shift)
            if x < limit:
                out.append(("undercut",
                            f"gear {i} (z = {g.teeth}) is undercut by its generating rack: "
                            f"profile shift {x:.4g} is below the limit {limit:.4g} "
                            f"(h_f* = {val(g.dedendum):.4g}, rho_f* = {val(g.root_radius):.4g},"
                            f" pressure angle {val(g.pressure_angle_deg):.4g} deg)"))
    for i, g in gears:
        tip = val(g.tip_thickness())
        if tip <= 0:
            out.append(("pointed teeth",
                        f"gear {i} (z = {g.teeth}) has pointed teeth: the tooth thickness on "
                        f"its tip circle (radius {mm(g.tip_radius())}) is {mm(tip)}"))
        elif tip < THIN_TIP * val(g.module()):
            out.append(("warning: thin tip",
                        f"gear {i} (z = {g.teeth}) has a thin tip: the tooth thickness on its "
                        f"tip circle is {mm(tip)}, below {THIN_TIP} m = "
                        f"{mm(THIN_TIP * val(g.module()))}"))
    a_w, a_w0 = val(contact.centre_distance), val(contact.zero_backlash_centre_distance)
    excess = (a_w - a_w0) if contact.internal else (a_w0 - a_w)
    if excess > JAM_TOLERANCE_M:
        side = "larger" if contact.internal else "smaller"
        out.append(("jamming",
                    f"the centre distance {a_w * 1e3:.6f} mm is {excess * 1e3:.4g} mm {side} "
                    f"than the zero-backlash one ({a_w0 * 1e3:.6f} mm), so the teeth would "
                    f"jam (normal backlash {mm(contact.normal_backlash)})"))
    return out
