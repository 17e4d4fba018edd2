"""How derivatives with respect to different parameters are ranked: a step per parameter.

A derivative ``dR/dp`` is in units of the response per unit of ``p`` (N per N/m, N per
degree, ...). Ranking parameters of different units needs a step ``s`` for each, and
``(s / R) dR/dp``, the relative change of the response over that step (to first
order), is what is ranked (largest ``|.|`` first):

- a parameter with a natural zero (a stiffness, an inertia, a mass, a torque, a
  length, a damping ratio): its own value, ``s = p``, which gives the elasticity
  ``(p / R) dR/dp``, the relative change of ``R`` per relative change of ``p``;
- an angle whose origin is a convention: a planet's position angle (planet 1 sits at
  0 by convention: turning the whole set changes every angle and no response), the
  sun-ring phase and a stage's phase (phases of a periodic mesh cycle). ``(p / R)
  dR/dp`` would change with the origin, so the step is a span the gear sets:

  - ``S.planet_angles_deg.i``: one assembly slot of stage ``S``, ``360 / (Z_s + Z_r)``
    degrees, the smallest move of a planet the assembly rule allows (model.md,
    Geometry; it shifts the planet's sun-mesh phase by ``Z_s / (Z_s + Z_r)`` and its
    ring-mesh phase by ``Z_r / (Z_s + Z_r)`` of a mesh cycle);
  - ``S.sun_ring_phase_deg``, ``S.stage_phase_deg``: one mesh cycle, 360 degrees of
    their unit, the span over which the phase repeats itself.

- a profile shift ``S.profile_shift.GEAR``: a coefficient in modules whose usual value
  is 0, where the elasticity vanishes whatever the derivative: one module, ``x = 1``.

Both kinds of step are independent of any origin, so one ranking holds them all.
"""

from __future__ import annotations

import numpy as np

from ..._gear.train import Train

RANKING_RULE = (
    "by |(s/R) dR/dp|, the relative change of the response over a step s of each "
    "parameter: its own value (the elasticity (p/R) dR/dp), or for an angle whose "
    "origin is a convention one assembly slot 360/(Z_s + Z_r) deg of a planet angle and "
    "one mesh cycle (360 deg) of a phase, and one module (x = 1) of a profile shift")
"""How the ``sensitivity`` derivatives are ranked, in words (module docstring)."""

PHASES = ("sun_ring_phase_deg", "stage_phase_deg")
"""Stage keys whose value is a phase of the mesh cycle (deg, 360 = one whole cycle)."""


def parameter_steps(train: Train, paths, values) -> tuple[np.ndarray, tuple[str | None, ...]]:
    """The step ``s`` of each TOML path of ``paths`` (module docstring), in the path's
    file unit, with ``values`` ``(p,)`` their nominal values.

    **Returns:** ``(steps (p,), rules)``: ``rules[k]`` is ``None`` where the step is the
    parameter's own value, else the step's rule in words (its value in the unit
    included), e.g. ``"one assembly slot, 360/(40 + 100) deg"``."""
    steps = np.asarray(values, dtype=float).copy()
    rules: list[str | None] = []
    for k, path in enumerate(paths):
        parts = str(path).split(".")
        rule = None
        if len(parts) >= 3 and parts[-2] == "planet_angles_deg":
            stage = next((s for s in train.stages if s.id == ".".join(parts[:-2])), None)
            if stage is not None:
                slots = int(stage.teeth.sun + stage.teeth.ring)
                steps[k] = 360.0 / slots
                rule = (f"one assembly slot, 360/({stage.teeth.sun} + {stage.teeth.ring}) = "
                        f"{steps[k]:.4g} deg")
        elif len(parts) >= 2 and parts[-1] in PHASES:
            steps[k] = 360.0
            rule = "one mesh cycle, 360 deg"
        elif len(parts) >= 3 and parts[-2] == "profile_shift":
            steps[k] = 1.0
            rule = "one module of profile shift, x = 1"
        rules.append(rule)
    return steps, tuple(rules)


def relative_change(derivative, steps, response: float) -> np.ndarray:
    """``(s / R) dR/dp`` per parameter (module docstring); NaN where ``s`` or ``R`` is 0
    (no relative change: ranked after, by ``|dR/dp|``)."""
    derivative, steps = np.asarray(derivative, float), np.asarray(steps, float)
    ok = (steps != 0) & (response != 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ok, derivative * steps / (response if response != 0 else 1.0),
                        np.nan)
