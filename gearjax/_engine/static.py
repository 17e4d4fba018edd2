"""Static solution: mean stiffness, no backlash, mean torques only.

``(K + W^T diag(kbar) W) x = f_mean + W^T diag(kbar) e_mean`` and
``F_m = kbar_m (w_m . x - e_mean_m)``.
"""

from __future__ import annotations

import jax.numpy as jnp

from .programs import one_program
from .system import System


@one_program
def static_deflection(system: System):
    """Static coordinates ``x`` (rad or m) and mesh forces ``F`` (N) of a ``System``.

    Solved by a symmetric eigen-decomposition that drops exactly singular directions
    (a train with ``housing.free = 0`` and no brake has a free rigid-body rotation,
    which carries no mesh load). **Returns:** ``(x, F)``, shapes ``(n,)``, ``(m,)``.
    """
    Kt = system.mean_stiffness()
    lam, V = jnp.linalg.eigh(0.5 * (Kt + Kt.T))
    tol = lam.shape[0] * jnp.finfo(lam.dtype).eps * jnp.max(jnp.abs(lam))
    inv = jnp.where(jnp.abs(lam) > tol, 1.0 / jnp.where(jnp.abs(lam) > tol, lam, 1.0), 0.0)
    f = system.f_mean + system.W.T @ (system.kbar * system.te_mean)
    x = V @ (inv * (V.T @ f))
    return x, system.kbar * (system.W @ x - system.te_mean)


