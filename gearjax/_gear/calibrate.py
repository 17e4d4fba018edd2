"""Calibration: fit train parameters to measured natural frequencies.

Least squares on the relative frequency error of the lowest elastic modes,

    r_k = (f_k(p) - f_k^target) / f_k^target,   k = 1..n,

over the chosen parameters (TOML paths, see ``_paths``) in log space,
``x = log p``, with physical bounds. Targets are ascending with repeated modes
repeated (a triple planet mode is three targets) and are matched in order to the
``n`` lowest modes that :func:`gearjax.modes` classes ``elastic`` at the current
parameters. That classification is Python-side and not differentiated; the
Jacobian is ``jax.jacfwd`` through ``assemble`` and ``generalized_eigvals``, whose
JVP ``v^T (dK - lambda dM) v`` stays finite at the repeated planet modes.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .assembly import assemble
from .._config import require_x64
from .._errors import TrainError, bad_argument
from .kinematics import Kinematics, kinematics
from .._engine.modal import generalized_eigvals, modes
from .paths import Leaf, leaf_selector, set_leaf
from .train import Train
from .validate import validate_train

PRESSURE_ANGLE_MAX_DEG = 89.0
"""Upper default bound of a free pressure angle (the file rule is < 90 deg)."""


@dataclasses.dataclass(frozen=True)
class CalibrationResult:
    """Outcome of :func:`calibrate`.

    **Fields:**

    - ``train``: the calibrated :class:`Train` (write it with ``save_train``);
    - ``free``: the fitted paths, as given; ``initial``, ``fitted``: path -> value in
      the file's unit;
    - ``targets_hz``, ``model_hz``: target and fitted elastic frequencies (Hz),
      ascending, matched in order; ``residual_hz`` = model - target (Hz),
      ``residual_rel`` = residual / target, per target;
    - ``converged``: the optimiser stopped on a tolerance (not on ``max_nfev`` or an
      error); it says nothing about the size of the residual, which a model may be
      unable to make small; ``message``: the optimiser's reason; ``nfev``: residual
      evaluations;
    - ``at_bound``: paths whose fitted value lies on a bound (widen it, or the data
      pull the parameter out of its physical range);
    - ``gear``: the gear whose modes were fitted.
    """

    train: Train
    free: tuple[str, ...]
    initial: dict[str, float]
    fitted: dict[str, float]
    targets_hz: tuple[float, ...]
    model_hz: tuple[float, ...]
    residual_hz: tuple[float, ...]
    residual_rel: tuple[float, ...]
    converged: bool
    message: str
    nfev: int
    at_bound: tuple[str, ...]
    gear: str


def calibrate(
    train: Train,
    targets_hz: Sequence[float],
    free: Sequence[str],
    gear: str | None = None,
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    bound_factor: float = 100.0,
    xtol: float = 1e-12,
    ftol: float = 1e-12,
    gtol: float = 1e-12,
    max_nfev: int = 200,
) -> CalibrationResult:
    """Fit the parameters ``free`` of ``train`` to natural frequencies ``targets_hz``.

    **Arguments:**

    - ``targets_hz``: ``n`` target frequencies (Hz), positive, ascending, repeated
      modes repeated; matched to the ``n`` lowest elastic modes of ``gear``;
    - ``free``: TOML paths (``1.inertia.sun``, ``2.planet_mass``, ...), each with a
      value > 0 that changes some natural frequency;
    - ``gear``: default the first gear of the train;
    - ``bounds``: path -> ``(low, high)`` in the file's unit, ``0 < low < high``,
      containing the start; a path not given gets ``[p0 / bound_factor,
      p0 * bound_factor]`` (a pressure angle at most 89 deg);
    - ``xtol``, ``ftol``, ``gtol``, ``max_nfev``: ``scipy.optimize.least_squares``
      ("trf") stopping rules, on ``x = log p`` and the relative residual.

    **Returns:** a :class:`CalibrationResult`.

    **Raises:** ``TrainError`` naming ``--targets-hz`` or ``--free`` for bad targets
    (not positive, not ascending, more than the elastic modes) or paths (unknown,
    duplicated, value <= 0, no effect on any natural frequency), and when the fitted
    train breaks a train rule.
    """
    require_x64()
    g = train.gear(gear)
    targets = _check_targets(train, targets_hz)
    free = (free,) if isinstance(free, str) else tuple(free)
    leaves = _check_free(train, free)
    kin = kinematics(train, g.name)
    n = targets.size

    p0 = np.array([_value(train, leaf) for leaf in leaves])
    for path, p in zip(free, p0):
        if not p > 0:
            raise bad_argument("free", path,
                       f"its value is {p:g}; calibration fits log-parameters, so a free "
                       "parameter must be > 0")
    n_elastic = len(modes(assemble(train, g.name, kin)).elastic_hz)
    if n > n_elastic:
        raise bad_argument("targets_hz", targets.tolist(),
                   f"{n} targets but gear {g.name!r} has only {n_elastic} elastic modes")
    lo, hi = _bounds(train, free, leaves, p0, bounds, bound_factor)

    model = _FrequencyModel(train, leaves, g.name, kin, n)
    x0 = np.log(p0)
    jac0 = model.jacobian(x0)
    for j, path in enumerate(free):
        if not np.any(jac0[:, j]):
            raise bad_argument("free", path,
                       "changes none of the targeted natural frequencies (modes use the "
                       "linear, undamped, mean-stiffness model without backlash): free "
                       "inertias, masses, stiffnesses or geometry instead")

    import scipy.optimize  # on first use: its import costs every gearjax start
    fit = scipy.optimize.least_squares(
        lambda x: model.hz(x) / targets - 1.0,
        x0,
        jac=lambda x: model.jacobian(x) / targets[:, None],
        bounds=(np.log(lo), np.log(hi)),
        method="trf",
        xtol=xtol,
        ftol=ftol,
        gtol=gtol,
        max_nfev=max_nfev,
    )
    x = fit.x
    fitted_train = model.train_at(x)
    p = np.array([_value(fitted_train, leaf) for leaf in leaves])
    _check_fitted(fitted_train, free)
    model_hz = model.hz(x)
    log_lo, log_hi = np.log(lo), np.log(hi)
    on_bound = (fit.active_mask != 0) | np.isclose(x, log_lo, rtol=0, atol=1e-9) | np.isclose(
        x, log_hi, rtol=0, atol=1e-9)
    residual = model_hz - targets
    message = fit.message
    if not model.all_elastic(x):
        message += ("; at the fitted parameters fewer than the targeted number of modes are "
                    "elastic, the lowest other modes were matched")
    return CalibrationResult(
        train=fitted_train,
        free=free,
        initial={path: float(v) for path, v in zip(free, p0)},
        fitted={path: float(v) for path, v in zip(free, p)},
        targets_hz=tuple(targets.tolist()),
        model_hz=tuple(model_hz.tolist()),
        residual_hz=tuple(residual.tolist()),
        residual_rel=tuple((residual / targets).tolist()),
        converged=bool(fit.status > 0),
        message=message,
        nfev=int(fit.nfev),
        at_bound=tuple(path for path, b in zip(free, on_bound) if b),
        gear=g.name,
    )


def elastic_sensitivity(
    train: Train, free: Sequence[str], gear: str | None = None, n: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` lowest elastic frequencies and their derivatives, as ``calibrate`` uses them.

    **Returns:** ``(hz, dhz_dp)``: shapes ``(n,)`` in Hz and ``(n, len(free))`` in Hz
    per unit of each parameter (the file's unit); ``n`` defaults to every elastic mode.
    """
    g = train.gear(gear)
    free = (free,) if isinstance(free, str) else tuple(free)
    leaves = _check_free(train, free)
    kin = kinematics(train, g.name)
    if n is None:
        n = len(modes(assemble(train, g.name, kin)).elastic_hz)
    model = _FrequencyModel(train, leaves, g.name, kin, n)
    p = np.array([_value(train, leaf) for leaf in leaves])
    x = np.log(p)
    return model.hz(x), model.jacobian(x) / p[None, :]


