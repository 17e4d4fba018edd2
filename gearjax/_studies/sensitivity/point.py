"""The sensitivity study at one frequency: the gear prepared once (:class:`GearPoint`),
the point solved as a sweep would start it, and its derivatives or the reason it has
none (:class:`Sensitivity`).

The derivative itself and the rule that refuses it are :mod:`.implicit`'s; the
parameters and responses :mod:`.family`'s.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..._engine import hb as _hb
from ..._engine.responses import mesh_responses, static_mesh_forces
from ..._engine.results import RESULTS, result_word
from ..._engine.system import System
from ..._errors import bad_argument
from ..._gear.case import gear_case, torus_fields
from ..._gear.train import Train
from .. import harmonics as _harmonics
from ..sweep import backlash_start
from ..point_truncation import checked_orders
from .family import RESPONSE_UNITS, GearFamily, MeshResponse, check_paths, response_field
from .implicit import (FOLD_TOL, SensitivityRefused, check_point, implicit_gradient,
                       point_status, slow_mode, solve_at)
from .steps import parameter_steps, relative_change


@dataclasses.dataclass(frozen=True)
class Sensitivity:
    """Derivatives of one response of one mesh at one frequency.

    **Fields:**

    - ``gear``, ``reference_stage``, ``mesh_frequency_hz`` (reference stage, Hz),
      ``omega`` (base, rad/s; on a torus the base of angle 0), ``harmonics`` (K: an
      ``int``, or on a torus the orders per angle, a tuple), ``linear``;
    - ``response`` (``rms`` | ``max`` | ``dlf``), ``unit``, ``mesh`` (name such as
      ``1.sp1``), ``value``: the response there (NaN when not converged);
    - ``result``: ``ok``, ``not_converged``, ``fold``, ``lightly_damped_mode`` (a linear
      point's multiplier near +1, :func:`~gearjax._studies.sensitivity.check_point`) or
      ``unstable``; ``message``:
      why a point was refused (``None`` when ok); ``converged``, ``stable``,
      ``fold_distance`` (:func:`point_status`), ``fold_tol``;
    - ``paths``: the TOML paths; ``values``: their values (file units);
      ``derivative``: ``dR/dp`` per unit of each path (``None`` when refused; a planet
      angle's or a phase's per degree);
      ``normalised``: ``(p / R) dR/dp`` (NaN where ``p`` or ``R`` is 0, and for an angle
      whose origin is a convention: planet angles and phases, whose relative change
      means nothing); ``partial``: the explicit part ``dr/dp`` at fixed solution;
    - ``meshes``: every mesh name; ``mesh_values``: the response of every mesh;
    - ``torus``: what a torus study solves (:func:`~gearjax._gear.case.torus_fields`:
      ``G``, angle ratios, truncation, near return); ``None`` for a periodic gear;
    - ``steps``: the step ``s`` of each path that ranks it (file units,
      :func:`~gearjax._studies.sensitivity.steps.parameter_steps`: its value, one
      assembly slot of a planet angle, one mesh cycle of a phase); ``step_rules``:
      ``None`` where ``s`` is the value, else the rule in words; ``relative``: ``(s /
      R) dR/dp``, what :meth:`ranking` ranks (``None`` when refused);
    - ``mode``: where a linear point is refused next to a lightly damped mode, that mode
      (:func:`~gearjax._studies.sensitivity.implicit.slow_mode`), else ``None``;
    - ``truncation``: the a posteriori truncation checks of the point
      (:func:`~gearjax._studies.point_truncation.checked_orders`: ``K``, ``K_check``,
      ``change``), ``harmonics`` the orders they kept.
    """

    gear: str
    reference_stage: str
    mesh_frequency_hz: float
    omega: float
    harmonics: int | tuple[int, ...]
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
    torus: dict | None = None
    steps: np.ndarray | None = None
    step_rules: tuple[str | None, ...] = ()
    relative: np.ndarray | None = None
    mode: dict | None = None
    truncation: tuple[dict, ...] = ()

    @property
    def ok(self) -> bool:
        return self.result == "ok"

    def ranking(self) -> list[int]:
        """Indices of ``paths`` by decreasing ``|relative|``, ``(s / R) dR/dp`` with each
        path's step ``s`` (:data:`~gearjax._studies.sensitivity.steps.RANKING_RULE`;
        independent of any angle's origin), undefined ones last, by decreasing
        ``|derivative|``."""
        if self.derivative is None:
            return list(range(len(self.paths)))
        rel = np.abs(self.normalised if self.relative is None else self.relative)
        key = [(0, -rel[k]) if np.isfinite(rel[k]) else (1, -abs(self.derivative[k]))
               for k in range(len(self.paths))]
        return sorted(range(len(self.paths)), key=lambda k: key[k])


class GearPoint:
    """A gear prepared at fixed harmonics for the point and band studies: family, nominal
    parameters, reference stage.

    **Arguments:** ``train``; ``gear``, ``stage``, ``linear``: as :func:`sensitivity`
    (:func:`~gearjax._gear.case.gear_case`); ``paths``: TOML paths or ``None``
    (:func:`~gearjax._studies.sensitivity.check_paths`); ``harmonics``: K, or ``None``
    for the sweep's rule at the lowest of ``f_hz``; ``f_hz``: the reference-stage mesh
    frequency or frequencies (Hz) to be solved.

    A gear whose frequencies fall in ``G > 1`` groups is solved on its torus (as the
    sweep solves it): orders ``K_g`` per angle from
    :func:`~gearjax._studies.harmonics.torus_orders_rule` at the lowest of ``f_hz``, or
    ``harmonics`` on every angle.

    **Attributes:** ``gear`` (name), ``ref`` (reference stage), ``mu_ref``, ``paths``,
    ``family`` (:class:`~gearjax._studies.sensitivity.GearFamily`), ``theta`` ``(p,)``,
    ``settings``, ``problem`` and ``system`` at ``theta``, ``has_backlash``, ``torus``
    (:func:`~gearjax._gear.case.torus_fields`, ``None`` for a periodic gear).

    **Raises:** ``ArgumentError`` naming ``paths`` or ``harmonics``; ``TrainError`` as
    :func:`~gearjax._gear.case.gear_case` and the harmonics rules.
    """

    def __init__(self, train: Train, gear, paths, stage, linear, harmonics, f_hz):
        case = self.case = gear_case(train, gear, stage, linear, torus=True)
        self.ref, self.mu_ref = case.stage, case.mu_ref
        self.gear, self.train, self.linear = case.gear.name, train, linear
        self.torus = torus_fields(case)
        self.paths = tuple(leaf.path for leaf in check_paths(train, paths, gear=self.gear,
                                                              linear=linear))
        if harmonics is not None and (int(harmonics) != harmonics or harmonics < 1):
            raise bad_argument("harmonics", harmonics, "must be an integer >= 1")
        self.family = GearFamily.of(train, self.paths, self.gear, linear, case.layout)
        self.theta = self.family.theta()
        f = np.atleast_1d(np.asarray(f_hz, dtype=float))
        if harmonics is not None:
            _harmonics.require_harmonics(case.system, harmonics)
            K = (int(harmonics),) * case.G if case.G > 1 else int(harmonics)
        elif case.G > 1:
            K = _harmonics.torus_orders_rule(
                case.system, float(case.omega(f.min())),
                cutoff_hz=_harmonics.response_cutoff_hz(case.system))
        else:
            K = _harmonics.harmonics_rule(
                float(f.min()) / self.mu_ref, _harmonics.excitation_floor(case.system),
                cutoff_hz=_harmonics.response_cutoff_hz(case.system))
        _harmonics.require_size(case.system, K, mu=case.mu)
        self.use_orders(K)
        self.has_backlash = self.system.has_backlash

    def use_orders(self, K) -> None:
        """Solve with K harmonics (orders per angle on a torus) from now on."""
        self.settings = _harmonics.settings_for(self.case.system, K)
        self.problem = _problem_jit(self.family, self.theta, self.settings)
        self.system = self.problem.system

    def checked_solve(self, f_hz: float, fixed: bool) -> tuple[_hb.HBSolution, list]:
        """:meth:`solve` at ``f_hz``, then its truncation checked a posteriori as a sweep
        checks a segment's (:func:`~gearjax._studies.point_truncation.checked_orders`):
        where the estimate exceeds the target the orders are raised and the point solved
        again from its solution, unless ``fixed`` (the caller's K, kept and warned
        about).
        **Returns:** ``(solution, estimates)`` (no estimate where the point did not
        converge)."""
        sol = self.solve(f_hz)
        if not bool(sol.converged):
            return sol, []
        K = self.settings.n_harmonics
        K_new, y, estimates = checked_orders(self.case, {K: self.problem}, K, sol.y,
                                             self.omega(f_hz), fixed=fixed,
                                             command="sensitivity")
        if K_new != K:
            self.use_orders(K_new)
            X0 = jnp.asarray(y).reshape(self.problem.shape) * self.problem.x_scale
            sol = self.solve(f_hz, X0)
        return sol, estimates

    def omega(self, f_hz: float) -> float:
        """The base frequency (rad/s) of the reference-stage mesh frequency ``f_hz`` (Hz)."""
        return 2 * math.pi * float(f_hz) / self.mu_ref

    def solve(self, f_hz: float, X0=None) -> _hb.HBSolution:
        """Newton from ``X0`` (or the linear guess); with backlash, when Newton from the
        linear guess fails, :func:`~gearjax._studies.sweep.backlash_start` (as the sweep
        starts a branch)."""
        w = jnp.asarray(self.omega(f_hz))
        sol = solve_at(self.family, self.theta, self.settings, w, X0)
        if not bool(sol.converged) and X0 is not None:
            sol = solve_at(self.family, self.theta, self.settings, w, None)
        if not bool(sol.converged) and self.has_backlash:
            sol = backlash_start(self.problem, w)
        return sol

    def differentiate(self, sol, f_hz, response, fold_tol):
        """``(PointGradient, stable, fold_distance)`` at a converged ``sol``; the caller
        decides with :func:`~gearjax._studies.sensitivity.check_point`."""
        omega = jnp.asarray(self.omega(f_hz))
        pg = implicit_gradient(self.family, self.theta, self.settings, sol.y, omega, response)
        stable, distance = point_status(self.problem, sol.X, omega)
        return pg, bool(stable), float(distance)

    def refusal_mode(self, sol, f_hz, stable, distance, fold_tol) -> dict | None:
        """Where a linear point will be refused (a multiplier within ``fold_tol`` of +1,
        or unstable), the mode behind it
        (:func:`~gearjax._studies.sensitivity.implicit.slow_mode`), which the refusal
        names; ``None`` otherwise (a point with backlash names no mode)."""
        if not self.linear or (distance >= fold_tol and stable):
            return None
        return slow_mode(self.problem, sol.X, jnp.asarray(self.omega(f_hz)))


@eqx.filter_jit
def _problem_jit(family, theta, settings):
    return _hb.hb_problem(family(theta), settings)


@eqx.filter_jit
def _responses_jit(problem, X, omega):
    return mesh_responses(problem, X, omega, static_mesh_forces(problem.system))


def mesh_index(system: System, mesh: str) -> int:
    """The index of the mesh named ``mesh`` (``1.sp1``) in ``system``.

    **Raises:** ``ArgumentError`` naming ``mesh`` for no such mesh."""
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
    progress: Callable[[str], None] | None = None,
) -> Sensitivity:
    """Derivatives of a mesh response at one frequency with respect to train parameters.

    **Arguments:** ``at_hz``: reference-stage mesh frequency (Hz), as in ``sweep``;
    ``response``: ``rms`` (RMS alternating force, N), ``max`` (peak ``|F|``, N) or
    ``dlf`` (dynamic load factor); ``mesh``: mesh name (``1.sp1``; default: the mesh
    with the largest response); ``paths``: TOML paths (default: every continuous path
    that changes the gear's system, :func:`~gearjax.continuous_paths` of the gear);
    ``stage``, ``linear``: as ``sweep``;
    ``harmonics``: K (default: the sweep's rule at ``at_hz``; on a torus, ``G > 1``, the
    same K on every angle, default the orders of
    :func:`~gearjax._studies.harmonics.torus_orders_rule`); ``fold_tol``: the fold
    test on ``min |mu - 1|`` (:func:`~gearjax._studies.sensitivity.point_status`,
    :data:`~gearjax._studies.sensitivity.FOLD_TOL`); ``progress(message)``: called before
    the solve, before the derivatives and at the end.

    The point is solved from the linear in-contact guess (with backlash, if Newton fails,
    from the orbit a time integration settles to, else by the backlash homotopy), so with
    coexisting solutions it is the one a sweep starting at ``at_hz`` would start on.

    **Returns:** :class:`Sensitivity`; a refused point has ``result`` ``not_converged``,
    ``fold``, ``lightly_damped_mode`` or ``unstable``, a ``message`` naming the
    frequency (and for a linear point the mode behind it), and no derivative. The
    derivatives are ranked by a rule independent of any angle's origin
    (:meth:`Sensitivity.ranking`).

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming the argument for bad
    ``paths``, ``response``, ``mesh``, ``at_hz`` or ``harmonics``; ``TrainError`` as
    :func:`~gearjax._gear.case.gear_case` for the gear and stage.
    """
    field = response_field(response)
    if not (isinstance(at_hz, int | float) and at_hz > 0 and math.isfinite(at_hz)):
        raise bad_argument("at_hz", at_hz, "must be a positive mesh frequency in Hz")
    gp = GearPoint(train, gear, paths, stage, linear, harmonics, at_hz)
    j = None if mesh is None else mesh_index(gp.system, mesh)
    say = progress or (lambda message: None)
    t0 = time.perf_counter()
    say(f"sensitivity: solving gear {gp.gear!r} at {at_hz:g} Hz (K = "
        f"{_harmonics.orders_text(gp.settings.n_harmonics)}, "
        f"{int(np.prod(gp.problem.shape))} unknowns; the first call compiles), then its "
        "truncation checked against doubled orders")
    sol, truncation = gp.checked_solve(at_hz, fixed=harmonics is not None)
    omega = gp.omega(at_hz)
    converged = bool(sol.converged)
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
                  meshes=tuple(gp.system.mesh_labels), mesh_values=values, torus=gp.torus,
                  truncation=tuple(truncation))
    steps, rules = parameter_steps(train, gp.paths, np.asarray(gp.theta))
    common.update(steps=steps, step_rules=rules)
    refused = dict(derivative=None, normalised=None, partial=None)
    if not converged:
        return Sensitivity(**common, **refused, result=result_word(RESULTS.not_converged),
                           stable=None,
                           fold_distance=None,
                           message=f"the harmonic balance did not converge at {at_hz:g} Hz "
                                   f"({result_word(sol.result)}): no derivative")
    say(f"sensitivity: the derivatives of mesh {common['mesh']}'s {response} with respect "
        f"to {len(gp.paths)} parameters, and the point's stability "
        f"({time.perf_counter() - t0:.1f} s so far)")
    pg, stable, distance = gp.differentiate(sol, at_hz, MeshResponse(field=field, mesh=j),
                                            fold_tol)
    say(f"sensitivity: done in {time.perf_counter() - t0:.1f} s")
    status = dict(stable=stable, fold_distance=distance)
    mode = gp.refusal_mode(sol, at_hz, stable, distance, fold_tol)
    try:
        check_point(stable, distance, f"{at_hz:g} Hz", fold_tol, torus=gp.torus is not None,
                    linear=linear, mode=mode)
    except SensitivityRefused as e:
        return Sensitivity(**common, **refused, **status, result=e.result, message=str(e),
                           mode=mode)
    d = np.asarray(pg.gradient)
    return Sensitivity(**common, **status, result="ok", message=None, derivative=d,
                       normalised=normalise(d, np.asarray(gp.theta), float(pg.value),
                                            [r is not None for r in rules]),
                       partial=np.asarray(pg.partial),
                       relative=relative_change(d, steps, float(pg.value)))


def normalise(derivative: np.ndarray, values: np.ndarray, response: float,
              arbitrary_origin=None) -> np.ndarray:
    """``(p / R) dR/dp``; NaN where ``p == 0`` or ``R == 0`` (no relative change) and where
    ``arbitrary_origin`` (``(p,)`` bool, default none) marks an angle whose origin is a
    convention (a planet angle, a phase: :mod:`~gearjax._studies.sensitivity.steps`),
    whose relative change means nothing."""
    ok = (values != 0) & (response != 0)
    if arbitrary_origin is not None:
        ok = ok & ~np.asarray(arbitrary_origin, bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, derivative * values / (response if response != 0 else 1.0), np.nan)

