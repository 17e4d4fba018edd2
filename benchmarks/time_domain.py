"""Paper first gear: diffrax time integration vs a SciPy ``solve_ivp`` loop vs harmonic balance.

The bundled Al-shyyab et al. (2009) train, gear "first", at ``N`` stage-1 mesh
frequencies from 2 to 15 kHz (default 20), without backlash (``linear``) and with
the example's 0.05 mm half backlash. At every point all three methods solve the same
orbit:

- harmonic balance: ``K`` from the sweep's harmonics rule (64 / 48 / 32 harmonics over
  the band: three compiled shapes), one batched Newton solve per ``K`` from the
  linear guess (the backlash homotopy for a point that fails), then the mesh
  responses; Floquet stability is not part of the timing;
- diffrax: :func:`gearjax.simulate_points` (Dopri8, ``rtol = atol = 1e-8`` on the
  scaled state), vmapped over all points in one call (``batch_size=None``), and the
  same with ``batch_size=1`` (``lax.map``, one point at a time);
- SciPy: a Python loop over the points, ``solve_ivp`` (LSODA with the analytic
  Jacobian; on one period at 4 kHz it took 1.9 s against 2.7 s for DOP853 and 8.9 s
  for Radau) in the same scaled variables and with the same tolerances, one base
  period at a time, with the same steady-state test (mesh deflections and rates after
  one period within ``periodic_tol = 1e-6``, at most 100 periods) and the same 512
  samples of the last period.

Both integrations start from the harmonic-balance state at ``t = 0``, so all three
land on the same branch where it is stable. The RMS agreement is the largest
``|RMS_a - RMS_b|`` over points and meshes, relative to the largest RMS of the mesh's
stage at that point (as ``gearjax verify``), over the points where both converged.

Run times are medians of ``--repeats`` calls (default 1 for the integrations, at least
3 for the harmonic balance). Compile time: for diffrax the ahead-of-time
``lower().compile()`` of the call (which fills the jit cache, so no warm-up run is
needed); for the harmonic balance (several jitted functions) the first call minus
the median. SciPy needs none.

    python benchmarks/time_domain.py [--quick] [--points 20] [--repeats 1]
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import scipy.integrate
import xarray as xr

import gearjax as gj

SETTINGS = gj.TimeDomain()


def timed(fn, repeats: int):
    """``(result, compile_s, run_s)``: the first call warms up, then the median of repeats."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    run = statistics.median(times) if times else first
    return out, max(first - run, 0.0), run


# ------------------------------------------------------------------ harmonic balance


@jax.jit
def _responses(problem, Xs, omegas, F_static):
    return jax.vmap(gj.mesh_responses, in_axes=(None, 0, 0, None))(problem, Xs, omegas, F_static)


def harmonic_balance(case, f_hz, repeats):
    omegas = case.omega(f_hz)
    min_k = gj.excitation_floor(case.system)
    cutoff = gj.response_cutoff_hz(case.system)
    ks = np.array([gj.harmonics_rule(f / case.mu_ref, min_k, cutoff_hz=cutoff)
                   for f in f_hz])
    problems = {int(K): gj.hb_problem(case.system, gj.HarmonicBalance(n_harmonics=int(K)))
                for K in np.unique(ks)}
    F_static = jnp.asarray(case.F_static)

    def run():
        rms = np.full((len(f_hz), case.system.n_meshes), np.nan)
        x0 = np.zeros((len(f_hz), case.system.n_dof))
        v0 = np.zeros_like(x0)
        ok = np.zeros(len(f_hz), bool)
        for K, problem in problems.items():
            idx = np.flatnonzero(ks == K)
            sols = gj.solve_hb_points(problem, jnp.asarray(omegas[idx]))
            ys = [sols.y[j] for j in range(len(idx))]
            converged = np.asarray(sols.converged).copy()
            for j, i in enumerate(idx):
                if not converged[j] and case.has_backlash:
                    sol = gj.backlash_start(problem, omegas[i])
                    ys[j], converged[j] = sol.y, bool(sol.converged)
            Xs = jnp.stack(ys).reshape((-1,) + problem.shape) * problem.x_scale
            resp = _responses(problem, Xs, jnp.asarray(omegas[idx]), F_static)
            a, b = jax.vmap(gj.hb_initial_state)(Xs, jnp.asarray(omegas[idx]))
            rms[idx], x0[idx], v0[idx] = np.asarray(resp.rms_force), np.asarray(a), np.asarray(b)
            ok[idx] = converged
        return rms, ok, x0, v0

    (rms, ok, x0, v0), compile_s, run_s = timed(run, repeats)
    return {"rms": rms, "ok": ok, "x0": x0, "v0": v0, "compile_s": compile_s, "run_s": run_s,
            "note": "K " + "/".join(str(k) for k in sorted(problems, reverse=True))}


