"""Alternating frequency-time (AFT) operators on the torus, in real Fourier coefficients.

A function on the ``G``-torus (model.md, "Incommensurate stages") with the
truncation set ``S = {0} + S+ + (-S+)`` of integer vectors is stored as ``2P + 1``
real coefficients along axis 0, ``P = |S+|``:

    x(theta) = X[0] + sum_j X[2j-1] cos(k_j . theta) + X[2j] sin(k_j . theta),  k_j in S+

with ``S+`` the half set (first non-zero entry positive) of a :class:`Basis`. Angle
``g`` turns at ``rates[g]`` times the base frequency ``omega_0``, so the time
derivative of ``cos(k . theta)`` carries the frequency number ``nu = k . rates``.
``G = 1`` with ``S+ = {1..K}`` and rate 1 is the periodic case: ``x(tau)`` of phase
``tau = omega_0 t`` with ``K`` harmonics (:func:`periodic_basis`), and the functions
without a basis (``synthesis(X, T)``, ``analysis(x, K)``, ...) are that case.

``synthesis`` samples the function on the uniform grid of ``T_1 x ... x T_G`` angles
(``theta_g = 2 pi j_g / T_g``, flattened in C order, angle ``G`` fastest) with an
inverse real FFT; ``analysis`` is its inverse (exact for functions whose wave vectors
stay distinct modulo the grid, a projection otherwise). Both act on the leading axis
and are linear, so JAX differentiates them exactly.
"""

from __future__ import annotations

import functools
import itertools
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .programs import one_program

TRUNCATIONS = ("box", "diamond")
"""Truncation sets: ``box`` ``|k_g| <= K_g``; ``diamond`` ``sum_g |k_g| / K_g <= 1``."""


class Basis(eqx.Module):
    """The truncation set and sample grid of a (torus) harmonic balance; static.

    **Fields:** ``orders``: the half set ``S+``, ``P`` tuples of ``G`` integers (first
    non-zero entry positive); ``grid``: samples per angle ``(T_1, ..., T_G)``;
    ``rates``: each angle's rate over the base frequency ``omega_0``, ``(G,)``.
    """

    orders: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    grid: tuple[int, ...] = eqx.field(static=True)
    rates: tuple[float, ...] = eqx.field(static=True, default=(1.0,))

    @property
    def G(self) -> int:
        return len(self.grid)

    @property
    def n_pairs(self) -> int:
        """``P``: cosine-sine pairs (wave vectors of ``S+``)."""
        return len(self.orders)

    @property
    def n_coefficients(self) -> int:
        return 2 * len(self.orders) + 1

    @property
    def n_samples(self) -> int:
        """Grid points on the torus, ``T_1 ... T_G``."""
        return math.prod(self.grid)


def periodic_basis(n_harmonics: int, n_time: int) -> Basis:
    """The periodic basis: harmonics ``1..K`` of one angle sampled ``T`` times."""
    return Basis(orders=tuple((k,) for k in range(1, n_harmonics + 1)), grid=(int(n_time),))


