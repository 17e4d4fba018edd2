"""Where a time integration starts: the static contact state, the state at ``t = 0`` of a
harmonic-balance solution, and the start arrays every integration program takes."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import aft as _aft
from .programs import one_program
from .static import static_deflection
from .system import System


def contact_state(system: System):
    """The static solution shifted into contact on each mesh's loaded flank.

    Solves the mean-stiffness statics with ``g(p) = p - b sign(F_static)`` (as
    ``_hb.linear_guess``): every mesh deflects by its static deflection plus its
    backlash, never starting inside the gap. **Returns:** ``(x0, v0)``, ``(n,)``
    each (rad or m, and zero rates).
    """
    _, F_static = static_deflection(system)
    preload = system.W.T @ (system.kbar * system.backlash * jnp.sign(F_static))
    x0, _ = static_deflection(dataclasses.replace(system, f_mean=system.f_mean + preload))
    return x0, jnp.zeros_like(x0)


contact_state_jit = eqx.filter_jit(contact_state)
""":func:`contact_state`, compiled (one program instead of its operations one by one)."""


def hb_initial_state(X: Float[Array, "C n"], omega, eta: int = 1, basis=None):
    """State at ``t = 0`` of a harmonic-balance solution.

    **Arguments:** ``X`` ``(2K+1, n)``: coefficients of ``x(tau)``, ``tau = (Omega /
    eta) t`` (``HBSolution.X``); ``omega``: base frequency Omega (rad/s); ``eta``: the
    sub-harmonic index of the solution; ``basis``: the
    :class:`~gearjax._engine.aft.Basis` of a torus solution ``(2P+1, n)`` (``None``: the
    periodic harmonics ``1..K``), whose wave vector ``k`` turns at ``k . rates`` times
    ``Omega / eta``. **Returns:** ``(x0, v0)``, ``(n,)`` each (rad or m, and rad/s or
    m/s).
    """
    X = jnp.asarray(X)
    if basis is None:
        k = np.arange(1, (X.shape[0] - 1) // 2 + 1)
    else:
        k = _aft.frequency_numbers(basis)[2::2]
    return _state_at_zero(X, jnp.asarray(omega, dtype=float) / eta, k.astype(float))


@one_program
def _state_at_zero(X, rate, k):
    """``(x(0), x'(0))`` of coefficients ``X`` ``(2P+1, n)`` whose pair ``j`` turns at
    ``k_j`` times ``rate`` (rad/s): one program, not one per operation."""
    return X[0] + jnp.sum(X[1::2], axis=0), rate * jnp.sum(k[:, None] * X[2::2], axis=0)


def start_state(system: System, x0, v0):
    """``(x0, v0)`` as float arrays: the contact state (:func:`contact_state`, one
    compiled program) where ``x0`` is None, zero rates where ``v0`` is None."""
    if x0 is None:
        x0, zero = contact_state_jit(system)
        return x0, zero if v0 is None else jnp.asarray(v0, dtype=float)
    x0 = jnp.asarray(x0, dtype=float)
    return x0, jnp.zeros_like(x0) if v0 is None else jnp.asarray(v0, dtype=float)
