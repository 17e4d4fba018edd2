"""What every segment of a sweep shares: the system, its harmonic-balance settings and
the frequency scale of the continuation parameter."""

from __future__ import annotations

import dataclasses
import math
import threading

import jax.numpy as jnp
import numpy as np

from ..._engine import hb as _hb
from .. import harmonics as _harmonics


@dataclasses.dataclass(frozen=True)
class Context:
    """The ``system`` and harmonic-balance settings (``eta``, ``smoothing``), the band
    ``from_hz`` -> ``to_hz`` (reference-stage mesh Hz) and the reference stage's
    ``mu_ref``, the caps (``max_step_hz``, ``max_points``, ``max_detour``), and the
    ``runaway`` deflection limits ``(m,)`` (m); one harmonic-balance problem per K,
    built once."""

    system: object
    eta: int
    smoothing: float
    from_hz: float
    to_hz: float
    mu_ref: float
    max_step_hz: float | None
    max_points: int
    max_detour: int
    runaway: np.ndarray
    problems: dict = dataclasses.field(default_factory=dict, compare=False, repr=False)
    lock: threading.Lock = dataclasses.field(default_factory=threading.Lock, compare=False,
                                             repr=False)

    def problem(self, K: int, backlash: bool = True) -> _hb.HBProblem:
        """The harmonic-balance problem with ``K`` harmonics (orders per angle on a
        torus; the same object for every segment of that K, in any thread); of the
        system without its backlash where ``backlash`` is false."""
        K = _harmonics.as_orders(K)
        key = K if backlash else (K, "no backlash")
        with self.lock:  # built once though threads ask at once
            if key not in self.problems:
                system = self.system if backlash else dataclasses.replace(
                    self.system, backlash=jnp.zeros_like(self.system.backlash))
                self.problems[key] = _hb.hb_problem(system, _harmonics.settings_for(
                    system, K, eta=self.eta, smoothing=self.smoothing))
            return self.problems[key]

    def omega(self, f_hz: float) -> float:
        """Base frequency (rad/s) at reference-stage mesh frequency ``f_hz``."""
        return 2 * math.pi * f_hz / self.mu_ref

    @property
    def omega_ref(self) -> float:
        """The continuation parameter's reference (rad/s): ``lambda = Omega / omega_ref``,
        1 at the start of the band."""
        return self.omega(self.from_hz)

    def lam(self, f_hz: float) -> float:
        """The continuation parameter ``lambda`` at ``f_hz`` (Hz)."""
        return self.omega(f_hz) / self.omega_ref
