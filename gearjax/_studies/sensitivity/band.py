"""Derivatives of a band response: the smooth peak or the integral of one mesh response
over a grid of frequencies ``f_1 < ... < f_n`` (Hz).

- ``peak``: the smooth maximum ``R = tau log sum_i exp(r_i / tau)`` with temperature
  ``tau = temperature * max_i r_i`` at the nominal parameters, held constant
  (``max r <= R <= max r + tau log n``; the default ``temperature`` 0.01 puts the
  bound at 1% of the peak times ``log n``);
- ``integral``: the trapezoid rule ``R = sum_i (r_i + r_{i+1}) (f_{i+1} - f_i) / 2``
  (response units times Hz).

Points of the band that are refused (not converged, or refused by
:func:`~gearjax._studies.sensitivity.check_point`) are left out of both (listed with the
reason); when the largest response of the converged points is at a refused point the
band's peak is not differentiable and ``peak`` is refused with a message naming it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from ..._engine.results import result_word
from ..._errors import bad_argument
from ..._gear.train import Train
from .family import MeshResponse, response_field
from .implicit import FOLD_TOL, SensitivityRefused, check_point
from .point import GearPoint, mesh_index, normalise
from .steps import parameter_steps, relative_change

BAND_OBJECTIVES = ("peak", "integral")
"""The band objectives (argument ``objective``)."""


@dataclasses.dataclass(frozen=True)
class BandSensitivity:
    """A band response and its derivatives.

    **Fields:** ``objective`` (``peak`` | ``integral``), ``temperature`` (``peak``: tau
    relative to the largest response), ``tau`` (absolute, response units); ``value``;
    ``paths``, ``values``, ``derivative``, ``normalised``, ``steps``, ``step_rules``,
    ``relative`` as :class:`~gearjax._studies.sensitivity.Sensitivity`;
    ``frequencies_hz``, ``point_values`` ``(n,)`` (NaN where refused),
    ``point_gradients`` ``(n, p)`` (NaN rows where refused), ``weights`` ``(n,)``:
    ``dR/dr_i``; ``excluded``: ``{frequency_hz: reason}`` of the refused points;
    ``mesh``, ``response``, ``harmonics`` (K, or the orders per angle on a torus);
    ``torus``: :func:`~gearjax._gear.case.torus_fields` (``None`` for a periodic gear).
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
    harmonics: int | tuple[int, ...]
    torus: dict | None = None
    steps: np.ndarray | None = None
    step_rules: tuple[str | None, ...] = ()
    relative: np.ndarray | None = None


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
    followed upwards), else as :func:`~gearjax._studies.sensitivity.sensitivity`
    starts; ``mesh``: the mesh name;
    ``objective``: ``peak`` (log-sum-exp, temperature ``temperature`` relative to the
    largest response) or ``integral`` (trapezoid, response times Hz); ``harmonics``: one
    K for the band (default: the sweep's rule at the lowest frequency, the largest it
    gives in the band; on a torus the orders per angle of
    :func:`~gearjax._studies.harmonics.torus_orders_rule` at the lowest frequency, or
    ``harmonics`` on every angle); the rest as :func:`~gearjax._studies.sensitivity.sensitivity`.

    **Returns:** :class:`BandSensitivity`. **Raises:** ``ArgumentError`` naming the
    argument for bad input, and naming ``frequencies_hz`` when fewer than two points are
    left or (``peak``) when the largest response of the converged points is at a refused
    point (a fold is typically where a backlash response peaks: it jumps there and has no
    derivative).
    """
    field = response_field(response)
    if objective not in BAND_OBJECTIVES:
        raise bad_argument("objective", objective, f"must be one of {', '.join(BAND_OBJECTIVES)}")
    f = np.asarray(frequencies_hz, dtype=float)
    if f.ndim != 1 or f.size < 2 or not np.all(np.isfinite(f)) or np.any(f <= 0) or np.any(
            np.diff(f) <= 0):
        raise bad_argument("frequencies_hz", f.tolist(),
                           "needs at least 2 positive, strictly ascending frequencies in Hz")
    if not (temperature > 0 and math.isfinite(temperature)):
        raise bad_argument("temperature", temperature, "must be a number > 0")
    gp = GearPoint(train, gear, paths, stage, linear, harmonics, f)
    j = mesh_index(gp.system, mesh)
    resp = MeshResponse(field=field, mesh=j)
    n, p = f.size, len(gp.paths)
    vals, grads = np.full(n, np.nan), np.full((n, p), np.nan)
    raw = np.full(n, np.nan)  # every converged response, refused or not
    excluded: dict[float, str] = {}
    X_prev = None
    for i, fi in enumerate(f):
        sol = gp.solve(fi, X_prev)
        if not bool(sol.converged):
            excluded[float(fi)] = f"not converged ({result_word(sol.result)})"
            continue
        X_prev = sol.X
        pg, stable, distance = gp.differentiate(sol, fi, resp, fold_tol)
        raw[i] = float(pg.value)
        try:
            check_point(stable, distance, f"{fi:g} Hz", fold_tol, torus=gp.torus is not None,
                        linear=gp.linear,
                        mode=gp.refusal_mode(sol, fi, stable, distance, fold_tol))
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
    steps, rules = parameter_steps(train, gp.paths, np.asarray(gp.theta))
    return BandSensitivity(
        objective=objective, temperature=temperature if objective == "peak" else None, tau=tau,
        value=float(value), paths=gp.paths, values=np.asarray(gp.theta), derivative=d,
        normalised=normalise(d, np.asarray(gp.theta), float(value),
                             [r is not None for r in rules]), frequencies_hz=f,
        point_values=vals, point_gradients=grads, weights=w, excluded=excluded,
        mesh=mesh, response=response, harmonics=gp.settings.n_harmonics, torus=gp.torus,
        steps=steps, step_rules=rules, relative=relative_change(d, steps, float(value)))