def torus_basis(orders_max, grid, rates, truncation: str = "diamond") -> Basis:
    """The basis of the truncation set ``truncation`` with ``K_g = orders_max[g]``.

    **Arguments:** ``orders_max`` ``(G,)`` positive integers; ``grid`` ``(G,)`` samples
    per angle; ``rates`` ``(G,)`` angle rates over ``omega_0``; ``truncation``: one of
    :data:`TRUNCATIONS`. Wave vectors are ordered by ``sum |k_g| / K_g``, then
    lexicographically (for ``G = 1``: ``1..K``).

    **Raises:** ``ValueError`` for a truncation not in :data:`TRUNCATIONS`, lengths that
    differ, a ``K_g < 1``, or a grid that cannot carry the set (``T_g <= 2 K_g + 1``).
    """
    Kmax = tuple(int(k) for k in orders_max)
    grid = tuple(int(t) for t in grid)
    if truncation not in TRUNCATIONS:
        raise ValueError(f"truncation = {truncation!r}: must be one of {TRUNCATIONS}")
    if not (len(Kmax) == len(grid) == len(rates)) or not Kmax:
        raise ValueError(f"orders_max {Kmax}, grid {grid} and rates {tuple(rates)} must have "
                         "one entry per torus angle")
    for g, (K, T) in enumerate(zip(Kmax, grid)):
        if K < 1:
            raise ValueError(f"orders_max[{g}] = {K}: at least one harmonic per angle")
        if T < 2 * K + 2:
            raise ValueError(f"grid[{g}] = {T} samples cannot carry {K} harmonics (need >= "
                             f"{2 * K + 2})")
    keep = []
    vectors = (itertools.product(*(range(-K, K + 1) for K in Kmax)) if truncation == "box"
               else _diamond_vectors(Kmax))
    for k in vectors:
        first = next((v for v in k if v), 0)
        if first <= 0:
            continue
        size = sum(abs(v) / K for v, K in zip(k, Kmax))
        if truncation == "box" or size <= 1 + 1e-12:
            keep.append((size, k))
    keep.sort()
    return Basis(orders=tuple(k for _, k in keep), grid=grid,
                 rates=tuple(float(r) for r in rates))


