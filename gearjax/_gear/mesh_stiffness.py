"""Mesh stiffness of a stage's meshes from its tooth geometry, over one mesh cycle.

The time-varying stiffness of mesh ``sun-planet`` or ``ring-planet`` is the sum, over
the tooth pairs in contact, of each pair's stiffness ``1 / lambda(s)``, where ``s`` is
the contact point's position along the line of action (:mod:`.involute`) and

    lambda(s) = lambda_Hertz + lambda_tooth1(r1(s)) + lambda_tooth2(r2(s))

(potential-energy method, :mod:`.tooth_stiffness`). Successive pairs are one base
pitch ``p_b`` apart, so over one mesh cycle (phase ``tau`` in ``[0, 2 pi)``) the pair
``j`` sits at ``s_j = start + p_b (tau / 2 pi + f / 2 + j)``, ``f`` the fractional part
of the contact ratio ``C``. The origin ``tau = 0`` is the middle of the zone where
``floor(C) + 1`` pairs are in contact, as for the rectangular wave of
:func:`.phasing.stiffness_amplitudes`: with a pair stiffness constant along the path,
the derived wave *is* that rectangular wave (the limit the docs describe).

Without tip relief, the Fourier coefficients are integrals of one pair's stiffness
over the path of contact,

    k_0 = (1 / p_b) int k(s) ds,   k_h = (2 / p_b) int k(s) exp(i h tau(s)) ds,

taken by composite Gauss-Legendre quadrature: smooth in the path's ends, so
derivatives with respect to the geometry (profile shifts, face width, module) are
exact. With tip relief, the pairs share the static load ``F`` of the gear: each pair
of gap ``e_j`` (the relief of both flanks at its contact point) carries
``max(delta - e_j, 0) / lambda_j`` and ``delta`` (the loaded transmission error)
balances ``F``; the mesh is then the linear spring that reproduces ``delta`` at that
load, ``k(tau) = sum_active 1 / lambda_j`` with the transmission error
``e(tau) = delta - F / k``, which joins the file's transmission error. The
relieved mesh is sampled on :data:`RELIEF_SAMPLES` points of a cycle: the instants
where a relieved pair takes up load move with the load and the geometry, so
derivatives through a relieved mesh are those of the sampled wave.

Direction: contact travels from ``start`` to ``end`` (from gear 1's root to its tip;
gear 1 is the sun of a sun-planet mesh and the planet of a ring-planet mesh). A
reversed rotation mirrors the wave in time (its sine terms change sign), which only
matters where the wave is not symmetric.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .involute import MeshContact, ToothForm, mesh_contact
from .tooth_stiffness import hertz_compliance, tooth_compliance
from .kinematics import StageKinematics
from .train import Gear, Stage

RELIEF_SAMPLES = 2048
"""Samples per mesh cycle of a relieved mesh's load sharing."""

GAUSS_NODES = 8
"""Gauss-Legendre nodes per panel of the path-of-contact integrals."""


class MeshWave(eqx.Module):
    """One mesh's stiffness and relief transmission error as Fourier series in the
    mesh phase ``tau``:

        k(tau) = mean (1 + sum_h k_cos[h] cos(h tau) + k_sin[h] sin(h tau))
        e(tau) = sum_h te_cos[h] cos(h tau) + te_sin[h] sin(h tau)

    **Fields:** ``mean`` (N/m); ``contact_ratio`` (geometric); ``k_cos``, ``k_sin``:
    shape ``(H,)``, relative to the mean; ``te_cos``, ``te_sin``: shape ``(H,)``, m
    (zero without tip relief).
    """

    mean: Float[Array, ""]
    contact_ratio: Float[Array, ""]
    k_cos: Float[Array, " H"]
    k_sin: Float[Array, " H"]
    te_cos: Float[Array, " H"]
    te_sin: Float[Array, " H"]


class MeshCycle(eqx.Module):
    """One mesh over one mesh cycle, sampled: ``tau`` (rad, shape ``(n,)``), the mesh
    stiffness ``stiffness`` (N/m), the loaded transmission error ``loaded_te`` (m: the
    approach of the teeth under ``load``), ``pairs`` (pairs carrying load), and the
    rectangular wave of the same mean and contact ratio (``rectangular``, N/m).
    """

    tau: Float[Array, " n"]
    stiffness: Float[Array, " n"]
    loaded_te: Float[Array, " n"]
    pairs: Float[Array, " n"]
    rectangular: Float[Array, " n"]
    load: Float[Array, ""]


