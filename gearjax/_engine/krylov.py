"""Matrix-free solves with the harmonic-balance Jacobian: BiCGStab on the exact
Jacobian-vector product, preconditioned per cosine-sine pair.

A dense factorisation of the Jacobian costs ``(2/3) N^3`` floating-point operations
(``N`` the condensed unknowns, :mod:`gearjax._engine.bordered`); a product with it
costs one pass of the AFT over the meshes, ``O(N log N)``. :class:`KrylovHB` (Newton,
adjoints) and :func:`solve` (the continuation's bordered system) solve with products
only: BiCGStab (``lineax.BiCGStab``) on the exact product
(:func:`jacobian_product`, from the meshes' force slopes at the point), right
preconditioned by :class:`PairPreconditioner`.

The preconditioner is the Jacobian of the time-invariant gear at the point: every mesh
replaced by its mean contact stiffness ``mean(dF/dp)`` and mean damping ``mean(dF/dp')``
over the AFT grid (the mean of the current contact state, so a mesh that separates for
part of the period contributes less). Its Jacobian is block-diagonal over cosine-sine
pairs (the mean: ``n x n``; each pair: ``2n x 2n``), so it is inverted block by block in
``P (2n)^3`` operations. What it leaves out (the stiffness variation and the contact
changes: products of a harmonic with the excitation orders) is what the Krylov
iterations resolve; the number of iterations does not grow with ``K``, because the
highest harmonics, dominated by inertia, are inverted almost exactly.

:func:`uses_krylov` decides between the condensed LU and this solver for Newton and
implicit derivatives from the problem's shapes (:func:`krylov_cheaper`), with the
iterations at their bound :data:`STEP_BOUND`: Krylov is chosen where even its worst case
is cheaper than a factorisation, never on a measured timing, and a solve that does not
converge falls back to the LU (:class:`KrylovHB`'s ``fallback``). The continuation's
bordered solves are matrix-free only where asked for (``linear_solver = "krylov"``).
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array

from . import aft as _aft
from . import bordered as _bordered
from . import hb as _hb
from .bordered import small_inverses
from .linear_solver import CondensedLU, HBJacobian, register_structured

STEP_BOUND = 200
"""BiCGStab steps per solve (each two Jacobian-vector products and two preconditioner
applications); a solve that does not meet :data:`RTOL` within them returns its last
iterate with ``lineax.RESULTS.max_steps_reached``, and Newton's own test decides."""

RTOL = 1e-10
"""Relative tolerance of a Krylov solve: every residual entry below ``RTOL max |b|``
(and the last update below ``RTOL max |b|`` per unknown: the scaled unknowns are of
order one where the scaled right-hand side is)."""


class PairPreconditioner(lx.AbstractLinearOperator):
    """Approximate inverse of the scaled Jacobian ``J`` (``(N, N)``; ``J^-T`` when
    ``transposed``): ``S_in^-1 B^-1 S_out`` with ``B`` the block-diagonal Jacobian of
    the time-invariant gear (module docstring) and ``S_in``, ``S_out`` the scales of the
    unknowns and residual rows.

    **Fields:** ``mean_inverse`` ``(n, n)``; ``pair_inverse`` ``(P, 2n, 2n)``, rows and
    columns ``(cos, sin)`` of each pair; ``row_scale`` ``(C, n)``
    (``hb.residual_scale``); ``x_scale`` ``(n,)``.
    """

    mean_inverse: Array
    pair_inverse: Array
    row_scale: Array
    x_scale: Array
    transposed: bool = eqx.field(static=True, default=False)

    def mv(self, vector):
        C, n = self.row_scale.shape
        P = self.pair_inverse.shape[0]
        mean, pairs = self.mean_inverse, self.pair_inverse
        scale_in, scale_out = self.row_scale, 1.0 / self.x_scale
        if self.transposed:  # S_out B^-T S_in^-1
            mean, pairs = mean.T, jnp.swapaxes(pairs, 1, 2)
            scale_in, scale_out = scale_out, scale_in
        V = vector.reshape(C, n) * scale_in
        Z = jnp.concatenate([(mean @ V[0])[None], jnp.einsum(
            "pij,pj->pi", pairs, V[1:].reshape(P, 2 * n)).reshape(2 * P, n)])
        return (Z * scale_out).reshape(-1)

    def as_matrix(self):
        eye = jnp.eye(self.in_size())
        return jax.vmap(self.mv, in_axes=1, out_axes=1)(eye)

    def transpose(self):
        return PairPreconditioner(self.mean_inverse, self.pair_inverse, self.row_scale,
                                  self.x_scale, not self.transposed)

    def in_structure(self):
        return jax.ShapeDtypeStruct((self.row_scale.size,), self.row_scale.dtype)

    def out_structure(self):
        return self.in_structure()


