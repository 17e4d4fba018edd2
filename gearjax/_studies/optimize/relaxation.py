"""The continuous relaxation of the phasing problem, for comparison with the discrete
optimum.

Planet angles are continuous, kept apart through a softmax of the gaps (:class:`_Relaxed`),
phases continuous; the assembly rule is dropped, so the result cannot be built. The
smooth peak (log-sum-exp) of the linear model is minimised by L-BFGS with ``jax.grad``
from the discrete optimum, at the resonance frequencies and the optimum's screen grid.
The objective oscillates in the angles (a planet moved by ``360 / Z_s`` deg brings its
phases back), so this is a local optimum next to the discrete one.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._gear.train import Train
from ..._gear.validate import assembly_slots, min_planet_gap_deg
from ..design import batched_rms
from .screen import Screen
from .settings import OptimizeSettings
from .variables import theta_of, train_at


class _Relaxed(eqx.Module):
    """``z -> theta``: unconstrained variables to the design vector of the relaxation.

    Per stage with a free planet set, ``N`` logits ``u``: gaps ``g = g_min + (360 - N
    g_min) softmax(u)`` (deg), so no two neighbours come closer than ``g_min``; angles
    ``cumsum(g)[:-1]`` from planet 1 at 0. Phases pass through (deg).
    """

    layout: tuple = eqx.field(static=True)  # per stage: (n_planets or 0, n_phases)
    g_min: tuple = eqx.field(static=True)

    def __call__(self, z):
        out, k = [], 0
        for (N, n_phase), gmin in zip(self.layout, self.g_min):
            if N:
                u = z[k:k + N]
                k += N
                gaps = gmin + (360.0 - N * gmin) * jax.nn.softmax(u)
                out.append(jnp.cumsum(gaps)[:-1])
            if n_phase:
                out.append(z[k:k + n_phase])
                k += n_phase
        return jnp.concatenate(out)

    def start(self, theta) -> np.ndarray:
        """``z`` for a design vector ``theta`` (gaps above ``g_min`` kept; at ``g_min``,
        nudged inside by 1e-6 of the free span)."""
        theta = np.asarray(theta, dtype=float)
        out, k = [], 0
        for (N, n_phase), gmin in zip(self.layout, self.g_min):
            if N:
                angles = np.concatenate([[0.0], theta[k:k + N - 1], [360.0]])
                k += N - 1
                free = np.maximum(np.diff(angles) - gmin, 1e-6 * (360.0 - N * gmin))
                out.append(np.log(free / free.sum()))
            if n_phase:
                out.append(theta[k:k + n_phase])
                k += n_phase
        return np.concatenate(out)


@dataclasses.dataclass(frozen=True)
class Relaxation:
    """The continuous relaxation: ``values`` (path -> value, deg); ``start_peak`` (N, the
    optimum's on the relaxation's grid), ``linear_peak`` and ``linear_rms`` ``(F, m)``
    (N, on the result's common grid), ``smooth_start``, ``smooth_end`` (the smooth peak
    it minimised), ``iterations``, ``message`` (L-BFGS; where the peak on its grid did
    not fall, the start is kept and the message says so); ``assembly_violations``:
    planets off an assembly slot (it is not assemblable); ``max_slot_offset``: the
    largest distance of a planet from its nearest slot (slots, at most 0.5)."""

    values: dict
    start_peak: float
    linear_peak: float
    smooth_start: float
    smooth_end: float
    iterations: int
    message: str
    assembly_violations: int
    max_slot_offset: float
    linear_rms: np.ndarray | None


def _wrap_deg(x) -> float:
    """``x`` (deg) in ``[0, 360)``, with values a rounding error below 360 as 0."""
    v = float(x) % 360.0
    return 0.0 if v > 360.0 - 1e-9 else v


def relax(train: Train, variables, paths, screen: Screen, freqs_hz,
          settings: OptimizeSettings) -> tuple[Relaxation, np.ndarray]:
    """Minimise the smooth peak of the linear model at ``freqs_hz`` (Hz) over continuous
    planet angles (gaps kept above the overlap limit) and phases, from ``train``'s values
    of ``paths`` (the design vector of ``variables``), by L-BFGS with gradients from
    ``jax.grad`` (module docstring); ``settings.relax_iterations`` iterations at most, the
    smooth peak's temperature ``settings.temperature`` (relative).

    **Returns:** ``(Relaxation, design vector (p,))``; the relaxation's ``linear_peak``
    is at ``freqs_hz`` and its ``linear_rms`` ``None`` until the caller re-evaluates
    it on its own grid.
    """
    layout, gmin = [], []
    for v in variables:
        st = train.stage(v.stage)
        N = st.n_planets if v.planets else 0
        layout.append((N, int(v.sun_ring) + int(v.stage_phase)))
        gmin.append(min_planet_gap_deg(st) * (1 + 1e-9) if N else 0.0)
    mapping = _Relaxed(layout=tuple(layout), g_min=tuple(gmin))
    theta0 = theta_of(train, paths)
    z0 = mapping.start(theta0)
    family, hb_settings = screen.family, screen.hb_settings
    omegas = jnp.asarray(screen.to_omega(np.asarray(freqs_hz, dtype=float)))

    def rms_of(z):
        return batched_rms(family, mapping(z)[None], omegas, hb_settings, solver="linear")[0]

    hard = jax.jit(lambda z: jnp.max(rms_of(z)))
    peak0 = float(hard(jnp.asarray(z0)))
    tau = settings.temperature * peak0
    smooth = lambda z: tau * jax.scipy.special.logsumexp(rms_of(z) / tau)
    value_and_grad = jax.jit(jax.value_and_grad(smooth))

    def fun(z):
        val, grad = value_and_grad(jnp.asarray(z))
        return float(val), np.asarray(grad, dtype=float)

    s0 = fun(z0)[0]
    import scipy.optimize  # on first use: its import costs every gearjax start
    res = scipy.optimize.minimize(fun, z0, jac=True, method="L-BFGS-B",
                                  options={"maxiter": settings.relax_iterations})
    message = str(res.message)
    z = res.x
    if not (res.fun <= s0 and float(hard(jnp.asarray(z))) <= peak0):
        z, message = z0, f"no descent of the peak, start kept ({message})"
    theta = np.asarray(mapping(jnp.asarray(z)))
    values = {p: _wrap_deg(x) for p, x in zip(paths, theta)}
    relaxed = train_at(train, paths, [values[p] for p in paths])
    off, worst = 0, 0.0
    for v in variables:
        if v.planets:
            a = np.asarray(relaxed.stage(v.stage).planet_angles_deg, float)
            q = assembly_slots(relaxed.stage(v.stage)) * a / 360.0
            off += int(np.sum(np.abs(q - np.round(q)) > 1e-6))
            worst = max(worst, float(np.max(np.abs(q - np.round(q)))))
    return Relaxation(values=values, start_peak=peak0, linear_peak=float(hard(jnp.asarray(z))),
                      smooth_start=float(s0), smooth_end=float(min(res.fun, s0)),
                      iterations=int(res.nit), message=message,
                      assembly_violations=off, max_slot_offset=worst, linear_rms=None), theta
