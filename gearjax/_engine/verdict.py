"""Stability of periodic solutions: the verdict on Floquet multipliers and bifurcations.

The multipliers come from :mod:`gearjax._engine.floquet` (the reference; the linearised
equations and the method are described there) or, as a cross-check,
:mod:`gearjax._engine.hill`. The verdict leaves out the multipliers of the model's
rigid-body modes (:class:`Stability`).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Complex, Float

from .floquet import ScaledFrame, floquet_steps, monodromy_scaled, return_turns, scaled_frame
from .hb import HBProblem
from .modal import mode_classes
from .programs import one_program

__all__ = ["Stability", "stability", "VerdictBasis", "verdict_basis", "scaled_monodromy",
           "verdict", "bifurcation_kind", "floquet_steps"]


class Stability(eqx.Module):
    """Stability of one periodic solution (a batch of them under ``vmap``).

    **Fields:**

    - ``multipliers`` ``(2n,)`` complex: Floquet multipliers (eigenvalues of the
      monodromy matrix over one response period); for a solution on a torus, the
      principal ``q``-th roots of those of the monodromy over the ``q`` turns of the base
      angle of its near return (:func:`gearjax._engine.floquet.return_turns`): their
      moduli are the growth per turn, their phases are not those of a period;
    - ``mesh_strain`` ``(2n,)``: how much each Floquet mode deflects the meshes,
      ``max_m |w_m . dz| / max_i (lever_i |dz_i|)``, ``lever_i = max_m |W_mi|`` (the
      mesh deflection a unit motion of coordinate ``i`` can cause; 0: no mesh strained);
    - ``rigid_share`` ``(2n,)``: share of each Floquet mode's displacement (in the mass
      norm, ``dz^H M dz``) that lies in the rigid-body modes of the mean-stiffness model
      (:func:`gearjax._engine.modal.mode_classes`: strain energy mostly in the free-class housing
      springs, such as the 1e2 N m/rad ones of the paper, or eigenvalue zero);
    - ``excluded`` ``(2n,)`` bool: multipliers left out of the verdict, those of the
      (near-)rigid-body modes: with ``r`` rigid modes in the model, the ``2 r`` Floquet
      modes with the largest ``rigid_share``. Nothing damps such a mode (model.md) and
      it does not change the mesh forces; its pair of multipliers sits on the unit
      circle up to a slight parametric coupling through its small mesh strain
      (docs/stability.md), and an exact rigid-body mode gives the double
      multiplier +1. The verdict is on the gear's vibration: the other ``2 (n - r)``
      multipliers;
    - ``max_abs``: the largest ``|mu|`` of the multipliers that are not excluded;
    - ``stable`` bool: ``max_abs < 1 + tol`` (per turn of the base angle on a torus).
    """

    multipliers: Complex[Array, " 2n"]
    mesh_strain: Float[Array, " 2n"]
    rigid_share: Float[Array, " 2n"]
    excluded: Bool[Array, " 2n"]
    max_abs: Float[Array, ""]
    stable: Bool[Array, ""]


def stability(problem: HBProblem, X: Array, omega, tol=1e-6, n_steps: int | None = None
              ) -> Stability:
    """Floquet stability of the periodic solution ``X`` ``(2K+1, n)`` at ``omega`` (rad/s).

    Multipliers from :func:`floquet_multipliers` (``n_steps`` static, default
    :func:`floquet_steps`); ``tol`` is the margin on ``|mu| = 1`` for the verdict. The
    multipliers of the model's rigid-body modes are excluded (see :class:`Stability`).
    Jit- and vmap-able over ``X``, ``omega`` (CPU: it needs a non-symmetric
    eigen-decomposition).
    """
    basis = verdict_basis(problem)
    Phi, _, _ = monodromy_scaled(problem, X, omega, n_steps, basis.frame)
    mu, V = jnp.linalg.eig(Phi)
    return verdict(problem, basis, mu, V, tol)


class VerdictBasis(eqx.Module):
    """What the Floquet verdict needs of the system, the same for every solution: the
    scaled frame of the monodromy (:class:`ScaledFrame`) and the model's rigid-body modes
    (``modal`` ``(n, n)`` M-normalised shapes, ``rigid`` ``(n,)`` bool)."""

    frame: ScaledFrame
    modal: Array
    rigid: Array


@one_program
def verdict_basis(problem: HBProblem) -> VerdictBasis:
    """:class:`VerdictBasis` of ``problem`` (Cholesky and symmetric eigen-decompositions).

    With it, :func:`monodromy_scaled` and :func:`verdict` call no LAPACK routine: the
    sweep evaluates them in several threads at once, and jaxlib 0.10's CPU LAPACK
    kernels can deadlock XLA's thread pool when several run concurrently (each waits
    on pool tasks that the others hold the threads for), so the only non-symmetric
    eigen-decomposition there is NumPy's, outside XLA."""
    _, modal, _, rigid, _ = mode_classes(problem.system)
    return VerdictBasis(frame=scaled_frame(problem), modal=modal, rigid=rigid)


