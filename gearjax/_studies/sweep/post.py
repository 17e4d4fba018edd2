"""Responses and stability of a sweep's solutions, in chunks of points, and where the
stability changes along a branch (bifurcations).

Post-processing is a pure function of the solutions: it runs beside the continuation
(:class:`PostStream`, a background worker of :mod:`gearjax._studies.concurrency`) or
after it, with the same chunks and the same compiled programs either way.
"""

from __future__ import annotations

import jax
import numpy as np

from ..._engine.kept import kept_program
from ..._engine.responses import mesh_responses
from ..._engine.results import RESULTS, result_word
from ..._engine.verdict import (
    bifurcation_kind,
    floquet_steps,
    scaled_monodromy,
    verdict,
    verdict_basis,
)
from .. import concurrency

POST_CHUNK = 8
"""Points per compiled call of the post-processing (responses + Floquet): the step
exponentials of a chunk stay in cache; one compilation per K (the last chunk is
padded)."""

SWEEP_FLOQUET_STEPS = 16
"""Floquet steps per period of the highest harmonic in a sweep's stability
(:func:`gearjax._engine.verdict.floquet_steps`, whose default for a single point is
32): the multipliers of a truncated orbit are only as accurate as the orbit, and half
the steps change them by much less than the truncation does."""

POST_THREAD = "gearjax-post"
"""Name (prefix) of the post-processing threads."""


def point_rows(problem, Xs, omegas, results, F_static, done=()):
    """Responses and stability of a batch of solutions ``Xs`` ``(P, C, n)`` at base
    frequencies ``omegas`` ``(P,)`` (rad/s) with results ``results`` ``(P,)`` (words,
    :func:`~gearjax._engine.results.result_word`), in chunks of :data:`POST_CHUNK` points (the
    last padded by repeating its final point), several chunks at a time
    (:func:`gearjax._studies.concurrency.map_in_threads`). ``done``: the outputs of
    :func:`post_chunk` for the leading chunks, computed before (:class:`PostStream`).
    The chunk programs call no LAPACK routine (``stability.verdict_basis``); the
    eigenvalues of the monodromy matrices are NumPy's.

    **Returns:** a dict of per-point host arrays: ``responses`` (``MeshResponses``,
    fields ``(P, m)``), ``omega``, ``result``, ``X`` (list of ``(C, n)``), ``K``,
    ``stable``, ``max_multiplier``, ``multipliers``, ``excluded``."""
    P = len(omegas)
    pad = -P % POST_CHUNK
    # host arrays: padding and chunking on the device would each be a program per P
    Xs, omegas_p = np.asarray(Xs), np.asarray(omegas)
    if pad:
        Xs = np.concatenate([Xs, np.repeat(Xs[-1:], pad, axis=0)])
        omegas_p = np.concatenate([omegas_p, np.repeat(omegas_p[-1:], pad)])
    basis = verdict_basis(problem)
    size = POST_CHUNK

    def chunk(i):
        return post_chunk(problem, basis, Xs[i:i + size], omegas_p[i:i + size], F_static)

    starts = range(len(done) * size, P + pad, size)
    parts = list(done)
    if starts and _signature((problem, basis, Xs[:size], omegas_p[:size], F_static)) \
            not in _POST_COMPILED:  # the first call compiles: alone, before the threads
        parts.append(chunk(starts[0]))
        starts = starts[1:]
    parts += concurrency.map_in_threads(chunk, starts, POST_THREAD)
    resp, stab = jax.tree.map(lambda *a: np.concatenate(a)[:P], *parts)
    return {"responses": resp, "omega": np.asarray(omegas), "result": np.asarray(results),
            "X": list(Xs[:P]), "K": _orders_rows(problem, P),
            "stable": np.asarray(stab.stable), "max_multiplier": np.asarray(stab.max_abs),
            "multipliers": np.asarray(stab.multipliers), "excluded": np.asarray(stab.excluded)}


