"""How many harmonics a periodic harmonic balance of a ``System`` needs, and whether it fits.

Three rules, each derived from the system, none a constant fitted on one train:

1. **Floor** (:func:`excitation_floor`): the solution holds at least the highest
   excitation order (stiffness, transmission error and torque-ripple harmonics of the
   base, times ``eta``). Fewer harmonics cannot hold the excitation itself: such a
   discretisation is refused, never used.
2. **First choice** (:func:`harmonics_rule`): enough harmonics of the response's base
   frequency to reach :func:`response_cutoff_hz`, ``CUTOFF_MARGIN`` times the highest
   elastic mode whose strain energy sits mostly in the meshes (the modes the mesh
   excitation drives; contact loss adds content above them), in steps of 16 (a sweep
   compiles once per step), for the first choice at most ``MAX_INITIAL`` per response
   period or twice the floor (a cost bound; never below the floor).
3. **A posteriori** (:func:`truncation_change`): the same point solved with twice the
   harmonics; the largest relative change of a mesh's RMS alternating force is the
   truncation estimate, checked against ``TRUNCATION_TARGET``. A sweep raises K where
   it is exceeded.

And a size rule (:func:`require_size`): the dense factorisation of the condensed
bordered Jacobian, ``C r + 1`` unknowns (``C = 2K+1`` coefficients, ``r`` the rank of
the mesh projection), dominates memory and time. A problem whose estimated memory
exceeds ``MEMORY_SHARE`` of the memory available is refused with the numbers, before
any work.

**On a torus** (``G > 1`` angles, model.md, "Incommensurate stages") the harmonics are
orders ``K = (K_1, ..., K_G)``, one per angle, of a truncation set (the diamond by
default, :data:`TORUS_TRUNCATION`). The same three rules hold per angle: the floor is
each angle's highest excitation order (:func:`orders_floor`); the first choice
(:func:`torus_orders_rule`) reaches the response cutoff on each angle's own base
frequency, in steps of half the floor, at most twice the floor (a cost bound: the set
holds about ``2 K_1 K_2`` wave vectors for ``G = 2``); and the a posteriori check
doubles one angle's order at a time (:func:`widened`), so that only the angle that
needs it grows. ``K`` is an ``int`` for a periodic system and a tuple on a torus
everywhere in the studies (:func:`as_orders`).
"""

from __future__ import annotations

import functools
import math
import time

import jax.numpy as jnp
import numpy as np

from .._engine import aft as _aft
from .resources import available_memory
from .._engine import hb as _hb
from .._engine import krylov as _krylov
from .._errors import bad_argument
from .._engine.modal import mode_classes
from .._engine.newton import newton_jit
from .._engine.programs import one_program
from .._engine.responses import mesh_responses
from .._engine.system import System

TRUNCATION_TARGET = 5e-3
"""Largest accepted relative change of a mesh's RMS alternating force when K doubles."""

CUTOFF_MARGIN = 5.0 / 3.0
"""Response content the first choice of K reaches, relative to the highest mesh mode:
tooth separation adds harmonics above the modes it excites. Only a first guess: the
truncation check decides."""

MAX_INITIAL = 64
"""Cap on the first choice of K per response period, unless twice the floor is more (a
cost bound); the truncation check raises K beyond it where the estimate asks for more."""

MEMORY_SHARE = 0.5
"""Share of the available memory one factorisation may take."""

RMS_FLOOR = 1e-3
"""Meshes whose RMS alternating force is below this share of the largest one are judged
against that share (a relative change of a negligible force is noise)."""


TORUS_TRUNCATION = "diamond"
"""The truncation set of a study's torus harmonic balance (:data:`gearjax.TRUNCATIONS`)."""


def excitation_floor(system: System, eta: int = 1) -> int:
    """The fewest solution harmonics that hold the excitation: its highest order (>= 1);
    on a torus, the largest of the angles' floors (:func:`orders_floor` gives each)."""
    return max(max(_hb.highest_excitation(system, eta, g), 1) for g in range(system.n_angles))