# --------------------------------------------------------------------------- diffrax


def diffrax_points(case, f_hz, x0, v0, batch_size, repeats):
    omegas = jnp.asarray(case.omega(f_hz))
    # ahead-of-time compilation fills the jit cache: a full warm-up run would double the cost
    t0 = time.perf_counter()
    gj.compile_simulate_points(case.system, omegas, x0=x0, v0=v0, settings=SETTINGS,
                               batch_size=batch_size)
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        tr = jax.block_until_ready(gj.simulate_points(case.system, omegas, x0=x0, v0=v0,
                                                      settings=SETTINGS, batch_size=batch_size))
        times.append(time.perf_counter() - t0)
    run_s = statistics.median(times)
    F = np.asarray(tr.F)
    rms = np.sqrt(np.mean((F - F.mean(-1, keepdims=True)) ** 2, axis=-1))
    periods = np.asarray(tr.periods)
    return {"rms": rms, "ok": np.asarray(tr.periodic), "compile_s": compile_s,
            "run_s": run_s, "periods": periods,
            "steps_per_period": float(np.sum(tr.stats["num_steps"]) / np.sum(periods))}


# ----------------------------------------------------------------------------- SciPy


class NumpyModel:
    """The right-hand side of :func:`gearjax.simulate` in NumPy, for SciPy.

    Built from the ``System`` fields (M, C, K, W, kbar, the truncated stiffness series
    k_cos / k_sin at h mu_m Omega, backlash, damping, f_mean) and the same state
    scaling as the diffrax integrator (:func:`gearjax.state_scales`): ``tau = Omega t``,
    ``y = x / x_scale``, ``u = dy/dtau``. It restates ``gearjax.mesh_force`` for NumPy;
    the case has no transmission error, no torque ripple and damping in and out of
    contact (checked below), which this baseline does not implement.
    """

    def __init__(self, system: gj.System, omega: float):
        s = system
        if s.te_cos.shape[-1] or s.forcing_mu or s.contact_damping:
            raise NotImplementedError("baseline without TE, ripple or contact damping")
        length, xs = (np.asarray(a) for a in gj.state_scales(s))
        self.n, self.omega, self.xs, self.length = s.n_dof, omega, xs, length
        self.rate_scale = length * max(tuple(s.mesh_mu) + (1,))
        self.M_inv = np.linalg.inv(np.asarray(s.M))
        self.C, self.K, self.W = np.asarray(s.C), np.asarray(s.K), np.asarray(s.W)
        self.kbar, self.b, self.c = (np.asarray(a) for a in (s.kbar, s.backlash, s.damping))
        self.kc, self.ks = np.asarray(s.k_cos), np.asarray(s.k_sin)
        h = np.arange(1, self.kc.shape[1] + 1)
        self.order = h[None, :] * np.asarray(s.mesh_mu, float)[:, None]
        self.f = np.asarray(s.f_mean)
        self.Av = -self.M_inv @ (self.C + self.W.T @ (self.c[:, None] * self.W))

    def forces(self, tau, x, v):
        arg = self.order[..., None] * np.atleast_1d(tau)  # (m, H, T)
        kappa = 1 + np.einsum("mh,mht->mt", self.kc, np.cos(arg)) + np.einsum(
            "mh,mht->mt", self.ks, np.sin(arg))
        p, p_dot = self.W @ x, self.W @ v
        p, p_dot = p.reshape(kappa.shape), p_dot.reshape(kappa.shape)
        b = self.b[:, None]
        F = self.kbar[:, None] * kappa * (p - np.clip(p, -b, b)) + self.c[:, None] * p_dot
        return p, kappa, F

    def rhs(self, tau, z):
        n, w, xs = self.n, self.omega, self.xs
        x, v = xs * z[:n], w * xs * z[n:]
        _, _, F = self.forces(tau, x, v)
        acc = self.M_inv @ (self.f - self.C @ v - self.K @ x - self.W.T @ F[:, 0])
        return np.concatenate([z[n:], acc / (w**2 * xs)])

    def jac(self, tau, z):
        n, w, xs = self.n, self.omega, self.xs
        x = xs * z[:n]
        p, kappa, _ = self.forces(tau, x, np.zeros_like(x))
        stiff = self.kbar * kappa[:, 0] * (np.abs(p[:, 0]) > self.b)  # dF/dp
        Ax = -self.M_inv @ (self.K + self.W.T @ (stiff[:, None] * self.W))
        J = np.zeros((2 * n, 2 * n))
        J[:n, n:] = np.eye(n)
        J[n:, :n] = Ax * xs[None, :] / (w**2 * xs[:, None])
        J[n:, n:] = self.Av * xs[None, :] / (w * xs[:, None])
        return J

    def poincare(self, z):
        n = self.n
        return np.concatenate([self.W @ (self.xs * z[:n]) / self.length,
                               self.W @ (self.xs * z[n:]) / self.rate_scale])


