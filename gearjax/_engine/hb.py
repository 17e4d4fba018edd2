"""Multi-term harmonic balance on a ``System``, periodic or on a torus: the problem,
AFT residual, structured Jacobian.

The periodic solution of period ``2 pi eta / Omega`` is ``x(tau)`` with
``tau = omega_0 t``, ``omega_0 = Omega / eta``, stored as real coefficients
``X`` of shape ``(2K+1, n)`` (see ``_aft``). Mesh ``m`` varies at ``mu_m Omega``, so
its stiffness harmonic ``h`` is harmonic ``h mu_m eta`` of ``tau``. A system of
``G > 1`` torus angles (model.md, "Incommensurate stages") has the quasi-periodic
solution ``x(theta)``, ``theta_g = angle_ratio[g] Omega t``, with coefficients
``(2P+1, n)`` on the truncation set of a :class:`~gearjax._engine.aft.Basis`; mesh
``m`` varies with ``mu_m`` times its own angle. The periodic balance is the basis of
``K`` harmonics on one angle: one code path. The residual per cosine-sine pair of
wave vector ``k`` (frequency ``nu_k omega_0``, ``nu_k = k . rates``) is

    R = K X + omega_0^2 M D^2 X + omega_0 C D X + W^T F_hat(W X) - f_hat

with ``D`` the derivative over ``omega_0 t`` and the mesh forces ``F = kbar kappa g(p)
+ c p'`` evaluated on the AFT grid by the one shared ``mesh_force`` (inverse FFT ->
forces -> FFT).

Unknowns and residual are scaled: ``X = Y * x_scale`` with ``x_scale`` the
rotation that deflects a mesh by the characteristic length (the largest backlash
or static mesh deflection), and each residual row divided by the magnitude of its
linear diagonal (``|Kt_ii| + (nu omega_0)^2 M_ii + nu omega_0 |C_ii|``, times
``x_scale_i``): the 1e10 brake springs and the planet inertias then give rows of
one size.

The Jacobian exploits structure: each mesh force depends on one scalar deflection,
so ``dR/dX = L(omega) + sum_m (w_m w_m^T) (x) J_m`` with ``J_m`` the
``C x C`` derivative of the mesh's force coefficients with respect to its deflection
coefficients (exact, forward mode through the mesh's AFT map), and
``L = I (x) K + omega_0^2 D^2 (x) M + omega_0 D (x) C`` block-diagonal over pairs.

The solvers are elsewhere: Newton at a fixed frequency in :mod:`gearjax._engine.newton`,
the condensed factorisation in :mod:`gearjax._engine.bordered`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import aft as _aft
from .mesh_force import mesh_force, stiffness_series, transmission_error
from .programs import one_program
from .results import RESULTS
from .static import static_deflection
from .system import System



LINEAR_SOLVERS = ("auto", "lu", "krylov")
"""Values of ``HarmonicBalance.linear_solver``."""


class HarmonicBalance(eqx.Module):
    """Harmonic-balance settings (static: they are compile keys).

    **Fields:** ``n_harmonics``: K, harmonics of ``Omega / eta`` in the solution; on a
    system of ``G > 1`` torus angles, ``K_g`` per angle (one int: the same for every
    angle); ``truncation``: the torus truncation set, ``"diamond"`` or ``"box"``
    (``gearjax._engine.aft.torus_basis``; no effect for ``G = 1``);
    ``n_time``: T, time samples per period for the AFT, per angle on a torus (``None``:
    the rule of :func:`time_samples`); ``eta``: sub-harmonic index (1 on a torus);
    ``rtol``: Newton tolerance on
    the scaled step and residual; ``max_steps``: Newton iterations; ``smoothing``: 0 for
    the exact piecewise-linear backlash, ``s > 0`` rounds its corners over ``s b``
    (``gearjax._engine.mesh_force.backlash``): an option for branches that graze a contact boundary;
    ``linear_solver``: how Newton and implicit derivatives solve with the Jacobian, one of
    :data:`LINEAR_SOLVERS`: ``"lu"`` the condensed factorisation
    (:mod:`gearjax._engine.bordered`), ``"krylov"`` preconditioned BiCGStab on
    Jacobian-vector products (:mod:`gearjax._engine.krylov`; the continuation's bordered
    solves too), ``"auto"`` the one that costs less for the problem's size
    (:func:`gearjax._engine.krylov.uses_krylov`), falling back to the LU where BiCGStab
    does not converge (the continuation factorises).
    """

    n_harmonics: int | tuple[int, ...] = eqx.field(static=True, default=32)
    n_time: int | tuple[int, ...] | None = eqx.field(static=True, default=None)
    eta: int = eqx.field(static=True, default=1)
    rtol: float = eqx.field(static=True, default=1e-9)
    max_steps: int = eqx.field(static=True, default=40)
    smoothing: float = eqx.field(static=True, default=0.0)
    truncation: str = eqx.field(static=True, default="diamond")
    linear_solver: str = eqx.field(static=True, default="auto")


def highest_excitation(system: System, eta: int = 1, angle: int = 0) -> int:
    """Highest harmonic of torus angle ``angle`` (of ``tau`` for a periodic system)
    present in the excitation (stiffness, TE, forcing)."""
    H = max(system.k_cos.shape[-1], system.te_cos.shape[-1])
    orders = ([H * mu * eta for mu, g in zip(system.mesh_mu, system.mesh_angles) if g == angle]
              + [mu * eta for mu, g in zip(system.forcing_mu, system.forcing_angles)
                 if g == angle])
    return max(orders + [0])


SAMPLES_PER_ORDER = 16
"""AFT samples per period of the highest order, per angle (:func:`time_samples`)."""

DENSE_TORUS_SAMPLES_PER_ORDER = 8
"""AFT samples per period of the highest order of each angle on a torus of three or more
angles (:func:`time_samples`), whose grid holds their product."""


def time_samples(n_harmonics: int, system: System, eta: int = 1, angle: int = 0) -> int:
    """The AFT sample rule, per torus angle: the smallest power of two >= ``S`` max(K,
    highest excitation of the angle), ``S`` = :data:`SAMPLES_PER_ORDER` (16) on a period
    or a 2-torus and :data:`DENSE_TORUS_SAMPLES_PER_ORDER` (8) on a torus of three or
    more angles.

    A product of the stiffness (highest excitation order) and a deflection (K) has
    content up to their sum; the kinks of the piecewise-linear backlash add more, and
    their sampling error falls about as T^-3: 16x oversampling keeps a doubling of T
    below 0.1% of the RMS forces (checked by tests/engine/test_hb_rules.py, and on a
    2-torus by tests/engine/test_torus.py). The grid of a torus is the product of its
    angles': 16 per angle would make a 3-torus grid 4096 times a period's; 8 per angle
    also keeps a doubling of every angle's samples below 0.1% of the RMS forces
    (tests/engine/test_torus.py -k grid_rule), but its orbit is coarser pointwise, so a
    2-torus keeps 16.
    """
    per = SAMPLES_PER_ORDER if system.n_angles <= 2 else DENSE_TORUS_SAMPLES_PER_ORDER
    need = per * max(n_harmonics, highest_excitation(system, eta, angle), 1)
    return int(2 ** int(np.ceil(np.log2(need))))


def _per_angle(value, G: int, name: str) -> tuple[int, ...]:
    values = tuple(int(v) for v in value) if isinstance(value, (tuple, list)) else (
        int(value),) * G
    if len(values) != G:
        raise ValueError(f"HarmonicBalance.{name} = {value}: the system has {G} torus angles, "
                         f"so one value or {G}")
    return values


def harmonic_basis(system: System, settings: "HarmonicBalance") -> _aft.Basis:
    """The basis of ``settings`` on ``system``: ``K`` harmonics of ``tau`` for a periodic
    system, the truncation set ``settings.truncation`` of ``K_g`` per angle on a torus.

    **Raises:** ``ValueError`` where the discretisation cannot hold the excitation:
    ``K_g`` below the angle's highest excitation order (:func:`highest_excitation`),
    ``n_time`` too few samples for the product of the stiffness and a deflection
    (``2 K + highest`` or fewer: aliased), ``eta > 1`` on a torus, or a
    ``linear_solver`` not in :data:`LINEAR_SOLVERS`.
    """
    G, eta = system.n_angles, settings.eta
    if settings.linear_solver not in LINEAR_SOLVERS:
        raise ValueError(f"HarmonicBalance.linear_solver = {settings.linear_solver!r}: one of "
                         f"{', '.join(repr(v) for v in LINEAR_SOLVERS)}")
    if G > 1 and eta != 1:
        raise ValueError(f"HarmonicBalance.eta = {eta}: sub-harmonic solutions are periodic; "
                         f"a system of {G} torus angles has eta = 1")
    Ks = _per_angle(settings.n_harmonics, G, "n_harmonics")
    times = (None,) * G if settings.n_time is None else _per_angle(settings.n_time, G, "n_time")
    grid = []
    for g, (K, T) in enumerate(zip(Ks, times)):
        top = highest_excitation(system, eta, g)
        where = f" of torus angle {g}" if G > 1 else ""
        if K < max(top, 1):
            raise ValueError(f"HarmonicBalance.n_harmonics = {settings.n_harmonics}: the "
                             f"excitation{where} reaches harmonic {top} of the base (eta = "
                             f"{eta}); the solution needs at least that many harmonics")
        if T is not None and T <= 2 * K + top:
            raise ValueError(f"HarmonicBalance.n_time = {settings.n_time}: the AFT{where} needs "
                             f"more than 2 K + {top} = {2 * K + top} samples (products of the "
                             "stiffness and a deflection alias otherwise)")
        grid.append(T or time_samples(K, system, eta, g))
    if G == 1:
        return _aft.Basis(orders=_aft.periodic_basis(Ks[0], grid[0]).orders, grid=tuple(grid),
                          rates=system.angle_ratio)
    return _aft.torus_basis(Ks, grid, system.angle_ratio, settings.truncation)


class HBProblem(eqx.Module):
    """A ``System`` prepared for harmonic balance: everything that does not depend on Omega.

    **Fields:** ``basis``: the truncation set and AFT grid (:func:`harmonic_basis`);
    ``n_time``: samples on the grid (``T``, or ``T_1 ... T_G`` on a torus); ``kappa``
    ``(m, T)``: dimensionless stiffness at the samples; ``te``, ``te_rate`` ``(m, T)``:
    transmission error (m) and its time derivative over ``omega_0 = Omega / eta`` (m/rad);
    ``forcing`` ``(C, n)``: external torque coefficients; ``x_scale`` ``(n,)``: unknown
    scale; ``length``: characteristic mesh length (m); ``mesh_null`` ``(n, n - r)``: an
    orthonormal basis of the motions that deflect no mesh (null space of ``W``, rank
    ``r``; the solves of Newton and continuation condense them out,
    ``gearjax._engine.bordered``), derived from ``system.W`` when the problem is built;
    ``None`` where every motion deflects a mesh or ``W`` is traced (dense solves).
    """

    system: System
    settings: HarmonicBalance
    basis: _aft.Basis = eqx.field(static=True)
    n_time: int = eqx.field(static=True)
    kappa: Float[Array, "m T"]
    te: Float[Array, "m T"]
    te_rate: Float[Array, "m T"]
    forcing: Float[Array, "C n"]
    x_scale: Float[Array, " n"]
    length: Float[Array, ""]
    mesh_null: Float[Array, "n nv"] | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return (self.basis.n_coefficients, self.system.n_dof)

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


def stiffness_at_phases(system: System, eta: int, tau: Array) -> Array:
    """Dimensionless mesh stiffness ``kappa_m`` ``(m, T)`` at base phases ``tau``
    ``(T,)`` (rad, ``tau = Omega t / eta``) of a periodic system:
    :func:`~gearjax._engine.mesh_force.stiffness_series`, independent of ``Omega``."""
    return stiffness_series(system.k_cos, system.k_sin, jnp.asarray(system.mesh_mu) * eta, tau)


def excitation_on_grid(system: System, basis: _aft.Basis, eta: int = 1):
    """Stiffness ``kappa``, transmission error ``e`` (m) and ``de/dt / omega_0`` (m/rad),
    each ``(m, T)``, at the samples of ``basis``: mesh ``m`` varies with ``mu_m eta``
    times its own torus angle."""
    mu = jnp.asarray(system.mesh_mu) * eta
    if basis.G == 1:
        tau = _aft.phases(basis.n_samples)
        kappa = stiffness_at_phases(system, eta, tau)
        te, te_rate = transmission_error(system.te_mean, system.te_cos, system.te_sin, mu, tau)
        return kappa, te, te_rate * basis.rates[0]
    # a mesh varies with its own angle only: its series along that angle's T_g samples,
    # spread over the grid by each sample's index along the angle
    rows = np.asarray(system.mesh_angles, dtype=int)
    T_max = max(basis.grid)
    per_angle = []
    for T in basis.grid:
        tau = 2 * np.pi * np.arange(T) / T
        series = (stiffness_series(system.k_cos, system.k_sin, mu, tau),
                  *transmission_error(system.te_mean, system.te_cos, system.te_sin, mu, tau))
        per_angle.append(jnp.stack([jnp.pad(a, ((0, 0), (0, T_max - T))) for a in series]))
    own = jnp.stack(per_angle)[rows, :, np.arange(len(rows))]  # (m, 3, T_max)
    where = jnp.asarray(_aft.angle_index(basis)[rows])  # (m, T)
    kappa, te, te_rate = (jnp.take_along_axis(own[:, i], where, axis=1) for i in range(3))
    return kappa, te, te_rate * jnp.asarray(basis.rates)[rows][:, None]


def hb_problem(system: System, settings: HarmonicBalance = HarmonicBalance()) -> HBProblem:
    """Precompute the Omega-independent parts of the harmonic balance of ``system``.

    **Raises:** ``ValueError`` where the discretisation cannot hold the excitation
    (:func:`harmonic_basis`).
    """
    basis = harmonic_basis(system, settings)
    kappa, te, te_rate, forcing, x_scale, length = _problem_arrays(system, basis, settings.eta)
    return HBProblem(system=system, settings=settings, basis=basis, n_time=basis.n_samples,
                     kappa=kappa, te=te, te_rate=te_rate, forcing=forcing, x_scale=x_scale,
                     length=length, mesh_null=mesh_null_space(system.W))


@eqx.filter_jit
def _problem_arrays(system: System, basis: _aft.Basis, eta: int):
    """The arrays of :func:`hb_problem`, in one compiled program (its operations one by
    one would each be a program of their own to trace and load)."""
    kappa, te, te_rate = excitation_on_grid(system, basis, eta)
    forcing = _aft.torus_place(basis, system.f_cos, system.f_sin,
                               [o * eta for o in system.forcing_mu], system.forcing_angles)
    forcing = forcing.at[0].add(system.f_mean)
    _, F_static = static_deflection(system)
    p_static = jnp.abs(F_static / system.kbar) if system.n_meshes else jnp.zeros(0)
    length = jnp.max(jnp.concatenate([system.backlash, p_static, jnp.array([1e-12])]))
    lever = jnp.max(jnp.abs(system.W), axis=0) if system.n_meshes else jnp.ones(system.n_dof)
    x_scale = length / jnp.where(lever > 0, lever, 1.0)
    return kappa, te, te_rate, forcing, x_scale, length


def mesh_null_space(W) -> Array | None:
    """Orthonormal basis ``(n, n - r)`` of the null space of ``W`` ``(m, n)`` (rank ``r``):
    the motions that deflect no mesh. ``None`` where there are none, and for a traced
    ``W`` (its rank sets a shape, so it must be known when the problem is built)."""
    try:
        W = np.asarray(W, float)
    except jax.errors.TracerArrayConversionError:
        return None
    if W.ndim != 2:  # a batch of systems
        return None
    r = int(np.linalg.matrix_rank(W)) if W.size else 0
    if not 0 < r < W.shape[1]:
        return None
    return jnp.asarray(np.linalg.svd(W)[2][r:].T)


# ------------------------------------------------------------------------- residual


def mesh_samples(problem: HBProblem, P: Array, omega) -> tuple[Array, Array, Array]:
    """Deflection (m), its rate (m/s) and the mesh force (N) of every mesh at the ``T``
    AFT samples, each ``(m, T)``, from the deflection coefficients ``P`` ``(C, m)``
    (coefficients of ``w_m . x``; the transmission error is removed here)."""
    basis = problem.basis
    w0 = omega / problem.settings.eta
    p = _aft.torus_synthesis(basis, P).T - problem.te
    p_dot = w0 * (_aft.torus_synthesis(basis, _aft.torus_derivative(basis, P)).T
                  - problem.te_rate)
    return p, p_dot, sampled_force(problem, p, p_dot)


def sampled_force(problem: HBProblem, p: Array, p_dot: Array) -> Array:
    """The shared ``mesh_force`` at the ``(m, T)`` AFT samples of deflection and rate."""
    s = problem.system
    return mesh_force(p, p_dot, problem.kappa, s.kbar[:, None], s.backlash[:, None],
                      s.damping[:, None], s.contact_damping, problem.settings.smoothing)


def mesh_force_harmonics(problem: HBProblem, P: Array, omega) -> Array:
    """Force coefficients ``(C, m)`` of every mesh from its deflection coefficients ``P``."""
    return _aft.torus_analysis(problem.basis, mesh_samples(problem, P, omega)[2].T)


def linear_part(problem: HBProblem, X: Array, omega) -> Array:
    """``K X + omega_0^2 M D^2 X + omega_0 C D X`` (the springs and inertia), ``(C, n)``."""
    s = problem.system
    w0 = omega / problem.settings.eta
    DX = _aft.torus_derivative(problem.basis, X)
    return (X @ s.K.T + w0**2 * _aft.torus_derivative(problem.basis, DX) @ s.M.T
            + w0 * DX @ s.C.T)


def physical_residual(problem: HBProblem, X: Array, omega) -> Array:
    """Unscaled residual (N m or N), ``(C, n)``, for coefficients ``X`` (rad or m)."""
    W = problem.system.W
    return (linear_part(problem, X, omega) + mesh_force_harmonics(problem, X @ W.T, omega) @ W
            - problem.forcing)


def residual_scale(problem: HBProblem, omega) -> Array:
    """Row scale ``(C, n)``: magnitude of each row's linear diagonal, per scaled unknown."""
    s = problem.system
    Kt = jnp.abs(jnp.diag(s.mean_stiffness()))
    k = jnp.asarray(_aft.frequency_numbers(problem.basis))[:, None]
    w = k * omega / problem.settings.eta
    return (Kt[None, :] + w**2 * jnp.diag(s.M)[None, :] + w * jnp.abs(jnp.diag(s.C))[None, :]
            ) * problem.x_scale[None, :]


