"""Factorisation and solves of the bordered harmonic-balance Jacobian, condensed to the
degree-of-freedom combinations that deflect a mesh.

Continuation solves, per corrector iteration and per tangent,

    [[J, g], [t^T, tau]] [dy; dl] = [r; q]

with ``J = L + sum_m (w_m w_m^T) (x) J_m`` the scaled Jacobian (``_hb.jacobian``),
``g`` the parameter derivative of the residual and ``(t, tau)`` the tangent. A
combination of degrees of freedom that deflects no mesh (the null space of ``W``: in
a planetary stage the two kinematic motions, rigid rotation and the gear train's
rotation about a held carrier) enters only the linear part ``L``, which is
block-diagonal over harmonic pairs (cosine and sine of one harmonic). In a basis of
unknowns split into ``u`` (the ``r = rank W`` combinations that deflect meshes) and
``v`` (the ``n - r`` that do not), and of equations split alike, the mesh part
couples ``u`` with ``u`` only. So ``v`` is eliminated pair by pair (blocks of
``2(n - r)`` unknowns) and the dense factorisation is of ``(2K+1) r + 1`` unknowns
instead of ``(2K+1) n + 1``: ``(r/n)^3`` of the floating-point work (``r = 10`` of
``n = 14`` on a gear of two four-planet stages). The solution
is the same as the dense one up to round-off (tests/test_bordered.py). Newton at a
fixed frequency uses the same factors with a trivial border (:func:`jacobian_factors`),
through the lineax solver of :mod:`gearjax._engine.linear_solver`.

Both bases are orthonormal in the scaled unknowns and scaled equations (per harmonic:
the residual scale depends on the harmonic number), so the condensed matrix is as well
conditioned as the scaled Jacobian. The eliminated blocks are the linear part's
restriction to the motions that deflect no mesh: invertible whenever the gear has no
free rigid-body motion, the condition the harmonic balance needs anyway.

A system where every combination deflects a mesh (``r = n``, e.g. a one-degree-of-freedom
oscillator), or whose ``W`` was not concrete when its ``HBProblem`` was built, is
factorised densely.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from . import aft as _aft
from . import hb as _hb
from .programs import one_program


class Factors(eqx.Module):
    """Factors of a bordered Jacobian (:func:`factor`).

    ``lu``, ``perm``: LU of the condensed bordered matrix ``M``, ``(C r + 1)^2`` (the full
    ``(C n + 1)^2`` one when not condensed, and the other fields ``None``), with ``M[perm]
    = L U`` (``L`` unit lower triangular, both in ``lu``); in single
    precision when factorised with ``single``, and :func:`solve` then solves with them in
    single precision, everything around in double. ``R`` ``(n, n)``: unknown basis
    ``[u | v]``; ``P`` ``(C, n, n)``: equation basis per coefficient row. Per group of
    rows (the mean; the ``K`` harmonic pairs), as tuples ``(mean, pairs)``: ``Vinv`` the
    inverse of the ``v``-``v`` block, ``E = Vinv L_vu``, ``F = L_uv Vinv``, ``hv = Vinv
    g_v``, ``wv = Vinv^T t_v``.
    """

    lu: Array
    perm: Array
    R: Array | None = None
    P: Array | None = None
    Vinv: tuple | None = None
    E: tuple | None = None
    F: tuple | None = None
    hv: tuple | None = None
    wv: tuple | None = None


@one_program
def factor(problem: _hb.HBProblem, y: Array, omega, g: Array, ty: Array, tlam,
           single: bool = False) -> Factors:
    """Factorise ``[[J(y, omega), g], [ty^T, tlam]]`` (jittable).

    **Arguments:** ``y`` ``(N,)`` scaled unknowns; ``omega`` base frequency (rad/s);
    ``g`` ``(N,)`` the bordering column; ``ty`` ``(N,)``, ``tlam`` the bordering row;
    ``single``: the dense LU in single precision (the accuracy of a preconditioner, for
    quasi-Newton iterations on the double residual: ``continuation.Settings.single``).
    """
    null = problem.mesh_null  # (n, nv)
    if null is None:
        return dense(_hb.jacobian(problem, y, omega), g, ty, tlam, single)
    s = problem.system
    C, n = problem.shape
    K = problem.basis.n_pairs
    nv = null.shape[1]
    r = n - nv
    w0 = omega / problem.settings.eta
    xs = problem.x_scale
    row_scale = _hb.residual_scale(problem, omega)  # (C, n), per harmonic number
    harmonic = _aft.pair_index(problem.basis)
    scale_k = row_scale[np.concatenate([[0], np.arange(1, C, 2)])]  # (K+1, n): per k
    # unknowns y deflect no mesh where x_scale * y is in the null space; equation rows
    # (divided by the row scale) see no mesh force where orthogonal to (row scale) null
    bases = _complete_bases(
        jnp.concatenate([(null / xs[:, None])[None], scale_k[:, :, None] * null]))
    R, P = bases[0], bases[1:]

    # linear part per pair (the mean first), scaled: (K+1, 2, n, 2, n), rows (cos, sin)
    Lk = _hb.harmonic_blocks(s.K, s.M, s.C, w0, _aft.frequency_numbers(problem.basis)[::2])
    Lk = Lk / scale_k[:, None, :, None, None] * xs
    Lk = jnp.einsum("kip,kaibj,jq->kapbq", P, Lk, R)
    mean, pairs = Lk[:1, :1, :, :1, :], Lk[1:]
    blocks = _condense((mean, pairs), r)  # (Lam, Vinv, E, F) per group

    # mesh part, in u only: W scaled and rotated on each side
    X = y.reshape(C, n) * xs
    Jm = _hb.mesh_blocks(problem, X @ s.W.T, omega)  # (m, C, C)
    Wl = jnp.einsum("mi,ai,aip->amp", s.W, 1.0 / row_scale, P[harmonic][:, :, :r])  # (C, m, r)
    Wr = (s.W * xs) @ R[:, :r]  # (m, r)
    A = jnp.einsum("mab,amp,mq->apbq", Jm, Wl, Wr).reshape(C * r, C * r)
    rows, cols = _diag_indices(K, r)
    A = A.at[rows, cols].add(
        jnp.concatenate([blocks[0][0].reshape(-1), blocks[1][0].reshape(-1)]))

    # bordering column and row, rotated and condensed
    Pc = P[harmonic]  # (C, n, n)
    gu, gv = _split(jnp.einsum("aip,ai->ap", Pc, g.reshape(C, n)), r)
    tu, tv = _split(ty.reshape(C, n) @ R, r)
    hv = tuple(jnp.einsum("gij,gj->gi", b[1], v) for b, v in zip(blocks, gv))
    wv = tuple(jnp.einsum("gji,gj->gi", b[1], v) for b, v in zip(blocks, tv))
    col = _join([u - jnp.einsum("gij,gj->gi", b[3], v) for b, u, v in zip(blocks, gu, gv)], K)
    row = _join([u - jnp.einsum("gji,gj->gi", b[2], v) for b, u, v in zip(blocks, tu, tv)], K)
    corner = tlam - sum(jnp.sum(w * v) for w, v in zip(wv, gv))
    lu, perm = _bordered_lu(A, col.reshape(-1), row.reshape(-1), corner, single)
    return Factors(lu=lu, perm=perm, R=R, P=Pc, Vinv=tuple(b[1] for b in blocks),
                   E=tuple(b[2] for b in blocks), F=tuple(b[3] for b in blocks), hv=hv, wv=wv)


def dense(J: Array, g: Array, ty: Array, tlam, single: bool = False) -> Factors:
    """Factorise ``[[J, g], [ty^T, tlam]]`` as it is (``J`` ``(N, N)``; jittable)."""
    lu, perm = _bordered_lu(J, g, ty, tlam, single)
    return Factors(lu=lu, perm=perm)


def jacobian_factors(problem: _hb.HBProblem, y: Array, omega) -> Factors:
    """Factors of the Jacobian alone, as the bordered matrix ``[[J, 0], [0, 1]]`` (Newton at
    fixed frequency; :func:`jacobian_solve`)."""
    zero = jnp.zeros_like(y)
    return factor(problem, y, omega, zero, zero, 1.0)


def jacobian_solve(factors: Factors, r: Array) -> Array:
    """``J^-1 r`` ``(N,)`` from :func:`jacobian_factors`."""
    return solve(factors, jnp.concatenate([r, jnp.zeros(1)]))[:-1]


@one_program
def solve(factors: Factors, rhs: Array) -> Array:
    """Solution ``(N + 1,)`` of the factorised bordered system for ``rhs`` ``(N + 1,)``
    (jittable)."""
    f = factors
    if f.R is None:
        return _lu_solve(f, rhs)
    C, n, _ = f.P.shape
    K = (C - 1) // 2
    r = n - f.Vinv[0].shape[-1]
    ru, rv = _split(jnp.einsum("aip,ai->ap", f.P, rhs[:-1].reshape(C, n)), r)
    reduced = _join([u - jnp.einsum("gij,gj->gi", F, v) for F, u, v in zip(f.F, ru, rv)], K)
    q = rhs[-1] - sum(jnp.sum(w * v) for w, v in zip(f.wv, rv))
    sol = _lu_solve(f, jnp.concatenate([reduced.reshape(-1), q[None]]))
    U, dl = sol[:-1].reshape(C, r), sol[-1]
    V = [jnp.einsum("gij,gj->gi", Vi, v) - jnp.einsum("gij,gj->gi", E, u) - h * dl
         for Vi, E, h, v, u in zip(f.Vinv, f.E, f.hv, rv, _groups(U))]
    Z = jnp.concatenate([U, _join(V, K)], axis=1)  # (C, n): [u | v] per row
    return jnp.concatenate([(Z @ f.R.T).reshape(-1), dl[None]])


# ------------------------------------------------------------------------- parts


def _bordered_lu(A: Array, col: Array, row: Array, corner, single: bool = False):
    """LU factors ``(lu, perm)`` of ``[[A, col], [row^T, corner]]`` (:class:`Factors`), in
    single precision with ``single`` (:func:`factor`)."""
    top = jnp.concatenate([A, col[:, None]], axis=1)
    bottom = jnp.concatenate([row, jnp.asarray(corner)[None]])[None, :]
    M = jnp.concatenate([top, bottom], axis=0)
    lu, _, perm = jax.lax.linalg.lu(M.astype(jnp.float32) if single else M)
    return _pad_blocks(lu), perm


TRIANGLE_BLOCK = 64
"""Rows per block of :func:`_triangular_solve`."""


def _pad_blocks(lu: Array) -> Array:
    """``lu`` ``(p, p)`` padded to whole blocks of :data:`TRIANGLE_BLOCK` rows, with a unit
    diagonal in the padding (the triangles of the padded matrix are those of ``lu`` and
    an identity beside them)."""
    p = lu.shape[0]
    q = -(-p // TRIANGLE_BLOCK) * TRIANGLE_BLOCK
    pad = jnp.arange(p, q)
    return jnp.pad(lu, (0, q - p)).at[pad, pad].set(1.0)


def _lu_solve(factors: Factors, rhs: Array) -> Array:
    """``rhs`` solved with the LU factors, in their precision, returned in ``rhs``'s."""
    lu = factors.lu
    p = factors.perm.shape[0]
    b = jnp.pad(rhs.astype(lu.dtype)[factors.perm], (0, lu.shape[0] - p))
    x = _triangular_solve(lu, _triangular_solve(lu, b, lower=True), lower=False)
    return x[:p].astype(rhs.dtype)