def scipy_point(system, omega, x0, v0, method="LSODA"):
    model = NumpyModel(system, omega)
    z = np.concatenate([x0 / model.xs, v0 / (omega * model.xs)])
    N = SETTINGS.n_samples
    taus = 2 * np.pi * np.arange(N + 1) / N  # the last sample is the period's end state
    kw = {"jac": model.jac} if method in ("LSODA", "Radau", "BDF") else {}
    steps = 0
    for k in range(1, SETTINGS.max_periods + 1):
        sol = scipy.integrate.solve_ivp(model.rhs, (0.0, 2 * np.pi), z, method=method,
                                        rtol=SETTINGS.rtol, atol=SETTINGS.atol, t_eval=taus,
                                        **kw)
        if sol.status != 0:
            return None, False, k, steps
        steps += sol.nfev
        z_new = sol.y[:, -1]
        settled = np.max(np.abs(model.poincare(z_new) - model.poincare(z))) < SETTINGS.periodic_tol
        z = z_new
        if settled:
            break
    x = model.xs[:, None] * sol.y[:model.n, :N]
    v = omega * model.xs[:, None] * sol.y[model.n:, :N]
    _, _, F = model.forces(taus[:N], x, v)
    rms = np.sqrt(np.mean((F - F.mean(-1, keepdims=True)) ** 2, axis=-1))
    return rms, bool(settled), k, steps


def scipy_points(case, f_hz, x0, v0, method="LSODA"):
    t0 = time.perf_counter()
    rms = np.full((len(f_hz), case.system.n_meshes), np.nan)
    ok = np.zeros(len(f_hz), bool)
    periods = np.zeros(len(f_hz), int)
    nfev = 0
    for i, omega in enumerate(case.omega(f_hz)):
        r, ok[i], periods[i], n = scipy_point(case.system, float(omega), x0[i], v0[i], method)
        nfev += n
        if r is not None:
            rms[i] = r
    return {"rms": rms, "ok": ok, "compile_s": 0.0, "run_s": time.perf_counter() - t0,
            "periods": periods, "nfev_per_period": nfev / max(periods.sum(), 1)}


# ------------------------------------------------------------------------------ main


def agreement(a, b, stages, f_hz):
    both = a["ok"] & b["ok"]
    if not both.any():
        return 0, float("nan"), float("nan")
    _, _, rel, _ = gj.compare_rms(_frame(a["rms"], both, stages),
                                  _frame(b["rms"], both, stages), 1.0)
    worst = np.unravel_index(np.nanargmax(rel), rel.shape)
    return int(both.sum()), float(np.nanmax(rel)), float(f_hz[worst[0]])