def post_chunk(problem, basis, Xs, omegas, F_static):
    """Responses and stability verdicts (host arrays) of one chunk of :data:`POST_CHUNK`
    solutions ``Xs`` ``(POST_CHUNK, C, n)`` at ``omegas`` (rad/s)."""
    resp, Phi = batch_monodromy(problem, basis, Xs, omegas, F_static)
    mu, V = _eig(np.asarray(Phi))
    out = jax.device_get((resp, batch_verdict(problem, basis, mu, V)))
    _POST_COMPILED.add(_signature((problem, basis, Xs, omegas, F_static)))
    return out


class PostStream:
    """Responses and stability of a continuation's points while it goes on: each full
    chunk of :data:`POST_CHUNK` points of a segment, as soon as the continuation has
    found it, on a background worker (:class:`gearjax._studies.concurrency.Worker`;
    at once where the policy is serial); :meth:`rows` waits for those and computes the
    rest. Results are those of :func:`point_rows` over the whole segment at once (the
    same chunks). Segments are named by any hashable key."""

    def __init__(self, F_static):
        self._F = F_static
        self._worker = concurrency.Worker(POST_THREAD)
        self._chunks: dict = {}  # segment -> futures of its leading chunks
        self._basis: dict = {}

    def feed(self, j, problem, omega_ref: float, pts: list[dict]) -> None:
        """Submit the full chunks of segment ``j``'s points ``pts`` (journal records) not
        submitted yet."""
        futures = self._chunks.setdefault(j, [])
        while (len(futures) + 1) * POST_CHUNK <= len(pts):
            i = len(futures) * POST_CHUNK
            if j not in self._basis:
                self._basis[j] = verdict_basis(problem)
            Xs, omegas = point_arrays(problem, omega_ref, pts[i:i + POST_CHUNK])
            futures.append(self._worker.submit(post_chunk, problem, self._basis[j], Xs,
                                               omegas, self._F))

    def rows(self, j, problem, omega_ref: float, pts: list[dict]) -> dict:
        """:func:`point_rows` of segment ``j``'s points ``pts``."""
        done = [f.result() for f in self._chunks.pop(j, [])]
        Xs, omegas = point_arrays(problem, omega_ref, pts)
        return point_rows(problem, Xs, omegas, np.full(len(pts), result_word(RESULTS.successful)),
                          self._F, done)

    def rename(self, old, new) -> None:
        """Segment ``old``'s chunks are segment ``new``'s (an adopted speculation)."""
        if old in self._chunks:
            self._chunks[new] = self._chunks.pop(old)
        if old in self._basis:
            self._basis[new] = self._basis.pop(old)

    def drop(self, j) -> None:
        """Forget segment ``j``'s chunks; those not started are not computed."""
        for f in self._chunks.pop(j, []):
            f.cancel()
        self._basis.pop(j, None)

    def close(self) -> None:
        """Stop: chunks not started are dropped (an interrupted sweep)."""
        self._worker.close()


def _orders_rows(problem, P: int) -> np.ndarray:
    """Each point's ``K``: ``(P,)`` for a periodic problem, ``(P, G)`` orders on a torus."""
    K = problem.settings.n_harmonics
    if problem.basis.G == 1:
        return np.full(P, int(K if not isinstance(K, tuple) else K[0]))
    return np.tile(np.asarray(problem.basis.G * (K,) if isinstance(K, int) else K,
                              dtype=np.int64)[None], (P, 1))


def point_arrays(problem, omega_ref: float, pts: list[dict]):
    """Unscaled solutions ``(P, C, n)`` and base frequencies ``(P,)`` (rad/s) of journal
    point records (``y``, ``lam``), host arrays."""
    Xs = np.stack([p["y"] for p in pts]).reshape((-1,) + problem.shape) * np.asarray(
        problem.x_scale)
    return Xs, np.array([p["lam"] for p in pts]) * omega_ref