def orders_floor(system: System, eta: int = 1):
    """The floor of ``K``: :func:`excitation_floor` (an ``int``) for a periodic system, the
    highest excitation order of each angle (a tuple) on a torus."""
    if system.n_angles == 1:
        return excitation_floor(system, eta)
    return tuple(max(_hb.highest_excitation(system, eta, g), 1) for g in range(system.n_angles))


def as_orders(K):
    """``K`` as the studies keep it: an ``int`` (periodic) or a tuple of ints (torus; a
    list, e.g. read back from JSON, becomes a tuple)."""
    if isinstance(K, (tuple, list, np.ndarray)):
        return tuple(int(k) for k in K)
    return int(K)


def orders_text(K) -> str:
    """``K`` in words: ``"32"`` or ``"(8, 6)"``."""
    K = as_orders(K)
    return str(K) if isinstance(K, int) else "(" + ", ".join(str(k) for k in K) + ")"


def orders_json(K):
    """``K`` as JSON: an integer, or on a torus the list of orders per angle (``None``
    stays ``None``)."""
    if K is None:
        return None
    K = as_orders(K)
    return list(K) if isinstance(K, tuple) else K


def settings_for(system: System, K, **fields) -> _hb.HarmonicBalance:
    """The harmonic-balance settings of orders ``K`` on ``system`` (the torus truncation
    set :data:`TORUS_TRUNCATION` where ``K`` is a tuple). Where the solves at ``K`` are
    matrix-free (:func:`solves_by_krylov`) and a factorisation would not fit in
    ``MEMORY_SHARE`` of the available memory (:func:`memory_bytes`), ``linear_solver`` is
    ``"krylov"`` unless given: no fallback to a factorisation that cannot run (a solve
    that does not converge is reported as such)."""
    K = as_orders(K)
    if isinstance(K, tuple):
        fields.setdefault("truncation", TORUS_TRUNCATION)
    if "linear_solver" not in fields and solves_by_krylov(system, K) and (
            memory_bytes(system, K) > MEMORY_SHARE * available_memory()):
        fields["linear_solver"] = "krylov"
    return _hb.HarmonicBalance(n_harmonics=K, **fields)


MAX_INITIAL_COEFFICIENTS = 256
"""Cap on the coefficient rows of the first choice of torus orders (a cost bound, as
:data:`MAX_INITIAL` for a periodic balance, whose cap is ``2 MAX_INITIAL + 1 = 129``
rows): over it, the order of the angle furthest above its floor comes down first. The
truncation check raises an angle's order beyond it where the estimate asks for more."""


