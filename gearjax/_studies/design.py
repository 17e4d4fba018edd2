"""Batched designs: one compiled call over a batch of design variants, sharded across devices.

A *design* is a parameter vector ``theta`` ``(p,)`` of a family ``theta -> System``
(:class:`~gearjax._studies.sensitivity.GearFamily`: the TOML paths of a train, e.g. planet
angles and phases). A batch ``thetas`` ``(B, p)`` is solved by one jitted function,

    vmap over designs ( assemble -> hb_problem -> vmap over frequencies ( solve -> responses ) ),

so the assembly and the Omega-independent harmonic-balance set-up run once per design
and every shape (designs, frequencies, harmonics, samples) is fixed: a batch of the
same size compiles once, whatever its values. The response is the RMS of the
alternating force of every mesh (N), per design and frequency.

Solvers (``solver``):

- ``"linear"``: one factorisation per point. Without backlash (``GearFamily(...,
  linear=True)``) the harmonic-balance residual is affine in the unknowns, so
  ``y = -J^-1 R(0)`` is the linear, time-varying solution (the stiffness variation and
  its parametric coupling kept, exactly what Newton converges to from any start); the
  residual is checked afterwards and a point whose residual is not small gets
  ``max_steps``. Differentiable by ``jax.grad`` (the solve is a plain
  ``jnp.linalg.solve``).
- ``"newton"``: :func:`gearjax._engine.newton.solve_hb` from the linear, in-contact
  guess, valid with backlash too (no continuation: far inside a non-linear regime, use
  :func:`gearjax.sweep`). ``jax.grad`` does not pass through the Newton iterations: the
  derivative is the implicit one at the converged point
  (:func:`gearjax._engine.adjoint.implicit_coefficients`).
- ``"auto"`` (default): ``"linear"`` when the nominal system has no backlash and no
  contact-only damping, else ``"newton"``.

Sharding. ``devices`` puts the design axis across devices: the batch is padded to a
multiple of the device count (copies of the last design, dropped from the output),
placed with ``NamedSharding(Mesh(devices, ("design",)), PartitionSpec("design"))``
(the train and a shared frequency grid replicated) and each device runs the same
function on its slice (``jax.shard_map``), so sharded and unsharded results agree to
rounding. On one host with several GPUs, ``devices=jax.devices()`` is all that
changes. On several hosts, call ``jax.distributed.initialize()`` in every process
first (coordinator address, process count and id, or the cluster's environment):
``jax.devices()`` then lists every device of every host, the same mesh spans them,
each process passes the same global ``thetas`` (or builds the global array with
``jax.make_array_from_process_local_data``), each host computes its own devices'
designs, and ``jax.experimental.multihost_utils.process_allgather`` brings the global
results to every host. Nothing here needs a GPU: on a CPU,
``XLA_FLAGS=--xla_force_host_platform_device_count=4`` (set before jax is imported)
makes four host devices to test it on; host devices then solve one point at a time
each (jaxlib's batched LAPACK kernels spread a batch over the host's thread pool and
wait for it, and host devices that all do so on a pool with fewer threads than devices
wait on each other forever).

Memory: a point holds a few dense ``N x N`` matrices (``N = (2K + 1) n``, 53 MB per
point at K = 32 on the paper train), so only as many points as fit in
``memory_bytes`` are solved at once (:func:`chunks`); the rest follow in sequence in the
same compiled call.

Quasi-periodic gears. Where a gear's mesh frequencies fall in ``G > 1`` incommensurate
groups, :func:`design_sweep` solves the torus harmonic balance (model.md,
"Incommensurate stages"): the family carries the gear's torus layout, ``K`` is a tuple
of orders per angle (``harmonics`` on every angle, or each angle's excitation floor),
and ``N = (2P + 1) n`` for the ``P`` wave vectors of the truncation set. Every solver
above is generic over the basis.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from jaxtyping import Array, Float

from .._engine import aft as _aft
from .._engine import hb as _hb
from .._engine.results import RESULTS, result_word
from .._engine.adjoint import implicit_coefficients
from .._engine.newton import solve_hb
from .._engine.responses import mesh_responses, static_mesh_forces
from .._errors import bad_argument
from .._gear.case import gear_case, torus_fields
from .._io.results import json_number
from .._gear.train import Train
from . import harmonics as _harmonics
from .sensitivity import GearFamily, check_paths

SOLVERS = ("auto", "linear", "newton")


# -------------------------------------------------------------------- point solvers


def linear_solve(problem: _hb.HBProblem, omega) -> tuple[Array, Array]:
    """``(X, result)`` (a ``RESULTS`` item): the harmonic balance of a system without
    backlash in one factorisation, ``y = -J^-1 R(0)`` (scaled unknowns, flat ``(N,)``), as
    coefficients ``X = y x_scale`` ``(2K+1, n)``.

    Exact when the residual is affine in ``y`` (no backlash, no contact-only damping):
    one Newton step ``y = y0 - J(y0)^-1 R(y0)`` from any ``y0``. The step starts from a
    fixed, nowhere-special ``y0`` (not 0: at a zero deflection the clearance function
    ``p - clip(p, -b, b)`` with ``b = 0`` sits on its kink, where autodiff gives a
    one-sided slope). The result is ``nonlinear_max_steps_reached`` when the residual at
    ``y`` is not below Newton's test (``sqrt(rtol)``), ``nonfinite`` on a non-finite
    solution.
    Differentiable: the solve is a plain ``jnp.linalg.solve``.
    """
    omega = jnp.asarray(omega, dtype=float)
    y0 = jnp.cos(1.2345 * jnp.arange(problem.size))
    y = y0 - jnp.linalg.solve(_hb.jacobian(problem, y0, omega), _hb.residual(problem, y0, omega))
    norm = jnp.max(jnp.abs(_hb.residual(problem, y, omega)))
    ok = norm <= jnp.sqrt(problem.settings.rtol)
    code = RESULTS.where(~jnp.all(jnp.isfinite(y)), RESULTS.nonfinite,
                         RESULTS.where(ok, RESULTS.successful,
                                       RESULTS.nonlinear_max_steps_reached))
    return y.reshape(problem.shape) * problem.x_scale, code


def newton_solve(problem: _hb.HBProblem, omega) -> tuple[Array, Array]:
    """``(X, result)`` by :func:`gearjax._engine.newton.solve_hb` from the linear,
    in-contact guess, as coefficients ``X`` ``(2K+1, n)``; differentiable: the Newton
    iterations see stop-gradient inputs and the derivative is the implicit one
    (:func:`gearjax._engine.adjoint.implicit_coefficients`)."""
    omega = jnp.asarray(omega, dtype=float)
    sol = solve_hb(jax.lax.stop_gradient(problem), jax.lax.stop_gradient(omega))
    return implicit_coefficients(problem, sol.y, omega), sol.result


def _point_rms(problem: _hb.HBProblem, omega, solver: str, F_static):
    X, code = (linear_solve if solver == "linear" else newton_solve)(problem, omega)
    return mesh_responses(problem, X, omega, F_static).rms_force, code


MEMORY_BYTES = 2e9
"""Default bound on the memory the points solved at once may take (bytes): a point holds
a few dense ``N x N`` matrices (Jacobian, its factors, the Kronecker blocks)."""


def point_bytes(settings: _hb.HarmonicBalance, n_dof: int) -> int:
    """Rough memory of one point in flight (bytes): ``64 N^2``, ``N = C n`` with ``C =
    2K + 1`` coefficient rows (``2P + 1`` for the ``P`` wave vectors of a torus
    truncation set, orders ``K`` a tuple) (eight dense float64 ``N x N`` arrays)."""
    K = settings.n_harmonics
    if isinstance(K, tuple):
        C = _aft.torus_basis(K, [2 * k + 2 for k in K], (1.0,) * len(K),
                             settings.truncation).n_coefficients
    else:
        C = 2 * K + 1
    N = C * n_dof
    return 64 * N * N


def chunks(n_designs: int, settings: _hb.HarmonicBalance, n_dof: int,
           memory_bytes: float = MEMORY_BYTES) -> tuple[int, int]:
    """``(designs, frequencies)`` solved at once so that their points fit in
    ``memory_bytes``: every design and as many frequencies as fit, else designs in
    groups and one frequency at a time."""
    fit = max(1, int(memory_bytes // point_bytes(settings, n_dof)))
    if n_designs <= fit:
        return n_designs, max(1, fit // n_designs)
    return fit, 1


def design_kernel(family, thetas: Float[Array, "B p"], omegas: Float[Array, "*B F"],
                  settings: _hb.HarmonicBalance, solver: str,
                  batches: tuple[int | None, int | None] = (None, None)):
    """The batched computation, unjitted: ``(rms (B, F, m), result (B, F))``.

    Over designs of (``family(theta)`` -> ``hb_problem`` -> static forces -> over
    ``omegas`` of the point solve and :func:`~gearjax.mesh_responses`). ``omegas``:
    ``(F,)`` shared, or ``(B, F)`` a grid per design. ``solver`` is ``"linear"`` or
    ``"newton"`` (module docstring). ``batches``: ``(designs, frequencies)`` vmapped at
    once, the rest in sequence (``jax.lax.map``); ``None``: all at once; 1: one at a time,
    unbatched.
    """
    d_batch, f_batch = batches

    def over(fn, xs, batch, n):
        if batch is None or batch >= n:
            return jax.vmap(fn)(xs)
        return jax.lax.map(fn, xs) if batch == 1 else jax.lax.map(fn, xs, batch_size=batch)

    def one_design(args):
        theta, om = args
        problem = _hb.hb_problem(family(theta), settings)
        F_static = static_mesh_forces(problem.system)
        return over(lambda w: _point_rms(problem, w, solver, F_static), om, f_batch,
                    om.shape[-1])

    om = omegas if omegas.ndim == 2 else jnp.broadcast_to(omegas, thetas.shape[:1] + omegas.shape)
    return over(one_design, (thetas, om), d_batch, thetas.shape[0])


_design_jit = eqx.filter_jit(design_kernel)


@eqx.filter_jit
def _design_sharded(family, thetas, omegas, settings, solver: str, mesh: Mesh, batches):
    spec, whole = PartitionSpec("design"), PartitionSpec()
    local = jax.shard_map(
        lambda fam, th, om: design_kernel(fam, th, om, settings, solver, batches), mesh=mesh,
        in_specs=(whole, spec, spec if omegas.ndim == 2 else whole), out_specs=(spec, spec),
        check_vma=False)
    return local(family, thetas, omegas)


def design_mesh(devices: Sequence | None = None) -> Mesh:
    """A one-axis device mesh named ``"design"`` over ``devices`` (default: every device
    JAX sees, all hosts' after ``jax.distributed.initialize``)."""
    devices = jax.devices() if devices is None else list(devices)
    if not devices:
        raise ValueError("design_mesh: at least one device is required")
    return Mesh(np.asarray(devices), ("design",))


def shard_designs(thetas, mesh: Mesh) -> tuple[Array, int]:
    """``(thetas padded to a multiple of the mesh size and sharded on its leading axis,
    the original batch size)``. Padding repeats the last design."""
    thetas = jnp.asarray(thetas, dtype=float)
    B = thetas.shape[0]
    pad = (-B) % mesh.size
    if pad:
        thetas = jnp.concatenate([thetas, jnp.repeat(thetas[-1:], pad, axis=0)])
    return _placed(thetas, NamedSharding(mesh, PartitionSpec("design"))), B


def _placed(tree, sharding):
    """``tree``'s arrays put on ``sharding``, waited for. Every input of the sharded call
    is placed before it runs: XLA:CPU otherwise copies inputs committed to one device
    onto the others on the same worker pool that the per-device executions wait on, and
    with several host-platform devices on a two-core machine that can deadlock."""
    arrays, rest = eqx.partition(tree, eqx.is_array)
    return eqx.combine(jax.block_until_ready(jax.device_put(arrays, sharding)), rest)


def batched_rms(family, thetas, omegas, settings: _hb.HarmonicBalance, *,
                solver: str = "linear", devices: Sequence | Mesh | None = None,
                memory_bytes: float = MEMORY_BYTES) -> tuple[Array, Array]:
    """RMS alternating mesh forces of a batch of designs at a grid of frequencies.

    **Arguments:** ``family``: ``theta -> System`` (an ``equinox.Module``, e.g.
    :class:`~gearjax._studies.sensitivity.GearFamily`); ``thetas`` ``(B, p)``; ``omegas``:
    base frequencies (rad/s), ``(F,)`` for every design or ``(B, F)`` one grid per
    design; ``settings``: harmonic balance (K, samples); ``solver``: ``"linear"`` or
    ``"newton"`` (module docstring); ``devices``: ``None`` (the default device), a list
    of devices or a ``Mesh`` with the axis ``"design"``: shard the designs across them;
    ``memory_bytes``: bound on the points in flight per device (:func:`chunks`: the rest
    run in sequence inside the same compiled call).

    **Returns:** ``(rms, result)``: ``(B, F, m)`` RMS forces (N) and a ``(B, F)``
    batched :class:`~gearjax._engine.results.RESULTS` item. Differentiable in ``thetas`` when
    unsharded.
    """
    if solver not in ("linear", "newton"):
        raise ValueError(f"solver must be 'linear' or 'newton', not {solver!r}")
    thetas = jnp.asarray(thetas, dtype=float)
    omegas = jnp.asarray(omegas, dtype=float)
    if omegas.ndim == 2 and omegas.shape[0] != thetas.shape[0]:
        raise ValueError(f"omegas per design must have shape ({thetas.shape[0]}, F), not "
                         f"{omegas.shape}")
    train = getattr(family, "train", None)
    n_dof = train.n_dof if isinstance(train, Train) else jax.eval_shape(family, thetas[0]).n_dof
    if devices is None:
        batches = chunks(thetas.shape[0], settings, n_dof, memory_bytes)
        return _design_jit(family, thetas, omegas, settings, solver, batches)
    mesh = devices if isinstance(devices, Mesh) else design_mesh(devices)
    sharded, B = shard_designs(thetas, mesh)
    if omegas.ndim == 2:
        omegas, _ = shard_designs(omegas, mesh)
    else:
        omegas = _placed(omegas, NamedSharding(mesh, PartitionSpec()))
    family = _placed(family, NamedSharding(mesh, PartitionSpec()))
    batches = chunks(sharded.shape[0] // mesh.size, settings, n_dof, memory_bytes)
    if mesh.devices.flat[0].platform == "cpu":
        # one point at a time per host device: jaxlib's batched LAPACK kernels spread a
        # batch over the host's intra-op pool and wait for it, so host devices that each
        # run one on a pool with fewer workers than devices wait on each other forever
        batches = (1, 1)
    rms, code = _design_sharded(family, sharded, omegas, settings, solver, mesh, batches)
    return rms[:B], jax.tree.map(lambda a: a[:B], code)


# ------------------------------------------------------------------------ gear level


@dataclasses.dataclass(frozen=True)
class DesignSweep:
    """Responses of a batch of designs over a frequency grid.

    **Fields:** ``paths`` (TOML paths), ``thetas`` ``(B, p)`` (file units);
    ``frequencies_hz`` ``(F,)`` (reference-stage mesh frequency), ``omega`` ``(F,)``
    (rad/s); ``rms_force`` ``(B, F, m)`` (N; NaN where a point failed); ``result``
    ``(B, F)`` words (:func:`~gearjax._engine.results.result_word`); ``converged``
    ``(B, F)``; ``peak`` ``(B,)``: the largest RMS over
    converged points and meshes (N); ``meshes`` (names); ``gear``, ``reference_stage``,
    ``harmonics`` (K; on a torus the orders per angle, a tuple), ``linear``,
    ``solver``, ``devices`` (how many the designs were spread over); ``torus``: what a
    torus study solves (:func:`~gearjax._gear.case.torus_fields`), ``None`` for a
    periodic gear (``omega`` is then the base of torus angle 0); ``truncation``: the a
    posteriori check at each design's peak (:func:`peak_truncation`).
    """

    paths: tuple[str, ...]
    thetas: np.ndarray
    frequencies_hz: np.ndarray
    omega: np.ndarray
    rms_force: np.ndarray
    result: np.ndarray
    converged: np.ndarray
    peak: np.ndarray
    meshes: tuple[str, ...]
    gear: str
    reference_stage: str
    harmonics: int | tuple[int, ...]
    linear: bool
    solver: str
    devices: int
    torus: dict | None = None
    truncation: dict | None = None


def design_sweep(
    train: Train,
    gear: str | None = None,
    paths: Sequence[str] = (),
    thetas=(),
    frequencies_hz: Sequence[float] = (),
    *,
    stage: str | None = None,
    linear: bool = True,
    harmonics: int | None = None,
    solver: str = "auto",
    devices: Sequence | Mesh | None = None,
) -> DesignSweep:
    """RMS mesh forces of ``B`` variants of ``train`` at reference-stage mesh frequencies.

    **Arguments:** ``paths``: TOML paths (``1.planet_angles_deg.2``,
    ``1.sun_ring_phase_deg``, ...); ``thetas`` ``(B, p)``: their values per design (file
    units); ``frequencies_hz``: reference-stage mesh frequencies (Hz); ``stage``: the
    reference stage (default: the first turning one); ``linear``: drop the backlash
    (default: the linear, time-varying model); ``harmonics``: K on every torus angle,
    kept, its truncation checked at each design's peak (:func:`peak_truncation`) and
    warned about (:class:`~gearjax._studies.harmonics.TruncationWarning`) where the
    estimate exceeds the target; default: the excitation floor
    (:func:`~gearjax._studies.harmonics.orders_floor`, each angle's highest excitation
    order), raised per angle and the batch solved again while the check exceeds the
    target and the next check is affordable, as a sweep raises a segment's K;
    ``solver``: module docstring; ``devices``: shard the designs (module docstring).

    **Returns:** :class:`DesignSweep`. One compilation per batch size, frequency count
    and K, and one per check. **Raises:** ``ArgumentError`` (a ``TrainError``) naming
    the argument for bad ``paths``, ``thetas``, ``frequencies_hz`` or ``solver``;
    ``TrainError`` for bad harmonics, and as :func:`~gearjax._gear.case.gear_case` for
    the gear and stage.
    """
    case = gear_case(train, gear, stage, linear, torus=True)
    leaves = check_paths(train, paths)
    paths = tuple(leaf.path for leaf in leaves)
    th = np.asarray(thetas, dtype=float)
    if th.ndim != 2 or th.shape[1] != len(paths) or th.shape[0] < 1:
        raise bad_argument("thetas", list(th.shape),
                           f"must have shape (designs, {len(paths)}) for `paths` {list(paths)}")
    f = np.asarray(frequencies_hz, dtype=float).reshape(-1)
    if f.size < 1 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise bad_argument("frequencies_hz", f.tolist(), "must be positive frequencies in Hz")
    family = GearFamily.of(train, paths, case.gear.name, linear, case.layout)
    nominal = case.system
    K = orders_of(nominal, harmonics)
    _harmonics.require_size(nominal, K, mu=case.mu)
    solver = resolve_solver(solver, nominal)
    omegas = case.omega(f)
    while True:
        rms, code = batched_rms(family, th, omegas, _harmonics.settings_for(nominal, K),
                                solver=solver, devices=devices)
        rms, ok = np.asarray(rms), np.asarray(code == RESULTS.successful)
        rms = np.where(ok[..., None], rms, np.nan)
        truncation = peak_truncation(family, nominal, th, omegas, rms, K, solver=solver,
                                     devices=devices)
        short = short_angles(truncation)
        if not short or harmonics is not None:
            break
        for g in short:  # K chosen here: raise the short angles' orders, as a sweep does
            K = _harmonics.widened(K, g)
    warn_truncation(truncation, "design sweep")
    code = result_word(code)
    n_dev = 1 if devices is None else (devices.size if isinstance(devices, Mesh)
                                       else len(list(devices)))
    return DesignSweep(paths=paths, thetas=th, frequencies_hz=f, omega=np.asarray(omegas),
                       rms_force=rms, result=code, converged=ok, peak=peak_of(rms),
                       meshes=tuple(nominal.mesh_labels), gear=case.gear.name,
                       reference_stage=case.stage, harmonics=K, linear=linear,
                       solver=solver, devices=n_dev, torus=torus_fields(case),
                       truncation=truncation)


def peak_truncation(family, system, thetas, omegas, rms, K, *, solver: str = "linear",
                    devices: Sequence | Mesh | None = None) -> dict:
    """The a posteriori truncation check of a batch of designs, as a sweep makes it for a
    segment: each design solved again at its peak (the frequency of its largest RMS over
    converged points and meshes) with one angle's order doubled at a time
    (:func:`~gearjax._studies.harmonics.widened`), from the same start as the batch, and
    the largest relative change of a mesh's RMS alternating force
    (:func:`~gearjax._studies.harmonics.rms_change`, as
    :func:`~gearjax._studies.harmonics.truncation_change`).

    **Arguments:** ``family``: ``theta -> System``; ``system``: the nominal system (its
    sizes decide whether a check is affordable,
    :func:`~gearjax._studies.harmonics.check_affordable`); ``thetas`` ``(B, p)``;
    ``omegas`` ``(F,)`` or ``(B, F)`` (rad/s) and ``rms`` ``(B, F, m)`` (N, NaN where a
    point failed): the batch at orders ``K``; ``solver``, ``devices``: as
    :func:`batched_rms`.

    **Returns:** a dict: ``target`` (``TRUNCATION_TARGET``); ``checks``, per angle:
    ``K``, ``K_check`` and ``change`` (the largest over the designs; ``None`` where no
    design's check converged) or ``skipped`` (why not affordable); ``change`` ``(B,)``
    per design, the largest over the angles checked (NaN where the design has no
    converged point, a doubled solve of it failed, or no angle could be checked);
    ``frequency_hz`` ``(B,)``: base frequencies of the peaks (Hz)."""
    rms = np.asarray(rms, dtype=float)
    B = rms.shape[0]
    om = np.broadcast_to(np.asarray(omegas, dtype=float), rms.shape[:2])
    per_f = np.max(np.where(np.isfinite(rms), rms, -np.inf), axis=-1)
    has = np.any(np.isfinite(per_f), axis=1)
    j = np.argmax(per_f, axis=1)
    om_peak, a = om[np.arange(B), j], rms[np.arange(B), j]
    change, checked, checks = np.zeros(B), False, []
    for g in range(system.n_angles):
        K2 = _harmonics.widened(K, g)
        pair = {"K": _harmonics.orders_json(K), "K_check": _harmonics.orders_json(K2)}
        skip = _harmonics.check_affordable(system, K, g)
        if skip is not None:
            checks.append({**pair, "change": None, "skipped": skip})
            continue
        b, code = batched_rms(family, thetas, om_peak[:, None],
                              _harmonics.settings_for(system, K2), solver=solver,
                              devices=devices)
        ok = np.asarray(code == RESULTS.successful)[:, 0] & has
        c = np.where(ok, _harmonics.rms_change(a, np.asarray(b)[:, 0]), np.nan)
        change, checked = np.maximum(change, c), True
        checks.append({**pair, "change": float(np.nanmax(c)) if np.any(ok) else None})
    return {"target": _harmonics.TRUNCATION_TARGET, "checks": checks,
            "change": change if checked else np.full(B, np.nan),
            "frequency_hz": om_peak / (2 * np.pi)}


def short_angles(truncation: dict) -> list[int]:
    """The torus angles (``[0]`` for a periodic gear) whose check in ``truncation``
    (:func:`peak_truncation`) exceeds the target."""
    return [g for g, c in enumerate(truncation["checks"])
            if c["change"] is not None and c["change"] > truncation["target"]]


def warn_truncation(truncation: dict, study: str, advice: str | None = None) -> None:
    """One :class:`~gearjax._studies.harmonics.TruncationWarning` where a check of
    :func:`peak_truncation` exceeds the target (none otherwise): the largest estimate,
    at which design's peak (index in the batch, base frequency) and against which
    orders, in the words of ``study``, with ``advice`` (default: raise ``harmonics`` or
    let ``study`` choose it)."""
    change = np.asarray(truncation["change"])
    if not short_angles(truncation):
        return
    b = int(np.nanargmax(change))
    check = max((c for c in truncation["checks"] if c["change"] is not None),
                key=lambda c: c["change"])
    warnings.warn(_harmonics.TruncationWarning(
        f"{study}: K = {_harmonics.orders_text(check['K'])}: truncation estimate "
        f"{change[b]:.2%} at design {b}'s peak ({truncation['frequency_hz'][b]:.1f} Hz, "
        f"base; the largest of {change.size} designs; RMS mesh force change against K = "
        f"{_harmonics.orders_text(check['K_check'])}; target "
        f"{truncation['target']:.1%}): "
        + (advice or f"raise `harmonics`, or omit it to let the {study} choose K")),
        stacklevel=3)


def truncation_json(truncation: dict) -> dict:
    """:func:`peak_truncation`'s check as JSON values (NaN as ``None``)."""
    return {"target": truncation["target"], "checks": truncation["checks"],
            "change": [json_number(x) for x in truncation["change"]],
            "frequency_hz": [float(x) for x in truncation["frequency_hz"]]}


def orders_of(system, harmonics: int | None):
    """The orders ``K`` of a batched design study on ``system``: ``harmonics`` (on every
    torus angle where ``G > 1``: a tuple), default the excitation floor
    (:func:`~gearjax._studies.harmonics.orders_floor`: an ``int``, or each angle's floor).

    **Raises:** ``ArgumentError`` naming ``harmonics`` below the floor."""
    if harmonics is None:
        return _harmonics.orders_floor(system)
    _harmonics.require_harmonics(system, harmonics)
    return (int(harmonics),) * system.n_angles if system.n_angles > 1 else int(harmonics)


def resolve_solver(solver: str, system) -> str:
    """``"auto"`` -> ``"linear"`` for a system without backlash or contact-only damping,
    else ``"newton"``.

    **Raises:** ``ArgumentError`` naming ``solver`` for an unknown solver, and for
    ``"linear"`` on a system with backlash or contact-only damping."""
    if solver not in SOLVERS:
        raise bad_argument("solver", solver, f"must be one of {', '.join(SOLVERS)}")
    affine = not bool(np.any(np.asarray(system.backlash) != 0)) and not system.contact_damping
    if solver == "auto":
        return "linear" if affine else "newton"
    if solver == "linear" and not affine:
        raise bad_argument("solver", solver,
                           "the one-factorisation solver needs a system without backlash and "
                           "with damping that always acts; use 'newton'")
    return solver


def peak_of(rms: np.ndarray, mesh_mask=None) -> np.ndarray:
    """Largest finite value over every axis but the first (NaN where none is finite);
    ``mesh_mask`` ``(m,)`` restricts the last axis."""
    rms = np.asarray(rms, dtype=float)
    if mesh_mask is not None:
        rms = rms[..., np.asarray(mesh_mask, dtype=bool)]
    flat = rms.reshape(rms.shape[0], -1)
    out = np.full(flat.shape[0], np.nan)
    has = np.any(np.isfinite(flat), axis=1)
    out[has] = np.nanmax(flat[has], axis=1)
    return out