def _diamond_vectors(Kmax: tuple):
    """Every integer vector with ``sum_g |k_g| / K_g <= 1`` (zero included), in
    ``itertools.product`` order: the prefixes past the budget are never extended, so the
    cost grows with the set, not with the box ``prod (2 K_g + 1)`` around it."""
    L = math.lcm(*Kmax)
    weight = [L // K for K in Kmax]

    def extend(prefix: tuple, budget: int):
        g = len(prefix)
        if g == len(Kmax):
            yield prefix
            return
        reach = budget // weight[g]
        for v in range(-reach, reach + 1):
            yield from extend(prefix + (v,), budget - abs(v) * weight[g])

    return extend((), L)


def truncation_set_size(orders_max, truncation: str = "diamond") -> int:
    """Coefficient rows ``2P + 1`` of the basis :func:`torus_basis` would build (``P``
    wave vectors), counted in closed form or by a recursion over the budget left per
    angle, without enumerating the set: for sizing a problem before it is built.

    **Raises:** ``ValueError`` for a truncation not in :data:`TRUNCATIONS` or a
    ``K_g < 1``."""
    Kmax = tuple(int(k) for k in orders_max)
    if truncation not in TRUNCATIONS:
        raise ValueError(f"truncation = {truncation!r}: must be one of {TRUNCATIONS}")
    if not Kmax or min(Kmax) < 1:
        raise ValueError(f"orders_max {Kmax}: at least one harmonic per angle")
    if truncation == "box":
        return math.prod(2 * K + 1 for K in Kmax)
    L = math.lcm(*Kmax)
    weight = [L // K for K in Kmax]

    @functools.cache
    def points(g: int, budget: int) -> int:  # vectors of angles g.. within the budget
        reach = budget // weight[g]
        if g == len(Kmax) - 1:
            return 2 * reach + 1
        return points(g + 1, budget) + 2 * sum(points(g + 1, budget - v * weight[g])
                                               for v in range(1, reach + 1))

    return points(0, L)  # zero and each wave vector with its negative: 2P + 1


# ------------------------------------------------------------------ index tables


@functools.lru_cache(maxsize=64)
def _orders_array(orders: tuple, G: int) -> np.ndarray:
    return np.asarray(orders, dtype=np.int64).reshape(len(orders), G)


def _flat(k: np.ndarray, grid: tuple) -> np.ndarray:
    """Flat index (C order) of wave vectors ``k`` ``(..., G)`` modulo the grid."""
    return np.ravel_multi_index(tuple(np.moveaxis(k % np.asarray(grid), -1, 0)), grid)


@functools.lru_cache(maxsize=64)
def _half_spectrum_slots(orders: tuple, grid: tuple):
    """Where each coefficient goes in the half spectrum of ``rfftn`` (last axis cut to
    ``T_G // 2 + 1``): ``(index, sign)`` per wave vector of ``S+`` (sign ``+1``: ``Z_k``
    sits at ``k``; ``-1``: its conjugate sits at ``-k``), and the extra slots of the
    vectors with ``k_G = 0`` (both ``k`` and ``-k`` lie in the half spectrum)."""
    G = len(grid)
    k = _orders_array(orders, G)
    half = grid[:-1] + (grid[-1] // 2 + 1,)
    sign = np.where(k[:, -1] >= 0, 1, -1)
    at = k * sign[:, None]
    index = np.ravel_multi_index(tuple((at % np.asarray(grid)).T), half) if len(k) else \
        np.zeros(0, int)
    both = np.nonzero(k[:, -1] == 0)[0]
    mirror = np.ravel_multi_index(tuple(((-k[both]) % np.asarray(grid)).T), half) if len(
        both) else np.zeros(0, int)
    return index, sign, both, mirror


@functools.lru_cache(maxsize=64)
def _product_slots(orders: tuple, grid: tuple):
    """Flat indices of ``k``, ``k - l`` and ``k + l`` modulo the grid, for rows ``k`` in
    ``{0} + S+`` and columns ``l`` in ``S+``."""
    G = len(grid)
    k = np.concatenate([np.zeros((1, G), np.int64), _orders_array(orders, G)])
    l = _orders_array(orders, G)
    return (_flat(k, grid), _flat(k[:, None, :] - l[None, :, :], grid),
            _flat(k[:, None, :] + l[None, :, :], grid))


def frequency_numbers(basis: Basis) -> np.ndarray:
    """The frequency number of each coefficient row over ``omega_0``, ``(2P+1,)``:
    ``[0, nu_1, nu_1, ..., nu_P, nu_P]``, ``nu_j = k_j . rates``."""
    k = _orders_array(basis.orders, basis.G)
    nu = k @ np.asarray(basis.rates, float) if len(k) else np.zeros(0)
    return np.concatenate([[0.0], np.repeat(nu, 2)])


def pair_index(basis: Basis) -> np.ndarray:
    """The pair of each coefficient row: ``[0, 1, 1, 2, 2, ..., P, P]``."""
    return np.concatenate([[0], np.repeat(np.arange(1, basis.n_pairs + 1), 2)])


def angle_index(basis: Basis) -> np.ndarray:
    """Each sample's index along each angle, ``(G, T_1 ... T_G)`` (grid order): sample
    ``s`` sits at angle ``2 pi angle_index[g, s] / T_g`` of angle ``g``."""
    axes = [np.arange(T, dtype=np.int32) for T in basis.grid]
    return np.stack([a.reshape(-1) for a in np.meshgrid(*axes, indexing="ij")])


def angles(basis: Basis) -> np.ndarray:
    """The torus angles of the samples, ``(G, T_1 ... T_G)`` (rad), grid order."""
    T = np.asarray(basis.grid, dtype=float)[:, None]
    return 2 * np.pi * angle_index(basis) / T


# ------------------------------------------------------------ the AFT on the torus


@one_program
def torus_synthesis(basis: Basis, X: jnp.ndarray) -> jnp.ndarray:
    """Samples ``(T_1 ... T_G, ...)`` of the function with coefficients ``X``
    ``(2P+1, ...)`` on the grid of ``basis`` (:func:`angles`)."""
    grid, n = basis.grid, basis.n_samples
    index, sign, both, mirror = _half_spectrum_slots(basis.orders, grid)
    # FFTs run along the last axes: XLA's CPU FFT rejects other layouts inside loops
    Xt = jnp.moveaxis(X, 0, -1)
    lead = Xt.shape[:-1]
    half = grid[:-1] + (grid[-1] // 2 + 1,)
    Z = 0.5 * n * (Xt[..., 1::2] - 1j * sign * Xt[..., 2::2])  # Z_k, or conj at -k
    spectrum = jnp.zeros(lead + (math.prod(half),), dtype=jnp.complex128)
    spectrum = spectrum.at[..., 0].set(n * Xt[..., 0])
    spectrum = spectrum.at[..., index].set(Z)
    if len(both):
        spectrum = spectrum.at[..., mirror].set(jnp.conj(Z[..., both]))
    spectrum = spectrum.reshape(lead + half)
    axes = tuple(range(-basis.G, 0))
    x = jnp.fft.irfftn(spectrum, s=grid, axes=axes) if basis.G > 1 else jnp.fft.irfft(
        spectrum, n=grid[0], axis=-1)
    return jnp.moveaxis(x.reshape(lead + (n,)), -1, 0)


@one_program
def torus_analysis(basis: Basis, x: jnp.ndarray) -> jnp.ndarray:
    """Coefficients ``(2P+1, ...)`` of samples ``x`` ``(T_1 ... T_G, ...)`` on the grid of
    ``basis``."""
    grid, n = basis.grid, basis.n_samples
    index, sign, _, _ = _half_spectrum_slots(basis.orders, grid)
    xt = jnp.moveaxis(x, 0, -1)
    lead = xt.shape[:-1]
    if basis.G > 1:
        spectrum = jnp.fft.rfftn(xt.reshape(lead + grid), axes=tuple(range(-basis.G, 0)))
    else:
        spectrum = jnp.fft.rfft(xt, axis=-1)
    spectrum = spectrum.reshape(lead + (-1,)) / n
    Z = spectrum[..., index]
    out = jnp.zeros(lead + (basis.n_coefficients,))
    out = out.at[..., 0].set(spectrum[..., 0].real)
    out = out.at[..., 1::2].set(2 * Z.real)
    out = out.at[..., 2::2].set(-2 * sign * Z.imag)
    return jnp.moveaxis(out, -1, 0)


@one_program
def torus_product_matrix(basis: Basis, a: jnp.ndarray) -> jnp.ndarray:
    """``M`` with ``analysis(a * synthesis(X)) == M @ X``: multiplication by the sampled
    function ``a`` ``(..., T_1 ... T_G)`` (samples on the last axis), ``(..., 2P+1, 2P+1)``.

    Assembled from the DFT ``A_q`` of the samples (product to sum: ``a cos(l . theta)``
    has the complex coefficients ``(A_{k-l} + A_{k+l}) / 2``, indices modulo the grid,
    so aliasing is the AFT's own): one FFT of the samples instead of ``2P+1`` pairs.
    """
    P = basis.n_pairs
    lead = a.shape[:-1]
    if basis.G > 1:
        A = jnp.fft.fftn(a.reshape(lead + basis.grid), axes=tuple(range(-basis.G, 0)))
        A = A.reshape(lead + (-1,)) / basis.n_samples
    else:
        A = jnp.fft.fft(a, axis=-1) / basis.n_samples
    at_k, at_lo, at_hi = _product_slots(basis.orders, basis.grid)
    lo, hi = A[..., at_lo], A[..., at_hi]  # (..., P+1, P)
    F = jnp.concatenate([A[..., at_k[:, None]],  # column 0: the constant
                         jnp.stack([(lo + hi) / 2, (lo - hi) / 2j], axis=-1).reshape(
                             lo.shape[:-1] + (2 * P,))], axis=-1)  # (..., P+1, 2P+1)
    rows = jnp.stack([2 * F[..., 1:, :].real, -2 * F[..., 1:, :].imag], axis=-2)
    return jnp.concatenate([F[..., :1, :].real, rows.reshape(F.shape[:-2] + (2 * P, 2 * P + 1))],
                           axis=-2)


@one_program
def torus_derivative(basis: Basis, X: jnp.ndarray) -> jnp.ndarray:
    """Coefficients of ``dx/dt / omega_0``: ``cos_j <- nu_j sin_j``, ``sin_j <- -nu_j cos_j``."""
    nu = jnp.asarray(frequency_numbers(basis)[1::2]).reshape((-1,) + (1,) * (X.ndim - 1))
    out = jnp.zeros_like(X)
    out = out.at[1::2].set(nu * X[2::2])
    return out.at[2::2].set(-nu * X[1::2])


@one_program
def torus_times_derivative(basis: Basis, M: jnp.ndarray) -> jnp.ndarray:
    """``M @ torus_derivative_matrix(basis)`` for ``M`` ``(..., r, 2P+1)``, by columns."""
    nu = jnp.asarray(frequency_numbers(basis)[1::2])
    out = jnp.zeros_like(M)
    out = out.at[..., 1::2].set(-nu * M[..., 2::2])
    return out.at[..., 2::2].set(nu * M[..., 1::2])


def torus_derivative_matrix(basis: Basis) -> np.ndarray:
    """``D`` with ``torus_derivative(basis, X) == D @ X``, ``(2P+1, 2P+1)``."""
    nu = frequency_numbers(basis)
    D = np.zeros((basis.n_coefficients,) * 2)
    for j in range(1, basis.n_pairs + 1):
        D[2 * j - 1, 2 * j] = nu[2 * j]
        D[2 * j, 2 * j - 1] = -nu[2 * j]
    return D


def resize_rows(old: Basis, new: Basis) -> tuple[np.ndarray, np.ndarray]:
    """``(to, frm)``: coefficient rows shared by two bases of the same torus, so that
    ``Y[to] = X[frm]`` carries the coefficients ``X`` of ``old`` over to ``new`` (wave
    vectors in only one of them: dropped, or zero). For periodic bases of ``K`` and
    ``K'`` harmonics: the first ``2 min(K, K') + 1`` rows."""
    if old.G != new.G:
        raise ValueError(f"bases of {old.G} and {new.G} torus angles cannot be resized")
    slot = {k: j for j, k in enumerate(new.orders)}
    to, frm = [0], [0]
    for j, k in enumerate(old.orders):
        if k in slot:
            to += [2 * slot[k] + 1, 2 * slot[k] + 2]
            frm += [2 * j + 1, 2 * j + 2]
    return np.asarray(to), np.asarray(frm)


def resize(old: Basis, new: Basis, X):
    """The coefficients ``X`` ``(2P+1, ...)`` on ``old`` as coefficients on ``new``
    (:func:`resize_rows`; NumPy in, NumPy out)."""
    to, frm = resize_rows(old, new)
    X = np.asarray(X)
    out = np.zeros((new.n_coefficients,) + X.shape[1:], dtype=X.dtype)
    out[to] = X[frm]
    return out


def line_matrix(basis: Basis, tau) -> np.ndarray:
    """The basis functions on the line ``theta = rates tau``, ``(S, 2P+1)`` (NumPy): row
    ``s`` holds ``[1, cos(nu_1 tau_s), sin(nu_1 tau_s), ...]`` at the base phases ``tau``
    ``(S,)`` (rad, ``tau = omega_0 t``), so that the samples of the function with
    coefficients ``X`` along the line are ``line_matrix(basis, tau) @ X``."""
    tau = np.asarray(tau, dtype=float)
    nu = frequency_numbers(basis)[1::2]
    arg = tau[:, None] * nu[None, :]
    out = np.empty((tau.size, basis.n_coefficients))
    out[:, 0] = 1.0
    out[:, 1::2] = np.cos(arg)
    out[:, 2::2] = np.sin(arg)
    return out


def line_analysis(basis: Basis, tau, x) -> np.ndarray:
    """Coefficients ``(2P+1, ...)`` on ``basis`` fitted by least squares to samples ``x``
    ``(S, ...)`` taken along the line at base phases ``tau`` ``(S,)`` (rad): the inverse
    of :func:`line_matrix` for a function of the basis, a projection otherwise. On a
    torus the samples must cover the torus (a span of many beats of its angles) for the
    fit to be well posed. **Raises:** ``ValueError`` with fewer samples than
    coefficients."""
    A = line_matrix(basis, tau)
    if A.shape[0] < A.shape[1]:
        raise ValueError(f"line_analysis: {A.shape[0]} samples cannot determine "
                         f"{A.shape[1]} coefficients")
    x = np.asarray(x, dtype=float)
    X, *_ = np.linalg.lstsq(A, x.reshape(x.shape[0], -1), rcond=None)
    return X.reshape((basis.n_coefficients,) + x.shape[1:])


def torus_place(basis: Basis, cos: jnp.ndarray, sin: jnp.ndarray, orders, angle) -> jnp.ndarray:
    """Coefficients ``(2P+1, r)`` of ``sum_l cos[:, l] cos(o_l theta_g(l)) + sin[:, l]
    sin(o_l theta_g(l))``.

    ``cos``, ``sin``: ``(r, L)``; ``orders``: ``L`` positive integers; ``angle``: the
    torus angle ``g(l)`` of each column. A wave vector outside the basis is dropped
    (the caller refuses such a truncation).
    """
    slot = {k: j for j, k in enumerate(basis.orders)}
    out = jnp.zeros((basis.n_coefficients, cos.shape[0]))
    for l, (o, g) in enumerate(zip(orders, angle)):
        k = tuple(int(o) if i == g else 0 for i in range(basis.G))
        if k in slot:
            j = slot[k] + 1
            out = out.at[2 * j - 1].add(cos[:, l]).at[2 * j].add(sin[:, l])
    return out


# ------------------------------------------------- the periodic case (G = 1, K harmonics)


def n_coefficients(n_harmonics: int) -> int:
    return 2 * n_harmonics + 1


def phases(n_time: int) -> jnp.ndarray:
    """The sample phases ``tau_j = 2 pi j / T`` (rad), shape ``(T,)``."""
    return 2 * jnp.pi * jnp.arange(n_time) / n_time


def synthesis(X: jnp.ndarray, n_time: int) -> jnp.ndarray:
    """Samples ``(T, ...)`` of the periodic signal with coefficients ``X`` ``(2K+1, ...)``."""
    K = (X.shape[0] - 1) // 2
    if n_time < 2 * K + 2:
        raise ValueError(f"{n_time} time samples cannot carry {K} harmonics (need >= {2 * K + 2})")
    return torus_synthesis(periodic_basis(K, n_time), X)


def analysis(x: jnp.ndarray, n_harmonics: int) -> jnp.ndarray:
    """Coefficients ``(2K+1, ...)`` of samples ``x`` ``(T, ...)`` (the first ``K`` harmonics)."""
    return torus_analysis(periodic_basis(n_harmonics, x.shape[0]), x)


def product_matrix(a: jnp.ndarray, n_harmonics: int) -> jnp.ndarray:
    """:func:`torus_product_matrix` of the periodic basis, ``(..., 2K+1, 2K+1)``."""
    return torus_product_matrix(periodic_basis(n_harmonics, a.shape[-1]), a)


def times_derivative(M: jnp.ndarray) -> jnp.ndarray:
    """``M @ derivative_matrix(K)`` for ``M`` ``(..., r, 2K+1)``, by columns."""
    K = (M.shape[-1] - 1) // 2
    return torus_times_derivative(periodic_basis(K, 2 * K + 2), M)


def derivative(X: jnp.ndarray) -> jnp.ndarray:
    """Coefficients of ``dx/dtau``: ``cos_k <- k sin_k``, ``sin_k <- -k cos_k``."""
    K = (X.shape[0] - 1) // 2
    return torus_derivative(periodic_basis(K, 2 * K + 2), X)


def derivative_matrix(n_harmonics: int) -> np.ndarray:
    """``D`` with ``derivative(X) == D @ X``, shape ``(2K+1, 2K+1)``."""
    return torus_derivative_matrix(periodic_basis(n_harmonics, 2 * n_harmonics + 2))


def harmonic_numbers(n_harmonics: int) -> np.ndarray:
    """Harmonic number of each coefficient row: ``[0, 1, 1, 2, 2, ..., K, K]``."""
    return np.concatenate([[0], np.repeat(np.arange(1, n_harmonics + 1), 2)])


def place_harmonics(cos: jnp.ndarray, sin: jnp.ndarray, orders, n_harmonics: int) -> jnp.ndarray:
    """Coefficients ``(2K+1, r)`` of ``sum_l cos[:, l] cos(o_l tau) + sin[:, l] sin(o_l tau)``.

    ``cos``, ``sin``: ``(r, L)``; ``orders``: ``L`` positive integers (harmonics of
    ``tau``). Orders above ``K`` are dropped (the caller warns).
    """
    return torus_place(periodic_basis(n_harmonics, 2 * n_harmonics + 2), cos, sin, orders,
                       (0,) * len(orders))