def planet_load(stage: Stage, sk: StageKinematics, gear: Gear):
    """Static normal load (N) of one planet's meshes of ``stage`` in ``gear``: the
    rigid statics' tooth load shared equally by the planets (0 where the statics is
    indeterminate). Sun-planet and ring-planet meshes of a planet carry the same load.
    """
    if sk.load is None:
        return jnp.asarray(0.0)
    base = stage.module_mm * 1e-3 * jnp.cos(jnp.deg2rad(stage.pressure_angle_deg)) / 2
    return jnp.abs(float(sk.load) * gear.input_torque) / (base * stage.n_planets)


def tooth_forms(stage: Stage) -> tuple[ToothForm, ToothForm, ToothForm]:
    """Sun, planet and ring tooth forms of a stage with a geometry."""
    geo = stage.geometry
    if geo is None:
        raise ValueError(f"stage {stage.id!r} has no tooth geometry (face_width_mm)")
    common = dict(module_mm=stage.module_mm, pressure_angle_deg=stage.pressure_angle_deg,
                  addendum=geo.addendum, dedendum=geo.dedendum, root_radius=geo.root_radius)
    return tuple(
        ToothForm(teeth=getattr(stage.teeth, name), internal=name == "ring",
                  profile_shift=getattr(geo.profile_shift, name), **common)
        for name in ("sun", "planet", "ring")
    )


def stage_contacts(stage: Stage) -> tuple[MeshContact, MeshContact]:
    """The sun-planet and ring-planet contacts at the stage's one centre distance.

    The centre distance is ``carrier_radius_mm`` where the file gives it, otherwise the
    sun-planet mesh's zero-backlash centre distance (with its profile shifts); the
    ring-planet mesh runs at the same distance.
    """
    sun, planet, ring = tooth_forms(stage)
    if stage.carrier_radius_mm is not None:
        centre = stage.carrier_radius_mm * 1e-3
        return (mesh_contact(sun, planet, centre_distance_m=centre),
                mesh_contact(planet, ring, centre_distance_m=centre))
    sp = mesh_contact(sun, planet)
    return sp, mesh_contact(planet, ring, centre_distance_m=sp.centre_distance)


MESH_GEARS = {"sun": ("sun", "planet"), "ring": ("planet", "ring")}
"""Gear 1 and gear 2 of each mesh side."""


def mesh_pair(stage: Stage, side: str):
    """Mesh ``side`` (``"sun"`` or ``"ring"``) of a stage with a geometry: ``(forms,
    names, contact)``, its gear 1 and gear 2 (:data:`MESH_GEARS`) as tooth forms and
    names, and their contact at the stage's centre distance (:func:`stage_contacts`).

    **Raises:** ``ValueError`` for another ``side``."""
    if side not in MESH_GEARS:
        raise ValueError(f"side must be 'sun' or 'ring', not {side!r}")
    forms = dict(zip(("sun", "planet", "ring"), tooth_forms(stage)))
    contact = stage_contacts(stage)[0 if side == "sun" else 1]
    return tuple(forms[n] for n in MESH_GEARS[side]), MESH_GEARS[side], contact


def _compliance(stage: Stage, forms, contact: MeshContact, s):
    """Compliance (m/N) of one tooth pair in contact at ``s`` along the line of action."""
    geo = stage.geometry
    b = geo.face_width_mm * 1e-3
    out = hertz_compliance(b, geo.youngs_modulus, geo.poisson_ratio)
    for form, radius in zip(forms, (contact.radius1(s), contact.radius2(s))):
        out = out + tooth_compliance(
            form.teeth, form.module_mm * 1e-3, jnp.deg2rad(form.pressure_angle_deg),
            form.profile_shift, form.addendum, form.dedendum, form.root_radius, b,
            geo.youngs_modulus, geo.poisson_ratio, radius, internal=form.internal)
    return out