def bifurcations(f_hz, stable, multipliers, excluded, branch=None, torus: bool = False,
                 linear: bool = False) -> list[dict]:
    """Where stability changes between neighbouring points of one branch, and how
    (interface: a list of ``{"mesh_frequency_hz", "kind"}``, the frequency the midpoint
    of the two points), with ``multiplier``: the largest retained ``|mu|`` of the
    unstable one of the two points (``None`` where not finite).

    ``kind`` is from :func:`~gearjax._engine.verdict.bifurcation_kind`: ``fold``,
    ``period_doubling`` or ``neimark_sacker`` (``None`` where no retained multiplier
    changed side of the unit circle; the rigid-body multipliers are left out, see
    :class:`~gearjax._engine.verdict.Stability`). On a ``torus`` the multipliers are
    growths per turn of the base angle whose phases mean nothing (``verdict``): the kind
    is ``None`` (a stability change) there.

    A ``linear`` system (no backlash) has no fold, period doubling or torus: its
    solution is unique, and a multiplier outside the unit circle means that any
    disturbance grows without bound, a parametric instability. There ``kind`` is
    ``"parametric_instability"`` and ``crossing`` says how the multiplier left the
    circle (the kind above: ``period_doubling`` through -1, ``neimark_sacker`` a complex
    pair, ``fold`` through +1; ``None`` on a torus).
    """
    out = []
    stable = np.asarray(stable, dtype=float)  # NaN: unknown (e.g. a runaway point)
    change = (stable[1:] != stable[:-1]) & np.isfinite(stable[1:]) & np.isfinite(stable[:-1])
    if branch is not None:
        change &= np.asarray(branch[1:]) == np.asarray(branch[:-1])
    for i in np.flatnonzero(change):
        kind = None if torus else bifurcation_kind(multipliers[i][~excluded[i]],
                                                   multipliers[i + 1][~excluded[i + 1]])
        u = i if stable[i] == 0 else i + 1  # the unstable one of the two
        mu = np.abs(np.asarray(multipliers[u])[~np.asarray(excluded[u])])
        top = float(np.max(mu)) if mu.size and np.all(np.isfinite(mu)) else None
        entry = {"mesh_frequency_hz": float((f_hz[i] + f_hz[i + 1]) / 2), "kind": kind,
                 "multiplier": top}
        if linear:
            entry.update(kind=PARAMETRIC, crossing=kind)
        out.append(entry)
    return out


PARAMETRIC = "parametric_instability"
"""The ``kind`` of a linear system's stability change (:func:`bifurcations`)."""


@kept_program
def batch_monodromy(problem, basis, Xs, omegas, F_static):
    """Mesh responses and scaled monodromy matrices of a chunk of solutions."""
    resp = jax.vmap(mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs, omegas, F_static)
    n_steps = floquet_steps(problem, SWEEP_FLOQUET_STEPS)
    Phi = jax.vmap(lambda X, w: scaled_monodromy(problem, basis, X, w, n_steps))(Xs, omegas)
    return resp, Phi


@kept_program
def batch_verdict(problem, basis, mu, V):
    """Stability verdicts of a chunk from its multipliers and Floquet modes."""
    return jax.vmap(verdict, in_axes=(None, None, 0, 0))(problem, basis, mu, V)


def _eig(Phi):
    """Eigenvalues ``(c, k)`` and eigenvectors ``(c, k, k)`` (complex) of a batch of
    matrices, NaN for a matrix with a non-finite entry (as ``jnp.linalg.eig`` gives)."""
    finite = np.all(np.isfinite(Phi), axis=(1, 2))
    mu, V = np.linalg.eig(np.where(finite[:, None, None], Phi, np.eye(Phi.shape[-1])))
    mu, V = mu.astype(complex), V.astype(complex)  # NumPy's are real when all are
    mu[~finite], V[~finite] = np.nan, np.nan
    return mu, V


_POST_COMPILED: set = set()
"""Signatures (:func:`_signature`) of the post-processing chunk programs compiled in
this process: the first chunk of a new signature runs alone, before the threads."""


def _signature(args) -> tuple:
    """What a jitted function's compilation depends on, of arguments ``args``: the tree
    structure (with the static fields) and every leaf's shape and type."""
    leaves, tree = jax.tree.flatten(args)
    return tree, tuple((np.shape(a), str(getattr(a, "dtype", type(a).__name__)))
                       for a in leaves)
