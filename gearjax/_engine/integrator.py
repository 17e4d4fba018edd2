"""The settings every time integration shares: the ODE solver and its step-size
controller (:class:`Integrator`), extended by the periodic integration's
(:class:`~gearjax._engine.time_domain.TimeDomain`) and the windowed one's
(:class:`~gearjax._engine.windowed.Windowed`)."""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx


class Integrator(eqx.Module):
    """The ODE solver and its step-size controller, the fields every integration's
    settings share (static: they are compile keys).

    **Fields:** ``solver``: a diffrax solver (default ``Dopri8()``: see
    :mod:`gearjax._engine.time_domain` for the choice); ``rtol``, ``atol``: step-size
    controller tolerances on the scaled state (units of the characteristic mesh length);
    ``pcoeff``, ``icoeff``: PI coefficients of ``diffrax.PIDController`` (use 0.3, 0.3
    with an implicit solver); ``max_steps``: diffrax steps allowed per base period.

    **Raises:** ``ValueError`` for a ``max_steps`` below 1 or a tolerance not positive.
    """

    solver: dfx.AbstractSolver = dfx.Dopri8()
    rtol: float = eqx.field(static=True, default=1e-8)
    atol: float = eqx.field(static=True, default=1e-8)
    pcoeff: float = eqx.field(static=True, default=0.0)
    icoeff: float = eqx.field(static=True, default=1.0)
    max_steps: int = eqx.field(static=True, default=50_000)

    def __check_init__(self):
        name = type(self).__name__
        if int(self.max_steps) < 1:
            raise ValueError(f"{name}.max_steps must be a positive integer, not "
                             f"{self.max_steps!r}.")
        for field in ("rtol", "atol"):
            if not float(getattr(self, field)) > 0:
                raise ValueError(f"{name}.{field} must be positive, not "
                                 f"{getattr(self, field)!r}.")
