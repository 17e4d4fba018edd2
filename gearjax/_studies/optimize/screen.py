"""The linear screen: the first-order proxy and the linear, time-varying harmonic balance
over the design vector of every varied path, and the frequency grids they are solved on.

The modes do not depend on the phasing, so every linear peak of every phasing sits where
an excitation order meets a natural frequency (:func:`resonance_frequencies`), and a
design's proxy puts its resonances where the harmonic balance finds them: each design is
solved at a shared geometric grid plus its own highest proxy peaks (:meth:`Screen.grids`).
"""

from __future__ import annotations

from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ..._engine import hb as _hb
from ..._engine.modal import modes
from ..._engine.results import RESULTS
from ..._gear.train import Train
from ..design import batched_rms
from ..sensitivity import GearFamily
from .proxy import batched_first_order_rms, first_order


class Screen:
    """The models over the design vector of the varied ``paths`` of ``gear``.

    **Arguments:** ``f_proxy`` ``(Fp,)`` (Hz): the proxy's fine grid; ``f_shared`` (Hz):
    the geometric part of every design's linear grid; ``n_peaks``: how many of a design's
    proxy peaks are added to it; ``to_omega(f_hz)``: reference-stage mesh frequency (Hz)
    to base frequency (rad/s); ``hb_settings``: the linear harmonic balance
    (:class:`~gearjax.HarmonicBalance`); ``devices``: shard the designs across these
    (:mod:`gearjax._studies.design`); ``batch``: designs per call of :meth:`rms`;
    ``layout``: the gear's torus layout (``GearCase.layout``; ``None``: its periodic
    system), and ``hb_settings`` then holds orders per torus angle.
    """

    def __init__(self, train: Train, gear: str, paths, f_proxy, f_shared, n_peaks: int,
                 to_omega: Callable, hb_settings: _hb.HarmonicBalance, devices, batch: int,
                 layout=None):
        self.family = GearFamily.of(train, paths, gear, linear=True, layout=layout)
        self.fo = first_order(self.family(self.family.theta()), to_omega(f_proxy))
        self.f_proxy = np.asarray(f_proxy)
        self.f_shared = np.asarray(f_shared)
        self.n_peaks = n_peaks
        self.to_omega = to_omega
        self.hb_settings = hb_settings
        self.devices = devices
        self.batch = batch

    def proxy(self, thetas) -> np.ndarray:
        """``(B, F_proxy, m)`` first-order RMS (N) of the design vectors ``thetas``
        ``(B, p)``."""
        return np.asarray(batched_first_order_rms(self.fo, self.family,
                                                  jnp.asarray(thetas, dtype=float)))

    def grids(self, thetas, n_peaks: int | None = None) -> np.ndarray:
        """``(B, F)`` Hz: the shared points and each design's ``n_peaks`` highest proxy
        peaks (local maxima over frequency of the largest mesh RMS), sorted."""
        n = self.n_peaks if n_peaks is None else n_peaks
        per_f = np.max(self.proxy(thetas), axis=-1)  # (B, Fp)
        out = []
        for row in per_f:
            out.append(np.sort(np.concatenate([self.f_shared,
                                               self.f_proxy[peak_indices(row, n)]])))
        return np.asarray(out).reshape(len(per_f), -1)

    def rms(self, thetas, freqs_hz, batch: int | None = None) -> np.ndarray:
        """``(B, F, m)`` RMS (N; NaN where a point failed) at ``freqs_hz`` ``(B, F)``, in
        batches of ``batch`` (default ``self.batch``; padded) so calls share one shape."""
        thetas = np.asarray(thetas, dtype=float)
        om = self.to_omega(np.asarray(freqs_hz, dtype=float))
        size = batch or self.batch
        out = []
        for start in range(0, len(thetas), size):
            part, w = thetas[start:start + size], om[start:start + size]
            n = len(part)
            if n < size:
                part = np.concatenate([part, np.repeat(part[-1:], size - n, axis=0)])
                w = np.concatenate([w, np.repeat(w[-1:], size - n, axis=0)])
            rms, code = batched_rms(self.family, part, w, self.hb_settings, solver="linear",
                                    devices=self.devices)
            ok = np.asarray(code == RESULTS.successful)[:n]
            out.append(np.where(ok[..., None], np.asarray(rms)[:n], np.nan))
        return np.concatenate(out)


def peak_indices(values, n: int) -> np.ndarray:
    """Indices of the ``n`` largest local maxima of ``values`` (1-D; the ends count),
    topped up with the next largest values when there are fewer maxima."""
    v = np.asarray(values, dtype=float)
    left = np.concatenate([[-np.inf], v[:-1]])
    right = np.concatenate([v[1:], [-np.inf]])
    maxima = np.flatnonzero((v >= left) & (v >= right))
    order = list(maxima[np.argsort(-v[maxima], kind="stable")][:n])
    if len(order) < n:
        rest = [i for i in np.argsort(-v, kind="stable") if i not in set(order)]
        order += rest[:n - len(order)]
    return np.asarray(order[:n], dtype=int)


def resonance_frequencies(system, orders, mu_ref: int, lo: float, hi: float) -> np.ndarray:
    """Reference-stage mesh frequencies (Hz) in ``[lo, hi]`` where an excitation of base
    order ``o`` meets an elastic natural frequency ``f_k`` of the mean-stiffness model,
    ``mu_ref f_k / o``: where every linear peak of every phasing sits (the phasing
    changes how hard a mode is driven, not where), sorted. On a torus ``orders`` are the
    tones' frequencies over Omega (:attr:`.proxy.FirstOrder.tone_rates`, floats)."""
    hz = np.asarray([m.hz for m in modes(system).modes if m.cls == "elastic"], dtype=float)
    f = np.asarray([mu_ref * fk / o for fk in np.unique(np.round(hz, 6)) for o in orders
                    if o > 0], dtype=float)
    return np.unique(np.round(f[(f >= lo) & (f <= hi)], 6))