@one_program
def residual(problem: HBProblem, y: Array, omega) -> Array:
    """Scaled residual, flat ``(N,)``, of scaled unknowns ``y`` (flat ``(N,)``)."""
    X = y.reshape(problem.shape) * problem.x_scale
    return (physical_residual(problem, X, omega) / residual_scale(problem, omega)).reshape(-1)


@one_program
def jacobian(problem: HBProblem, y: Array, omega) -> Array:
    """Exact ``d residual / d y``, ``(N, N)``, assembled from per-mesh blocks.

    ``L(omega)`` is block-diagonal over cosine-sine pairs; the mesh part is
    ``sum_m J_m[a, b] W[m, i] W[m, j]`` with ``J_m`` from ``jax.jacfwd`` of one mesh's
    AFT map (vmapped over meshes), so no dense autodiff of the whole residual.
    """
    s = problem.system
    C, n = problem.shape
    X = y.reshape(problem.shape) * problem.x_scale
    w0 = omega / problem.settings.eta
    D = jnp.asarray(_aft.torus_derivative_matrix(problem.basis))
    L = jnp.kron(jnp.eye(C), s.K) + w0**2 * jnp.kron(D @ D, s.M) + w0 * jnp.kron(D, s.C)
    Jm = mesh_blocks(problem, X @ s.W.T, omega)  # (m, C, C)
    nonlinear = jnp.einsum("mab,mi,mj->aibj", Jm, s.W, s.W).reshape(C * n, C * n)
    scale_in = jnp.tile(problem.x_scale, C)
    scale_out = residual_scale(problem, omega).reshape(-1)
    return (L + nonlinear) * scale_in[None, :] / scale_out[:, None]


