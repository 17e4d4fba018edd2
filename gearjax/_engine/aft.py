"""Alternating frequency-time (AFT) operators on real Fourier coefficients.

A periodic signal of phase ``tau = omega_0 t`` (period ``2 pi``) with ``K`` harmonics
is stored as ``2K + 1`` real coefficients along axis 0:

    x(tau) = X[0] + sum_k X[2k-1] cos(k tau) + X[2k] sin(k tau),   k = 1..K

``synthesis`` samples it at ``T`` equally spaced phases ``tau_j = 2 pi j / T`` with an
inverse real FFT; ``analysis`` is its inverse (exact for signals with at most
``T/2 - 1`` harmonics, a least-squares projection otherwise). Both act on the
leading axis and are linear, so JAX differentiates them exactly.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def n_coefficients(n_harmonics: int) -> int:
    return 2 * n_harmonics + 1


def phases(n_time: int) -> jnp.ndarray:
    """The sample phases ``tau_j = 2 pi j / T`` (rad), shape ``(T,)``."""
    return 2 * jnp.pi * jnp.arange(n_time) / n_time


def synthesis(X: jnp.ndarray, n_time: int) -> jnp.ndarray:
    """Samples ``(T, ...)`` of the signal with coefficients ``X`` ``(2K+1, ...)``."""
    K = (X.shape[0] - 1) // 2
    if n_time < 2 * K + 2:
        raise ValueError(f"{n_time} time samples cannot carry {K} harmonics (need >= {2 * K + 2})")
    # FFTs run along the last axis: XLA's CPU FFT rejects other layouts inside loops
    Xt = jnp.moveaxis(X, 0, -1)
    spectrum = jnp.zeros(Xt.shape[:-1] + (n_time // 2 + 1,), dtype=jnp.complex128)
    spectrum = spectrum.at[..., 0].set(n_time * Xt[..., 0])
    spectrum = spectrum.at[..., 1: K + 1].set(0.5 * n_time * (Xt[..., 1::2] - 1j * Xt[..., 2::2]))
    return jnp.moveaxis(jnp.fft.irfft(spectrum, n=n_time, axis=-1), -1, 0)


def analysis(x: jnp.ndarray, n_harmonics: int) -> jnp.ndarray:
    """Coefficients ``(2K+1, ...)`` of samples ``x`` ``(T, ...)`` (the first ``K`` harmonics)."""
    n_time = x.shape[0]
    spectrum = jnp.fft.rfft(jnp.moveaxis(x, 0, -1), axis=-1)[..., : n_harmonics + 1] / n_time
    out = jnp.zeros(spectrum.shape[:-1] + (2 * n_harmonics + 1,))
    out = out.at[..., 0].set(spectrum[..., 0].real)
    out = out.at[..., 1::2].set(2 * spectrum[..., 1:].real)
    out = out.at[..., 2::2].set(-2 * spectrum[..., 1:].imag)
    return jnp.moveaxis(out, -1, 0)


def product_matrix(a: jnp.ndarray, n_harmonics: int) -> jnp.ndarray:
    """``M`` with ``analysis(a * synthesis(X, T), K) == M @ X``: multiplication by the
    sampled signal ``a`` ``(..., T)`` (samples on the last axis), ``(..., 2K+1, 2K+1)``.

    Assembled from the DFT ``A_q`` of the samples (product to sum: ``a cos(l tau)`` has
    the complex harmonics ``(A_{k-l} + A_{k+l}) / 2``, indices mod ``T``, so aliasing is
    the AFT's own): one FFT of ``T`` samples instead of ``2K+1`` pairs of FFTs.
    """
    n_time, K = a.shape[-1], n_harmonics
    A = jnp.fft.fft(a, axis=-1) / n_time  # A_q at index q mod T
    k = np.arange(K + 1)[:, None]
    l = np.arange(1, K + 1)[None, :]
    lo, hi = A[..., (k - l) % n_time], A[..., (k + l) % n_time]  # (..., K+1, K)
    F = jnp.concatenate([A[..., k % n_time],  # column 0: the constant
                         jnp.stack([(lo + hi) / 2, (lo - hi) / 2j], axis=-1).reshape(
                             lo.shape[:-1] + (2 * K,))], axis=-1)  # (..., K+1, 2K+1)
    rows = jnp.stack([2 * F[..., 1:, :].real, -2 * F[..., 1:, :].imag], axis=-2)
    return jnp.concatenate([F[..., :1, :].real, rows.reshape(F.shape[:-2] + (2 * K, 2 * K + 1))],
                           axis=-2)


def times_derivative(M: jnp.ndarray) -> jnp.ndarray:
    """``M @ derivative_matrix(K)`` for ``M`` ``(..., r, 2K+1)``, by columns."""
    K = (M.shape[-1] - 1) // 2
    k = jnp.arange(1, K + 1)
    out = jnp.zeros_like(M)
    out = out.at[..., 1::2].set(-k * M[..., 2::2])
    return out.at[..., 2::2].set(k * M[..., 1::2])


def derivative(X: jnp.ndarray) -> jnp.ndarray:
    """Coefficients of ``dx/dtau``: ``cos_k <- k sin_k``, ``sin_k <- -k cos_k``."""
    K = (X.shape[0] - 1) // 2
    k = jnp.arange(1, K + 1).reshape((K,) + (1,) * (X.ndim - 1))
    out = jnp.zeros_like(X)
    out = out.at[1::2].set(k * X[2::2])
    return out.at[2::2].set(-k * X[1::2])


def derivative_matrix(n_harmonics: int) -> np.ndarray:
    """``D`` with ``derivative(X) == D @ X``, shape ``(2K+1, 2K+1)``."""
    n = 2 * n_harmonics + 1
    D = np.zeros((n, n))
    for k in range(1, n_harmonics + 1):
        D[2 * k - 1, 2 * k] = k
        D[2 * k, 2 * k - 1] = -k
    return D


def harmonic_numbers(n_harmonics: int) -> np.ndarray:
    """Harmonic number of each coefficient row: ``[0, 1, 1, 2, 2, ..., K, K]``."""
    return np.concatenate([[0], np.repeat(np.arange(1, n_harmonics + 1), 2)])


def place_harmonics(cos: jnp.ndarray, sin: jnp.ndarray, orders, n_harmonics: int) -> jnp.ndarray:
    """Coefficients ``(2K+1, r)`` of ``sum_l cos[:, l] cos(o_l tau) + sin[:, l] sin(o_l tau)``.

    ``cos``, ``sin``: ``(r, L)``; ``orders``: ``L`` positive integers (harmonics of
    ``tau``). Orders above ``K`` are dropped (the caller warns).
    """
    out = jnp.zeros((2 * n_harmonics + 1, cos.shape[0]))
    for l, o in enumerate(orders):
        if 0 < o <= n_harmonics:
            out = out.at[2 * o - 1].add(cos[:, l]).at[2 * o].add(sin[:, l])
    return out