register_structured(PairPreconditioner)


class Slopes(eqx.Module):
    """The scaled Jacobian of ``problem``'s residual at one point, as the data of its
    product (:func:`jacobian_product`): every mesh's force slopes at the AFT samples.

    **Fields:** ``problem``; ``omega``: base frequency (rad/s); ``stiffness``,
    ``damping`` ``(m, T)``: ``dF/dp`` (N/m) and ``dF/dp'`` (N s/m) at the samples
    (``hb.force_slopes``); ``row_scale`` ``(C, n)``: the residual's row scale there.
    """

    problem: _hb.HBProblem
    omega: Array
    stiffness: Array
    damping: Array
    row_scale: Array


def slopes(problem: _hb.HBProblem, y: Array, omega) -> Slopes:
    """:class:`Slopes` of ``problem`` at the scaled unknowns ``y`` ``(N,)`` and base
    frequency ``omega`` (rad/s) (jittable)."""
    s = problem.system
    X = y.reshape(problem.shape) * problem.x_scale
    p, p_dot, _ = _hb.mesh_samples(problem, X @ s.W.T, omega)
    a, b = _hb.force_slopes(problem, p, p_dot)
    return Slopes(problem, jnp.asarray(omega, dtype=y.dtype), a, b,
                  _hb.residual_scale(problem, omega))


def jacobian_product(at: Slopes, v: Array) -> Array:
    """``J v`` ``(N,)``, ``J`` the scaled Jacobian of :class:`Slopes` ``at``: the linear
    part, and each mesh's force change ``a p + b p'`` on the AFT grid for the deflection
    ``p`` of ``v`` (exact: the mesh force of a sample depends on that sample's deflection
    and rate only)."""
    problem = at.problem
    basis, W = problem.basis, problem.system.W
    X = v.reshape(problem.shape) * problem.x_scale
    P = X @ W.T  # (C, m)
    w0 = at.omega / problem.settings.eta
    p = _aft.torus_synthesis(basis, P).T
    p_dot = w0 * _aft.torus_synthesis(basis, _aft.torus_derivative(basis, P)).T
    force = _aft.torus_analysis(basis, (at.stiffness * p + at.damping * p_dot).T)
    return ((_hb.linear_part(problem, X, at.omega) + force @ W) / at.row_scale).reshape(-1)


def pair_preconditioner(at: Slopes) -> PairPreconditioner:
    """:class:`PairPreconditioner` of the scaled Jacobian of :class:`Slopes` ``at``
    (jittable)."""
    problem = at.problem
    s = problem.system
    n = problem.shape[1]
    P = problem.basis.n_pairs
    stiffness = s.K + s.W.T @ (jnp.mean(at.stiffness, axis=1)[:, None] * s.W)
    damping = s.C + s.W.T @ (jnp.mean(at.damping, axis=1)[:, None] * s.W)
    w0 = at.omega / problem.settings.eta
    nu = _aft.frequency_numbers(problem.basis)[1::2]
    pairs = _hb.harmonic_blocks(stiffness, s.M, damping, w0, nu).reshape(P, 2 * n, 2 * n)
    mean = jnp.zeros((1, 2 * n, 2 * n)).at[0, :n, :n].set(stiffness).at[0, n:, n:].set(
        jnp.eye(n))
    inverse = small_inverses(jnp.concatenate([mean, pairs]))
    return PairPreconditioner(inverse[0, :n, :n], inverse[1:], at.row_scale, problem.x_scale)


def _bicgstab(product, preconditioner, vector: Array):
    """BiCGStab (lineax) on ``product(v)`` (a function of ``(M,)`` vectors) right
    preconditioned by the lineax operator ``preconditioner``, to :data:`RTOL` of
    ``max |vector|`` within :data:`STEP_BOUND` steps: ``(solution, result, stats)``.

    It starts from the preconditioned right-hand side ``y0 = B^-1 vector``, whose
    residual (BiCGStab's shadow residual) holds what ``B`` misses: from zero, a
    right-hand side that the preconditioner solves exactly in some rows (the bordered
    one's last row) leaves later residuals orthogonal to it, and BiCGStab breaks down
    (0/0). Where it breaks down all the same (a residual of exactly zero, ``y0``
    exact), the solution returned is ``y0``, with lineax's result."""
    scale = RTOL * jnp.max(jnp.abs(vector))
    solver = lx.BiCGStab(rtol=RTOL, atol=jnp.where(scale > 0, scale, 1.0), max_steps=STEP_BOUND)
    operator = lx.FunctionLinearOperator(product, jax.ShapeDtypeStruct(vector.shape, vector.dtype))
    y0 = preconditioner.mv(vector)
    x, result, stats = solver.compute(operator, vector,
                                      {"preconditioner": preconditioner, "y0": y0})
    return jnp.where(jnp.all(jnp.isfinite(x)), x, y0), result, stats