def mesh_blocks(problem: HBProblem, P: Array, omega) -> Array:
    """``J_m = d F_hat_m / d P_m``, shape ``(m, C, C)``.

    The mesh force is a function of each sample's deflection and rate, so with
    ``a = dF/dp`` and ``b = dF/dp'`` at the ``T`` samples (exact, forward-mode through
    the shared mesh force) ``J_m = A(a) + omega_0 A(b) D``, ``A`` the AFT matrix of a
    multiplication (``_aft.torus_product_matrix``, from one FFT of the samples) and
    ``D`` the derivative matrix.
    """
    basis = problem.basis
    p, p_dot, _ = mesh_samples(problem, P, omega)
    w0 = omega / problem.settings.eta
    a, b = force_slopes(problem, p, p_dot)
    return (_aft.torus_product_matrix(basis, a)
            + w0 * _aft.torus_times_derivative(basis, _aft.torus_product_matrix(basis, b)))


def force_slopes(problem: HBProblem, p: Array, p_dot: Array) -> tuple[Array, Array]:
    """``dF/dp`` (N/m) and ``dF/dp'`` (N s/m) of every mesh at the ``(m, T)`` AFT samples
    of deflection ``p`` and rate ``p_dot`` (exact, forward mode through the shared mesh
    force)."""
    ones = jnp.ones_like(p)
    # the force at a sample depends on that sample only: a JVP with ones is the diagonal
    a = jax.jvp(lambda q: sampled_force(problem, q, p_dot), (p,), (ones,))[1]
    b = jax.jvp(lambda v: sampled_force(problem, p, v), (p_dot,), (ones,))[1]
    return a, b