# --------------------------------------------------------------------------- model


class _FrequencyModel:
    """The ``n`` lowest elastic frequencies (Hz) as a function of ``x = log p``.

    ``hz(x)`` and ``jacobian(x)`` (``d hz / d x``, shape ``(n, p)``) come from one
    jitted ``jacfwd`` (compiled once per instance: ``p`` extra tangents of a 14-DOF
    eigenproblem cost little). The elastic mode indices at ``x`` come from ``modes``
    (eager, not differentiated); both are cached for the last ``x`` (least squares
    asks for the residual and then the Jacobian at the same point).
    """

    def __init__(self, train: Train, leaves: tuple[Leaf, ...], gear: str, kin: Kinematics,
                 n: int):
        self.train, self.leaves, self.gear, self.kin, self.n = train, leaves, gear, kin, n
        self._cache: tuple[bytes, np.ndarray, np.ndarray, bool] | None = None

        def hz(x, index):
            system = assemble(self.train_at(x), gear, kin)
            lam = generalized_eigvals(system.mean_stiffness(), system.M)
            out = jnp.sqrt(lam[index]) / (2 * jnp.pi)
            return out, out

        self._hz_and_jacobian = jax.jit(jax.jacfwd(hz, has_aux=True))

    def train_at(self, x) -> Train:
        train = self.train
        for leaf, xi in zip(self.leaves, x):
            train = set_leaf(train, leaf, jnp.exp(xi))
        return train

    def _evaluate(self, x) -> tuple[np.ndarray, np.ndarray, bool]:
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if self._cache is None or self._cache[0] != key:
            result = modes(assemble(self.train_at(jnp.asarray(x)), self.gear, self.kin))
            index = [k for k, m in enumerate(result.modes) if m.cls == "elastic"]
            complete = len(index) >= self.n
            if not complete:  # keep the residual's size: match the lowest other modes
                rest = [k for k, m in enumerate(result.modes) if m.cls != "elastic"]
                rest.sort(key=lambda k: (result.modes[k].cls == "rigid", k))
                index = sorted(index + rest[: self.n - len(index)])
            jac, hz = self._hz_and_jacobian(jnp.asarray(x), jnp.asarray(index[: self.n]))
            self._cache = (key, np.asarray(hz), np.asarray(jac), complete)
        return self._cache[1:]

    def all_elastic(self, x) -> bool:
        return self._evaluate(x)[2]

    def hz(self, x) -> np.ndarray:
        return self._evaluate(x)[0]

    def jacobian(self, x) -> np.ndarray:
        return self._evaluate(x)[1]


