"""Mesh stiffness of a gear stage: the rectangular-wave amplitudes and their phasing.

The stiffness of mesh ``j p_i`` of stage ``n`` is ``kbar_j kappa_ji(t)`` with

    kappa_ji(t) = 1 + sum_h A_h cos(h w_n t + h Phi_ji),
    A_h = 2 sin(h pi (C - floor(C))) / (h pi C),

phased after Parker & Lin (``phasing = "physical"``) or as the paper's eq. (4d)
(``phasing = "paper"``); see model.md.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .train import Stage


def stiffness_amplitudes(contact_ratio: Array, n_harmonics: int) -> Float[Array, " H"]:
    """Fourier amplitudes ``A_h`` (h = 1..H) of the rectangular stiffness wave of mean 1."""
    h = jnp.arange(1, n_harmonics + 1)
    frac = contact_ratio - jnp.floor(contact_ratio)
    return 2 * jnp.sin(h * jnp.pi * frac) / (h * jnp.pi * contact_ratio)


def harmonic_phases(stage: Stage, sigma: int, phasing: str, n_harmonics: int):
    """Phase (rad) of harmonic ``h`` of every mesh of a stage.

    **Returns:** ``(sun, ring)``, each shape ``(N, H)``: the argument added to
    ``h w_n t`` for planet ``i`` and harmonic ``h``. ``"physical"``: ``h Phi_ji`` with
    ``Phi_si = -sigma Z_s psi_i + Gamma``, ``Phi_ri = sigma Z_r psi_i + gamma_sr + Gamma``.
    ``"paper"``: ``h Z_s psi_i + Gamma`` and ``h Z_r psi_i + h gamma_sr + Gamma``.
    """
    h = jnp.arange(1, n_harmonics + 1)[None, :]
    psi = jnp.deg2rad(stage.planet_angles_deg)[:, None]
    gamma_sr = jnp.deg2rad(stage.sun_ring_phase_deg)
    stage_phase = jnp.deg2rad(stage.stage_phase_deg)
    zs, zr = stage.teeth.sun, stage.teeth.ring
    if phasing == "physical":
        sun = h * (-sigma * zs * psi + stage_phase)
        ring = h * (sigma * zr * psi + gamma_sr + stage_phase)
    elif phasing == "paper":
        sun = h * zs * psi + stage_phase
        ring = h * (zr * psi + gamma_sr) + stage_phase
    else:
        raise ValueError(f"phasing must be 'physical' or 'paper', not {phasing!r}")
    return sun, ring


# ------------------------------------------------------------------ phasing report


@dataclasses.dataclass(frozen=True)
class HarmonicPhasing:
    """Phasing of harmonic ``h`` of a stage's mesh stiffness across its planets.

    **Fields:** ``k``: ``h Z_s mod N`` (``None`` for unequal spacing); ``kind``:
    ``in-phase`` (k = 0), ``sequential`` (k = 1 or N-1), ``counter-phase`` (other k),
    or ``unequal spacing``; ``sun_deg``, ``ring_deg``: phase of every planet's sun and
    ring mesh relative to planet 1's sun mesh, degrees in (-180, 180]; ``signs``: the
    sun-mesh pattern as ``+``/``-``/``~`` (in phase, opposed, other) relative to planet 1.
    """

    h: int
    k: int | None
    kind: str
    sun_deg: tuple[float, ...]
    ring_deg: tuple[float, ...]
    signs: str


def phasing_report(stage: Stage, sigma: int, phasing: str, n_harmonics: int):
    """Per-harmonic planet phasing of a stage, after Parker & Lin (2004).

    For equally spaced planets ``k = h Z_s mod N`` classifies the harmonic; the phases
    of every mesh are reported for any spacing. **Returns:** a list of
    :class:`HarmonicPhasing`, one per stiffness harmonic.
    """
    n = stage.n_planets
    psi = np.asarray(stage.planet_angles_deg)
    equal = bool(np.allclose(psi, 360.0 * np.arange(n) / n, atol=1e-9))
    sun, ring = (np.asarray(x) for x in harmonic_phases(stage, sigma or 1, phasing, n_harmonics))
    out = []
    for j in range(n_harmonics):
        h = j + 1
        rel_s = _wrap_deg(np.rad2deg(sun[:, j] - sun[0, j]))
        rel_r = _wrap_deg(np.rad2deg(ring[:, j] - sun[0, j]))
        signs = "".join("+" if abs(a) < 1e-6 else "-" if abs(abs(a) - 180) < 1e-6 else "~"
                        for a in rel_s)
        if equal:
            k = (h * stage.teeth.sun) % n
            kind = "in-phase" if k == 0 else "sequential" if k in (1, n - 1) else "counter-phase"
        else:
            k, kind = None, "unequal spacing"
        out.append(HarmonicPhasing(h=h, k=k, kind=kind, sun_deg=tuple(rel_s.tolist()),
                                   ring_deg=tuple(rel_r.tolist()), signs=signs))
    return out


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    w = -((-a + 180.0) % 360.0 - 180.0)  # (-180, 180]
    return np.where(np.abs(w) < 1e-9, 0.0, w)