def scaled_monodromy(problem: HBProblem, basis: VerdictBasis, X: Array, omega,
                     n_steps: int | None = None) -> Array:
    """Monodromy matrix ``(2n, 2n)`` of one solution in the scaled coordinates of
    ``basis.frame`` (``n_steps`` static, default :func:`floquet_steps`; no LAPACK call):
    its eigenvalues are the Floquet multipliers, its eigenvalues and eigenvectors the
    input of :func:`verdict`."""
    return monodromy_scaled(problem, X, omega, n_steps, basis.frame)[0]


def verdict(problem: HBProblem, basis: VerdictBasis, mu, V, tol=1e-6) -> Stability:
    """:class:`Stability` from the eigenvalues ``mu`` ``(2n,)`` and eigenvectors ``V``
    ``(2n, 2n)`` (columns) of the scaled monodromy matrix (jittable; no LAPACK call)."""
    s = problem.system
    dz = basis.frame.Linv.T @ V[: s.n_dof]  # (n, 2n): displacement part of every Floquet mode
    lever = jnp.max(jnp.abs(s.W), axis=0) if s.n_meshes else jnp.zeros(s.n_dof)
    size = jnp.max(lever[:, None] * jnp.abs(dz), axis=0)
    strain = jnp.max(jnp.abs(s.W @ dz), axis=0) if s.n_meshes else jnp.zeros(2 * s.n_dof)
    ratio = jnp.where(size > 0, strain / jnp.where(size > 0, size, 1.0), 0.0)
    a = jnp.abs(basis.modal.T @ (s.M @ dz)) ** 2  # (n, 2n): modal content of every Floquet mode
    total = jnp.sum(a, axis=0)
    share = jnp.sum(jnp.where(basis.rigid[:, None], a, 0.0), axis=0) / jnp.where(
        total > 0, total, 1.0)
    rank = jnp.argsort(jnp.argsort(-share))  # 0 for the most rigid-body-like Floquet mode
    excluded = rank < 2 * jnp.sum(basis.rigid)
    turns, _ = return_turns(problem.basis.rates)
    if turns > 1:  # a torus: the growth per turn of the base angle (floquet.py)
        mu = jnp.abs(mu) ** (1.0 / turns) * jnp.exp(1j * jnp.angle(mu) / turns)
    max_abs = jnp.max(jnp.where(excluded, 0.0, jnp.abs(mu)))
    return Stability(multipliers=mu, mesh_strain=ratio, rigid_share=share, excluded=excluded,
                     max_abs=max_abs, stable=max_abs < 1.0 + tol)


def bifurcation_kind(mult_before, mult_after, tol: float = 1e-6) -> str | None:
    """How a multiplier crossed the unit circle between two neighbouring solutions.

    **Arguments:** the multipliers at the two points (arrays, or :class:`Stability`
    objects, whose excluded multipliers are dropped); ``tol``: margin on ``|mu| = 1``.
    The multipliers are paired by a minimum-distance assignment; a pair whose side of
    the circle changed is located where its straight path crosses ``|mu| = 1``.

    **Returns:** ``"fold"`` (a real multiplier through +1), ``"period_doubling"``
    (through -1), ``"neimark_sacker"`` (a complex pair), or ``None`` if no multiplier
    changed side.
    """
    from scipy.optimize import linear_sum_assignment

    def retained(m):
        if isinstance(m, Stability):
            return np.asarray(m.multipliers)[~np.asarray(m.excluded)]
        return np.asarray(m).astype(complex).ravel()

    before, after = retained(mult_before), retained(mult_after)
    rows, cols = linear_sum_assignment(np.abs(before[:, None] - after[None, :]))
    b, a = before[rows], after[cols]
    changed = (np.abs(b) > 1 + tol) != (np.abs(a) > 1 + tol)
    if not changed.any():
        return None
    b, a = b[changed], a[changed]
    j = int(np.argmax(np.abs(np.abs(a) - np.abs(b))))
    b, a = b[j], a[j]
    real_b = abs(b.imag) <= 1e-8 * abs(b)
    real_a = abs(a.imag) <= 1e-8 * abs(a)
    if not (real_b or real_a):
        return "neimark_sacker"
    t = (1.0 - abs(b)) / (abs(a) - abs(b)) if abs(a) != abs(b) else 0.5
    crossing = b + np.clip(t, 0.0, 1.0) * (a - b)
    if real_b and real_a:
        return "fold" if crossing.real > 0 else "period_doubling"
    real = b if real_b else a
    return "fold" if real.real > 0 else "period_doubling"
