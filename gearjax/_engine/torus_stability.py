"""Stability of a harmonic-balance solution on a torus (or periodic): the verdict on the
characteristic exponents of Hill's method.

A quasi-periodic solution has no period and so no monodromy matrix (model.md,
"Incommensurate stages"). Its linearisation ``dz = exp(s t) q(theta)`` gives the
characteristic exponents ``s`` by Hill's method on the basis of the harmonic balance
(:mod:`gearjax._engine.hill`: the equations, the one-member-per-family selection and its
checks). The solution is stable when every exponent left in the verdict has

    Re s < tol * omega_0 / (2 pi),

the growth over one turn of the base angle (``2 pi / omega_0`` seconds) below a factor
``1 + tol``: for ``G = 1`` this is the margin of the Floquet verdict
(:func:`gearjax._engine.verdict.stability`, ``|mu| < 1 + tol`` with ``mu = exp(s T)``), so
the two verdicts agree on a periodic solution, and a neutral exponent (an undamped mode)
is not called unstable by round-off. As in the Floquet verdict, the exponents of the
model's rigid-body modes (nothing damps them) are left out: with ``r`` rigid modes, the
``2 r`` whose eigenvectors lie most in them.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Complex, Float

from .floquet import scaled_frame
from .hb import HBProblem
from .hill import hill_selection
from .modal import mode_classes

__all__ = ["TorusStability", "torus_stability"]


class TorusStability(eqx.Module):
    """Stability of one harmonic-balance solution by Hill's method.

    **Fields:**

    - ``exponents`` ``(2n,)`` complex (1/s): one characteristic exponent per family
      (:func:`gearjax._engine.hill.hill_exponents`);
    - ``centres`` ``(2n, G)``: the power-weighted mean wave vector of each kept eigenvector;
    - ``rigid_share`` ``(2n,)``: share of each kept mode's displacement (mass norm, summed
      over the basis) in the rigid-body modes of the mean-stiffness model;
    - ``excluded`` ``(2n,)`` bool: exponents left out of the verdict (the ``2 r`` most
      rigid-body-like, ``r`` rigid modes in the model);
    - ``max_real`` (1/s): the largest ``Re s`` of the exponents not excluded;
    - ``threshold`` (1/s): ``tol * omega_0 / (2 pi)``;
    - ``stable`` bool: ``max_real < threshold``;
    - ``cell_violation``, ``conjugate_error``, ``edge_power`` ``(2n,)``, ``reliable``: the
      checks of the selection (:class:`gearjax._engine.hill.HillSelection`); a verdict
      with ``reliable`` false needs a larger truncation (or a Floquet check for ``G = 1``).
    """

    exponents: Complex[Array, " 2n"]
    centres: Float[Array, "2n G"]
    rigid_share: Float[Array, " 2n"]
    excluded: Bool[Array, " 2n"]
    max_real: Float[Array, ""]
    threshold: Float[Array, ""]
    stable: Bool[Array, ""]
    cell_violation: Float[Array, ""]
    conjugate_error: Float[Array, ""]
    edge_power: Float[Array, " 2n"]
    reliable: Bool[Array, ""]


def torus_stability(problem: HBProblem, X: Array, omega, tol=1e-6) -> TorusStability:
    """Hill stability of the solution ``X`` ``(2P+1, n)`` (rad or m) at the base frequency
    ``omega`` (rad/s), periodic or on a torus (see the module docstring); ``tol``: margin
    on the growth per turn of the base angle. Jit- and vmap-able over ``X``, ``omega``
    (CPU: a dense non-symmetric eigen-decomposition of size ``2 (2P+1) n``).

    **Raises** ``ValueError`` for ``contact_damping=True`` systems.
    """
    s = problem.system
    sel = hill_selection(problem, X, omega)
    frame = scaled_frame(problem)
    _, modal, _, rigid, _ = mode_classes(s)
    # modal content of every kept mode: modal^T M dz with dz = L^-T q, on every coefficient row
    dz = jnp.einsum("ji,kcj->kci", frame.Linv, sel.vectors)  # (2n, C, n)
    a = jnp.sum(jnp.abs(jnp.einsum("ij,kcj->kci", modal.T @ s.M, dz)) ** 2, axis=1)  # (2n, n)
    total = jnp.sum(a, axis=-1)
    share = jnp.sum(jnp.where(rigid[None, :], a, 0.0), axis=-1) / jnp.where(total > 0, total, 1.0)
    rank = jnp.argsort(jnp.argsort(-share))  # 0 for the most rigid-body-like mode
    excluded = rank < 2 * jnp.sum(rigid)
    max_real = jnp.max(jnp.where(excluded, -jnp.inf, sel.exponents.real))
    w0 = jnp.asarray(omega, dtype=float) / problem.settings.eta
    threshold = tol * w0 / (2 * jnp.pi)
    return TorusStability(exponents=sel.exponents, centres=sel.centres, rigid_share=share,
                          excluded=excluded, max_real=max_real, threshold=threshold,
                          stable=max_real < threshold, cell_violation=sel.cell_violation,
                          conjugate_error=sel.conjugate_error, edge_power=sel.edge_power,
                          reliable=sel.reliable)
