"""Tooth stiffness of spur gears by ISO 6336-1 (2006 and 2019, method B): the single
stiffness ``c'`` and the mesh stiffness ``c_gamma_alpha``, from the geometry of
:mod:`.involute`.

ISO 6336-1, clause 9 (method B), for spur gears (``beta = 0``, so ``z_n = z``):

    q' = C1 + C2/zn1 + C3/zn2 + C4 x1 + C5 x1/zn1 + C6 x2 + C7 x2/zn2 + C8 x1^2 + C9 x2^2
    c'_th = 1 / q'                                          (N/(mm um))
    c' = c'_th C_M C_R C_B cos(beta),   C_M = 0.8,  C_R = 1 (solid gear blanks)
    C_B = [1 + 0.5 (1.2 - h_fP/m)] [1 - 0.02 (20 - alpha_Pn)]   (alpha_Pn in degrees;
          the mean of both gears' values where their basic racks differ)
    c' *= (F_t K_A / b) / 100   where F_t K_A / b < 100 N/mm
    c_gamma_alpha = c' (0.75 eps_alpha + 0.25)

with ``C1..C9`` of :data:`Q_COEFFICIENTS`. ISO states the regression for
``x1 >= x2`` and ``-0.5 <= x1 + x2 <= 2``, and ``c_gamma_alpha`` for
``eps_alpha >= 1.2`` (below it, it may overstate the stiffness by up to about 10 %);
outside that range the formulas are applied as they stand.

Internal gears: ISO 6336-1 takes the ring's ``z_n2`` as infinite, which drops the
``C3/zn2`` and ``C7 x2/zn2`` terms; ``x2`` is the ring's profile shift coefficient
in the ISO 21771 sign that ISO 6336 uses for geometry (:class:`.involute.ToothForm`:
positive ``x`` thickens the ring's teeth), kept in the ``C6 x2`` and ``C9 x2^2`` terms.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .involute import MeshContact, ToothForm

Q_COEFFICIENTS = (0.04723, 0.15551, 0.25791, -0.00635, -0.11654, -0.00193, -0.24188,
                  0.00529, 0.00182)
"""``C1..C9`` of ISO 6336-1 for the minimum flexibility ``q'`` (mm um/N)."""

THEORETICAL_CORRECTION = 0.8
"""``C_M``: the correction from the theoretical to the measured single stiffness."""

BLANK_FACTOR = 1.0
"""``C_R``: gear blank factor of solid gears."""

REFERENCE_LINE_LOAD = 100.0
"""Line load ``F_t K_A / b`` (N/mm) below which ISO reduces ``c'`` in proportion."""


def _float(x) -> Array:
    return jnp.asarray(x, dtype=jnp.result_type(float))


class IsoStiffness(eqx.Module):
    """ISO 6336-1 stiffness of a spur mesh.

    **Fields:**

    - ``single_stiffness``: ``c'`` (N/(mm um)), one tooth pair, per unit face width;
    - ``mesh_stiffness``: ``c_gamma_alpha`` (N/(mm um)), the mean over the mesh cycle,
      per unit face width;
    - ``single_per_width``, ``mesh_per_width``: ``c' b`` and ``c_gamma_alpha b`` (N/m),
      the stiffness of the whole face width ``b`` (``1 N/(mm um)`` times ``b`` in mm is
      ``1e6 N/m``);
    - ``theoretical_single_stiffness``: ``c'_th = 1 / q'`` (N/(mm um));
    - ``basic_rack_factor``: ``C_B``;
    - ``load_factor``: ``min(1, (F_t K_A / b) / 100 N/mm)`` (1 without a load).
    """

    single_stiffness: Float[Array, ""]
    mesh_stiffness: Float[Array, ""]
    single_per_width: Float[Array, ""]
    mesh_per_width: Float[Array, ""]
    theoretical_single_stiffness: Float[Array, ""]
    basic_rack_factor: Float[Array, ""]
    load_factor: Float[Array, ""]


def basic_rack_factor(gear: ToothForm) -> Float[Array, ""]:
    """``C_B = [1 + 0.5 (1.2 - h_fP/m)] [1 - 0.02 (20 - alpha_Pn)]`` of one gear's basic
    rack (``h_fP/m`` its ``dedendum``, ``alpha_Pn`` its pressure angle in degrees)."""
    return ((1 + 0.5 * (1.2 - gear.dedendum))
            * (1 - 0.02 * (20.0 - gear.pressure_angle_deg)))


def iso_stiffness(gear1: ToothForm, gear2: ToothForm, contact: MeshContact,
                  face_width_m: ArrayLike, tangential_load_n: ArrayLike | None = None,
                  application_factor: ArrayLike = 1.0) -> IsoStiffness:
    """Single and mesh stiffness of a spur pair by ISO 6336-1 method B (module
    docstring).

    **Arguments:**

    - ``gear1``, ``gear2``, ``contact``: the pair as :func:`.involute.mesh_contact` takes
      and gives it (sun-planet, or planet-ring with the ring as ``gear2``); the contact
      gives ``eps_alpha``.
    - ``face_width_m``: face width ``b`` in contact (m).
    - ``tangential_load_n``: nominal transverse tangential load ``F_t`` at the reference
      circle (N); ``None``: no load correction (a line load of at least 100 N/mm).
    - ``application_factor``: ``K_A``.

    **Returns:** an :class:`IsoStiffness`.
    """
    C1, C2, C3, C4, C5, C6, C7, C8, C9 = Q_COEFFICIENTS
    zn1 = gear1.teeth
    x1, x2 = gear1.profile_shift, gear2.profile_shift
    q = C1 + C2 / zn1 + C4 * x1 + C5 * x1 / zn1 + C6 * x2 + C8 * x1**2 + C9 * x2**2
    if not contact.internal:  # a ring's zn2 is infinite
        q = q + C3 / gear2.teeth + C7 * x2 / gear2.teeth
    theoretical = 1 / q
    rack = (basic_rack_factor(gear1) + basic_rack_factor(gear2)) / 2
    b_mm = _float(face_width_m) * 1e3
    if tangential_load_n is None:
        load = jnp.ones_like(theoretical)
    else:
        line = _float(tangential_load_n) * _float(application_factor) / b_mm
        load = jnp.minimum(line / REFERENCE_LINE_LOAD, 1.0)
    single = theoretical * THEORETICAL_CORRECTION * BLANK_FACTOR * rack * load
    mesh = single * (0.75 * contact.contact_ratio + 0.25)
    return IsoStiffness(single_stiffness=single, mesh_stiffness=mesh,
                        single_per_width=single * b_mm * 1e6,
                        mesh_per_width=mesh * b_mm * 1e6,
                        theoretical_single_stiffness=theoretical, basic_rack_factor=rack,
                        load_factor=load)
