"""Multi-term harmonic balance on a ``System``: the problem, AFT residual, structured Jacobian.

The periodic solution of period ``2 pi eta / Omega`` is ``x(tau)`` with
``tau = omega_0 t``, ``omega_0 = Omega / eta``, stored as real coefficients
``X`` of shape ``(2K+1, n)`` (see ``_aft``). The residual per harmonic is

    R = K X + omega_0^2 M D^2 X + omega_0 C D X + W^T F_hat(W X) - f_hat

with the mesh forces ``F = kbar kappa g(p) + c p'`` evaluated in time by the one
shared ``mesh_force`` (inverse FFT -> forces -> FFT). Mesh ``m`` varies at
``mu_m Omega``, so its stiffness harmonic ``h`` is harmonic ``h mu_m eta`` of ``tau``.

Unknowns and residual are scaled: ``X = Y * x_scale`` with ``x_scale`` the
rotation that deflects a mesh by the characteristic length (the largest backlash
or static mesh deflection), and each residual row divided by the magnitude of its
linear diagonal (``|Kt_ii| + (k omega_0)^2 M_ii + k omega_0 |C_ii|``, times
``x_scale_i``): the 1e10 brake springs and the planet inertias then give rows of
one size.

The Jacobian exploits structure: each mesh force depends on one scalar deflection,
so ``dR/dX = L(omega) + sum_m (w_m w_m^T) (x) J_m`` with ``J_m`` the
``(2K+1) x (2K+1)`` derivative of the mesh's force harmonics with respect to its
deflection harmonics, from ``jax.jacfwd`` of the mesh's AFT map, and
``L = I (x) K + omega_0^2 D^2 (x) M + omega_0 D (x) C`` block-diagonal over harmonics.

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
from .results import RESULTS
from .static import static_deflection
from .system import System



class HarmonicBalance(eqx.Module):
    """Harmonic-balance settings (static: they are compile keys).

    **Fields:** ``n_harmonics``: K, harmonics of ``Omega / eta`` in the solution;
    ``n_time``: T, time samples per period for the AFT (``None``: the rule of
    :func:`time_samples`); ``eta``: sub-harmonic index; ``rtol``: Newton tolerance on
    the scaled step and residual; ``max_steps``: Newton iterations; ``smoothing``: 0 for
    the exact piecewise-linear backlash, ``s > 0`` rounds its corners over ``s b``
    (``gearjax._engine.mesh_force.backlash``): an option for branches that graze a contact boundary.
    """

    n_harmonics: int = eqx.field(static=True, default=32)
    n_time: int | None = eqx.field(static=True, default=None)
    eta: int = eqx.field(static=True, default=1)
    rtol: float = eqx.field(static=True, default=1e-9)
    max_steps: int = eqx.field(static=True, default=40)
    smoothing: float = eqx.field(static=True, default=0.0)


def highest_excitation(system: System, eta: int = 1) -> int:
    """Highest harmonic of ``tau`` present in the excitation (stiffness, TE, forcing)."""
    H = max(system.k_cos.shape[-1], system.te_cos.shape[-1])
    orders = [H * mu * eta for mu in system.mesh_mu] + [mu * eta for mu in system.forcing_mu]
    return max(orders + [0])


def time_samples(n_harmonics: int, system: System, eta: int = 1) -> int:
    """The AFT sample rule: the smallest power of two >= 16 max(K, highest excitation).

    A product of the stiffness (highest excitation order) and a deflection (K) has
    content up to their sum; the kinks of the piecewise-linear backlash add more, and
    their sampling error falls about as T^-3: 16x oversampling keeps a doubling of T
    below 0.1% of the RMS forces (checked by tests/test_hb_rules.py).
    """
    need = 16 * max(n_harmonics, highest_excitation(system, eta), 1)
    return int(2 ** int(np.ceil(np.log2(need))))


class HBProblem(eqx.Module):
    """A ``System`` prepared for harmonic balance: everything that does not depend on Omega.

    **Fields:** ``kappa`` ``(m, T)``: dimensionless stiffness at the sample phases;
    ``te``, ``te_rate`` ``(m, T)``: transmission error (m) and its derivative with
    respect to phase (m/rad); ``forcing`` ``(2K+1, n)``: external torque coefficients;
    ``x_scale`` ``(n,)``: unknown scale; ``length``: characteristic mesh length (m);
    ``mesh_null`` ``(n, n - r)``: an orthonormal basis of the motions that deflect no
    mesh (null space of ``W``, rank ``r``; the solves of Newton and continuation condense
    them out, ``gearjax._engine.bordered``), derived from ``system.W`` when the problem is built;
    ``None`` where every motion deflects a mesh or ``W`` is traced (dense solves).
    """

    system: System
    settings: HarmonicBalance
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
        return (2 * self.settings.n_harmonics + 1, self.system.n_dof)

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]


def stiffness_at_phases(system: System, eta: int, tau: Array) -> Array:
    """Dimensionless mesh stiffness ``kappa_m`` ``(m, T)`` at base phases ``tau``
    ``(T,)`` (rad, ``tau = Omega t / eta``): :func:`~gearjax._engine.mesh_force.stiffness_series`, independent of
    ``Omega``."""
    return stiffness_series(system.k_cos, system.k_sin, jnp.asarray(system.mesh_mu) * eta, tau)


def hb_problem(system: System, settings: HarmonicBalance = HarmonicBalance()) -> HBProblem:
    """Precompute the Omega-independent parts of the harmonic balance of ``system``.

    **Raises:** ``ValueError`` where the discretisation cannot hold the excitation:
    ``settings.n_harmonics`` below the highest excitation order
    (:func:`highest_excitation`), or ``settings.n_time`` too few samples for the
    product of the stiffness and a deflection (``2 K + highest`` or fewer: aliased).
    """
    K, eta = settings.n_harmonics, settings.eta
    top = highest_excitation(system, eta)
    if K < max(top, 1):
        raise ValueError(f"HarmonicBalance.n_harmonics = {K}: the excitation reaches harmonic "
                         f"{top} of the base (eta = {eta}); the solution needs at least that "
                         "many harmonics")
    if settings.n_time is not None and settings.n_time <= 2 * K + top:
        raise ValueError(f"HarmonicBalance.n_time = {settings.n_time}: the AFT needs more "
                         f"than 2 K + {top} = {2 * K + top} samples (products of the "
                         "stiffness and a deflection alias otherwise)")
    T = settings.n_time or time_samples(K, system, eta)
    tau = _aft.phases(T)
    mu = jnp.asarray(system.mesh_mu) * eta
    kappa = stiffness_at_phases(system, eta, tau)
    te, te_rate = transmission_error(system.te_cos, system.te_sin, mu, tau)
    forcing = _aft.place_harmonics(system.f_cos, system.f_sin,
                                   [o * eta for o in system.forcing_mu], K)
    forcing = forcing.at[0].add(system.f_mean)
    _, F_static = static_deflection(system)
    p_static = jnp.abs(F_static / system.kbar) if system.n_meshes else jnp.zeros(0)
    length = jnp.max(jnp.concatenate([system.backlash, p_static, jnp.array([1e-12])]))
    lever = jnp.max(jnp.abs(system.W), axis=0) if system.n_meshes else jnp.ones(system.n_dof)
    x_scale = length / jnp.where(lever > 0, lever, 1.0)
    return HBProblem(system=system, settings=settings, n_time=T, kappa=kappa, te=te,
                     te_rate=te_rate, forcing=forcing, x_scale=x_scale, length=length,
                     mesh_null=mesh_null_space(system.W))


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
    AFT instants, each ``(m, T)``, from the deflection harmonics ``P`` ``(2K+1, m)``
    (coefficients of ``w_m . x``; the transmission error is removed here)."""
    T = problem.n_time
    w0 = omega / problem.settings.eta
    p = _aft.synthesis(P, T).T - problem.te
    p_dot = w0 * (_aft.synthesis(_aft.derivative(P), T).T - problem.te_rate)
    return p, p_dot, _sampled_force(problem, p, p_dot)