def _relief(stage: Stage, forms, names, contact: MeshContact, s):
    """Gap (m) of a tooth pair at ``s``: the tip relief of both flanks there.

    Linear in roll distance ``rho = sqrt(r^2 - r_b^2)`` from the start diameter to the
    tip (for the ring, whose tip is its smallest diameter, towards smaller ``rho``).
    """
    relief = stage.geometry.tip_relief
    gap = jnp.zeros_like(s)
    for form, name, radius in zip(forms, names, (contact.radius1(s), contact.radius2(s))):
        amount = getattr(relief.amount_um, name) * 1e-6
        rb = form.base_radius()
        roll = lambda r: jnp.sqrt(jnp.maximum(r**2 - rb**2, 0.0))  # noqa: E731
        start = roll(getattr(relief.start_diameter_mm, name) * 0.5e-3)
        tip = roll(form.tip_radius())
        share = jnp.clip((roll(radius) - start) / (tip - start), 0.0, 1.0)
        gap = gap + amount * share
    return gap


def _pair_positions(contact: MeshContact, tau):
    """Positions ``s`` (shape ``tau.shape + (P,)``) of the pairs that can touch at
    ``tau``, and whether each is on the path of contact."""
    C = contact.contact_ratio
    frac = C - jnp.floor(C)
    j = jnp.arange(-1, 5)  # contact ratios up to 4
    u = tau[..., None] / (2 * jnp.pi) + frac / 2 + j
    s = contact.start + contact.base_pitch * u
    on = (u >= 0.0) & (u <= C)
    return s, on


def mesh_wave(stage: Stage, side: str, n_harmonics: int, load=0.0) -> MeshWave:
    """The stiffness wave of mesh ``side`` (``"sun"`` or ``"ring"``) of ``stage``.

    **Arguments:** ``n_harmonics``: H kept; ``load``: the static normal load of one
    planet's mesh (N), used only where some gear has tip relief.
    """
    return _mesh_wave_jit(stage, side, n_harmonics, jnp.asarray(load, dtype=float))


def _mesh_wave(stage: Stage, side: str, n_harmonics: int, load) -> MeshWave:
    forms, _, contact = mesh_pair(stage, side)
    if stage.geometry.relieved:
        cycle = _mesh_cycle(stage, side, load, RELIEF_SAMPLES)
        spec = jnp.fft.rfft(cycle.stiffness) / RELIEF_SAMPLES
        mean = spec[0].real
        k = 2 * spec[1:n_harmonics + 1] / mean
        te = 2 * jnp.fft.rfft(cycle.loaded_te - load / cycle.stiffness)[1:n_harmonics + 1]
        te = te / RELIEF_SAMPLES
        return MeshWave(mean=mean, contact_ratio=contact.contact_ratio, k_cos=k.real,
                        k_sin=-k.imag, te_cos=te.real, te_sin=-te.imag)
    mean, k = _path_integrals(stage, forms, contact, n_harmonics)
    zero = jnp.zeros(n_harmonics)
    return MeshWave(mean=mean, contact_ratio=contact.contact_ratio, k_cos=k.real / mean,
                    k_sin=k.imag / mean, te_cos=zero, te_sin=zero)


_mesh_wave_jit = eqx.filter_jit(_mesh_wave)


@eqx.filter_jit
def geometric_stiffness(stage: Stage, side: str):
    """Mean stiffness (N/m) and contact ratio of mesh ``side`` without load sharing
    (every pair on the path of contact carries load; tip relief ignored)."""
    forms, _, contact = mesh_pair(stage, side)
    return _path_integrals(stage, forms, contact, 1)[0], contact.contact_ratio


def _path_integrals(stage: Stage, forms, contact: MeshContact, n_harmonics: int):
    """``k_0`` and ``k_h`` (complex, ``a_h + i b_h``) by the path-of-contact integrals."""
    panels = 4 * max(n_harmonics, 4) + 8  # the integrand turns h C times along the path
    x, w = np.polynomial.legendre.leggauss(GAUSS_NODES)
    edges = jnp.linspace(contact.start, contact.end, panels + 1)
    half = (edges[1:] - edges[:-1])[:, None] / 2
    s = ((edges[1:] + edges[:-1])[:, None] / 2 + half * x[None, :]).ravel()
    ws = (half * w[None, :]).ravel()
    k = 1.0 / _compliance(stage, forms, contact, s)
    C = contact.contact_ratio
    tau = 2 * jnp.pi * ((s - contact.start) / contact.base_pitch - (C - jnp.floor(C)) / 2)
    h = jnp.arange(1, n_harmonics + 1)[:, None]
    pb = contact.base_pitch
    mean = jnp.sum(ws * k) / pb
    coef = 2 / pb * jnp.sum(ws * k * jnp.exp(1j * h * tau), axis=1)
    return mean, coef