def _triangular_solve(lu: Array, b: Array, lower: bool) -> Array:
    """``T^-1 b`` ``(q,)`` for the triangle ``T`` of ``lu`` ``(q, q)`` (whole blocks,
    :func:`_pad_blocks`): the unit lower one (``lower``) or the upper one with the
    diagonal.

    Block by block of :data:`TRIANGLE_BLOCK` rows (a scan: one body to trace): the
    rows' product with the part of the solution found so far (zero elsewhere), then a
    small triangular solve. XLA's CPU kernel for a whole triangle with one right-hand side
    is several times slower than matrix-vector products over the same entries
    (docs/benchmarks.md). The result agrees with a direct solve to round-off.
    """
    q, m = b.shape[0], TRIANGLE_BLOCK

    def block(x, part):
        i, rows = part  # the block's first row, its rows (m, q)
        r = jax.lax.dynamic_slice_in_dim(b, i, m) - rows @ x
        d = jax.lax.dynamic_slice_in_dim(rows, i, m, axis=1)
        xi = jax.lax.linalg.triangular_solve(d, r[:, None], left_side=True, lower=lower,
                                             unit_diagonal=lower)[:, 0]
        return jax.lax.dynamic_update_slice_in_dim(x, xi, i, 0), None

    parts = (jnp.arange(0, q, m), lu.reshape(q // m, m, q))
    return jax.lax.scan(block, jnp.zeros_like(b), parts, reverse=not lower)[0]


def _complete_bases(A: Array) -> Array:
    """Orthonormal bases ``(B, n, n)`` ``[u | v]``: ``v`` spans the columns of ``A[b]``
    ``(n, nv)`` (full column rank), ``u`` their orthogonal complement.

    Householder reflections in array operations (one loop body), not LAPACK (see
    :func:`small_inverses`).
    """
    B, n, nv = A.shape
    rows = jnp.arange(n)

    def reflect(j, c):
        A, Q = c
        x = jnp.where(rows >= j, jnp.take(A, j, axis=2), 0.0)  # (B, n)
        head = jnp.take(x, j, axis=1)
        v = x + jnp.where(rows == j, jnp.where(head >= 0, 1.0, -1.0)[:, None]
                          * jnp.linalg.norm(x, axis=1, keepdims=True), 0.0)
        v = v / jnp.linalg.norm(v, axis=1, keepdims=True)
        A = A - 2 * v[:, :, None] * jnp.einsum("bi,bik->bk", v, A)[:, None, :]
        Q = Q - 2 * jnp.einsum("bij,bj->bi", Q, v)[:, :, None] * v[:, None, :]
        return A, Q

    Q = jax.lax.fori_loop(0, nv, reflect, (A, jnp.broadcast_to(jnp.eye(n), (B, n, n))))[1]
    return jnp.concatenate([Q[:, :, nv:], Q[:, :, :nv]], axis=2)


def small_inverses(A: Array) -> Array:
    """Inverses ``(B, p, p)`` of a batch of small matrices: Gauss-Jordan elimination with
    partial pivoting in array operations, equilibrated first; one loop body (unrolled,
    every step would be separate compiled kernels: XLA's CPU code for them takes memory
    mappings, a finite resource in a long session).

    Not LAPACK: jaxlib's batched LAPACK kernels spread a batch over the XLA CPU thread
    pool and wait for it, so two of them running at once (XLA may hoist one out of a
    loop next to another) can wait for each other forever on a small pool. The
    factorisation keeps one LAPACK call (the LU of the condensed matrix), after every
    other, as the dense one does.
    """
    B, p, _ = A.shape
    # equilibrated first (powers of two: exact), for pivots that mean something
    row = 2.0 ** -jnp.round(jnp.log2(jnp.max(jnp.abs(A), axis=2, keepdims=True)))
    col = 2.0 ** -jnp.round(jnp.log2(jnp.max(jnp.abs(A * row), axis=1, keepdims=True)))
    A = A * row * col
    M = jnp.concatenate([A, jnp.broadcast_to(jnp.eye(p), A.shape)], axis=2)  # (B, p, 2p)
    rows = jnp.arange(p)

    def eliminate(j, M):
        column = jnp.take(M, j, axis=2)  # (B, p)
        pivot = jnp.argmax(jnp.where(rows >= j, jnp.abs(column), -1.0), axis=1)  # (B,)
        swap = jnp.where(rows == j, pivot[:, None], jnp.where(rows == pivot[:, None], j, rows))
        M = jnp.take_along_axis(M, swap[:, :, None], axis=1)
        head = jnp.take(M, j, axis=1)  # (B, 2p)
        head = head / jnp.take(head, j, axis=1)[:, None]
        factor = jnp.where(rows == j, 0.0, jnp.take(M, j, axis=2))  # (B, p)
        return jnp.where((rows == j)[None, :, None], head[:, None, :],
                         M - factor[:, :, None] * head[:, None, :])

    M = jax.lax.fori_loop(0, p, eliminate, M)
    return jnp.swapaxes(col, 1, 2) * M[:, :, p:] * jnp.swapaxes(row, 1, 2)


def _condense(groups, r: int):
    """Schur complements of the ``v``-``v`` blocks of the groups of rows.

    ``groups``: ``(mean, pairs)``, linear blocks in the rotated bases, ``(G, g, n, g, n)``
    with ``g`` rows per group (1 for the mean, ``G = 1``; 2 for a harmonic pair, ``G = K``).
    **Returns:** per group ``(Lam, Vinv, E, F)``: ``Lam = L_uu - L_uv Vinv L_vu``
    ``(G, g r, g r)``, ``Vinv`` ``(G, g nv, g nv)`` the inverse of ``L_vv``, ``E = Vinv
    L_vu``, ``F = L_uv Vinv``.

    The inverses of both groups are one batch (the mean's block padded with an identity
    to a pair's size), :func:`small_inverses`.
    """
    parts = []
    for L in groups:
        G, g, n = L.shape[:3]
        u, v = slice(0, r), slice(r, n)
        part = lambda a, b: L[:, :, a, :, b].reshape(  # noqa: E731
            G, g * (a.stop - a.start), g * (b.stop - b.start))
        parts.append((part(u, u), part(u, v), part(v, u), part(v, v)))
    (_, _, _, mean_vv), (_, _, _, pairs_vv) = parts
    nv = mean_vv.shape[-1]
    padded = jnp.zeros((1, 2 * nv, 2 * nv)).at[0, :nv, :nv].set(mean_vv[0]).at[
        0, nv:, nv:].set(jnp.eye(nv))
    inverse = small_inverses(jnp.concatenate([padded, pairs_vv]))
    out = []
    for (Luu, Luv, Lvu, _), Vinv in zip(parts, (inverse[:1, :nv, :nv], inverse[1:])):
        E = Vinv @ Lvu
        F = Luv @ Vinv
        out.append((Luu - Luv @ E, Vinv, E, F))
    return out


def _groups(Z: Array):
    """Rows ``(C, p)`` (harmonic-major) as groups ``(mean (1, p), pairs (K, 2p))``."""
    K = (Z.shape[0] - 1) // 2
    return Z[:1].reshape(1, -1), Z[1:].reshape(K, -1)


def _split(Z: Array, r: int):
    """Rows ``(C, n)`` in a ``[u | v]`` basis as ``(u groups, v groups)``: the first ``r``
    columns and the rest, each as :func:`_groups`."""
    return _groups(Z[:, :r]), _groups(Z[:, r:])


def _join(groups, K: int) -> Array:
    """Inverse of one half of :func:`_split`: groups ``(mean, pairs)`` to rows ``(C, q)``."""
    mean, pairs = groups
    q = mean.shape[-1]
    return jnp.concatenate([mean.reshape(1, q), pairs.reshape(2 * K, q)])


def _diag_indices(K: int, r: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of the condensed matrix's diagonal blocks (the mean's
    ``r x r``, then each harmonic pair's ``2r x 2r``), in :func:`_condense`'s order."""
    rows, cols = [], []
    for start, size in [(0, r)] + [(r + 2 * r * (k - 1), 2 * r) for k in range(1, K + 1)]:
        i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
        rows.append(start + i.reshape(-1))
        cols.append(start + j.reshape(-1))
    return np.concatenate(rows), np.concatenate(cols)