def _frame(rms, ok, stages):
    """The three variables of a results Dataset that :func:`gearjax.compare_rms` reads."""
    return xr.Dataset({"rms_force": (("point", "mesh"), rms), "converged": ("point", ok),
                       "stage": ("mesh", np.asarray(stages))})


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true", help="4 frequencies, for a smoke test")
    p.add_argument("--points", type=int, default=20)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--scipy-method", default="LSODA")
    a = p.parse_args()
    n = 4 if a.quick else a.points
    f_hz = np.linspace(2000.0, 15000.0, n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.load_train()
    print(f"paper first gear, {n} stage-1 mesh frequencies 2-15 kHz; integration from the "
          f"harmonic-balance state, rtol = atol = {SETTINGS.rtol:g}, periodic_tol "
          f"{SETTINGS.periodic_tol:g}; {jax.default_backend()} backend, "
          f"{jax.local_device_count()} device(s)")
    header = (f"{'case':<9} {'method':<30} {'ok':>5} {'compile s':>9} {'run s':>8} "
              f"{'s/point':>8} {'periods':>7} {'vs scipy':>8}  notes")
    print(header)
    print("-" * len(header))
    agree_rows, missed = [], []
    for linear in (True, False):
        case = gj.gear_case(train, "first", None, linear)
        label = "linear" if linear else "backlash"
        hb = harmonic_balance(case, f_hz, max(a.repeats, 3))
        x0, v0 = jnp.asarray(hb["x0"]), jnp.asarray(hb["v0"])
        vm = diffrax_points(case, f_hz, x0, v0, None, a.repeats)
        one = diffrax_points(case, f_hz, x0, v0, 1, a.repeats)
        sp = scipy_points(case, f_hz, hb["x0"], hb["v0"], a.scipy_method)
        rows = [
            ("harmonic balance (Newton)", hb, hb["note"]),
            ("diffrax Dopri8 vmapped", vm, f"{vm['steps_per_period']:.0f} steps/period"),
            ("diffrax Dopri8 batch_size=1", one, f"{one['steps_per_period']:.0f} steps/period"),
            (f"scipy solve_ivp {a.scipy_method} + jac", sp,
             f"{sp['nfev_per_period']:.0f} rhs calls/period"),
        ]
        for name, r, note in rows:
            periods = f"{np.mean(r['periods']):.1f}" if "periods" in r else "-"
            print(f"{label:<9} {name:<30} {int(r['ok'].sum()):>2}/{n:<2} {r['compile_s']:>9.2f} "
                  f"{r['run_s']:>8.2f} {r['run_s'] / n:>8.3f} {periods:>7} "
                  f"{sp['run_s'] / r['run_s']:>7.1f}x  {note}")
        for name, r, _ in rows:
            if not r["ok"].all():
                missed.append(f"{label} {name}: " + ", ".join(
                    f"{f:.0f}" for f in f_hz[~r["ok"]]) + " Hz")
        stages = list(case.system.mesh_group)
        for pair, (x, y) in {"HB vs diffrax": (hb, vm), "HB vs scipy": (hb, sp),
                             "diffrax vs scipy": (vm, sp)}.items():
            agree_rows.append((label, pair) + agreement(x, y, stages, f_hz))
    for line in missed:
        print(f"not converged: {line}")
    print()
    print(f"{'case':<9} {'pair':<18} {'points':>6} {'max rel diff':>12} {'at Hz':>9}")
    for label, pair, count, rel, at in agree_rows:
        print(f"{label:<9} {pair:<18} {count:>6} {rel:>12.2e} {at:>9.1f}")
    print("vs scipy: SciPy run time / the method's run time. The backlash rows reuse what the "
          "linear rows compiled (same shapes); their compile column is only what is new.")
    print("rel diff: |RMS_a - RMS_b| / largest RMS_a of the mesh's stage, max over points and "
          "meshes where both converged")


if __name__ == "__main__":
    main()