def mesh_cycle(stage: Stage, side: str, load=0.0, n_samples: int = 512) -> MeshCycle:
    """One mesh cycle of mesh ``side`` sampled on ``n_samples`` phases, with the tooth
    pairs sharing the normal ``load`` (N) through their tip relief.
    """
    return _mesh_cycle_jit(stage, side, jnp.asarray(load, dtype=float), n_samples)


def _mesh_cycle(stage: Stage, side: str, load, n_samples: int) -> MeshCycle:
    forms, names, contact = mesh_pair(stage, side)
    tau = 2 * jnp.pi * jnp.arange(n_samples) / n_samples
    s, on = _pair_positions(contact, tau)
    s = jnp.where(on, s, contact.start)  # a pair off the path: any point on it, unused
    inv = jnp.where(on, 1.0 / _compliance(stage, forms, contact, s), 0.0)
    gap = _relief(stage, forms, names, contact, s)
    gap = jnp.where(on, gap, 1.0)  # a pair off the path never touches
    delta, stiffness, pairs = _share(inv, gap, load)
    mean = jnp.mean(stiffness) if stage.geometry.relieved else _path_integrals(
        stage, forms, contact, 1)[0]
    rect = _rectangle(mean, contact.contact_ratio, tau)
    return MeshCycle(tau=tau, stiffness=stiffness, loaded_te=delta, pairs=pairs,
                     rectangular=rect, load=load)


_mesh_cycle_jit = eqx.filter_jit(_mesh_cycle)


def _rectangle(mean, C, tau):
    frac = C - jnp.floor(C)
    wrapped = jnp.abs((tau + jnp.pi) % (2 * jnp.pi) - jnp.pi)
    return mean / C * (jnp.floor(C) + jnp.where(wrapped < jnp.pi * frac, 1.0, 0.0))


def rectangular_cycle(stage: Stage, side: str, load=0.0, n_samples: int = 512) -> MeshCycle:
    """The file's rectangular wave (``contact_ratio``, ``mesh_stiffness``) over one mesh
    cycle, as :func:`mesh_cycle` gives the derived one; the loaded transmission error is
    ``load / k``."""
    load = jnp.asarray(load, dtype=float)
    tau = 2 * jnp.pi * jnp.arange(n_samples) / n_samples
    C = getattr(stage.contact_ratio, side)
    rect = _rectangle(getattr(stage.mesh_stiffness, side), C, tau)
    return MeshCycle(tau=tau, stiffness=rect, loaded_te=load / rect,
                     pairs=jnp.floor(C) + (rect > jnp.min(rect)), rectangular=rect, load=load)


def _share(inv, gap, load):
    """Load sharing: ``delta`` with ``sum_j inv_j max(delta - gap_j, 0) = load``.

    **Arguments:** ``inv``, ``gap``: shape ``(n, P)``, each pair's stiffness (0 for a
    pair off the path) and gap. **Returns:** ``delta``, the stiffness of the pairs
    carrying load, and their count, each shape ``(n,)``. The pairs take up load in
    order of their gaps; ``k`` active pairs give ``delta_k = (load + sum inv e) /
    sum inv`` over them, the answer is the first ``k`` whose ``delta_k`` stays below
    the next gap.
    """
    order = jnp.argsort(gap, axis=-1)
    g = jnp.take_along_axis(gap, order, axis=-1)
    k = jnp.take_along_axis(inv, order, axis=-1)
    stiff = jnp.cumsum(k, axis=-1)
    moment = jnp.cumsum(k * g, axis=-1)
    delta = (load + moment) / jnp.where(stiff > 0, stiff, 1.0)
    nxt = jnp.concatenate([g[..., 1:], jnp.full(g.shape[:-1] + (1,), jnp.inf)], axis=-1)
    valid = (delta < nxt) & (stiff > 0)
    first = jnp.argmax(valid, axis=-1)
    pick = lambda a: jnp.take_along_axis(a, first[..., None], axis=-1)[..., 0]  # noqa: E731
    count = (first + 1).astype(float)
    return pick(delta), pick(stiff), count
