"""The harmonic-balance Jacobian as a lineax operator, and the condensed LU as a lineax solver.

:class:`HBJacobian` is ``d residual / d y`` of :func:`gearjax._engine.hb.residual` at one
point: it carries what the factorisation needs (the problem, the scaled unknowns and
the base frequency), so a solver can factorise it without materialising it.
:class:`CondensedLU` factorises it condensed to the motions that deflect a mesh
(:func:`gearjax._engine.bordered.jacobian_factors`: dense where ``problem.mesh_null``
is ``None``) and solves with those factors; its transpose solves ``J^T x = b`` with the
same factors, so one factorisation serves Newton and the adjoint of an implicit
derivative (:mod:`gearjax._engine.adjoint`).
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array

from . import bordered as _bordered
from . import hb as _hb


class HBJacobian(lx.AbstractLinearOperator):
    """``J = d residual(problem, y, omega) / d y`` ``(N, N)`` (its transpose when
    ``transposed``), scaled unknowns to scaled residual rows.

    **Fields:** ``problem`` (:class:`~gearjax._engine.hb.HBProblem`); ``y`` ``(N,)``:
    the scaled unknowns it is taken at; ``omega``: base frequency (rad/s).
    """

    problem: _hb.HBProblem
    y: Array
    omega: Array
    transposed: bool = eqx.field(static=True, default=False)

    def mv(self, vector):
        def fn(y):
            return _hb.residual(self.problem, y, self.omega)

        if self.transposed:
            return jax.vjp(fn, self.y)[1](vector)[0]
        return jax.jvp(fn, (self.y,), (vector,))[1]

    def as_matrix(self):
        J = _hb.jacobian(self.problem, self.y, self.omega)
        return J.T if self.transposed else J

    def transpose(self):
        return HBJacobian(self.problem, self.y, self.omega, not self.transposed)

    def in_structure(self):
        return jax.ShapeDtypeStruct(self.y.shape, self.y.dtype)

    def out_structure(self):
        return jax.ShapeDtypeStruct(self.y.shape, self.y.dtype)


def register_structured(operator_type: type) -> type:
    """Register a lineax operator class of ours with lineax's structure queries: it is
    its own linearisation and materialisation, its diagonal is that of ``as_matrix()``,
    and it claims no structure (not symmetric, triangular, definite, ...). Returns the
    class."""
    for query in (lx.linearise, lx.materialise):
        query.register(operator_type)(lambda operator: operator)
    lx.diagonal.register(operator_type)(lambda operator: jnp.diag(operator.as_matrix()))
    for query in (lx.is_symmetric, lx.is_diagonal, lx.is_tridiagonal, lx.has_unit_diagonal,
                  lx.is_lower_triangular, lx.is_upper_triangular,
                  lx.is_positive_semidefinite, lx.is_negative_semidefinite):
        query.register(operator_type)(lambda operator: False)
    return operator_type


register_structured(HBJacobian)


class CondensedState(eqx.Module):
    """:class:`CondensedLU`'s state: the factors of ``J`` and whether solves are with
    ``J^T``."""

    factors: _bordered.Factors
    transposed: bool = eqx.field(static=True, default=False)


class CondensedLU(lx.AbstractLinearSolver):
    """LU of the harmonic-balance Jacobian condensed to the motions that deflect a mesh
    (:mod:`gearjax._engine.bordered`), for :class:`HBJacobian` operators only.

    ``init`` factorises once; ``compute`` is one solve with the factors; ``transpose``
    keeps the factors and solves ``J^T x = b`` (the transpose of the solve, exact).
    Assumes ``J`` nonsingular; a singular one gives non-finite solutions.
    """

    def init(self, operator, options: dict[str, Any]) -> CondensedState:
        del options
        if not isinstance(operator, HBJacobian):
            raise TypeError(f"CondensedLU solves HBJacobian operators, not {type(operator)}")
        factors = _bordered.jacobian_factors(operator.problem, operator.y, operator.omega)
        return CondensedState(factors, operator.transposed)

    def compute(self, state: CondensedState, vector, options: dict[str, Any]):
        del options
        return solve(state, vector), lx.RESULTS.successful, {}

    def transpose(self, state: CondensedState, options: dict[str, Any]):
        return CondensedState(state.factors, not state.transposed), options

    def conj(self, state: CondensedState, options: dict[str, Any]):
        return state, options  # real

    def assume_full_rank(self) -> bool:
        return True


def solve(state: CondensedState, vector: Array) -> Array:
    """``J^-1 vector`` (``J^-T vector`` for a transposed state), ``(N,)``, from
    :class:`CondensedLU`'s state (jittable)."""
    def forward(b):
        return _bordered.jacobian_solve(state.factors, b)

    if not state.transposed:
        return forward(vector)
    return jax.linear_transpose(forward, vector)(vector)[0]
