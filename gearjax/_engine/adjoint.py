"""Implicit differentiation through a converged harmonic-balance point.

At a converged point the scaled residual ``res(y, p) = 0``
(:func:`gearjax._engine.hb.residual`) defines the solution ``y(p)`` implicitly, ``p``
whatever the problem and the frequency are computed from. The implicit function
theorem gives its derivative without differentiating the Newton iterations:

    dy = -J^-1 (d res / d p) dp,    J = d res / d y,

and a reverse pass through it is one solve with ``J^T``. Both go through lineax on
:class:`~gearjax._engine.linear_solver.HBJacobian` with the problem's solver
(:func:`gearjax._engine.krylov.linear_solver`): one factorisation at the point
(:class:`~gearjax._engine.linear_solver.CondensedLU`), or the meshes' force slopes and
the preconditioner there (:class:`~gearjax._engine.krylov.KrylovHB`), whose transpose
serves the reverse pass. The unknowns and residual rows keep the
scales of the point (``x_scale``, ``residual_scale``), held constant: a change of scale
is a change of variables, and at ``res = 0`` the row scale drops out of the derivative.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array

from . import hb as _hb
from . import krylov as _krylov
from .linear_solver import HBJacobian


def implicit_coefficients(problem: _hb.HBProblem, y: Array, omega) -> Array:
    """The coefficients ``X`` ``(2K+1, n)`` (rad or m) of the converged point ``y``
    ``(N,)`` (scaled unknowns of ``problem`` at base frequency ``omega``, rad/s), with
    the implicit derivative (module docstring) with respect to everything ``problem``
    and ``omega`` are traced from (``jax.grad``, ``jax.jvp``, ``jax.vmap`` pass).

    The value is ``y * x_scale`` exactly (``y`` is not refined); the derivative is that
    of the exact solution where ``y`` has converged. ``y`` itself is not differentiated
    (the Newton iterations are never differentiated). A singular ``J`` (a fold), or a
    matrix-free solve that does not converge within its bound, gives non-finite values.
    """
    y = jax.lax.stop_gradient(y)
    point = jax.lax.stop_gradient(problem)
    omega0 = jax.lax.stop_gradient(omega)
    x_scale = point.x_scale
    row_scale = _hb.residual_scale(point, omega0)
    X = y.reshape(problem.shape) * x_scale
    res = (_hb.physical_residual(problem, X, omega) / row_scale).reshape(-1)
    sol = lx.linear_solve(HBJacobian(point, y, omega0), res, _krylov.linear_solver(point),
                          throw=False)
    # a Krylov solve that did not converge makes value and derivative non-finite, as a fold
    delta = -sol.value * jnp.where(sol.result == lx.RESULTS.successful, 1.0, jnp.nan)
    # value y exactly; derivative d delta = -J^-1 d res
    y = y + (delta - jax.lax.stop_gradient(delta))
    return y.reshape(problem.shape) * x_scale