# --------------------------------------------------------------------------- checks


def _value(train: Train, leaf: Leaf) -> float:
    value = np.asarray(leaf.where(train))
    return float(value if leaf.index is None else value[leaf.index])


def _check_targets(train: Train, targets_hz) -> np.ndarray:
    try:
        targets = np.atleast_1d(np.asarray(targets_hz, dtype=float))
    except (TypeError, ValueError):
        raise bad_argument("targets_hz", targets_hz, "must be numbers (Hz)") from None
    shown = targets.tolist()
    if targets.ndim != 1 or targets.size == 0:
        raise bad_argument("targets_hz", shown, "at least one target frequency is required")
    if not np.all(np.isfinite(targets)) or np.any(targets <= 0):
        raise bad_argument("targets_hz", shown, "target frequencies must be finite and > 0")
    if np.any(np.diff(targets) < 0):
        k = int(np.argmax(np.diff(targets) < 0))
        raise bad_argument("targets_hz", shown,
                   f"targets must be ascending (target {k + 2}, {targets[k + 1]:g} Hz, is below "
                   f"target {k + 1}, {targets[k]:g} Hz); repeat a repeated mode, e.g. a triple "
                   "planet mode three times")
    return targets


def _check_free(train: Train, free: tuple[str, ...]) -> tuple[Leaf, ...]:
    if not free:
        raise bad_argument("free", [], "at least one parameter path is required")
    leaves = tuple(leaf_selector(train, path, "free") for path in free)
    seen: dict[str, str] = {}
    for path, leaf in zip(free, leaves):
        if leaf.path in seen:
            same = "" if seen[leaf.path] == path else f" (as {seen[leaf.path]!r})"
            raise bad_argument("free", path,
                       f"the parameter is given twice{same}; name each parameter once")
        seen[leaf.path] = path
    return leaves


def _bounds(train, free, leaves, p0, bounds, factor) -> tuple[np.ndarray, np.ndarray]:
    if not (isinstance(factor, int | float) and factor > 1 and math.isfinite(factor)):
        raise bad_argument("bound_factor", factor, "must be a finite number > 1")
    bounds = dict(bounds or {})
    by_canonical = {leaf.path: path for path, leaf in zip(free, leaves)}
    for key in bounds:
        if key not in free and key not in by_canonical:
            raise bad_argument("bounds", key, f"is not a free path; free paths are "
                       f"{', '.join(free)}")
    lo, hi = p0 / factor, p0 * factor
    for j, (path, leaf) in enumerate(zip(free, leaves)):
        if leaf.path.endswith(".pressure_angle_deg"):
            hi[j] = min(hi[j], max(PRESSURE_ANGLE_MAX_DEG, p0[j]))
        pair = bounds.get(path, bounds.get(leaf.path))
        if pair is None:
            continue
        try:
            a, b = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise bad_argument(f"bounds[{path!r}]", pair, "must be (low, high)") from None
        if not (0 < a < b and math.isfinite(b)):
            raise bad_argument(f"bounds[{path!r}]", [a, b], "must satisfy 0 < low < high")
        if not a <= p0[j] <= b:
            raise bad_argument(f"bounds[{path!r}]", [a, b],
                       f"must contain the start value {p0[j]:g}")
        lo[j], hi[j] = a, b
    return lo, hi


def _check_fitted(train: Train, free: tuple[str, ...]) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            validate_train(train, emit_warnings=False)
        except TrainError as e:
            raise bad_argument("free", list(free),
                       f"the fitted train breaks a train rule ({e}); narrow the bounds") from None
