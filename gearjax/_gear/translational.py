"""The translational-rotational stage of Lin & Parker (1999) (model.md).

Coordinates of a stage at ``offset`` with ``N`` planets (:meth:`Train.stage_dof`):
first the ``3 + N`` rotations (rad) of sun, ring, carrier and planets (a planet's
absolute rotation, not relative to the carrier as in the torsional model), then the
translations (m) ``x, y`` of sun, ring and carrier and the radial ``zeta_n`` and
tangential ``eta_n`` motion of each planet centre, in a frame that turns with the
carrier at its nominal speed. With the rotations in radians, model.md's
``u_j = r_j theta_j`` appear as lever arms ``r_j`` in the mesh and pin rows, and the
mass of a rotation is the polar inertia ``I_j``; the natural frequencies are those of
model.md's form.

The functions are pure in the stage's array leaves (``jit``, ``vmap``, ``grad``).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._errors import fail
from .mesh_stiffness import stage_contacts
from .train import MEMBERS, Stage


def line_geometry(stage: Stage):
    """Pressure angles (rad) of the sun-planet and ring-planet lines of action and the
    planet-centre radius ``r_c`` (m), ``(alpha_s, alpha_r, r_c)``: the stage's
    ``pressure_angle_deg`` (both) and carrier radius; for a stage with a tooth geometry
    each mesh's operating pressure angle at the operating centre distance
    (:func:`.mesh_stiffness.stage_contacts`), so that ``r_c cos(alpha_s) = r_s + r_p``
    and ``r_c cos(alpha_r) = r_r - r_p`` hold with profile shifts too."""
    if stage.geometry is not None:
        sun, ring = stage_contacts(stage)
        return (sun.operating_pressure_angle, ring.operating_pressure_angle,
                sun.centre_distance)
    a = jnp.deg2rad(stage.pressure_angle_deg)
    return a, a, stage.carrier_radius()


def translation_offset(stage: Stage, offset: int) -> int:
    """Index of the stage's first translation, ``x_s``."""
    return offset + 3 + stage.n_planets


def stage_mass(stage: Stage, M, offset: int):
    """``M`` with the stage's diagonal block set: ``I_s, I_r, I_c, I_p...`` (kg m^2) on
    the rotations, ``m_j, m_j`` on each central member's ``x, y`` and ``m_p, m_p`` on
    each planet's radial and tangential motion (kg)."""
    N = stage.n_planets
    I, m = stage.inertia, stage.mass
    diagonal = [I.sun, I.ring, I.carrier] + [I.planet] * N
    for member in MEMBERS:
        diagonal += [getattr(m, member)] * 2
    diagonal += [stage.planet_mass] * (2 * N)
    for k, value in enumerate(diagonal):
        M = M.at[offset + k, offset + k].set(value)
    return M


def mesh_rows(stage: Stage, offset: int, n: int) -> dict[str, list]:
    """Projection rows ``(n,)`` (m per coordinate unit) of the deflections along the
    lines of action, ``{"sun": [d_s1..d_sN], "ring": [d_r1..d_rN]}``:

        d_sn = -x_s sin(psi_n - a_s) + y_s cos(psi_n - a_s) + r_s th_s - zeta_n sin a_s
               - eta_n cos a_s + r_p th_n
        d_rn = -x_r sin(psi_n + a_r) + y_r cos(psi_n + a_r) + r_r th_r + zeta_n sin a_r
               - eta_n cos a_r - r_p th_n

    with ``a_s``, ``a_r`` of :func:`line_geometry` (model.md's one ``alpha`` for a stage
    without tooth geometry).
    """
    r_s, r_p, r_r = stage.base_radii()
    a_s, a_r, _ = line_geometry(stage)
    t = translation_offset(stage, offset)
    rows: dict[str, list] = {"sun": [], "ring": []}
    for i, psi in enumerate(jnp.deg2rad(stage.planet_angles_deg)):
        zeta, eta, theta = t + 6 + 2 * i, t + 7 + 2 * i, offset + 3 + i
        for side, j, r_j, xy, a, psi_j, sign in (("sun", 0, r_s, t, a_s, psi - a_s, 1.0),
                                                 ("ring", 1, r_r, t + 2, a_r, psi + a_r, -1.0)):
            rows[side].append(
                jnp.zeros(n).at[xy].set(-jnp.sin(psi_j)).at[xy + 1].set(jnp.cos(psi_j))
                .at[offset + j].set(r_j).at[zeta].set(-sign * jnp.sin(a))
                .at[eta].set(-jnp.cos(a)).at[theta].set(sign * r_p))
    return rows


