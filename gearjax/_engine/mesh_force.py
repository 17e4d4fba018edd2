"""The mesh-force law: backlash, contact and ``F = k(t) g(p) + c p'``.

``mesh_force`` is the one definition of ``F = k(t) g(p) + c p'`` that the harmonic
balance, the time integration and every Jacobian call. The stiffness of mesh
``j p_i`` of stage ``n`` is ``kbar_j kappa_ji(t)`` with

    kappa_ji(t) = 1 + sum_h A_h cos(h w_n t + h Phi_ji),
    A_h = 2 sin(h pi (C - floor(C))) / (h pi C),

phased after Parker & Lin (``phasing = "physical"``) or as the paper's eq. (4d)
(``phasing = "paper"``); see model.md.
"""

from __future__ import annotations


import jax.numpy as jnp
from jaxtyping import Array, Float



def backlash(p: Array, b: Array, smoothing: float = 0.0) -> Array:
    """Clearance function ``g(p)``: ``p - b`` above ``b``, 0 inside ``|p| <= b``, ``p + b`` below.

    ``smoothing`` (static, dimensionless): 0 gives the exact piecewise-linear function;
    ``s > 0`` rounds each corner over a width of about ``s b`` with
    ``((p - b) + sqrt((p - b)^2 + e^2)) / 2 + ((p + b) - sqrt((p + b)^2 + e^2)) / 2``,
    ``e = s b``: odd, C-infinity, within ``e / 2`` of the exact function, and exactly
    ``p`` when ``b = 0``.
    """
    if not smoothing:
        # exactly p where b = 0, derivative included (clip's derivative at p = b = 0 is not 1)
        return jnp.where(b > 0, p - jnp.clip(p, -b, b), p)
    e = jnp.where(b > 0, smoothing * b, 1.0)  # any e > 0 where b = 0: that branch is unused
    hi, lo = p - b, p + b
    rounded = 0.5 * (hi + jnp.sqrt(hi**2 + e**2)) + 0.5 * (lo - jnp.sqrt(lo**2 + e**2))
    return jnp.where(b > 0, rounded, p)


def in_contact(p: Array, b: Array) -> Array:
    """1.0 where the teeth touch (``|p| > b``), else 0.0."""
    return (jnp.abs(p) > b).astype(p.dtype)


def mesh_force(
    p: Array,
    p_dot: Array,
    kappa: Array,
    kbar: Array,
    b: Array,
    c: Array,
    contact_damping: bool = False,
    smoothing: float = 0.0,
) -> Array:
    """Mesh force (N) ``F = kbar kappa(t) g(p) + c p'``.

    **Arguments:** ``p``, ``p_dot``: deflection (m) and its rate (m/s) along the line of
    action; ``kappa``: dimensionless stiffness at the same instants; ``kbar``: mean
    stiffness (N/m); ``b``: half backlash (m); ``c``: damping (N s/m);
    ``contact_damping``: apply the viscous term only while the teeth touch;
    ``smoothing``: corner rounding of the clearance function (:func:`backlash`). All
    arrays broadcast together (e.g. ``(m, T)`` against ``(m, 1)``).
    """
    damping = c * p_dot
    if contact_damping:
        damping = damping * in_contact(p, b)
    return kbar * kappa * backlash(p, b, smoothing) + damping


def fourier_series(
    cos: Float[Array, "m H"], sin: Float[Array, "m H"], mu: Array, omega, t: Array
) -> Array:
    """``sum_h cos_h cos(h mu Omega t) + sin_h sin(h mu Omega t)`` per row.

    **Arguments:** ``cos``, ``sin``: shape ``(m, H)``; ``mu``: shape ``(m,)`` integer
    multipliers of the base frequency ``omega`` (rad/s); ``t``: times (s), shape ``(T,)``
    or scalar. **Returns:** shape ``(m, T)`` (or ``(m,)`` for scalar ``t``).
    """
    t = jnp.asarray(t)
    h = jnp.arange(1, cos.shape[-1] + 1)
    arg = (h[None, :] * mu[:, None] * omega)[..., None] * jnp.atleast_1d(t)  # (m, H, T)
    out = jnp.einsum("mh,mht->mt", cos, jnp.cos(arg)) + jnp.einsum("mh,mht->mt", sin, jnp.sin(arg))
    return out if t.ndim else out[:, 0]


def stiffness_series(k_cos: Float[Array, "m H"], k_sin: Float[Array, "m H"], mu: Array,
                     tau) -> Array:
    """Dimensionless mesh stiffness ``kappa = 1 + fourier_series(k_cos, k_sin)`` at base
    phases ``tau`` (rad, ``(T,)`` or scalar) of meshes turning ``mu`` ``(m,)`` times per
    base period. **Returns:** ``(m, T)`` (or ``(m,)``); ones where ``H = 0``."""
    if k_cos.shape[-1] == 0:
        return jnp.ones(k_cos.shape[:1] + jnp.shape(tau))
    return 1.0 + fourier_series(k_cos, k_sin, mu, 1.0, tau)


def transmission_error(te_mean: Float[Array, " m"], te_cos: Float[Array, "m H"],
                       te_sin: Float[Array, "m H"], mu: Array, tau) -> tuple[Array, Array]:
    """Transmission error ``e`` (m) and its phase rate ``de/dtau`` (m/rad) at base phases
    ``tau`` (rad, ``(T,)`` or scalar) of meshes turning ``mu`` ``(m,)`` times per base
    period: the constant ``te_mean`` plus the harmonics. **Returns:** two ``(m, T)`` (or
    ``(m,)``) arrays; the rate zero where ``H = 0``."""
    H = te_cos.shape[-1]
    mean = jnp.broadcast_to(jnp.reshape(te_mean, te_mean.shape + (1,) * jnp.ndim(tau)),
                            te_cos.shape[:1] + jnp.shape(tau))
    if H == 0:
        return mean, jnp.zeros_like(mean)
    order = jnp.arange(1, H + 1)[None, :] * mu[:, None]
    return (mean + fourier_series(te_cos, te_sin, mu, 1.0, tau),
            fourier_series(order * te_sin, -order * te_cos, mu, 1.0, tau))