def _sampled_force(problem: HBProblem, p: Array, p_dot: Array) -> Array:
    """The shared ``mesh_force`` at the ``(m, T)`` AFT samples of deflection and rate."""
    s = problem.system
    return mesh_force(p, p_dot, problem.kappa, s.kbar[:, None], s.backlash[:, None],
                      s.damping[:, None], s.contact_damping, problem.settings.smoothing)


def mesh_force_harmonics(problem: HBProblem, P: Array, omega) -> Array:
    """Force harmonics ``(2K+1, m)`` of every mesh from its deflection harmonics ``P``."""
    return _aft.analysis(mesh_samples(problem, P, omega)[2].T, problem.settings.n_harmonics)


def linear_part(problem: HBProblem, X: Array, omega) -> Array:
    """``K X + omega_0^2 M D^2 X + omega_0 C D X`` (the springs and inertia), ``(2K+1, n)``."""
    s = problem.system
    w0 = omega / problem.settings.eta
    DX = _aft.derivative(X)
    return X @ s.K.T + w0**2 * _aft.derivative(DX) @ s.M.T + w0 * DX @ s.C.T


def physical_residual(problem: HBProblem, X: Array, omega) -> Array:
    """Unscaled residual (N m or N), ``(2K+1, n)``, for coefficients ``X`` (rad or m)."""
    W = problem.system.W
    return (linear_part(problem, X, omega) + mesh_force_harmonics(problem, X @ W.T, omega) @ W
            - problem.forcing)