def omega_derivative(problem: HBProblem, y: Array, omega) -> Array:
    """Exact ``d residual / d Omega`` (flat ``(N,)``), one forward-mode JVP."""
    return jax.jvp(lambda w: residual(problem, y, w), (omega,), (jnp.ones_like(omega),))[1]



# ------------------------------------------------------------------------ solutions


class HBSolution(eqx.Module):
    """One harmonic-balance point (:func:`gearjax._engine.newton.newton`).

    **Fields:** ``X`` ``(2K+1, n)``: coefficients (rad or m); ``y``: scaled unknowns,
    flat; ``omega``: base frequency (rad/s); ``result``: a :class:`RESULTS` item
    (``successful``, ``nonlinear_max_steps_reached`` or ``nonfinite``); ``stats``:
    ``num_steps`` (Newton iterations) and ``residual_norm`` (max scaled residual).
    Batched where the solver was vmapped.
    """

    X: Array
    y: Array
    omega: Array
    result: RESULTS
    stats: dict

    @property
    def converged(self):
        """Whether the point converged (a boolean array)."""
        return self.result == RESULTS.successful


@one_program
def linear_guess(problem: HBProblem, omega) -> Array:
    """Scaled solution of the linear, mean-stiffness equations at ``omega``, in contact.

    Every mesh is taken in contact on its loaded flank (the sign of its static force),
    so ``g(p) = p - b sign(F_static)`` (``p`` includes the mean transmission error
    ``te_mean``): the backlash shifts the mean deflection by ``b``
    without changing the dynamics. The stiffness variation is dropped (its parametric
    terms need the Newton solve). This is the usual starting point: never start from
    zero inside the backlash gap. Time-invariant equations decouple by cosine-sine pair:
    ``P`` systems of ``2n`` unknowns and the mean, not one dense system of ``(2P+1) n``.
    """
    s = problem.system
    _, F_static = static_deflection(s)
    preload = s.W.T @ (s.kbar * (s.backlash * jnp.sign(F_static) + s.te_mean))
    n = problem.shape[1]
    K = problem.basis.n_pairs
    w0 = omega / problem.settings.eta
    Kt = s.mean_stiffness()
    Ct = s.C + s.W.T @ (s.damping[:, None] * s.W)
    F = problem.forcing.at[0].add(preload)
    # time-invariant: one (2n, 2n) system per cosine-sine pair
    nu = _aft.frequency_numbers(problem.basis)[1::2]
    blocks = harmonic_blocks(Kt, s.M, Ct, w0, nu).reshape(K, 2 * n, 2 * n)
    mean = jnp.linalg.solve(Kt, F[0])
    osc = jnp.linalg.solve(blocks, F[1:].reshape(K, 2 * n, 1))[..., 0].reshape(2 * K, n)
    X = jnp.concatenate([mean[None], osc])
    return (X / problem.x_scale).reshape(-1)


def harmonic_blocks(stiffness: Array, mass: Array, damping: Array, w0,
                    harmonics) -> Array:
    """``stiffness + w0^2 mass d^2/dtau^2 + w0 damping d/dtau`` (each ``(n, n)``) on the
    cosine and sine coefficients of each harmonic number in ``harmonics`` ``(H,)``:
    ``(H, 2, n, 2, n)``, rows and columns ``(cos k, sin k)``; ``d/dtau`` of ``(cos, sin)``
    coefficients is ``k [[0, 1], [-1, 0]]`` (``_aft.derivative_matrix``)."""
    k = jnp.asarray(harmonics, dtype=float)[:, None, None, None, None]  # (H, a, i, b, j)
    d = jnp.asarray([[0.0, 1.0], [-1.0, 0.0]])[None, :, None, :, None]
    i2 = jnp.eye(2)[None, :, None, :, None]
    lift = lambda A: A[None, None, :, None, :]  # noqa: E731
    return i2 * lift(stiffness) - (k * w0) ** 2 * i2 * lift(mass) + k * w0 * d * lift(damping)
