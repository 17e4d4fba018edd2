"""Per-mesh responses over one steady-state period: forces, torques, load factors, contact.

For each mesh ``m`` with deflection ``p(t)``, force ``F(t)``, half backlash ``b`` and
static force ``F_static`` (mean stiffness, no backlash; model.md, Outputs):

- ``mean_force`` ``Fbar = mean(F)`` (N) and ``mean_torque`` ``r_m Fbar`` (N m);
- ``rms_force`` ``sqrt(mean((F - Fbar)^2))`` (N): RMS of the alternating force, the
  paper's "r.m.s. mesh force";
- ``max_force`` ``max |F|`` (N) and ``dlf`` ``max |F| / |F_static|``;
- ``separation``: share of the period with ``|p| <= b``;
- ``back_contact``: share of the period in contact on the flank opposite the loaded
  one (``p < -b`` when ``F_static > 0``, ``p > b`` when ``F_static < 0``).

The statistics are defined once, in :func:`responses_from_samples`, on samples
uniformly spaced over one period (endpoint excluded); the harmonic balance
(:func:`mesh_responses`) and the time integration both call it. Means and RMS of
such samples are exact for band-limited signals; peaks and time shares are sample
estimates: a share is a count of samples over ``T``, so its resolution is ``1/T``
(e.g. 1/256 = 0.4 % of the period on the default grid of the paper case), and a
peak between two samples is missed by at most the change of ``F`` over ``1/T`` of a
period. Pass a larger ``n_time`` for finer shares.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float


from .hb import HBProblem, hb_problem, mesh_samples
from .mesh_force import in_contact
from .programs import one_program
from .static import static_deflection
from .system import System


class MeshResponses(eqx.Module):
    """Per-mesh responses over one period, SI.

    **Fields**, each shape ``(m,)`` (``(..., m)`` when batched over points):

    - ``mean_force``: mean mesh force ``Fbar`` (N);
    - ``rms_force``: RMS of the alternating force ``sqrt(mean((F - Fbar)^2))`` (N);
    - ``max_force``: peak ``max |F|`` (N);
    - ``dlf``: dynamic load factor ``max |F| / |F_static|`` (NaN where ``F_static == 0``:
      a mesh without static load has no load factor);
    - ``separation``: share of the period with ``|p| <= b`` (0..1);
    - ``back_contact``: share of the period in contact on the unloaded flank (0..1;
      NaN where ``F_static == 0``: no loaded flank);
    - ``mean_torque``: mean transmitted torque ``r_m Fbar`` (N m), ``r_m`` the mesh's
      lever arm (base radius of the sun or ring).
    """

    mean_force: Float[Array, "*batch m"]
    rms_force: Float[Array, "*batch m"]
    max_force: Float[Array, "*batch m"]
    dlf: Float[Array, "*batch m"]
    separation: Float[Array, "*batch m"]
    back_contact: Float[Array, "*batch m"]
    mean_torque: Float[Array, "*batch m"]


RESPONSE_FIELDS = tuple(f.name for f in dataclasses.fields(MeshResponses))
"""Names of the :class:`MeshResponses` fields, in order."""

RESPONSE_UNITS = {
    "mean_force": "N",
    "rms_force": "N",
    "max_force": "N",
    "dlf": "1",
    "separation": "1",
    "back_contact": "1",
    "mean_torque": "N m",
}
"""Unit of every response field (``"1"``: dimensionless, shares of the period)."""


@one_program
def responses_from_samples(
    p: Float[Array, "*batch m T"],
    F: Float[Array, "*batch m T"],
    b: Float[Array, "*batch m"],
    F_static: Float[Array, "*batch m"],
    radius: Float[Array, "*batch m"],
    weights: Float[Array, " T"] | None = None,
) -> MeshResponses:
    """Per-mesh statistics of samples over one period: the one definition of the responses.

    **Arguments:**

    - ``p``: mesh deflections (m), shape ``(..., m, T)``, ``T`` samples uniformly spaced
      over one response period, the endpoint excluded;
    - ``F``: mesh forces (N) at the same instants, same shape;
    - ``b``: half backlash (m), ``(..., m)``;
    - ``F_static``: static mesh forces (N), ``(..., m)``; their signs name the loaded
      flanks;
    - ``radius``: lever arms (m), ``(..., m)``;
    - ``weights``: ``(T,)``, positive, summing to one: the averages (mean, RMS, shares)
      are weighted means over the samples (the windows of a quasi-periodic response,
      :func:`~gearjax._engine.windowed.window_weights`); ``None``: uniform, exact for a
      response with the period sampled.

    **Returns:** a :class:`MeshResponses` of shape ``(..., m)``. Shares of the period
    are sample counts over ``T`` (resolution ``1/T``; weighted where ``weights`` are
    given). Pure ``jnp``: ``jit``, ``vmap`` and ``grad`` (of the smooth statistics) pass
    through.
    """
    b = jnp.asarray(b)[..., None]
    F_static = jnp.asarray(F_static)

    def average(a):
        return jnp.mean(a, axis=-1) if weights is None else a @ weights

    mean = average(F)
    rms = jnp.sqrt(average((F - mean[..., None]) ** 2))
    peak = jnp.max(jnp.abs(F), axis=-1)
    loaded = F_static != 0
    safe_static = jnp.where(loaded, jnp.abs(F_static), 1.0)
    dlf = jnp.where(loaded, peak / safe_static, jnp.nan)
    contact = in_contact(p, b)
    separation = 1.0 - average(contact)
    # contact on the flank opposite the static force: p < -b when F_static > 0, p > b when < 0
    side = jnp.sign(F_static)[..., None]
    back = average(contact * (side * p < 0))
    back = jnp.where(loaded, back, jnp.nan)
    return MeshResponses(
        mean_force=mean,
        rms_force=rms,
        max_force=peak,
        dlf=dlf,
        separation=separation,
        back_contact=back,
        mean_torque=jnp.asarray(radius) * mean,
    )


def mesh_time_history(
    problem: HBProblem, X: Float[Array, "C n"], omega, n_time: int | None = None
):
    """Mesh deflections, rates and forces over one response period of a harmonic-balance
    solution.

    **Arguments:** ``problem``: the :class:`~gearjax._engine.hb.HBProblem` that ``X`` solves;
    ``X``: coefficients ``(2K+1, n)`` (rad or m), e.g. ``HBSolution.X``; ``omega``: base
    frequency ``Omega`` (rad/s); ``n_time``: samples ``T`` over the period (``None``:
    the problem's AFT grid; another value re-evaluates the stiffness and transmission
    error on the finer or coarser grid; at least ``2K + 2``).

    **Returns:** ``(p, p_dot, F)``, each ``(m, T)``: deflection (m), its rate (m/s) and
    the mesh force (N) at ``t_j = (2 pi eta / Omega) j / T``, from the one shared
    :func:`~gearjax.mesh_force`.
    """
    return _time_history(_on_grid(problem, n_time), X, omega)


def mesh_responses(
    problem: HBProblem,
    X: Float[Array, "C n"],
    omega,
    F_static: Float[Array, " m"],
    n_time: int | None = None,
) -> MeshResponses:
    """Per-mesh responses of a harmonic-balance solution.

    **Arguments:** ``problem``, ``X``, ``omega``, ``n_time``: as
    :func:`mesh_time_history`; ``F_static``: static mesh forces (N), ``(m,)``, from
    :func:`static_mesh_forces` (computed once per sweep, not per point).

    **Returns:** :class:`MeshResponses`, fields ``(m,)``. Pure ``jnp``: to batch over
    points, ``jax.vmap(mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs,
    omegas, F_static)`` gives fields ``(P, m)``.
    """
    return _responses(_on_grid(problem, n_time), X, omega, F_static)


def _on_grid(problem: HBProblem, n_time: int | None) -> HBProblem:
    """``problem`` with ``n_time`` samples on its grid (``None``: as it is)."""
    if n_time is not None and n_time != problem.n_time:
        problem = hb_problem(problem.system, dataclasses.replace(problem.settings, n_time=n_time))
    return problem


@one_program
def _time_history(problem: HBProblem, X, omega):
    return mesh_samples(problem, X @ problem.system.W.T, omega)


@one_program
def _responses(problem: HBProblem, X, omega, F_static) -> MeshResponses:
    p, _, F = _time_history(problem, X, omega)
    s = problem.system
    return responses_from_samples(p, F, s.backlash, F_static, s.mesh_radius)


def static_mesh_forces(system: System) -> Float[Array, " m"]:
    """Static mesh forces (N), ``(m,)``: mean stiffness, no backlash, mean torques only.

    Their signs name each mesh's loaded flank (positive: ``p > b``).
    """
    return static_deflection(system)[1]
