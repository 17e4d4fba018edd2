"""The generic ``System``: the seam between the gear model and the solvers.

    M x'' + C x' + K x + sum_m w_m F_m = f(t),
    p_m = w_m . x - e_m(t),   F_m = kbar_m kappa_m(t) g(p_m) + c_m p_m'

with every excitation quasi-periodic in ``G`` torus angles (model.md, "Incommensurate
stages"): angle ``g`` turns at ``angle_ratio[g] Omega``; mesh ``m`` varies at
``mu_m`` times the rate of its angle ``mesh_angle[m]`` (its stiffness and
transmission error harmonics ``h mu_m``), forcing column ``l`` at ``forcing_mu_l``
times the rate of angle ``forcing_angle[l]``. ``G = 1`` with ratio 1 is the periodic
case: everything varies at integer multiples of the one base frequency ``Omega``.
Solvers see only this module: nothing here knows about suns or rings except the labels.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

SPRING_CLASSES = ("elastic", "penalty", "rigid")


class System(eqx.Module):
    """Linear structure plus mesh elements, all SI.

    **Fields** (``n`` coordinates, ``m`` meshes, ``s`` linear springs):

    - ``M``, ``C``: ``(n, n)`` mass (kg m^2 or kg) and viscous damping matrices;
    - ``spring_rows`` ``(s, n)``, ``spring_stiffness`` ``(s,)``: linear springs, so
      ``K = S^T diag(k) S`` (housing and coupling springs in a gear train);
      ``spring_class``: ``"elastic" | "penalty" | "rigid"`` per spring, where its
      strain energy counts in modal classification;
    - ``W`` ``(m, n)``: mesh projection rows (m/rad), ``p = W x``;
    - ``kbar`` ``(m,)`` mean mesh stiffness (N/m); ``k_cos``, ``k_sin`` ``(m, H)``
      dimensionless stiffness Fourier coefficients of harmonics ``h mu_m Omega``;
    - ``backlash`` ``(m,)`` half clearance (m); ``damping`` ``(m,)`` mesh damping (N s/m);
    - ``te_mean`` ``(m,)``: constant part of the transmission error (m); ``te_cos``,
      ``te_sin`` ``(m, H_e)``: its harmonics, as the stiffness's;
    - ``mesh_radius`` ``(m,)``: lever arm (m) turning a mesh force into a torque;
    - ``f_mean`` ``(n,)``, ``f_cos``, ``f_sin`` ``(n, L)``: forcing (N m), column ``l``
      at ``forcing_mu[l] Omega``;
    - static: ``mesh_mu``, ``forcing_mu`` (integer multipliers of the rate of their
      torus angle), ``mesh_angle`` ``(m,)`` and ``forcing_angle`` ``(L,)`` (the torus
      angle of each mesh and forcing column; empty: all angle 0), ``angle_ratio``
      ``(G,)`` (each angle's rate over ``Omega``; ``(1.0,)``: periodic in ``Omega``),
      ``contact_damping`` and labels.
    """

    M: Float[Array, "n n"]
    C: Float[Array, "n n"]
    spring_rows: Float[Array, "s n"]
    spring_stiffness: Float[Array, " s"]
    W: Float[Array, "m n"]
    kbar: Float[Array, " m"]
    k_cos: Float[Array, "m H"]
    k_sin: Float[Array, "m H"]
    backlash: Float[Array, " m"]
    damping: Float[Array, " m"]
    te_mean: Float[Array, " m"]
    te_cos: Float[Array, "m He"]
    te_sin: Float[Array, "m He"]
    mesh_radius: Float[Array, " m"]
    f_mean: Float[Array, " n"]
    f_cos: Float[Array, "n L"]
    f_sin: Float[Array, "n L"]
    mesh_mu: tuple[int, ...] = eqx.field(static=True)
    forcing_mu: tuple[int, ...] = eqx.field(static=True)
    spring_class: tuple[str, ...] = eqx.field(static=True)
    contact_damping: bool = eqx.field(static=True, default=False)
    dof_labels: tuple[str, ...] = eqx.field(static=True, default=())
    dof_group: tuple[str, ...] = eqx.field(static=True, default=())
    dof_kind: tuple[str, ...] = eqx.field(static=True, default=())
    mesh_labels: tuple[str, ...] = eqx.field(static=True, default=())
    mesh_group: tuple[str, ...] = eqx.field(static=True, default=())
    mesh_side: tuple[str, ...] = eqx.field(static=True, default=())
    mesh_planet: tuple[int, ...] = eqx.field(static=True, default=())
    mesh_angle: tuple[int, ...] = eqx.field(static=True, default=())
    forcing_angle: tuple[int, ...] = eqx.field(static=True, default=())
    angle_ratio: tuple[float, ...] = eqx.field(static=True, default=(1.0,))

    @property
    def n_dof(self) -> int:
        return self.M.shape[-1]

    @property
    def n_meshes(self) -> int:
        return self.W.shape[-2]

    @property
    def n_angles(self) -> int:
        """``G``: torus angles of the excitation (1: periodic in ``Omega``)."""
        return len(self.angle_ratio)

    @property
    def mesh_angles(self) -> tuple[int, ...]:
        """The torus angle of each mesh, ``(m,)``."""
        return self.mesh_angle or (0,) * len(self.mesh_mu)

    @property
    def forcing_angles(self) -> tuple[int, ...]:
        """The torus angle of each forcing column, ``(L,)``."""
        return self.forcing_angle or (0,) * len(self.forcing_mu)

    def mesh_rates(self) -> np.ndarray:
        """Each mesh's fundamental frequency over ``Omega``, ``(m,)`` (floats):
        ``mu_m angle_ratio[mesh_angle[m]]``."""
        ratio = np.asarray(self.angle_ratio, float)
        return np.asarray(self.mesh_mu, float) * ratio[list(self.mesh_angles)]

    def forcing_rates(self) -> np.ndarray:
        """Each forcing column's frequency over ``Omega``, ``(L,)`` (floats)."""
        ratio = np.asarray(self.angle_ratio, float)
        return np.asarray(self.forcing_mu, float) * ratio[list(self.forcing_angles)]

    @property
    def K(self) -> Float[Array, "n n"]:
        """Linear stiffness of the springs, ``S^T diag(k) S``."""
        return self.spring_rows.T @ (self.spring_stiffness[:, None] * self.spring_rows)

    @property
    def has_backlash(self) -> bool:
        """Some mesh has a clearance (concrete values only: not under ``jit``)."""
        return bool(np.any(np.asarray(self.backlash) > 0))

    def mean_stiffness(self) -> Float[Array, "n n"]:
        """``K + W^T diag(kbar) W``: the linear, mean-stiffness, no-backlash stiffness."""
        return self.K + self.W.T @ (self.kbar[:, None] * self.W)


def system_from_matrices(
    M,
    C,
    K,
    W,
    kbar,
    *,
    backlash=None,
    damping=None,
    k_cos=None,
    k_sin=None,
    mesh_mu: Sequence[int] | None = None,
    te_mean=None,
    te_cos=None,
    te_sin=None,
    f_mean=None,
    f_cos=None,
    f_sin=None,
    forcing_mu: Sequence[int] = (),
    mesh_angle: Sequence[int] = (),
    forcing_angle: Sequence[int] = (),
    angle_ratio: Sequence[float] = (1.0,),
    contact_damping: bool = False,
    dof_labels: Sequence[str] | None = None,
    mesh_labels: Sequence[str] | None = None,
) -> System:
    """A :class:`System` from plain matrices, for models that are not gear trains.

    ``K`` (``(n, n)``, symmetric) becomes one spring per eigen-direction with class
    ``elastic``. Missing mesh arrays default to constant stiffness, no backlash, no
    damping and no transmission error; ``mesh_mu`` defaults to 1 per mesh. Torus
    angles (``mesh_angle``, ``forcing_angle``, ``angle_ratio``, see :class:`System`)
    default to one angle turning at ``Omega``: a periodic system.

    Example, the clearance oscillator ``x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(Omega t)``
    with unit stiffness and half clearance 1::

        system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                             f_mean=[0.1], f_cos=[[0.03]], f_sin=[[0.0]], forcing_mu=[1])
    """
    M = jnp.atleast_2d(jnp.asarray(M, dtype=float))
    n = M.shape[0]
    W = jnp.asarray(W, dtype=float).reshape(-1, n)
    m = W.shape[0]
    K = np.asarray(K, dtype=float).reshape(n, n)
    lam, vec = np.linalg.eigh(0.5 * (K + K.T))
    keep = np.abs(lam) > 0
    zeros_m = jnp.zeros(m)

    def mesh_array(x, cols=0):
        return jnp.zeros((m, cols)) if x is None else jnp.asarray(x, dtype=float).reshape(m, -1)

    L = len(forcing_mu)
    return System(
        M=M,
        C=jnp.asarray(C, dtype=float).reshape(n, n),
        spring_rows=jnp.asarray(vec[:, keep].T),
        spring_stiffness=jnp.asarray(lam[keep]),
        W=W,
        kbar=jnp.asarray(kbar, dtype=float).reshape(m),
        k_cos=mesh_array(k_cos),
        k_sin=mesh_array(k_sin) if k_sin is not None else jnp.zeros_like(mesh_array(k_cos)),
        backlash=zeros_m if backlash is None else jnp.asarray(backlash, dtype=float).reshape(m),
        damping=zeros_m if damping is None else jnp.asarray(damping, dtype=float).reshape(m),
        te_mean=zeros_m if te_mean is None else jnp.asarray(te_mean, dtype=float).reshape(m),
        te_cos=mesh_array(te_cos),
        te_sin=mesh_array(te_sin) if te_sin is not None else jnp.zeros_like(mesh_array(te_cos)),
        mesh_radius=jnp.ones(m),
        f_mean=jnp.zeros(n) if f_mean is None else jnp.asarray(f_mean, dtype=float).reshape(n),
        f_cos=jnp.zeros((n, L)) if f_cos is None else jnp.asarray(f_cos, dtype=float).reshape(n, L),
        f_sin=jnp.zeros((n, L)) if f_sin is None else jnp.asarray(f_sin, dtype=float).reshape(n, L),
        mesh_mu=tuple(int(v) for v in (mesh_mu if mesh_mu is not None else [1] * m)),
        forcing_mu=tuple(int(v) for v in forcing_mu),
        spring_class=("elastic",) * int(keep.sum()),
        contact_damping=contact_damping,
        dof_labels=tuple(dof_labels) if dof_labels is not None else tuple(
            f"x{i + 1}" for i in range(n)),
        dof_group=("",) * n,
        dof_kind=("other",) * n,
        mesh_labels=tuple(mesh_labels) if mesh_labels is not None else tuple(
            f"mesh{j + 1}" for j in range(m)),
        mesh_group=("",) * m,
        mesh_side=("",) * m,
        mesh_planet=(0,) * m,
        mesh_angle=tuple(int(g) for g in mesh_angle),
        forcing_angle=tuple(int(g) for g in forcing_angle),
        angle_ratio=tuple(float(r) for r in angle_ratio),
    )
