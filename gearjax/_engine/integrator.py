"""The settings every time integration shares: the ODE solver and its step-size
controller (:class:`Integrator`), extended by the periodic integration's
(:class:`~gearjax._engine.time_domain.TimeDomain`) and the windowed one's
(:class:`~gearjax._engine.windowed.Windowed`); and the two integrations built on them:
to an end time (:func:`integrate`) and through sample times (:func:`sample`).

Neither asks diffrax to save at given times (``SaveAt(ts=...)``): diffrax checks such
times with ``equinox.error_if``, a host callback in the compiled program, and JAX keeps
no program with a host callback in its persistent compilation cache, so every process
would compile the integration again. :func:`sample` integrates from one sample time to
the next instead, each interval one ``diffeqsolve`` that saves its end state (and picks
its first step itself, as diffrax does for a ``dt0`` of None).
"""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp


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

    def controller(self) -> dfx.PIDController:
        """The step-size controller of these settings."""
        return dfx.PIDController(rtol=self.rtol, atol=self.atol, pcoeff=self.pcoeff,
                                 icoeff=self.icoeff)


class Leg(eqx.Module):
    """The end of an integration: the state ``z`` at the end time, whether the solver
    got there (``ok``, a boolean array), why not (``result``, a ``diffrax.RESULTS``
    item), and its accepted and rejected ``steps``, ``rejected``."""

    z: jax.Array
    ok: jax.Array
    result: dfx.RESULTS
    steps: jax.Array
    rejected: jax.Array


def integrate(settings: Integrator, term, t0, t1, z0, args, max_steps: int) -> Leg:
    """Integrate ``term`` from ``(t0, z0)`` to ``t1`` with ``settings``' solver and PI
    controller, at most ``max_steps`` steps, its first step chosen by the controller
    (jittable; no host callback in the program, module docstring). **Returns:** a
    :class:`Leg` (``z`` the last state reached where the solver stopped early)."""
    sol = dfx.diffeqsolve(term, settings.solver, t0, t1, None, z0, args=args,
                          saveat=dfx.SaveAt(t1=True), stepsize_controller=settings.controller(),
                          max_steps=max_steps, adjoint=dfx.ForwardMode(), throw=False)
    return Leg(z=sol.ys[-1], ok=sol.result == dfx.RESULTS.successful, result=sol.result,
               steps=sol.stats["num_accepted_steps"], rejected=sol.stats["num_rejected_steps"])


def sample(settings: Integrator, term, t0, z0, ts, args, max_steps: int):
    """The states at the times ``ts`` ``(S,)`` (increasing, ``ts[0] >= t0``) of the
    integration of ``term`` from ``(t0, z0)``: one :func:`integrate` from each time to
    the next, at most ``max_steps`` steps each (jittable).

    **Returns:** ``(zs, leg)``: ``zs`` ``(S, d)`` and the :class:`Leg` of the whole
    (``z`` the state at ``ts[-1]``, ``ok`` and ``result`` of the first interval that
    failed, steps summed). Past a failed interval the states stay at the last one
    reached, and no more steps are taken (the intervals after it have no length).
    """
    def one(c, t1):
        t, z, ok, result, steps, rejected = c
        leg = integrate(settings, term, t, jnp.where(ok, t1, t), z, args, max_steps)
        good = ok & leg.ok
        z1 = jnp.where(good, leg.z, z)
        carry = (jnp.where(good, t1, t), z1, good, dfx.RESULTS.where(ok, leg.result, result),
                 steps + jnp.where(ok, leg.steps, 0), rejected + jnp.where(ok, leg.rejected, 0))
        return carry, z1

    t0 = jnp.asarray(t0, dtype=z0.dtype)
    init = (t0, z0, jnp.asarray(True), dfx.RESULTS.successful, jnp.asarray(0),
            jnp.asarray(0))
    (_, z, ok, result, steps, rejected), zs = jax.lax.scan(one, init, ts)
    return zs, Leg(z=z, ok=ok, result=result, steps=steps, rejected=rejected)
