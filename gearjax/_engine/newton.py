"""Harmonic balance at a fixed frequency: Newton's method through ``optimistix.root_find``.

:class:`FactorisedNewton` is an ``optimistix`` root finder whose step solves with a
lineax solver on an operator built from the iterate (for the harmonic balance
:class:`~gearjax._engine.linear_solver.HBJacobian` and
:class:`~gearjax._engine.linear_solver.CondensedLU`); ``chord`` factorises once, at the
start. Its test: the scaled step below ``rtol max(1, max |y|)`` and the residual below
``sqrt(rtol)`` (max norms), both at the iterate the step is taken from; the step is
taken either way. A non-finite step stops the iteration at the last finite iterate;
:data:`PATIENCE` steps in a row without a new lowest residual stop it as diverging (full
Newton steps on a residual with backlash, which is smooth between changes of contact,
converge in a few steps once the contact pattern is right; steps that keep failing to
lower the residual cycle between patterns, and the remaining ones would be spent for
nothing). Results are optimistix's, promoted into
:class:`gearjax._engine.results.RESULTS`: ``successful``, ``nonlinear_max_steps_reached``,
``nonlinear_divergence`` or ``nonfinite``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from jaxtyping import Array

from . import hb as _hb
from . import krylov as _krylov
from .kept import kept_program
from .linear_solver import CondensedLU, HBJacobian
from .results import RESULTS

PATIENCE = 8
"""Newton steps in a row without a new lowest residual (max norm) after which
:class:`FactorisedNewton` stops as diverging (module docstring)."""


class _NewtonState(eqx.Module):
    """Root-finder state: the chord's solver state (``None`` for Newton), whether the
    last step met the test, whether it was non-finite; the lowest residual so far and the
    steps since it."""

    linear_state: Any
    converged: Array
    nonfinite: Array
    best: Array
    stalled: Array


class FactorisedNewton(optx.AbstractRootFinder):
    """Newton's method (``chord``: the chord method) with a structured linear solve.

    **Fields:** ``rtol``: tolerance of the scaled step (relative to ``max(1, max |y|)``)
    and, as ``sqrt(rtol)``, of the residual; ``operator``: ``(y, args) ->`` the
    Jacobian at ``y`` as a lineax operator; ``linear_solver``: the lineax solver for it;
    ``chord``: factorise at the start only; ``patience``: steps without a new lowest
    residual before it stops as diverging (:data:`PATIENCE`). ``atol`` and ``norm`` are
    the ``optimistix`` interface: the test above is this solver's own.
    """

    rtol: float
    operator: Callable = eqx.field(static=True)
    linear_solver: lx.AbstractLinearSolver = CondensedLU()
    chord: bool = eqx.field(static=True, default=False)
    patience: int = eqx.field(static=True, default=PATIENCE)
    atol: float = 0.0
    norm: Callable = eqx.field(static=True, default=optx.max_norm)

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        del fn, options, f_struct, aux_struct, tags
        linear_state = None
        if self.chord:
            linear_state = self.linear_solver.init(self.operator(y, args), {})
        false = jnp.asarray(False)
        return _NewtonState(linear_state=linear_state, converged=false, nonfinite=false,
                            best=jnp.asarray(jnp.inf, dtype=y.dtype), stalled=jnp.asarray(0))

    def step(self, fn, y, args, options, state, tags):
        del options, tags
        r, aux = fn(y, args)
        operator = self.operator(y, args)
        if self.chord:
            sol = lx.linear_solve(operator, -r, self.linear_solver,
                                  state=state.linear_state, throw=False)
        else:
            sol = lx.linear_solve(operator, -r, self.linear_solver, throw=False)
        step = sol.value
        y_new = y + step
        finite = jnp.all(jnp.isfinite(y_new))
        small = jnp.max(jnp.abs(step)) <= self.rtol * jnp.maximum(1.0, jnp.max(jnp.abs(y)))
        size = jnp.max(jnp.abs(r))
        converged = finite & small & (size <= jnp.sqrt(self.rtol))
        lower = size < state.best
        new_state = _NewtonState(linear_state=state.linear_state, converged=converged,
                                 nonfinite=~finite, best=jnp.where(lower, size, state.best),
                                 stalled=jnp.where(lower, 0, state.stalled + 1))
        return jnp.where(finite, y_new, y), new_state, aux

    def terminate(self, fn, y, args, options, state, tags):
        del fn, y, args, options, tags
        diverging = ~state.converged & (state.stalled >= self.patience)
        result = optx.RESULTS.where(
            state.nonfinite, optx.RESULTS.nonfinite,
            optx.RESULTS.where(diverging, optx.RESULTS.nonlinear_divergence,
                               optx.RESULTS.successful))
        return state.converged | state.nonfinite | diverging, result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        del fn, args, options, state, tags, result
        return y, aux, {}


def _residual(y, args):
    problem, omega = args
    return _hb.residual(problem, y, omega)


def _jacobian(y, args):
    problem, omega = args
    return HBJacobian(problem, y, omega)


def _iterate(problem: _hb.HBProblem, omega, y0: Array, chord: bool) -> _hb.HBSolution:
    """``optimistix.root_find`` with :class:`FactorisedNewton` on the scaled residual."""
    settings = problem.settings
    solver = FactorisedNewton(rtol=settings.rtol, operator=_jacobian, chord=chord,
                              linear_solver=_krylov.linear_solver(problem))
    sol = optx.root_find(_residual, solver, y0, (problem, omega), max_steps=settings.max_steps,
                         throw=False)
    y = sol.value
    norm = jnp.max(jnp.abs(_hb.residual(problem, y, omega)))
    return _hb.HBSolution(X=y.reshape(problem.shape) * problem.x_scale, y=y, omega=omega,
                          result=RESULTS.promote(sol.result),
                          stats={"num_steps": sol.stats["num_steps"], "residual_norm": norm})


def newton(problem: _hb.HBProblem, omega, y0: Array) -> _hb.HBSolution:
    """Newton's method on the scaled residual at fixed ``omega`` (rad/s) from ``y0``
    ``(N,)`` (jit-compatible).

    Stops when the scaled step and residual are below ``problem.settings.rtol``
    (``RESULTS.successful``), after ``settings.max_steps``
    (``nonlinear_max_steps_reached``), after :data:`PATIENCE` steps without a new lowest
    residual (``nonlinear_divergence``), or on a non-finite value, keeping the last
    finite iterate (``nonfinite``): never NaN silently. Each
    step solves with the Jacobian at the iterate by the solver of
    ``problem.settings.linear_solver`` (:func:`gearjax._engine.krylov.linear_solver`): the
    condensed factorisation (:class:`~gearjax._engine.linear_solver.CondensedLU`) or
    preconditioned BiCGStab on Jacobian-vector products
    (:class:`~gearjax._engine.krylov.KrylovHB`).
    """
    return _iterate(problem, jnp.asarray(omega, dtype=float), y0, chord=False)


_newton_compiled = kept_program(newton)


def newton_jit(problem: _hb.HBProblem, omega, y0: Array) -> _hb.HBSolution:
    """:func:`newton`, compiled (one cache of programs for every caller): ``omega`` and
    ``y0`` are passed on as float64 arrays of fixed (strong) type, so that a Python
    float and a NumPy float do not compile two programs."""
    return _newton_compiled(problem, jnp.asarray(omega, dtype=jnp.float64),
                            jnp.asarray(y0, dtype=jnp.float64))


def solve_linear(problem: _hb.HBProblem, omega, y0: Array | None = None) -> _hb.HBSolution:
    """The periodic solution of a system without backlash (jit-compatible).

    With zero backlash every mesh force is linear in its deflection, however its
    stiffness varies in time, so the residual is affine in ``y`` and its Jacobian the
    same everywhere: it is factorised (matrix-free: its slopes and preconditioner kept) once (at
    ``y0``, default :func:`~gearjax._engine.hb.linear_guess`) and every step is a solve
    with it (the chord method). The first step is exact up to round-off; the next ones
    refine it and apply :func:`newton`'s test and results. The caller guarantees
    zero backlash (with backlash this is a chord iteration from ``y0``).
    """
    omega = jnp.asarray(omega, dtype=float)
    y0 = _hb.linear_guess(problem, omega) if y0 is None else y0
    return _iterate(problem, omega, y0, chord=True)


def solve_hb(problem: _hb.HBProblem, omega, y0: Array | None = None) -> _hb.HBSolution:
    """The periodic solution at base frequency ``omega`` (rad/s), by :func:`newton` from
    ``y0`` ``(N,)`` or :func:`~gearjax._engine.hb.linear_guess`."""
    y0 = _hb.linear_guess(problem, omega) if y0 is None else y0
    return newton(problem, omega, y0)