class KrylovState(eqx.Module):
    """:class:`KrylovHB`'s state: the Jacobian's :class:`Slopes`, its preconditioner, the
    scaled unknowns ``y`` it is taken at (for the fallback), and whether solves are with
    ``J^T``."""

    at: Slopes
    preconditioner: PairPreconditioner
    y: Array
    transposed: bool = eqx.field(static=True, default=False)


class KrylovHB(lx.AbstractLinearSolver):
    """BiCGStab on :class:`~gearjax._engine.linear_solver.HBJacobian` operators: products
    by :func:`jacobian_product`, right preconditioned by :func:`pair_preconditioner`, both
    at the operator's point.

    ``init`` evaluates the mesh slopes and builds the preconditioner (no factorisation of
    ``J``); ``compute`` is one BiCGStab solve to :data:`RTOL` within :data:`STEP_BOUND`
    steps (``stats["num_steps"]``; past the bound, ``max_steps_reached`` with the last
    iterate, or a breakdown); ``transpose`` solves ``J^T x = b`` with the transposed
    product and preconditioner (adjoints). With ``fallback``, a solve that does not
    converge is done again with the condensed LU of ``J`` at the same point
    (:class:`~gearjax._engine.linear_solver.CondensedLU`; ``stats["fallback"]``): the
    preconditioner is the time-invariant gear's, and where the stiffness variation
    couples the harmonics strongly (e.g. tests/data/three_stage.toml) BiCGStab from it
    does not converge.
    """

    fallback: bool = eqx.field(static=True, default=False)

    def init(self, operator, options: dict[str, Any]) -> KrylovState:
        del options
        if not isinstance(operator, HBJacobian):
            raise TypeError(f"KrylovHB solves HBJacobian operators, not {type(operator)}")
        at = slopes(operator.problem, operator.y, operator.omega)
        state = KrylovState(at, pair_preconditioner(at), operator.y)
        return self.transpose(state, {})[0] if operator.transposed else state

    def compute(self, state: KrylovState, vector, options: dict[str, Any]):
        del options

        def product(v):
            return jacobian_product(state.at, v)

        if state.transposed:  # the product is linear: its pullback is its transpose
            pullback = jax.vjp(product, jnp.zeros_like(vector))[1]

            def product(v):
                return pullback(v)[0]

            preconditioner = state.preconditioner.transpose()
        else:
            preconditioner = state.preconditioner
        x, result, stats = _bicgstab(product, preconditioner, vector)
        if not self.fallback:
            return x, result, stats
        failed = result != lx.RESULTS.successful

        def factorised(_):
            jacobian = HBJacobian(state.at.problem, state.y, state.at.omega, state.transposed)
            return lx.linear_solve(jacobian, vector, CondensedLU(), throw=False).value

        x = jax.lax.cond(failed, factorised, lambda _: x, None)
        return (x, lx.RESULTS.where(failed, lx.RESULTS.successful, result),
                {**stats, "fallback": failed})

    def transpose(self, state: KrylovState, options: dict[str, Any]):
        return (KrylovState(state.at, state.preconditioner, state.y, not state.transposed),
                options)

    def conj(self, state: KrylovState, options: dict[str, Any]):
        return state, options  # real

    def assume_full_rank(self) -> bool:
        return True


# -------------------------------------------------------------------------- bordered


class KrylovFactors(eqx.Module):
    """The bordered Jacobian ``[[J, g], [ty^T, tlam]]`` kept for matrix-free solves
    (:func:`solve`), the counterpart of ``bordered.Factors``.

    **Fields:** ``at``: :class:`Slopes` of ``J``; ``preconditioner`` of ``J``
    (:func:`pair_preconditioner`); ``g``, ``ty`` ``(N,)``, ``tlam``: the border;
    ``z = B^-1 g`` ``(N,)`` with ``B^-1`` the preconditioner, and ``corner = tlam - ty .
    z``: the bordered preconditioner's elimination (:func:`solve`).
    """

    at: Slopes
    preconditioner: PairPreconditioner
    g: Array
    ty: Array
    tlam: Array
    z: Array
    corner: Array