def bearing_springs(stage: Stage, offset: int, n: int) -> tuple[list, list, list[str]]:
    """The stage's bearings as springs: rows ``(n,)``, stiffness (N/m) and a name each.

    Sun, ring and carrier: ``k_j`` on ``x_j`` and on ``y_j`` (names ``"ID.sun.x"``...).
    Planet pin ``n``: ``k_p`` on its radial deflection ``x_c cos psi + y_c sin psi -
    zeta_n`` and its tangential deflection ``-x_c sin psi + y_c cos psi + r_c th_c -
    eta_n`` (names ``"ID.pinN.radial"``, ``"ID.pinN.tangential"``), ``r_c`` of
    :func:`line_geometry`.
    """
    k = stage.bearing_stiffness
    t = translation_offset(stage, offset)
    rows, ks, names = [], [], []
    for j, member in enumerate(MEMBERS):
        for d, axis in enumerate("xy"):
            rows.append(jnp.zeros(n).at[t + 2 * j + d].set(1.0))
            ks.append(getattr(k, member))
            names.append(f"{stage.id}.{member}.{axis}")
    r_c = line_geometry(stage)[2]
    x_c, y_c = t + 4, t + 5
    for i, psi in enumerate(jnp.deg2rad(stage.planet_angles_deg)):
        c, s = jnp.cos(psi), jnp.sin(psi)
        rows.append(jnp.zeros(n).at[x_c].set(c).at[y_c].set(s).at[t + 6 + 2 * i].set(-1.0))
        rows.append(jnp.zeros(n).at[x_c].set(-s).at[y_c].set(c).at[offset + 2].set(r_c)
                    .at[t + 7 + 2 * i].set(-1.0))
        ks += [k.planet, k.planet]
        names += [f"{stage.id}.pin{i + 1}.radial", f"{stage.id}.pin{i + 1}.tangential"]
    return rows, ks, names


def bearing_offsets(stage: Stage) -> list:
    """Rest offset (m) of each row of :func:`bearing_springs`: 0 for sun, ring and
    carrier; a pin's radial and tangential position error
    (``planet_position_error_um``). A bearing's deflection is ``r x + e``: a pin moved
    out by ``e_r`` holds its planet at ``zeta = e_r``, one moved ahead by ``e_t`` at
    ``eta = r_c theta_c + e_t``."""
    out = [jnp.asarray(0.0)] * 6
    errors = stage.planet_position_error_um
    for i in range(stage.n_planets):
        if errors is None:
            out += [jnp.asarray(0.0)] * 2
        else:
            out += [errors.radial[i] * 1e-6, errors.tangential[i] * 1e-6]
    return out


def pin_error_forcing(stage: Stage, offset: int, n: int):
    """Generalised force ``(n,)`` of the pin errors: ``-sum k e r`` over the bearing
    rows (the springs' energy ``k (r x + e)^2 / 2``), added to the mean forcing."""
    rows, ks, _ = bearing_springs(stage, offset, n)
    f = jnp.zeros(n)
    for row, k, e in zip(rows, ks, bearing_offsets(stage)):
        f = f - k * e * row
    return f


def bearing_damping(stage: Stage, offset: int, n: int):
    """Viscous matrix ``(n, n)`` of the stage's bearings: ``c r r^T`` for each bearing
    row ``r`` of :func:`bearing_springs` and its coefficient ``c`` of
    :func:`bearing_dampers`."""
    rows, _, _ = bearing_springs(stage, offset, n)
    C = jnp.zeros((n, n))
    for row, c in zip(rows, bearing_dampers(stage)):
        C = C + c * jnp.outer(row, row)
    return C


def bearing_dampers(stage: Stage) -> list:
    """Viscous coefficient (N s/m) of each row of :func:`bearing_springs`:
    ``c = 2 zeta sqrt(k m)``, ``m`` the supported mass (the central member's, the
    planet's for a pin), ``zeta`` the stage's ``bearing_damping_ratio`` (default its
    ``mesh_damping_ratio``)."""
    zeta = stage.bearing_damping_ratio
    zeta = stage.mesh_damping_ratio if zeta is None else zeta
    k, m = stage.bearing_stiffness, stage.mass
    pairs = [(getattr(k, j), getattr(m, j)) for j in MEMBERS for _ in "xy"]
    pairs += [(k.planet, stage.planet_mass)] * (2 * stage.n_planets)
    return [2 * zeta * jnp.sqrt(stiffness * mass) for stiffness, mass in pairs]


def bearing_table(train) -> dict:
    """Every bearing of a translational train, for its force outputs: ``names``
    (``"ID.sun"``, ``"ID.ring"``, ``"ID.carrier"``, ``"ID.pinN"``), ``stages``, ``rows``
    ``(b, 2, n)`` (its two deflection rows: ``x, y``, or a pin's radial and tangential,
    :func:`bearing_springs`), ``offsets`` ``(b, 2)`` (m, :func:`bearing_offsets`),
    ``stiffness`` ``(b,)`` (N/m) and ``damping`` ``(b,)`` (N s/m). The force on a
    bearing is ``k (r x + e) + c r x'`` per row."""
    names, stages, rows, offsets, ks, cs = [], [], [], [], [], []
    n = train.n_dof
    for s, offset in zip(train.stages, train.stage_offsets()):
        r, k, row_names = bearing_springs(s, offset, n)
        c = bearing_dampers(s)
        e = [float(np.asarray(v)) for v in bearing_offsets(s)]
        for i in range(0, len(r), 2):
            offsets.append([e[i], e[i + 1]])
            names.append(row_names[i].rsplit(".", 1)[0])
            stages.append(s.id)
            rows.append(np.stack([np.asarray(r[i]), np.asarray(r[i + 1])]))
            ks.append(float(np.asarray(k[i])))
            cs.append(float(np.asarray(c[i])))
    return {"names": names, "stages": stages, "rows": np.asarray(rows).reshape(-1, 2, n),
            "offsets": np.asarray(offsets).reshape(-1, 2), "stiffness": np.asarray(ks),
            "damping": np.asarray(cs)}