def residual_scale(problem: HBProblem, omega) -> Array:
    """Row scale ``(2K+1, n)``: magnitude of each row's linear diagonal, per scaled unknown."""
    s = problem.system
    Kt = jnp.abs(jnp.diag(s.mean_stiffness()))
    k = jnp.asarray(_aft.harmonic_numbers(problem.settings.n_harmonics))[:, None]
    w = k * omega / problem.settings.eta
    return (Kt[None, :] + w**2 * jnp.diag(s.M)[None, :] + w * jnp.abs(jnp.diag(s.C))[None, :]
            ) * problem.x_scale[None, :]


def residual(problem: HBProblem, y: Array, omega) -> Array:
    """Scaled residual, flat ``(N,)``, of scaled unknowns ``y`` (flat ``(N,)``)."""
    X = y.reshape(problem.shape) * problem.x_scale
    return (physical_residual(problem, X, omega) / residual_scale(problem, omega)).reshape(-1)


def jacobian(problem: HBProblem, y: Array, omega) -> Array:
    """Exact ``d residual / d y``, ``(N, N)``, assembled from per-mesh blocks.

    ``L(omega)`` is block-diagonal over harmonics; the mesh part is
    ``sum_m J_m[a, b] W[m, i] W[m, j]`` with ``J_m`` from ``jax.jacfwd`` of one mesh's
    AFT map (vmapped over meshes), so no dense autodiff of the whole residual.
    """
    s = problem.system
    C, n = problem.shape
    X = y.reshape(problem.shape) * problem.x_scale
    w0 = omega / problem.settings.eta
    D = jnp.asarray(_aft.derivative_matrix(problem.settings.n_harmonics))
    L = jnp.kron(jnp.eye(C), s.K) + w0**2 * jnp.kron(D @ D, s.M) + w0 * jnp.kron(D, s.C)
    Jm = mesh_blocks(problem, X @ s.W.T, omega)  # (m, C, C)
    nonlinear = jnp.einsum("mab,mi,mj->aibj", Jm, s.W, s.W).reshape(C * n, C * n)
    scale_in = jnp.tile(problem.x_scale, C)
    scale_out = residual_scale(problem, omega).reshape(-1)
    return (L + nonlinear) * scale_in[None, :] / scale_out[:, None]


def mesh_blocks(problem: HBProblem, P: Array, omega) -> Array:
    """``J_m = d F_hat_m / d P_m``, shape ``(m, 2K+1, 2K+1)``.

    The mesh force is a function of each sample's deflection and rate, so with
    ``a = dF/dp`` and ``b = dF/dp'`` at the ``T`` samples (exact, forward-mode through
    the shared mesh force) ``J_m = A(a) + omega_0 A(b) D``, ``A`` the AFT matrix of a
    multiplication (``_aft.product_matrix``, from one FFT of the samples) and ``D`` the
    derivative matrix.
    """
    K = problem.settings.n_harmonics
    p, p_dot, _ = mesh_samples(problem, P, omega)
    w0 = omega / problem.settings.eta
    ones = jnp.ones_like(p)
    # the force at a sample depends on that sample only: a JVP with ones is the diagonal
    a = jax.jvp(lambda q: _sampled_force(problem, q, p_dot), (p,), (ones,))[1]
    b = jax.jvp(lambda v: _sampled_force(problem, p, v), (p_dot,), (ones,))[1]
    return _aft.product_matrix(a, K) + w0 * _aft.times_derivative(_aft.product_matrix(b, K))


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


def linear_guess(problem: HBProblem, omega) -> Array:
    """Scaled solution of the linear, mean-stiffness equations at ``omega``, in contact.

    Every mesh is taken in contact on its loaded flank (the sign of its static force),
    so ``g(p) = p - b sign(F_static)``: the backlash shifts the mean deflection by ``b``
    without changing the dynamics. The stiffness variation is dropped (its parametric
    terms need the Newton solve). This is the usual starting point: never start from
    zero inside the backlash gap. Time-invariant equations decouple by harmonic: ``K``
    systems of ``2n`` unknowns and the mean, not one dense system of ``(2K+1) n``.
    """
    s = problem.system
    _, F_static = static_deflection(s)
    preload = s.W.T @ (s.kbar * s.backlash * jnp.sign(F_static))
    n = problem.shape[1]
    K = problem.settings.n_harmonics
    w0 = omega / problem.settings.eta
    Kt = s.mean_stiffness()
    Ct = s.C + s.W.T @ (s.damping[:, None] * s.W)
    F = problem.forcing.at[0].add(preload)
    # time-invariant: one (2n, 2n) system per harmonic
    blocks = harmonic_blocks(Kt, s.M, Ct, w0, np.arange(1, K + 1)).reshape(K, 2 * n, 2 * n)
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