def factor(problem: _hb.HBProblem, y: Array, omega, g: Array, ty: Array,
           tlam) -> KrylovFactors:
    """:class:`KrylovFactors` of ``[[J(y, omega), g], [ty^T, tlam]]`` (jittable):
    ``bordered.factor``'s arguments, no factorisation."""
    at = slopes(problem, y, omega)
    preconditioner = pair_preconditioner(at)
    z = preconditioner.mv(g)
    return KrylovFactors(at, preconditioner, g, ty, jnp.asarray(tlam, dtype=y.dtype), z,
                         tlam - ty @ z)


def solve(factors, rhs: Array) -> Array:
    """Solution ``(N + 1,)`` of the bordered system for ``rhs`` ``(N + 1,)``: with
    ``bordered.Factors``, their LU; with :class:`KrylovFactors`, BiCGStab on the
    bordered product, right preconditioned by the preconditioner bordered alike (``u
    = B^-1 r``, ``l = (q - ty . u) / corner``, ``x = u - l z``: exact for ``J = B``,
    regular at a fold of the branch where ``J`` is singular but ``B`` is not)
    (jittable)."""
    if not isinstance(factors, KrylovFactors):
        return _bordered.solve(factors, rhs)
    f = factors

    def product(v):
        x, l = v[:-1], v[-1]
        return jnp.concatenate([jacobian_product(f.at, x) + f.g * l,
                                (f.ty @ x + f.tlam * l)[None]])

    def precondition(v):
        u = f.preconditioner.mv(v[:-1])
        l = (v[-1] - f.ty @ u) / f.corner
        return jnp.concatenate([u - l * f.z, l[None]])

    structure = jax.ShapeDtypeStruct(rhs.shape, rhs.dtype)
    return _bicgstab(product, lx.FunctionLinearOperator(precondition, structure), rhs)[0]


# ---------------------------------------------------------------------------- choice


def lu_flops(C: int, r: int) -> float:
    """Floating-point operations of one condensed LU of a Jacobian of ``C`` coefficient
    rows and ``r`` motions that deflect a mesh: ``(2/3) (C r)^3``."""
    return (2 / 3) * float(C * r) ** 3


def step_flops(C: int, n: int, m: int, T: int) -> float:
    """Floating-point operations of one BiCGStab step on a Jacobian of ``C`` coefficient
    rows, ``n`` degrees of freedom, ``m`` meshes and ``T`` AFT samples, counted from
    these shapes: two Jacobian-vector products (per mesh, the deflection and its rate
    synthesised and the force analysed on the grid, four real FFTs of ``2.5 T log2 T``,
    and ten operations a sample; the linear part ``3 C n^2``; the projections on the
    meshes ``4 C m n``) and two preconditioner applications (``2 C (2n)^2``)."""
    fft = 4 * 2.5 * T * math.log2(max(T, 2)) + 10 * T
    product = m * fft + 3 * C * n * n + 4 * C * m * n
    return 2 * product + 2 * 2 * C * (2 * n) ** 2


def krylov_cheaper(C: int, n: int, r: int, m: int, T: int) -> bool:
    """Whether a Krylov solve of :data:`STEP_BOUND` BiCGStab steps (:func:`step_flops`)
    costs less than one condensed LU (:func:`lu_flops`) and a solve with it on a Jacobian
    of these shapes: the worst case of the Krylov solve against the fixed cost of a
    factorisation."""
    lu = lu_flops(C, r) + 2 * float(C * r) ** 2
    return lu > STEP_BOUND * step_flops(C, n, m, T)


def uses_krylov(problem: _hb.HBProblem) -> bool:
    """Whether ``problem``'s Newton and implicit-derivative solves go through
    :class:`KrylovHB`: ``settings.linear_solver`` ``"krylov"``, or ``"auto"`` where
    :func:`krylov_cheaper`."""
    setting = problem.settings.linear_solver
    if setting != "auto":
        return setting == "krylov"
    C, n = problem.shape
    r = n - (0 if problem.mesh_null is None else problem.mesh_null.shape[1])
    return krylov_cheaper(C, n, r, problem.system.n_meshes, problem.n_time)


def linear_solver(problem: _hb.HBProblem) -> lx.AbstractLinearSolver:
    """The lineax solver for ``problem``'s Jacobian (:func:`uses_krylov`):
    :class:`KrylovHB` (with the LU as its fallback where ``"auto"`` chose it) or
    :class:`~gearjax._engine.linear_solver.CondensedLU`."""
    if not uses_krylov(problem):
        return CondensedLU()
    return KrylovHB(fallback=problem.settings.linear_solver == "auto")