def stage_dof_labels(stage: Stage) -> tuple[list[str], list[str]]:
    """Label and kind of each coordinate: rotations ``"ID.sun"``... (kind ``central``),
    ``"ID.planetN"`` (``planet``); translations ``"ID.sun.x"``... (``translation``),
    ``"ID.planetN.radial"``, ``"ID.planetN.tangential"`` (``planet``)."""
    N = stage.n_planets
    planets = [f"{stage.id}.planet{i + 1}" for i in range(N)]
    labels = [f"{stage.id}.{m}" for m in MEMBERS] + planets
    labels += [f"{stage.id}.{m}.{axis}" for m in MEMBERS for axis in "xy"]
    labels += [f"{p}.{d}" for p in planets for d in ("radial", "tangential")]
    kinds = ["central"] * 3 + ["planet"] * N + ["translation"] * 6 + ["planet"] * (2 * N)
    return labels, kinds


def check_support(train) -> None:
    """Refuse a translational stage that its bearings and meshes cannot hold in place.

    Every stage needs ``mass`` and ``bearing_stiffness``; at least one central member
    on a bearing (else the whole stage translates freely); and a floating sun or ring
    (bearing stiffness 0) needs two planets whose lines of action are not parallel
    (planet angles that differ by other than 0 or 180 degrees), or it moves freely
    across its one line of action.

    **Raises:** ``TrainError`` naming the stage's field, its value and the rule.
    """
    for s in train.stages:
        f = f"{s.id}."
        for key in ("mass", "bearing_stiffness"):
            if getattr(s, key) is None:
                raise fail(train.source, f + key, None,
                           'is required when model = "translational"')
        k = s.bearing_stiffness
        stiff = {m: float(np.asarray(getattr(k, m))) for m in MEMBERS}
        if not any(v > 0 for v in stiff.values()):
            raise fail(train.source, f + "bearing_stiffness", stiff,
                       "at least one of sun, ring and carrier needs a bearing (> 0): with all "
                       "three floating the stage translates freely")
        psi = np.deg2rad(np.asarray(s.planet_angles_deg, dtype=float))
        spread = np.abs(np.sin(psi[:, None] - psi[None, :])).max()
        for member in ("sun", "ring"):
            if stiff[member] == 0 and spread < 1e-6:
                raise fail(train.source, f"{f}bearing_stiffness.{member}", 0.0,
                           f"a floating {member} needs two planets whose lines of action are "
                           f"not parallel; planet angles {np.rad2deg(psi).tolist()} hold it "
                           "along one line only")


def rigid_rotation_messages(train) -> list[str]:
    """Stages whose radii let a rigid rotation strain their meshes in this model:
    ``r_c cos(alpha)`` must equal ``r_s + r_p`` and ``r_r - r_p`` (model.md; the angles and
    ``r_c`` of :func:`line_geometry`, which a tooth geometry satisfies). Where one
    differs by more than 0.1% of ``r_c``, the static loads leak torque into the housing
    springs; each message names the stage, the three lengths and the keys that set them."""
    out = []
    where = train.source or train.name
    for s in train.stages:
        r_s, r_p, r_r = (float(np.asarray(r)) for r in s.base_radii())
        a_s, a_r, r_c = (float(np.asarray(v)) for v in line_geometry(s))
        lever = r_c * math.cos(a_s)
        off = {side: d for side, d, a in (("sun", r_s + r_p, a_s), ("ring", r_r - r_p, a_r))
               if abs(d - r_c * math.cos(a)) > 1e-3 * r_c}
        if off:
            shown = ", ".join(f"{'r_s + r_p' if side == 'sun' else 'r_r - r_p'} = "
                              f"{d * 1e3:.4g} mm" for side, d in off.items())
            out.append(
                f"{where}: stage {s.id!r}: the translational model needs r_c cos(alpha) = "
                f"r_s + r_p = r_r - r_p, but r_c cos(alpha) = {lever * 1e3:.4g} mm and {shown}: "
                f"a rigid rotation of the stage strains its {' and '.join(off)} meshes, so "
                "static loads leak torque into the housing springs (gearjax info shows the "
                "torque balance); teeth, carrier_radius_mm or base_diameter_mm that satisfy "
                "it remove the leak")
    return out
