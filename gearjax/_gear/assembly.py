"""Assembly of a gear train in one gear into the generic ``System`` (model.md).

Torsional model: coordinates per stage, in order: ``theta_s``, ``theta_r``,
``theta_c`` (absolute vibratory rotations) and ``phi_i = theta_pi - theta_c`` for each
planet (rad). Meshes per stage, in order: ``sp1..spN`` then ``rp1..rpN`` with

    p_si = r_s (theta_s - theta_c) + r_p phi_i - e_si(t)
    p_ri = r_r (theta_r - theta_c) - r_p phi_i - e_ri(t)

A pin out of place by ``e_i`` (m) along the carrier's positive rotation moves planet
``i`` as a carrier rotation ``e_i / r_c`` of its own would: the constant transmission
errors ``(r_s + r_p) e_i / r_c`` and ``(r_r - r_p) e_i / r_c`` (base radii over the
centre distance: the cosine of each mesh's operating pressure angle), :func:`pin_te`.

Translational model: the coordinates, mesh deflections and bearings of
:mod:`.translational` (Lin & Parker 1999), the same meshes in the same order.

The function is pure in the train's array leaves, so ``jit``, ``vmap`` and ``grad``
pass through it (design variables are leaves of ``Train``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._config import require_x64
from .frequency_groups import TorusLayout
from .kinematics import Kinematics, kinematics
from .mesh_stiffness import mesh_wave, planet_load
from .phasing import harmonic_phases, stiffness_amplitudes
from .._engine.system import System
from .train import MEMBERS, Train, member_index, member_inertia, member_paths
from . import translational


def assemble(train: Train, gear: str | None = None, kin: Kinematics | None = None,
             layout: TorusLayout | None = None) -> System:
    """The train in ``gear`` (default: the first) as a :class:`System`.

    Excitation frequencies: with ``layout`` ``None``, multiples ``mu`` of the gear's one
    common base (``kin.mu``: a periodic system); with a
    :class:`~gearjax._gear.frequency_groups.TorusLayout`, each stage and ripple order
    on its group's torus angle, ``Omega`` the base of the first group (model.md,
    "Incommensurate stages").

    Housing springs: ``housing.braked`` for members in the gear's ``brakes``,
    ``housing.free`` for every other central member; engaged couplings as springs
    between members, and their dampers (``damping`` or ``damping_ratio``,
    :meth:`~gearjax._gear.train.Coupling.viscous_damping`) in ``C``; in the
    translational model the bearings as springs (elastic) and dampers;
    mean torques: ``input_torque`` on the input, ``-input_torque * ratio`` on the
    output, ``drag_torque`` against the motion of every other free member; ripple on the
    input member at its orders of the input speed.
    """
    require_x64()
    g = train.gear(gear)
    kin = kinematics(train, g.name) if kin is None else kin
    n = train.n_dof
    H = train.stiffness_harmonics
    H_e = max([s.transmission_error.sun.shape[0] for s in train.stages]
              + [s.transmission_error.ring.shape[0] for s in train.stages]
              + [H for s in train.stages if s.stiffness_from_geometry and s.geometry.relieved])
    M = jnp.zeros((n, n))
    W_rows, kbar, k_cos, k_sin, back, damp, te_cos, te_sin, radius = ([] for _ in range(9))
    te_mean = []
    mesh_mu, mesh_angle, labels, groups, sides, planets = [], [], [], [], [], []
    dof_labels, dof_group, dof_kind = [], [], []
    offset = 0
    for s, sk in zip(train.stages, kin.stages):
        N = s.n_planets
        i_s, i_r, i_c = offset, offset + 1, offset + 2
        r_s, r_p, r_r = s.base_radii()
        I = s.inertia
        if train.translational:
            M = translational.stage_mass(s, M, offset)
            rows = translational.mesh_rows(s, offset, n)
            labels_n, kinds_n = translational.stage_dof_labels(s)
        else:
            I_ce = I.carrier + N * (I.planet + s.planet_mass * s.carrier_radius() ** 2)
            M = M.at[i_s, i_s].set(I.sun).at[i_r, i_r].set(I.ring).at[i_c, i_c].set(I_ce)
            for i in range(N):
                ip = offset + 3 + i
                M = M.at[ip, ip].set(I.planet).at[ip, i_c].set(I.planet).at[i_c, ip].set(I.planet)
            rows = {side: [jnp.zeros(n).at[i_j].set(r_j).at[i_c].add(-r_j)
                           .at[offset + 3 + i].set(sign * r_p) for i in range(N)]
                    for side, i_j, r_j, sign in (("sun", i_s, r_s, 1.0), ("ring", i_r, r_r, -1.0))}
            labels_n = ([f"{s.id}.{m}" for m in MEMBERS]
                        + [f"{s.id}.planet{i + 1}" for i in range(N)])
            kinds_n = ["central"] * 3 + ["planet"] * N
        dof_labels += labels_n
        dof_group += [s.id] * len(labels_n)
        dof_kind += kinds_n

        turning = sk.mesh_frequency != 0
        if layout is not None:
            angle_n, mu_n = layout.stage.get(s.id, (0, 0))
        else:
            angle_n = 0
            mu_n = kin.mu[train.stages.index(s)] if (turning and kin.mu is not None) else 0
        phases_s, phases_r = harmonic_phases(s, sk.sigma, train.phasing, max(H, H_e))
        for side, r_j, I_j, phases in (("sun", r_s, I.sun, phases_s),
                                       ("ring", r_r, I.ring, phases_r)):
            if s.stiffness_from_geometry:
                wave = mesh_wave(s, side, H, load=planet_load(s, sk, g))
                k_mean, k_a, k_b = wave.mean, wave.k_cos, wave.k_sin
                relief_a = jnp.zeros(H_e).at[:H].set(wave.te_cos)
                relief_b = jnp.zeros(H_e).at[:H].set(wave.te_sin)
            else:
                k_mean = getattr(s.mesh_stiffness, side)
                k_a = stiffness_amplitudes(getattr(s.contact_ratio, side), H)
                k_b = relief_a = relief_b = 0.0
            te = getattr(s.transmission_error, side)
            te_amp = jnp.zeros(H_e).at[: te.shape[0]].set(te[:, 0])
            te_phase = jnp.zeros(H_e).at[: te.shape[0]].set(jnp.deg2rad(te[:, 1]))
            m_eq = I_j * I.planet / (I_j * r_p**2 + I.planet * r_j**2)
            c = 2 * s.mesh_damping_ratio * jnp.sqrt(k_mean * m_eq)
            on = 1.0 if turning else 0.0
            pins = jnp.zeros(N) if train.translational else pin_te(s, side)
            for i in range(N):
                W_rows.append(rows[side][i])
                te_mean.append(pins[i])
                kbar.append(k_mean)
                ph = phases[i, :H]
                k_cos.append(on * (k_a * jnp.cos(ph) + k_b * jnp.sin(ph)))
                k_sin.append(on * (k_b * jnp.cos(ph) - k_a * jnp.sin(ph)))
                ph_e = phases[i, :H_e] + te_phase
                ph_r = phases[i, :H_e]
                te_cos.append(on * (te_amp * jnp.cos(ph_e)
                                    + relief_a * jnp.cos(ph_r) + relief_b * jnp.sin(ph_r)))
                te_sin.append(on * (-te_amp * jnp.sin(ph_e)
                                    + relief_b * jnp.cos(ph_r) - relief_a * jnp.sin(ph_r)))
                back.append(getattr(s.half_backlash, side))
                damp.append(c)
                radius.append(r_j)
                mesh_mu.append(mu_n)
                mesh_angle.append(angle_n)
                labels.append(f"{s.id}.{side[0]}p{i + 1}")
                groups.append(s.id)
                sides.append(side)
                planets.append(i + 1)
        offset += train.stage_dof(s)

    spring_rows, spring_k, spring_class = _springs(train, g, n)
    f_mean, f_cos, f_sin = _forcing(train, g, kin, n)
    for s, offset in zip(train.stages, train.stage_offsets()) if train.translational else ():
        f_mean = f_mean + translational.pin_error_forcing(s, offset, n)
    stack = lambda xs, cols: jnp.stack(xs) if xs else jnp.zeros((0, cols))  # noqa: E731
    return System(
        M=M,
        C=_dampers(train, g, n),
        spring_rows=spring_rows,
        spring_stiffness=spring_k,
        W=stack(W_rows, n),
        kbar=jnp.stack(kbar),
        k_cos=stack(k_cos, H).reshape(len(labels), H),
        k_sin=stack(k_sin, H).reshape(len(labels), H),
        backlash=jnp.stack(back),
        damping=jnp.stack(damp),
        te_mean=jnp.stack(te_mean),
        te_cos=stack(te_cos, H_e).reshape(len(labels), H_e),
        te_sin=stack(te_sin, H_e).reshape(len(labels), H_e),
        mesh_radius=jnp.stack(radius),
        f_mean=f_mean,
        f_cos=f_cos,
        f_sin=f_sin,
        mesh_mu=tuple(mesh_mu),
        forcing_mu=tuple(kin.ripple_mu) if layout is None else tuple(m for _, m in layout.ripple),
        mesh_angle=tuple(mesh_angle) if layout is not None else (),
        forcing_angle=tuple(g for g, _ in layout.ripple) if layout is not None else (),
        angle_ratio=tuple(float(r) for r in layout.ratio) if layout is not None else (1.0,),
        spring_class=spring_class,
        contact_damping=train.mesh_damping == "contact",
        dof_labels=tuple(dof_labels),
        dof_group=tuple(dof_group),
        dof_kind=tuple(dof_kind),
        mesh_labels=tuple(labels),
        mesh_group=tuple(groups),
        mesh_side=tuple(sides),
        mesh_planet=tuple(planets),
    )


def pin_te(stage, side: str):
    """Constant transmission error (m) of each planet's ``side`` mesh (``"sun"`` or
    ``"ring"``) in the torsional model from its pin's tangential position error,
    ``(N,)``: ``(r_s + r_p) e / r_c`` or ``(r_r - r_p) e / r_c`` (``r_c`` of
    :func:`.translational.line_geometry`: the operating centre distance of a stage with
    a tooth geometry); zeros without errors."""
    errors = stage.planet_position_error_um
    if errors is None:
        return jnp.zeros(stage.n_planets)
    r_s, r_p, r_r = stage.base_radii()
    arm = r_s + r_p if side == "sun" else r_r - r_p
    return arm / translational.line_geometry(stage)[2] * errors.tangential * 1e-6


def _springs(train: Train, g, n: int):
    """Housing springs of every central member, the engaged couplings and, in the
    translational model, the bearings (elastic)."""
    rows, ks, classes = [], [], []
    for path in member_paths(train):
        braked = path in g.brakes
        rows.append(jnp.zeros(n).at[member_index(train, path)].set(1.0))
        ks.append(train.housing.braked if braked else train.housing.free)
        classes.append("penalty" if braked else "rigid")
    for c in train.engaged_couplings(g.name):
        rows.append(jnp.zeros(n).at[member_index(train, c.members[0])].set(1.0)
                    .at[member_index(train, c.members[1])].set(-1.0))
        ks.append(c.stiffness)
        classes.append("penalty" if _at_least(c.stiffness, train.housing.braked) else "elastic")
    for s, offset in zip(train.stages, train.stage_offsets()) if train.translational else ():
        b_rows, b_ks, _ = translational.bearing_springs(s, offset, n)
        rows += b_rows
        ks += b_ks
        classes += ["elastic"] * len(b_rows)
    return jnp.stack(rows), jnp.stack(ks), tuple(classes)


def _dampers(train: Train, g, n: int):
    """Viscous matrix ``(n, n)`` of the engaged couplings' dampers (N m s/rad):
    ``c (e_i - e_j)(e_i - e_j)^T`` each, and in the translational model the bearings'
    (:func:`.translational.bearing_damping`); exactly zero where there is neither."""
    C = jnp.zeros((n, n))
    for c in train.engaged_couplings(g.name):
        if not c.damped:
            continue
        i, j = (member_index(train, m) for m in c.members)
        coef = c.viscous_damping(*(member_inertia(train, m) for m in c.members))
        C = C.at[i, i].add(coef).at[j, j].add(coef).at[i, j].add(-coef).at[j, i].add(-coef)
    for s, offset in zip(train.stages, train.stage_offsets()) if train.translational else ():
        C = C + translational.bearing_damping(s, offset, n)
    return C


def _at_least(a, b) -> bool:
    """``a >= b`` for concrete values; ``False`` (elastic) while tracing."""
    try:
        return bool(np.asarray(a) >= np.asarray(b))
    except Exception:  # traced under jit/vmap: class is a label only
        return False


def _forcing(train: Train, g, kin: Kinematics, n: int):
    """Mean torques and input-torque ripple columns (N m)."""
    f = jnp.zeros(n)
    i_in, i_out = member_index(train, g.input), member_index(train, g.output)
    f = f.at[i_in].add(g.input_torque)
    f = f.at[i_out].add(-g.input_torque * float(kin.ratio))
    for path, w in kin.speeds.items():
        if path in (g.input, g.output) or path in g.brakes or w == 0:
            continue
        f = f.at[member_index(train, path)].add(-g.drag_torque * (1.0 if w > 0 else -1.0))
    ripple = g.input_torque_ripple
    L = ripple.shape[0]
    amp, phase = ripple[:, 0], jnp.deg2rad(ripple[:, 1])
    f_cos = jnp.zeros((n, L)).at[i_in].set(amp * jnp.cos(phase))
    f_sin = jnp.zeros((n, L)).at[i_in].set(-amp * jnp.sin(phase))
    return f, f_cos, f_sin
