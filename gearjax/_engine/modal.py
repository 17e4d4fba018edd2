"""Modal analysis of the linear, undamped, mean-stiffness model without backlash.

Modes solve ``(K + W^T diag(kbar) W) v = lambda M v``. Each is classified by where
its strain energy sits (model.md): more than half in ``penalty`` springs (braked
housing springs, couplings at least that stiff) -> ``penalty``; more than half in
``rigid`` springs (free housing springs) -> ``rigid`` (near-rigid-body); otherwise
``elastic``. A mode in which no central member moves and only the planets of one
stage do is a ``planet`` mode of that stage. In a system with translations (Lin &
Parker's model) a mode in which no central member translates is ``rotational``, one in
which none turns ``translational`` (the three types they prove for equally spaced
planets); every other mode is ``overall``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .programs import one_program
from .system import System

REPEATED_RTOL = 1e-6
"""Modes whose frequencies differ by less than this fraction (1 ppm) are one repeated mode."""

STILL_ATOL = 1e-6
"""A coordinate moves in a mode if its amplitude exceeds this fraction of the largest."""


@jax.custom_jvp
def generalized_eigvals(K, M):
    """Eigenvalues (ascending) of ``K v = lambda M v`` for symmetric ``K``, SPD ``M``.

    Differentiable at repeated eigenvalues: the JVP is ``v^T (dK - lambda dM) v`` per
    mass-normalised eigenvector, where ``jnp.linalg.eigh`` alone gives NaN gradients
    for the triple planet modes.
    """
    return _generalized_eigh(K, M)[0]


@generalized_eigvals.defjvp
def _generalized_eigvals_jvp(primals, tangents):
    K, M = primals
    dK, dM = tangents
    lam, V = _generalized_eigh(K, M)
    dlam = jnp.einsum("ik,ij,jk->k", V, dK, V) - lam * jnp.einsum("ik,ij,jk->k", V, dM, V)
    return lam, dlam


def _generalized_eigh(K, M):
    """Eigenvalues and M-normalised eigenvectors (columns) of ``K v = lambda M v``."""
    L = jnp.linalg.cholesky(0.5 * (M + M.T))
    Linv_K = jax.scipy.linalg.solve_triangular(L, 0.5 * (K + K.T), lower=True)
    A = jax.scipy.linalg.solve_triangular(L, Linv_K.T, lower=True)
    lam, U = jnp.linalg.eigh(0.5 * (A + A.T))
    V = jax.scipy.linalg.solve_triangular(L.T, U, lower=False)
    return lam, V


@dataclasses.dataclass(frozen=True)
class Mode:
    """One mode. ``shape``: coordinate label -> amplitude, largest magnitude 1 (positive);
    ``energy``: share of strain energy per spring class and ``mesh``; ``kinetic``:
    coordinate label -> share of the kinetic energy, ``v_i (M v)_i / v^T M v`` (sums to
    1; comparable across rotations and translations, unlike amplitudes in rad and m);
    ``multiplicity``: size of the group of repeated frequencies it belongs to."""

    hz: float
    multiplicity: int
    cls: str
    family: str
    stage: str | None
    shape: dict[str, float]
    energy: dict[str, float]
    kinetic: dict[str, float]


@dataclasses.dataclass(frozen=True)
class ModalResult:
    modes: tuple[Mode, ...]

    @property
    def elastic_hz(self) -> list[float]:
        """Elastic natural frequencies (Hz), ascending, repeated modes repeated."""
        return [m.hz for m in self.modes if m.cls == "elastic"]

    def elastic_multiplicities(self) -> list[int]:
        """Multiplicity of each distinct elastic frequency, ascending."""
        out, seen = [], 0
        elastic = [m for m in self.modes if m.cls == "elastic"]
        while seen < len(elastic):
            out.append(elastic[seen].multiplicity)
            seen += elastic[seen].multiplicity
        return out


@one_program
def mode_classes(system: System):
    """Classes of the modes of the mean-stiffness model, as :func:`modes` gives them
    (jittable and vmappable over the system's arrays, used by the Floquet verdict).

    **Returns** ``(lam, V, shares, rigid, penalty)``: eigenvalues ``(n,)`` (rad^2/s^2,
    ascending), M-normalised shapes ``(n, n)`` (columns), strain-energy shares
    ``{"elastic" | "penalty" | "rigid" | "mesh": (n,)}``, and ``(n,)`` booleans for the
    near-rigid-body and penalty modes (the rest are elastic). An exact rigid-body mode
    (housing.free = 0 and the brakes leave the train free to turn) has eigenvalue zero up
    to round-off; its strain-energy shares are round-off too (mostly ``"mesh"``), so it
    is classed rigid by its eigenvalue.
    """
    lam, V = _generalized_eigh(system.mean_stiffness(), system.M)
    classes = np.asarray(system.spring_class, dtype=object)
    spring_energy = 0.5 * system.spring_stiffness[:, None] * (system.spring_rows @ V) ** 2
    energy = {c: jnp.sum(spring_energy[classes == c], axis=0) if np.any(classes == c)
              else jnp.zeros(lam.shape) for c in ("elastic", "penalty", "rigid")}
    energy["mesh"] = jnp.sum(0.5 * system.kbar[:, None] * (system.W @ V) ** 2, axis=0)
    total = sum(energy.values())
    safe = jnp.where(total > 0, total, 1.0)
    shares = {c: jnp.where(total > 0, e / safe, 0.0) for c, e in energy.items()}
    zero = lam <= lam.size * jnp.finfo(lam.dtype).eps * jnp.max(jnp.abs(lam))
    rigid = (total <= 0) | zero | (shares["rigid"] > 0.5)
    penalty = ~rigid & (shares["penalty"] > 0.5)
    return lam, V, shares, rigid, penalty


def modes(system: System) -> ModalResult:
    """Natural frequencies (Hz), shapes, multiplicities, classes and families."""
    lam, V, shares, rigid, penalty = (jax.tree.map(np.asarray, a)
                                      for a in mode_classes(system))
    hz = np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)
    groups = _repeated_groups(hz)
    M = np.asarray(system.M)
    out = []
    for k in range(len(hz)):
        cls = "rigid" if rigid[k] else "penalty" if penalty[k] else "elastic"
        v = V[:, k]
        big = np.argmax(np.abs(v))
        v = v / v[big]
        family, stage = _family(system, v)
        out.append(Mode(hz=float(hz[k]), multiplicity=groups[k], cls=cls, family=family,
                        stage=stage, shape=dict(zip(system.dof_labels, np.where(
                            np.abs(v) < 1e-12, 0.0, v).tolist())),
                        energy={c: float(e[k]) for c, e in shares.items()},
                        kinetic=dict(zip(system.dof_labels, _kinetic_shares(M, V[:, k])))))
    return ModalResult(modes=tuple(out))


def _kinetic_shares(M: np.ndarray, v: np.ndarray) -> list[float]:
    """``v_i (M v)_i / v^T M v`` per coordinate, round-off below 1e-12 set to 0."""
    share = v * (M @ v) / (v @ M @ v)
    return np.where(np.abs(share) < 1e-12, 0.0, share).tolist()


def _repeated_groups(hz: np.ndarray) -> list[int]:
    sizes = [1] * len(hz)
    start = 0
    for k in range(1, len(hz) + 1):
        if k == len(hz) or abs(hz[k] - hz[start]) > REPEATED_RTOL * max(hz[k], 1.0):
            for j in range(start, k):
                sizes[j] = k - start
            start = k
    return sizes


def _family(system: System, v: np.ndarray) -> tuple[str, str | None]:
    """``planet`` (only one stage's planets move), in a system with translations
    (coordinate kind ``translation``) ``rotational`` (no central member translates) or
    ``translational`` (no central member turns), else ``overall``; and the one stage
    that moves, if one. With translations the coordinates mix units (rad, m), so
    motion is judged on mass-weighted amplitudes ``sqrt(M_ii) |v_i|``."""
    kinds = np.asarray(system.dof_kind)
    groups = np.asarray(system.dof_group)
    translations = kinds == "translation"
    if np.any(translations):
        w = np.abs(v) * np.sqrt(np.abs(np.diag(np.asarray(system.M))))
        moving = w > STILL_ATOL * np.max(w)
    else:
        moving = np.abs(v) > STILL_ATOL
    stages = set(groups[moving].tolist()) if kinds.size else set()
    stage = stages.pop() if len(stages) == 1 else None
    if kinds.size and stage is not None and not np.any(moving & (kinds != "planet")):
        return "planet", stage
    if np.any(translations) and not np.any(moving & translations):
        return "rotational", stage
    if np.any(translations) and not np.any(moving & (kinds == "central")):
        return "translational", stage
    return "overall", None
