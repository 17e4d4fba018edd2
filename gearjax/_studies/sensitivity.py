"""Sensitivities of harmonic-balance responses to train parameters, by implicit differentiation.

At a converged harmonic-balance point the scaled residual ``res(y, p) = 0`` (``_hb``)
defines the solution ``y(p)`` implicitly. For a response ``R(p) = r(y(p), p)`` (the RMS,
peak or load factor of one mesh) the implicit function theorem gives

    dR/dp = dr/dp - lambda^T dres/dp,    J^T lambda = dr/dy,    J = dres/dy,

with ``J`` the structured Jacobian of :func:`gearjax._engine.hb.jacobian`
(:func:`gearjax._engine.adjoint.implicit_coefficients`, the engine's one implicit
derivative). One adjoint solve per response and one reverse pass of the residual
through ``assemble`` and ``hb_problem`` give the derivative with respect to every
parameter at once; the Newton iterations are never differentiated.

Parameters are TOML paths (``_paths``): ``1.mesh_stiffness.sun``, ``2.planet_mass``,
``1.planet_angles_deg.2``, ``gears.first.input_torque``, ... A derivative is per unit
of the file's value, so a path in degrees gets a derivative per degree.

Where the derivative is refused:

- the point did not converge;
- the point is at or near a fold: there ``J`` is singular and ``dy/dp`` unbounded. The
  test is a Floquet multiplier within ``fold_tol`` (default :data:`FOLD_TOL`) of +1
  (:func:`point_status` says why not the singular values of ``J``);
- the periodic solution is unstable (Floquet multipliers, :func:`gearjax.stability`):
  it is not the response a gearbox shows.

Backlash makes the mesh force piecewise linear. The harmonic balance samples it on
its time grid, so the discrete residual is piecewise smooth in ``y`` and ``p`` with
kinks only where a sample crosses a clearance edge ``|p| = b``: the derivative is that
of the solver's own response, exact where contact is kept and well defined wherever
no sample sits on an edge. ``max_force`` is the largest sample, so its derivative is
that of the force at the sample where the peak is.

Band responses over a frequency grid ``f_1 < ... < f_n`` (Hz):

- ``peak``: the smooth maximum ``R = tau log sum_i exp(r_i / tau)`` with temperature
  ``tau = temperature * max_i r_i`` at the nominal parameters, held constant
  (``max r <= R <= max r + tau log n``; the default ``temperature`` 0.01 puts the
  bound at 1% of the peak times ``log n``);
- ``integral``: the trapezoid rule ``R = sum_i (r_i + r_{i+1}) (f_{i+1} - f_i) / 2``
  (response units times Hz).

Points of the band that are refused are left out of both (listed with the reason);
when the largest response of the converged points is at a refused point the band's
peak is not differentiable and ``peak`` is refused with a message naming it.

Why this module is long: the point and band studies share one gear preparation, one
refusal rule and one JSON contract (the ``sensitivity`` command's); the implicit
derivative itself is the engine's (:mod:`gearjax._engine.adjoint`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._engine import hb as _hb
from .._engine.adjoint import implicit_coefficients
from .._engine.newton import newton
from .._engine.responses import mesh_responses, static_mesh_forces
from .._engine.verdict import stability
from .._engine.system import System
from .._errors import bad_argument
from .._gear.assembly import assemble
from .._gear.case import gear_case
from .._gear.paths import Leaf, continuous_paths, leaf_selector, set_leaf
from .._gear.train import Train
from . import harmonics as _harmonics
from .sweep import backlash_start

FOLD_TOL = 0.05
"""Smallest distance ``min |mu - 1|`` of the Floquet multipliers ``mu`` from +1 accepted
(closer: the point is at or near a fold; :func:`point_status`)."""

RESPONSES = {"rms": "rms_force", "max": "max_force", "dlf": "dlf"}
"""Response names (argument ``response``) and the :class:`~gearjax.MeshResponses` field of
each."""

RESPONSE_UNITS = {"rms": "N", "max": "N", "dlf": "1"}

BAND_OBJECTIVES = ("peak", "integral")


# ------------------------------------------------------------------ parametric maps


class GearFamily(eqx.Module):
    """``theta -> System``: gear ``gear`` of ``train`` with the TOML ``paths`` set to
    ``theta`` (values in the file's units), assembled; ``backlash_scale`` multiplies
    every backlash (0: the linear system, where a backlash path has exactly no
    effect).

    Pure in ``theta``, so ``jit`` and ``grad`` pass through (``assemble`` is). The
    paths are static strings and the linear switch an array, so families of the same
    train, gear and paths share compiled code.
    """

    train: Train
    paths: tuple[str, ...] = eqx.field(static=True)
    gear: str = eqx.field(static=True)
    backlash_scale: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.0)

    @classmethod
    def of(cls, train: Train, paths: Sequence[str], gear: str, linear: bool = False
           ) -> "GearFamily":
        return cls(train=train, paths=tuple(paths), gear=gear,
                   backlash_scale=jnp.asarray(0.0 if linear else 1.0))

    @property
    def leaves(self) -> tuple[Leaf, ...]:
        return tuple(leaf_selector(self.train, p, "paths") for p in self.paths)

    def train_at(self, theta: Float[Array, " p"]) -> Train:
        train = self.train
        for k, leaf in enumerate(self.leaves):
            train = set_leaf(train, leaf, theta[k])
        return train

    def theta(self) -> Float[Array, " p"]:
        """The parameter values of ``train``, shape ``(p,)``."""
        vals = []
        for leaf in self.leaves:
            v = jnp.asarray(leaf.where(self.train), dtype=float)
            vals.append(v if leaf.index is None else v[leaf.index])
        return jnp.stack(vals) if vals else jnp.zeros(0)

    def __call__(self, theta: Float[Array, " p"]) -> System:
        system = assemble(self.train_at(theta), self.gear)
        return dataclasses.replace(system, backlash=system.backlash * self.backlash_scale)


class MeshResponse(eqx.Module):
    """``(problem, X, omega) -> r``: one :class:`~gearjax.MeshResponses` field of one mesh.

    ``field``: ``rms_force``, ``max_force``, ``dlf``, ... ; ``mesh``: the mesh's index.
    The static forces of ``dlf`` are recomputed from ``problem.system`` so they follow
    the parameters.
    """

    field: str = eqx.field(static=True)
    mesh: int = eqx.field(static=True)

    def __call__(self, problem: _hb.HBProblem, X: Array, omega) -> Array:
        F_static = static_mesh_forces(problem.system)
        return getattr(mesh_responses(problem, X, omega, F_static), self.field)[self.mesh]


# ------------------------------------------------------------------------- core

class PointGradient(eqx.Module):
    """A response and its implicit derivative at one converged point.

    **Fields:** ``value``: the response ``R``; ``gradient`` ``(p,)``: ``dR/dtheta``;
    ``partial`` ``(p,)``: the explicit part ``dr/dtheta`` at fixed solution.
    """

    value: Array
    gradient: Array
    partial: Array


@eqx.filter_jit
def implicit_gradient(family, theta: Float[Array, " p"], settings: _hb.HarmonicBalance,
                      y: Float[Array, " N"], omega, response) -> PointGradient:
    """``dR/dtheta`` of ``R = response(problem(theta), X(theta), omega)`` at a converged
    point, by the implicit function theorem (module docstring).

    **Arguments:** ``family``: ``theta -> System`` (e.g. :class:`GearFamily`, or any
    ``equinox.Module`` with ``__call__``); ``theta`` ``(p,)``: the nominal parameters;
    ``settings``: the harmonic balance ``y`` was solved with; ``y`` ``(N,)``: scaled
    unknowns converged at ``theta`` (``HBSolution.y`` of ``hb_problem(family(theta),
    settings)``); ``omega``: base frequency (rad/s); ``response``: ``(problem, X, omega)
    -> scalar`` (e.g. :class:`MeshResponse`), ``X`` ``(2K+1, n)`` physical coefficients.

    **Returns:** :class:`PointGradient`. Whether the point may be differentiated (not at
    or near a fold, stable) is the caller's test: :func:`point_status`,
    :func:`check_point`.
    """
    theta = jnp.asarray(theta, dtype=float)
    omega = jnp.asarray(omega, dtype=float)

    def responses(th):  # along the solution y(theta), and at the fixed solution
        problem = _hb.hb_problem(family(th), settings)
        X_fixed = y.reshape(problem.shape) * jax.lax.stop_gradient(problem.x_scale)
        X = implicit_coefficients(problem, y, omega)
        return response(problem, X, omega), response(problem, X_fixed, omega)

    (_, value), pullback = jax.vjp(responses, theta)
    one, zero = jnp.ones_like(value), jnp.zeros_like(value)
    (gradient,), (partial,) = pullback((one, zero)), pullback((zero, one))
    return PointGradient(value=value, gradient=gradient, partial=partial)


@eqx.filter_jit
def solve_at(family, theta: Float[Array, " p"], settings: _hb.HarmonicBalance, omega,
             X0: Array | None = None) -> _hb.HBSolution:
    """Newton at ``omega`` (rad/s) for the system ``family(theta)``, from the physical
    coefficients ``X0`` ``(2K+1, n)`` or, when ``None``, the linear in-contact guess."""
    problem = _hb.hb_problem(family(theta), settings)
    y0 = _hb.linear_guess(problem, omega) if X0 is None else (X0 / problem.x_scale).reshape(-1)
    return newton(problem, omega, y0)


def response_at(family, theta, settings: _hb.HarmonicBalance, omega, response,
                X0: Array | None = None) -> tuple[float, int]:
    """``(R, result code)`` by re-solving at ``theta`` (Newton from ``X0``): the
    finite-difference reference for :func:`implicit_gradient`."""
    theta = jnp.asarray(theta, dtype=float)
    sol = solve_at(family, theta, settings, jnp.asarray(omega, dtype=float), X0)
    value = _response_jit(family, theta, settings, sol.X, jnp.asarray(omega, dtype=float),
                          response)
    return float(value), int(sol.result)


@eqx.filter_jit
def _response_jit(family, theta, settings, X, omega, response):
    return response(_hb.hb_problem(family(theta), settings), X, omega)


# ------------------------------------------------------------------------ refusal


class SensitivityRefused(ValueError):
    """A point that has no derivative: ``result`` is ``fold`` or ``unstable``; the
    message names the point and the reason."""

    def __init__(self, result: str, message: str):
        super().__init__(message)
        self.result = result


@eqx.filter_jit
def point_status(problem: _hb.HBProblem, X: Array, omega) -> tuple[Array, Array]:
    """``(stable, fold_distance)`` of the solution ``X`` ``(2K+1, n)`` at ``omega`` (rad/s).

    ``stable``: :func:`gearjax.stability`; ``fold_distance``: ``min |mu - 1|`` over its
    Floquet multipliers ``mu`` (those of mesh-free rigid-body modes excluded). A fold
    (saddle-node) of the periodic solution is where a real multiplier passes through +1:
    there ``dres/dy`` is singular and ``dy/dp`` unbounded.

    Why the multipliers and not the singular values of the HB Jacobian: the sampled
    (AFT) backlash force makes the discrete residual piecewise smooth, so at a fold the
    Jacobian jumps across the singularity instead of passing through it; soft housing
    springs give near-rigid-body singular values at every point; and near a sharp linear
    resonance the branch tangent is as steep as near a fold. The multipliers, from exact
    contact intervals, have none of these faults.
    """
    s = stability(problem, X, omega)
    return s.stable, jnp.min(jnp.where(s.excluded, jnp.inf, jnp.abs(s.multipliers - 1.0)))


def check_point(stable, fold_distance, where: str, fold_tol: float = FOLD_TOL) -> None:
    """Raise :class:`SensitivityRefused` when the point ``where`` (e.g. ``"3000 Hz"``) is
    at or near a fold (``fold_distance < fold_tol``) or unstable."""
    d = float(fold_distance)
    if not d >= fold_tol:
        raise SensitivityRefused("fold", (
            f"the point at {where} is at or near a fold of the response curve (a Floquet "
            f"multiplier lies {d:.2g} from +1, closer than {fold_tol:g}): the response jumps "
            "there and is not a differentiable function of the parameters; choose a "
            "frequency away from the fold"))
    if not bool(stable):
        raise SensitivityRefused("unstable", (
            f"the periodic solution at {where} is unstable (a Floquet multiplier lies outside "
            "the unit circle): its derivatives describe no response the train shows"))


# ----------------------------------------------------------------- gear-level API


@dataclasses.dataclass(frozen=True)
class Sensitivity:
    """Derivatives of one response of one mesh at one frequency.

    **Fields:**

    - ``gear``, ``reference_stage``, ``mesh_frequency_hz`` (reference stage, Hz),
      ``omega`` (base, rad/s), ``harmonics`` (K), ``linear``;
    - ``response`` (``rms`` | ``max`` | ``dlf``), ``unit``, ``mesh`` (name such as
      ``1.sp1``), ``value``: the response there (NaN when not converged);
    - ``result``: ``ok``, ``not_converged``, ``fold`` or ``unstable``; ``message``:
      why a point was refused (``None`` when ok); ``converged``, ``stable``,
      ``fold_distance`` (:func:`point_status`), ``fold_tol``;
    - ``paths``: the TOML paths; ``values``: their values (file units);
      ``derivative``: ``dR/dp`` per unit of each path (``None`` when refused);
      ``normalised``: ``(p / R) dR/dp`` (NaN where ``p`` or ``R`` is 0);
      ``partial``: the explicit part ``dr/dp`` at fixed solution;
    - ``meshes``: every mesh name; ``mesh_values``: the response of every mesh.
    """

    gear: str
    reference_stage: str
    mesh_frequency_hz: float
    omega: float
    harmonics: int
    linear: bool
    response: str
    unit: str
    mesh: str
    value: float
    result: str
    message: str | None
    converged: bool
    stable: bool | None
    fold_distance: float | None
    fold_tol: float
    paths: tuple[str, ...]
    values: np.ndarray
    derivative: np.ndarray | None
    normalised: np.ndarray | None
    partial: np.ndarray | None
    meshes: tuple[str, ...]
    mesh_values: np.ndarray

    @property
    def ok(self) -> bool:
        return self.result == "ok"

    def ranking(self) -> list[int]:
        """Indices of ``paths`` by decreasing ``|normalised|`` (undefined ones last, by
        decreasing ``|derivative|``)."""
        if self.derivative is None:
            return list(range(len(self.paths)))
        norm = np.abs(self.normalised)
        key = [(0, -norm[k]) if np.isfinite(norm[k]) else (1, -abs(self.derivative[k]))
               for k in range(len(self.paths))]
        return sorted(range(len(self.paths)), key=lambda k: key[k])


class _GearPoint:
    """A gear prepared at fixed harmonics: family, nominal parameters, reference stage."""

    def __init__(self, train: Train, gear, paths, stage, linear, harmonics, f_hz):
        case = gear_case(train, gear, stage, linear)
        self.ref, self.mu_ref = case.stage, case.mu_ref
        self.gear, self.train, self.linear = case.gear.name, train, linear
        self.paths = tuple(leaf.path for leaf in check_paths(train, paths, gear=self.gear,
                                                              linear=linear))
        if harmonics is not None and (int(harmonics) != harmonics or harmonics < 1):
            raise bad_argument("harmonics", harmonics, "must be an integer >= 1")
        self.family = GearFamily.of(train, self.paths, self.gear, linear)
        self.theta = self.family.theta()
        f = np.atleast_1d(np.asarray(f_hz, dtype=float))
        if harmonics is None:
            harmonics = _harmonics.harmonics_rule(
                float(f.min()) / self.mu_ref, _harmonics.excitation_floor(case.system),
                cutoff_hz=_harmonics.response_cutoff_hz(case.system))
        else:
            _harmonics.require_harmonics(case.system, harmonics)
        _harmonics.require_size(case.system, int(harmonics), mu=case.mu)
        self.settings = _hb.HarmonicBalance(n_harmonics=int(harmonics))
        self.problem = _problem_jit(self.family, self.theta, self.settings)
        self.system = self.problem.system
        self.has_backlash = self.system.has_backlash

    def omega(self, f_hz: float) -> float:
        return 2 * math.pi * float(f_hz) / self.mu_ref

    def solve(self, f_hz: float, X0=None) -> _hb.HBSolution:
        """Newton from ``X0`` (or the linear guess); with backlash, when Newton from the
        linear guess fails, :func:`~gearjax._studies.sweep.backlash_start` (as the sweep
        starts a branch)."""
        w = jnp.asarray(self.omega(f_hz))
        sol = solve_at(self.family, self.theta, self.settings, w, X0)
        if int(sol.result) != _hb.CONVERGED and X0 is not None:
            sol = solve_at(self.family, self.theta, self.settings, w, None)
        if int(sol.result) != _hb.CONVERGED and self.has_backlash:
            sol = backlash_start(self.problem, w)
        return sol

    def differentiate(self, sol, f_hz, response, fold_tol):
        """``(PointGradient, stable, fold_distance)`` at a converged ``sol``; the caller
        decides with :func:`check_point`."""
        omega = jnp.asarray(self.omega(f_hz))
        pg = implicit_gradient(self.family, self.theta, self.settings, sol.y, omega, response)
        stable, distance = point_status(self.problem, sol.X, omega)
        return pg, bool(stable), float(distance)


@eqx.filter_jit
def _problem_jit(family, theta, settings):
    return _hb.hb_problem(family(theta), settings)


@eqx.filter_jit
def _responses_jit(problem, X, omega):
    return mesh_responses(problem, X, omega, static_mesh_forces(problem.system))


def check_paths(train: Train, paths: Sequence[str] | None, argument: str = "paths", *,
                gear: str | None = None, linear: bool = False) -> tuple[Leaf, ...]:
    """Resolve ``paths``, each once; ``None``: :func:`~gearjax.continuous_paths` of
    ``gear`` (the paths that change that gear's system; ``linear``: no backlash).

    **Raises:** ``ArgumentError`` naming ``argument`` (the caller's name for ``paths``)
    for no path, a bad path or one given twice."""
    paths = continuous_paths(train, gear, linear=linear) if paths is None else (
        (paths,) if isinstance(paths, str) else tuple(paths))
    if not paths:
        raise bad_argument(argument, [], "at least one parameter path is required")
    leaves = tuple(leaf_selector(train, p, argument) for p in paths)
    seen: dict[str, str] = {}
    for p, leaf in zip(paths, leaves):
        if leaf.path in seen:
            same = "" if seen[leaf.path] == p else f" (as {seen[leaf.path]!r})"
            raise bad_argument(argument, p,
                               f"the parameter is given twice{same}; name each parameter once")
        seen[leaf.path] = p
    return leaves


def _check_response(response: str) -> str:
    if response not in RESPONSES:
        raise bad_argument("response", response, f"must be one of {', '.join(RESPONSES)}")
    return RESPONSES[response]


def _mesh_index(system: System, mesh: str) -> int:
    names = list(system.mesh_labels)
    if mesh not in names:
        raise bad_argument("mesh", mesh, f"no such mesh; meshes are {', '.join(names)}")
    return names.index(mesh)


def sensitivity(
    train: Train,
    gear: str | None = None,
    at_hz: float = 3000.0,
    *,
    response: str = "rms",
    mesh: str | None = None,
    paths: Sequence[str] | None = None,
    stage: str | None = None,
    linear: bool = False,
    harmonics: int | None = None,
    fold_tol: float = FOLD_TOL,
) -> Sensitivity:
    """Derivatives of a mesh response at one frequency with respect to train parameters.

    **Arguments:** ``at_hz``: reference-stage mesh frequency (Hz), as in ``sweep``;
    ``response``: ``rms`` (RMS alternating force, N), ``max`` (peak ``|F|``, N) or
    ``dlf`` (dynamic load factor); ``mesh``: mesh name (``1.sp1``; default: the mesh
    with the largest response); ``paths``: TOML paths (default: every continuous path
    that changes the gear's system, :func:`~gearjax.continuous_paths` of the gear);
    ``stage``, ``linear``: as ``sweep``;
    ``harmonics``: K (default: the sweep's rule at ``at_hz``); ``fold_tol``: the fold
    test on ``min |mu - 1|`` (:func:`point_status`, :data:`FOLD_TOL`).

    The point is solved from the linear in-contact guess (with backlash, if Newton fails,
    from the orbit a time integration settles to, else by the backlash homotopy), so with
    coexisting solutions it is the one a sweep starting at ``at_hz`` would start on.

    **Returns:** :class:`Sensitivity`; a refused point has ``result`` ``not_converged``,
    ``fold`` or ``unstable``, a ``message`` naming the frequency, and no derivative.

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming the argument for bad
    ``paths``, ``response``, ``mesh``, ``at_hz`` or ``harmonics``; ``TrainError`` as
    :func:`~gearjax._gear.case.gear_case` for the gear and stage.
    """
    field = _check_response(response)
    if not (isinstance(at_hz, int | float) and at_hz > 0 and math.isfinite(at_hz)):
        raise bad_argument("at_hz", at_hz, "must be a positive mesh frequency in Hz")
    gp = _GearPoint(train, gear, paths, stage, linear, harmonics, at_hz)
    j = None if mesh is None else _mesh_index(gp.system, mesh)
    sol = gp.solve(at_hz)
    omega = gp.omega(at_hz)
    converged = int(sol.result) == _hb.CONVERGED
    values = np.asarray(getattr(_responses_jit(gp.problem, sol.X, jnp.asarray(omega)), field))
    if not converged:
        values = np.full_like(values, np.nan)
    if j is None:
        j = int(np.nanargmax(values)) if np.any(np.isfinite(values)) else 0
    common = dict(gear=gp.gear, reference_stage=gp.ref, mesh_frequency_hz=float(at_hz),
                  omega=omega, harmonics=gp.settings.n_harmonics, linear=linear,
                  response=response, unit=RESPONSE_UNITS[response], fold_tol=fold_tol,
                  mesh=gp.system.mesh_labels[j], value=float(values[j]), converged=converged,
                  paths=gp.paths, values=np.asarray(gp.theta),
                  meshes=tuple(gp.system.mesh_labels), mesh_values=values)
    refused = dict(derivative=None, normalised=None, partial=None)
    if not converged:
        return Sensitivity(**common, **refused, result="not_converged", stable=None,
                           fold_distance=None,
                           message=f"the harmonic balance did not converge at {at_hz:g} Hz "
                                   f"({_hb.RESULTS[int(sol.result)]}): no derivative")
    pg, stable, distance = gp.differentiate(sol, at_hz, MeshResponse(field=field, mesh=j),
                                            fold_tol)
    status = dict(stable=stable, fold_distance=distance)
    try:
        check_point(stable, distance, f"{at_hz:g} Hz", fold_tol)
    except SensitivityRefused as e:
        return Sensitivity(**common, **refused, **status, result=e.result, message=str(e))
    d = np.asarray(pg.gradient)
    return Sensitivity(**common, **status, result="ok", message=None, derivative=d,
                       normalised=normalise(d, np.asarray(gp.theta), float(pg.value)),
                       partial=np.asarray(pg.partial))


def normalise(derivative: np.ndarray, values: np.ndarray, response: float) -> np.ndarray:
    """``(p / R) dR/dp``; NaN where ``p == 0`` or ``R == 0`` (no relative change)."""
    ok = (values != 0) & (response != 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, derivative * values / (response if response != 0 else 1.0), np.nan)


# -------------------------------------------------------------------------- bands


@dataclasses.dataclass(frozen=True)
class BandSensitivity:
    """A band response and its derivatives.

    **Fields:** ``objective`` (``peak`` | ``integral``), ``temperature`` (``peak``: tau
    relative to the largest response), ``tau`` (absolute, response units); ``value``;
    ``paths``, ``values``, ``derivative``, ``normalised`` as :class:`Sensitivity`;
    ``frequencies_hz``, ``point_values`` ``(n,)`` (NaN where refused),
    ``point_gradients`` ``(n, p)`` (NaN rows where refused), ``weights`` ``(n,)``:
    ``dR/dr_i``; ``excluded``: ``{frequency_hz: reason}`` of the refused points;
    ``mesh``, ``response``, ``harmonics``.
    """

    objective: str
    temperature: float | None
    tau: float | None
    value: float
    paths: tuple[str, ...]
    values: np.ndarray
    derivative: np.ndarray
    normalised: np.ndarray
    frequencies_hz: np.ndarray
    point_values: np.ndarray
    point_gradients: np.ndarray
    weights: np.ndarray
    excluded: dict
    mesh: str
    response: str
    harmonics: int


def band_sensitivity(
    train: Train,
    gear: str | None = None,
    frequencies_hz: Sequence[float] = (),
    *,
    mesh: str,
    objective: str = "peak",
    response: str = "rms",
    paths: Sequence[str] | None = None,
    stage: str | None = None,
    linear: bool = False,
    harmonics: int | None = None,
    temperature: float = 0.01,
    fold_tol: float = FOLD_TOL,
) -> BandSensitivity:
    """Derivatives of the smooth peak or the integral of a mesh response over a band.

    **Arguments:** ``frequencies_hz``: ascending reference-stage mesh frequencies (Hz),
    at least 2; each point is solved from the previous converged one (the branch is
    followed upwards), else as :func:`sensitivity` starts; ``mesh``: the mesh name;
    ``objective``: ``peak`` (log-sum-exp, temperature ``temperature`` relative to the
    largest response) or ``integral`` (trapezoid, response times Hz); ``harmonics``: one
    K for the band (default: the sweep's rule at the lowest frequency, the largest it
    gives in the band); the rest as :func:`sensitivity`.

    **Returns:** :class:`BandSensitivity`. **Raises:** ``ArgumentError`` naming the
    argument for bad input, and naming ``frequencies_hz`` when fewer than two points are
    left or (``peak``) when the largest response of the converged points is at a refused
    point (a fold is typically where a backlash response peaks: it jumps there and has no
    derivative).
    """
    field = _check_response(response)
    if objective not in BAND_OBJECTIVES:
        raise bad_argument("objective", objective, f"must be one of {', '.join(BAND_OBJECTIVES)}")
    f = np.asarray(frequencies_hz, dtype=float)
    if f.ndim != 1 or f.size < 2 or not np.all(np.isfinite(f)) or np.any(f <= 0) or np.any(
            np.diff(f) <= 0):
        raise bad_argument("frequencies_hz", f.tolist(),
                           "needs at least 2 positive, strictly ascending frequencies in Hz")
    if not (temperature > 0 and math.isfinite(temperature)):
        raise bad_argument("temperature", temperature, "must be a number > 0")
    gp = _GearPoint(train, gear, paths, stage, linear, harmonics, f)
    j = _mesh_index(gp.system, mesh)
    resp = MeshResponse(field=field, mesh=j)
    n, p = f.size, len(gp.paths)
    vals, grads = np.full(n, np.nan), np.full((n, p), np.nan)
    raw = np.full(n, np.nan)  # every converged response, refused or not
    excluded: dict[float, str] = {}
    X_prev = None
    for i, fi in enumerate(f):
        sol = gp.solve(fi, X_prev)
        if int(sol.result) != _hb.CONVERGED:
            excluded[float(fi)] = f"not converged ({_hb.RESULTS[int(sol.result)]})"
            continue
        X_prev = sol.X
        pg, stable, distance = gp.differentiate(sol, fi, resp, fold_tol)
        raw[i] = float(pg.value)
        try:
            check_point(stable, distance, f"{fi:g} Hz", fold_tol)
        except SensitivityRefused as e:
            excluded[float(fi)] = str(e)
            continue
        vals[i], grads[i] = raw[i], np.asarray(pg.gradient)
    keep = np.isfinite(vals)
    if keep.sum() < 2:
        raise bad_argument("frequencies_hz", f.tolist(),
                           f"fewer than 2 points could be differentiated: {excluded}")
    tau = None
    w = np.zeros(n)
    if objective == "peak":
        top = int(np.nanargmax(raw))
        if not keep[top]:
            raise bad_argument(
                "frequencies_hz", f.tolist(),
                f"the band's largest {response} of mesh {mesh} is at {f[top]:g} Hz, which is "
                f"excluded ({excluded[float(f[top])]}); the band peak is not differentiable: "
                "choose a band whose peak is not at a fold")
        tau = temperature * float(np.max(vals[keep]))
        z = vals[keep] / tau
        e = np.exp(z - np.max(z))
        value = tau * (np.max(z) + math.log(float(np.sum(e))))
        w[keep] = e / np.sum(e)
    else:
        fk = f[keep]
        dw = np.zeros(fk.size)
        dw[:-1] += np.diff(fk) / 2
        dw[1:] += np.diff(fk) / 2
        w[keep] = dw
        value = float(np.sum(dw * vals[keep]))
    d = np.sum(w[keep, None] * grads[keep], axis=0)
    return BandSensitivity(
        objective=objective, temperature=temperature if objective == "peak" else None, tau=tau,
        value=float(value), paths=gp.paths, values=np.asarray(gp.theta), derivative=d,
        normalised=normalise(d, np.asarray(gp.theta), float(value)), frequencies_hz=f,
        point_values=vals, point_gradients=grads, weights=w, excluded=excluded,
        mesh=mesh, response=response, harmonics=gp.settings.n_harmonics)


# --------------------------------------------------------------------------- units


def path_unit(path: str) -> str:
    """The file unit of a TOML path's value (``deg`` for angles)."""
    parts = path.split(".")
    key = parts[1] if len(parts) > 1 else ""
    if parts[0] == "gears":
        return "N m"
    if parts[0] in ("housing", "couplings"):
        return "N m/rad"
    return {"module_mm": "mm", "carrier_radius_mm": "mm", "pressure_angle_deg": "deg",
            "sun_ring_phase_deg": "deg", "stage_phase_deg": "deg", "planet_angles_deg": "deg",
            "mesh_stiffness": "N/m", "half_backlash": "m", "inertia": "kg m^2",
            "planet_mass": "kg"}.get(key, "1")


def sensitivity_json(result: Sensitivity, top: int | None = None) -> dict:
    """The ``sensitivity`` JSON: point fields and ``derivatives``, ranked by
    ``|normalised|`` (each ``{path, value, unit, derivative, derivative_unit,
    normalised}``; ``reason`` where ``normalised`` is null)."""
    out = {
        "gear": result.gear,
        "reference_stage": result.reference_stage,
        "mesh_frequency_hz": result.mesh_frequency_hz,
        "omega": result.omega,
        "harmonics": result.harmonics,
        "linear": result.linear,
        "response": result.response,
        "unit": result.unit,
        "mesh": result.mesh,
        "value": result.value,
        "result": result.result,
        "converged": result.converged,
        "stable": result.stable,
        "fold_distance": result.fold_distance,
        "fold_tol": result.fold_tol,
        "reason": result.message,
        "mesh_values": {m: float(v) for m, v in zip(result.meshes, result.mesh_values)},
        "derivatives": [],
    }
    if result.derivative is None:
        out["derivatives"] = None
        return out
    rows = []
    for k in result.ranking()[:top]:
        path = result.paths[k]
        unit = path_unit(path)
        row = {"path": path, "value": float(result.values[k]), "unit": unit,
               "derivative": float(result.derivative[k]),
               "derivative_unit": f"{result.unit} per {unit}",
               "normalised": float(result.normalised[k])}
        if not np.isfinite(result.normalised[k]):
            row["normalised"] = None
            row["reason"] = ("the parameter is 0: no relative change (use the derivative)"
                             if result.values[k] == 0 else "the response is 0")
        rows.append(row)
    out["derivatives"] = rows
    return out
