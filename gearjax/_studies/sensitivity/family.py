"""Parametric maps of the sensitivity study: ``theta -> System`` and ``(problem, X, omega)
-> response``, and the parameters and responses a caller may name.

Parameters are TOML paths (:mod:`gearjax._gear.paths`): ``1.mesh_stiffness.sun``,
``2.planet_mass``, ``1.planet_angles_deg.2``, ``gears.first.input_torque``, ... A
parameter value is in the file's unit, so a derivative with respect to a path in
degrees is per degree.

A gear whose mesh frequencies fall in ``G > 1`` incommensurate groups is assembled on its
torus (model.md, "Incommensurate stages"): the family carries the gear's
:class:`~gearjax._gear.frequency_groups.TorusLayout` (``gear_case(..., torus=True).layout``),
which no continuous parameter changes (teeth are integers).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._engine import hb as _hb
from ..._engine.responses import mesh_responses, static_mesh_forces
from ..._engine.system import System
from ..._errors import bad_argument
from ..._gear.assembly import assemble
from ..._gear.frequency_groups import TorusLayout
from ..._gear.paths import Leaf, continuous_paths, leaf_selector, set_leaf
from ..._gear.train import Train

RESPONSES = {"rms": "rms_force", "max": "max_force", "dlf": "dlf"}
"""Response names (argument ``response``) and the :class:`~gearjax.MeshResponses` field of
each."""

RESPONSE_UNITS = {"rms": "N", "max": "N", "dlf": "1"}


class GearFamily(eqx.Module):
    """``theta -> System``: gear ``gear`` of ``train`` with the TOML ``paths`` set to
    ``theta`` (values in the file's units), assembled; ``backlash_scale`` multiplies
    every backlash (0: the linear system, where a backlash path has exactly no
    effect); ``layout``: ``None`` for the periodic system of the gear's common base, or
    the gear's torus layout (kept as a hashable tuple, :meth:`of` takes the
    :class:`~gearjax._gear.frequency_groups.TorusLayout`) for its torus system.

    Pure in ``theta``, so ``jit`` and ``grad`` pass through (``assemble`` is). The
    paths are static strings and the linear switch an array, so families of the same
    train, gear and paths share compiled code.
    """

    train: Train
    paths: tuple[str, ...] = eqx.field(static=True)
    gear: str = eqx.field(static=True)
    backlash_scale: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.0)
    layout: tuple | None = eqx.field(static=True, default=None)

    @classmethod
    def of(cls, train: Train, paths: Sequence[str], gear: str, linear: bool = False,
           layout: TorusLayout | None = None) -> "GearFamily":
        """The family of ``gear``; ``layout``: its torus layout (``GearCase.layout``;
        ``None``: the periodic system)."""
        frozen = None if layout is None else (tuple(layout.stage.items()), tuple(layout.ripple),
                                              tuple(layout.ratio))
        return cls(train=train, paths=tuple(paths), gear=gear,
                   backlash_scale=jnp.asarray(0.0 if linear else 1.0), layout=frozen)

    @property
    def torus_layout(self) -> TorusLayout | None:
        """The :class:`~gearjax._gear.frequency_groups.TorusLayout` (``None``: periodic)."""
        if self.layout is None:
            return None
        stage, ripple, ratio = self.layout
        return TorusLayout(stage=dict(stage), ripple=ripple, ratio=ratio)

    @property
    def leaves(self) -> tuple[Leaf, ...]:
        return tuple(leaf_selector(self.train, p, "paths") for p in self.paths)

    def train_at(self, theta: Float[Array, " p"]) -> Train:
        train = self.train
        for k, leaf in enumerate(self.leaves):
            train = set_leaf(train, leaf, theta[k])
        return train

    def theta(self) -> Float[Array, " p"]:
        """The parameter values of ``train``, shape ``(p,)``."""
        vals = []
        for leaf in self.leaves:
            v = jnp.asarray(leaf.where(self.train), dtype=float)
            vals.append(v if leaf.index is None else v[leaf.index])
        return jnp.stack(vals) if vals else jnp.zeros(0)

    def __call__(self, theta: Float[Array, " p"]) -> System:
        system = assemble(self.train_at(theta), self.gear, layout=self.torus_layout)
        return dataclasses.replace(system, backlash=system.backlash * self.backlash_scale)


class MeshResponse(eqx.Module):
    """``(problem, X, omega) -> r``: one :class:`~gearjax.MeshResponses` field of one mesh.

    ``field``: ``rms_force``, ``max_force``, ``dlf``, ... ; ``mesh``: the mesh's index.
    The static forces of ``dlf`` are recomputed from ``problem.system`` so they follow
    the parameters.
    """

    field: str = eqx.field(static=True)
    mesh: int = eqx.field(static=True)

    def __call__(self, problem: _hb.HBProblem, X: Array, omega) -> Array:
        F_static = static_mesh_forces(problem.system)
        return getattr(mesh_responses(problem, X, omega, F_static), self.field)[self.mesh]


def check_paths(train: Train, paths: Sequence[str] | None, argument: str = "paths", *,
                gear: str | None = None, linear: bool = False) -> tuple[Leaf, ...]:
    """Resolve ``paths``, each once; ``None``: :func:`~gearjax.continuous_paths` of
    ``gear`` (the paths that change that gear's system; ``linear``: no backlash).

    **Raises:** ``ArgumentError`` naming ``argument`` (the caller's name for ``paths``)
    for no path, a bad path or one given twice."""
    paths = continuous_paths(train, gear, linear=linear) if paths is None else (
        (paths,) if isinstance(paths, str) else tuple(paths))
    if not paths:
        raise bad_argument(argument, [], "at least one parameter path is required")
    leaves = tuple(leaf_selector(train, p, argument) for p in paths)
    seen: dict[str, str] = {}
    for p, leaf in zip(paths, leaves):
        if leaf.path in seen:
            same = "" if seen[leaf.path] == p else f" (as {seen[leaf.path]!r})"
            raise bad_argument(argument, p,
                               f"the parameter is given twice{same}; name each parameter once")
        seen[leaf.path] = p
    return leaves


def response_field(response: str) -> str:
    """The :class:`~gearjax.MeshResponses` field of the response name ``response``
    (:data:`RESPONSES`).

    **Raises:** ``ArgumentError`` naming ``response`` for an unknown name."""
    if response not in RESPONSES:
        raise bad_argument("response", response, f"must be one of {', '.join(RESPONSES)}")
    return RESPONSES[response]