def torus_orders_rule(system: System, omega: float, *, cutoff_hz: float) -> tuple[int, ...]:
    """First choice of the orders ``K_g`` at base frequency ``omega`` (rad/s) on a torus:
    per angle ``g`` of base frequency ``angle_ratio[g] omega / (2 pi)`` Hz, enough orders
    to reach ``cutoff_hz``, rounded up to a step of half the angle's floor
    (:func:`orders_floor`), at least the floor and at most twice it; then, while the set
    has more than :data:`MAX_INITIAL_COEFFICIENTS` rows, the order furthest above its
    floor (relative to it) comes down a step."""
    floors = orders_floor(system)
    steps = [max(1, floor // 2) for floor in floors]
    K = []
    for floor, step, ratio in zip(floors, steps, system.angle_ratio):
        base = max(ratio * omega / (2 * math.pi), 1e-9)
        k = step * math.ceil(cutoff_hz / base / step)
        K.append(int(min(max(k, floor), 2 * floor)))
    while coefficient_count(system, tuple(K)) > MAX_INITIAL_COEFFICIENTS:
        above = [(K[g] / floors[g], g) for g in range(len(K)) if K[g] > floors[g]]
        if not above:
            break
        g = max(above)[1]
        K[g] = max(floors[g], K[g] - steps[g])
    return tuple(K)


def widened(K, g: int):
    """Orders ``K`` with angle ``g``'s doubled (``2K`` for a periodic ``int``)."""
    K = as_orders(K)
    if isinstance(K, int):
        return 2 * K
    return tuple(2 * k if i == g else k for i, k in enumerate(K))


def elastic_mode_span_hz(system: System) -> tuple[float, float] | None:
    """``(lowest, top)`` natural frequencies (Hz) of the elastic modes: ``top`` the
    highest whose strain energy is mostly (> 1/2) in the meshes, the highest elastic one
    where none is; ``None`` where the system has no elastic mode."""
    lam, _, shares, rigid, penalty = mode_classes(system)
    hz = np.sqrt(np.maximum(np.asarray(lam), 0.0)) / (2 * math.pi)
    elastic = ~np.asarray(rigid) & ~np.asarray(penalty)
    if not elastic.any():
        return None
    mesh = elastic & (np.asarray(shares["mesh"]) > 0.5)
    pick = mesh if mesh.any() else elastic
    return float(hz[elastic].min()), float(hz[pick].max())


def response_cutoff_hz(system: System) -> float:
    """``CUTOFF_MARGIN`` times the top elastic mode of :func:`elastic_mode_span_hz`; 0
    where the system has no elastic mode."""
    span = elastic_mode_span_hz(system)
    return 0.0 if span is None else CUTOFF_MARGIN * span[1]


def harmonics_rule(base_hz: float, min_harmonics: int, eta: int = 1, *,
                   cutoff_hz: float) -> int:
    """First choice of K at response base frequency ``base_hz`` (Hz, ``Omega / (2 pi
    eta)``): ``ceil16(cutoff_hz / base_hz)``, at most ``MAX_INITIAL * eta`` or twice the
    floor ``min_harmonics`` (:func:`excitation_floor`) where that is more, at least 16,
    never below the floor."""
    k = 16 * math.ceil(cutoff_hz / max(base_hz, 1e-9) / 16)
    cap = max(MAX_INITIAL * eta, 2 * min_harmonics)
    return int(max(min(max(k, 16), cap), min_harmonics))


def require_harmonics(system: System, K: int, eta: int = 1, *,
                      argument: str = "harmonics") -> None:
    """Refuse ``K`` below the excitation floor (on a torus: below any angle's floor; one
    ``K`` then stands for every angle).

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming ``argument``, the caller's
    name for ``K``."""
    floor = excitation_floor(system, eta)
    if int(K) != K or K < floor:
        where = " on every torus angle" if system.n_angles > 1 else ""
        raise bad_argument(argument, K, f"the solution needs at least {floor} harmonics"
                           f"{where}: {floor_reason(system, eta)}; fewer cannot hold the "
                           "excitation")


def floor_reason(system: System, eta: int = 1) -> str:
    """Where the floor comes from, in words (``H x max(mu)``, ripple orders, eta)."""
    H = max(system.k_cos.shape[-1], system.te_cos.shape[-1])
    mu = max(system.mesh_mu, default=0)
    text = f"stiffness harmonics H = {H} x mesh order max(mu) = {mu}"
    if system.forcing_mu:
        text += f", torque-ripple orders up to {max(system.forcing_mu)}"
    return text + (f", times eta = {eta}" if eta != 1 else "")


# ----------------------------------------------------------------------------- size


def torus_basis_of(system: System, K) -> _aft.Basis:
    """The torus truncation set of orders ``K`` on ``system`` (:data:`TORUS_TRUNCATION`;
    the grid is the smallest that carries it: for its wave vectors, not for an AFT)."""
    K = as_orders(K)
    return _aft.torus_basis(K, [2 * k + 2 for k in K], system.angle_ratio, TORUS_TRUNCATION)


def coefficient_count(system: System, K) -> int:
    """Coefficient rows ``C`` of the solution: ``2K+1``, or ``2P+1`` for the ``P`` wave
    vectors of the torus truncation set of orders ``K``."""
    K = as_orders(K)
    if isinstance(K, int):
        return 2 * K + 1
    return _aft.truncation_set_size(K, TORUS_TRUNCATION)


def factor_unknowns(system: System, K) -> int:
    """Unknowns of the bordered factorisation, ``C r + 1`` (:func:`coefficient_count`):
    ``r`` the motions that deflect a mesh where the solves condense the others out
    (``_hb.mesh_null_space``), else every degree of freedom."""
    null = _hb.mesh_null_space(system.W)
    r = system.n_dof - (0 if null is None else null.shape[1])
    return coefficient_count(system, K) * r + 1


def grid_samples(system: System, K) -> int:
    """Samples of the AFT grid at ``K``: ``T``, or the product ``T_1 ... T_G`` of the
    angles' samples on a torus (``_hb.time_samples``), counted without building it."""
    K = as_orders(K)
    Ks = (K,) if isinstance(K, int) else K
    return math.prod(_hb.time_samples(k, system, 1, g) for g, k in enumerate(Ks))


def _grid_bytes(system: System, K) -> int:
    """Memory of the arrays on the AFT grid: per mesh the stiffness, transmission error
    and its rate, the deflection, the force and their tangents (eight doubles a sample),
    and the sample's index along each angle."""
    return 8 * grid_samples(system, K) * (8 * system.n_meshes + system.n_angles)


def memory_bytes(system: System, K) -> int:
    """Estimated peak memory (bytes) of one Newton or continuation step at ``K``: the
    condensed matrix, its LU and the products that assemble it (about four copies of
    ``N^2`` doubles), the per-mesh Jacobian blocks with their projections
    (``m C^2 (r + 2)`` doubles) and the arrays on the AFT grid (:func:`grid_samples`)."""
    N = factor_unknowns(system, K)
    C = coefficient_count(system, K)
    r = (N - 1) // C
    return 8 * (4 * N * N + system.n_meshes * C * C * (r + 2)) + _grid_bytes(system, K)


def solves_by_krylov(system: System, K) -> bool:
    """Whether a Newton solve at ``K`` (``linear_solver = "auto"``) goes through the
    matrix-free solver (``_krylov.krylov_cheaper`` on the shapes of ``K``, counted
    without building the problem)."""
    C = coefficient_count(system, K)
    r = (factor_unknowns(system, K) - 1) // C
    return _krylov.krylov_cheaper(C, system.n_dof, r, system.n_meshes,
                                  grid_samples(system, K))


def krylov_memory_bytes(system: System, K) -> int:
    """Estimated peak memory (bytes) of one matrix-free Newton step at ``K``: the arrays
    on the AFT grid twice (the residual's, and the force slopes the products use,
    :func:`grid_samples`), the preconditioner's blocks (``C (2n)^2`` doubles) and the
    Newton and BiCGStab vectors (sixteen of ``C n`` doubles)."""
    C, n = coefficient_count(system, K), system.n_dof
    return 8 * (C * (2 * n) ** 2 + 16 * C * n) + 2 * _grid_bytes(system, K)


@functools.cache
def _lu_rate() -> float:
    """Floating-point operations per second of a dense LU on this machine (LAPACK through
    SciPy, 1024 unknowns, best of three)."""
    n = 1024
    a = np.random.default_rng(0).standard_normal((n, n)) + n * np.eye(n)
    import scipy.linalg  # on first use: its import costs every gearjax start

    best = math.inf
    for _ in range(3):
        t = time.perf_counter()
        scipy.linalg.lu_factor(a)
        best = min(best, time.perf_counter() - t)
    return (2 / 3) * n**3 / max(best, 1e-6)


def factor_seconds(system: System, K: int) -> float:
    """Estimated seconds of one dense factorisation at ``K`` on this machine."""
    return (2 / 3) * factor_unknowns(system, K) ** 3 / _lu_rate()


def require_size(system: System, K, *, argument: str = "harmonics", mu=None,
                 value=None) -> None:
    """Refuse ``K`` where one factorisation would not fit in ``MEMORY_SHARE`` of the
    available memory.

    **Raises:** ``ArgumentError`` (a ``TrainError``) naming ``argument`` (the caller's
    name for ``K``) with ``value`` (what the caller gave; default ``K``), ``mu``, K, the
    unknowns, the memory and a time estimate."""
    need, avail = memory_bytes(system, K), available_memory()
    if need <= MEMORY_SHARE * avail:
        return
    N = factor_unknowns(system, K)
    mu_text = f"mu = {list(mu)}: " if mu is not None else ""
    kind = "periodic" if isinstance(as_orders(K), int) else "torus"
    grid = (f" and an AFT grid of {grid_samples(system, K)} samples"
            if 2 * _grid_bytes(system, K) > need else "")
    raise bad_argument(argument, orders_text(K) if value is None else value,
                       f"{mu_text}{orders_text(K)} harmonics make a factorisation of {N} "
                       f"unknowns{grid}, about {_size(need)} of the {_size(avail)} available "
                       f"(at most {MEMORY_SHARE:.0%}) and about "
                       f"{factor_seconds(system, K):.0f} s each: too large for the {kind} "
                       "harmonic balance; reduce stiffness_harmonics or the "
                       "transmission-error harmonics, or integrate in time (gearjax "
                       "simulate)")


def _size(n_bytes: float) -> str:
    return f"{n_bytes / 1e9:.1f} GB" if n_bytes >= 1e9 else f"{n_bytes / 1e6:.0f} MB"


# ----------------------------------------------------------------------- a posteriori


MAX_CHECK_UNKNOWNS = 16384
"""Largest factorisation (unknowns) the truncation check may solve at 2K: a dense LU of
2.9e12 floating-point operations and 2 GB a copy. A check whose solve is matrix-free
(:func:`solves_by_krylov`) is bounded by memory only. Beyond it (or beyond the memory
share) the check is skipped and the result says so. A size, not a timing: the decision
is the same on every run."""


def check_affordable(system: System, K, g: int = 0) -> str | None:
    """``None`` where the truncation check of a point at ``K`` (a solve at ``2 K``; on a
    torus with angle ``g``'s order doubled, :func:`widened`) fits: matrix-free where
    :func:`solves_by_krylov` (its memory, :func:`krylov_memory_bytes`, within the
    memory share), else a factorisation of at most ``MAX_CHECK_UNKNOWNS`` within the
    memory share; else why not, in words."""
    K2 = widened(K, g)
    if solves_by_krylov(system, K2):
        need = krylov_memory_bytes(system, K2)
    else:
        N = factor_unknowns(system, K2)
        if N > MAX_CHECK_UNKNOWNS:
            return (f"a check at K = {orders_text(K2)} would factorise {N} unknowns, more "
                    f"than {MAX_CHECK_UNKNOWNS}")
        need = memory_bytes(system, K2)
    avail = available_memory()
    if need > MEMORY_SHARE * avail:
        return (f"a check at K = {orders_text(K2)} would need about {_size(need)} of the "
                f"{_size(avail)} available")
    return None


def truncation_change(problem: _hb.HBProblem, wide: _hb.HBProblem, y, omega,
                      F_static) -> float:
    """The truncation estimate of a converged point: the largest relative change of a
    mesh's RMS alternating force when the point ``y`` (scaled unknowns of ``problem``)
    at base frequency ``omega`` (rad/s) is solved again with ``wide``, the same problem
    with twice the harmonics (on a torus: one angle's, :func:`widened`; Newton from
    ``y`` padded with zeros), as :func:`rms_change`.

    **Returns:** the change; ``inf`` where the doubled solve does not converge.
    """
    C, n = problem.shape
    y2 = _aft.resize(problem.basis, wide.basis, np.asarray(y).reshape(C, n))
    sol = newton_jit(wide, jnp.asarray(omega, float), jnp.asarray(y2.reshape(-1)))
    if not bool(sol.converged):
        return math.inf
    X = jnp.asarray(np.asarray(y).reshape(C, n)) * problem.x_scale
    a = np.asarray(_rms_forces(problem, X, omega, F_static))
    b = np.asarray(_rms_forces(wide, sol.X, omega, F_static))
    return float(rms_change(a, b))


def rms_change(a, b):
    """The largest relative change of a mesh's RMS alternating force from ``a`` to ``b``
    (``(..., m)``, N; ``b`` the wider truncation's), over the last axis: a mesh below
    ``RMS_FLOOR`` of the largest of ``b`` is judged against that share. **Returns:** an
    array of the leading shape (NaN where a value is)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    floor = RMS_FLOOR * np.maximum(np.max(b, axis=-1, keepdims=True), 1e-300)
    return np.max(np.abs(a - b) / np.maximum(b, floor), axis=-1)


@one_program
def _rms_forces(problem: _hb.HBProblem, X, omega, F_static):
    """The meshes' RMS alternating forces (N) of a solution, in one compiled program."""
    return mesh_responses(problem, X, omega, F_static).rms_force


class TruncationWarning(UserWarning):
    """A result whose truncation estimate exceeds ``TRUNCATION_TARGET`` (kept, flagged)."""
