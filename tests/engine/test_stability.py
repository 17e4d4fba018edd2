"""Stability of periodic solutions: Floquet multipliers (Magnus exponentials), Hill's method,
rigid-mode exclusion, bifurcation kinds. References are independent: analytic eigenvalues,
scipy's solve_ivp on the variational equations, a shooting solution of the non-linear flow."""

import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, linear_sum_assignment

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._engine import floquet as _floquet
from gearjax._engine import verdict as _stability
from gearjax._studies import sweep as _sweep

K_OSC = 32  # one harmonic count for every oscillator case: one compilation each
SETTINGS = _hb.HarmonicBalance(n_harmonics=K_OSC)

_solve = jax.jit(gj.solve_hb)


def solve(problem, omega, y0=None):
    """HB solution, always with an explicit start (one compilation per system shape)."""
    y0 = _hb.linear_guess(problem, omega) if y0 is None else y0
    return _solve(problem, float(omega), y0)


stability = jax.jit(gj.stability, static_argnames="n_steps")
floquet = jax.jit(gj.floquet_multipliers, static_argnames="n_steps")
hill = jax.jit(gj.hill_multipliers)
monodromy = jax.jit(_floquet.monodromy, static_argnames="n_steps")


def oscillator(*, c=0.1, clearance=0.0, eps=0.0, mean=0.1, amp=0.03, mesh_damping=0.0,
               contact_damping=False):
    """x'' + c x' + (1 + eps cos(Omega t)) g(x) + c_m x' = mean + amp cos(Omega t)."""
    return gj.system_from_matrices(
        [[1.0]], [[c]], [[0.0]], [[1.0]], [1.0], backlash=[clearance], damping=[mesh_damping],
        k_cos=[[eps]], mesh_mu=[1], f_mean=[mean], f_cos=[[amp]], f_sin=[[0.0]],
        forcing_mu=[1], contact_damping=contact_damping)


def matched_error(a, b):
    """Largest distance between two multiplier sets after optimal pairing."""
    a, b = np.asarray(a), np.asarray(b)
    D = np.abs(a[:, None] - b[None, :])
    rows, cols = linear_sum_assignment(D)
    return float(D[rows, cols].max())


def orbit(X, omega):
    """x(t), x'(t) of a one-DOF HB solution, straight from its coefficients."""
    X = np.asarray(X)[:, 0]
    k = np.arange(1, (X.size - 1) // 2 + 1)
    x = lambda t: X[0] + X[1::2] @ np.cos(k * omega * t) + X[2::2] @ np.sin(k * omega * t)
    v = lambda t: omega * (X[2::2] * k) @ np.cos(k * omega * t) - omega * (
        X[1::2] * k) @ np.sin(k * omega * t)
    return x, v


# ------------------------------------------------------------------- linear, Mathieu


@pytest.mark.parametrize("omega", [0.7, 1.3])
def test_linear_oscillator_multipliers_are_exp_lambda_T(omega):
    """x'' + 0.1 x' + x = cos(Omega t): mu = exp(lambda T), lambda roots of s^2 + 0.1 s + 1."""
    problem = _hb.hb_problem(oscillator(mean=0.0, amp=1.0), SETTINGS)
    sol = solve(problem, omega)
    exact = np.exp(np.roots([1.0, 0.1, 1.0]) * 2 * np.pi / omega)
    st = stability(problem, sol.X, omega)
    assert matched_error(st.multipliers, exact) < 1e-12
    assert matched_error(hill(problem, sol.X, omega), exact) < 1e-12
    assert bool(st.stable) and not np.any(st.excluded)
    np.testing.assert_allclose(float(st.max_abs), np.exp(-0.05 * 2 * np.pi / omega), rtol=1e-12)


def mathieu_monodromy(eps, c, omega):
    """Independent reference: solve_ivp on the variational equations of
    x'' + c x' + (1 + eps cos(Omega t)) x = 0 over one period."""
    def rhs(t, y):
        A = np.array([[0.0, 1.0], [-(1 + eps * np.cos(omega * t)), -c]])
        return (A @ y.reshape(2, 2)).ravel()

    r = solve_ivp(rhs, (0, 2 * np.pi / omega), np.eye(2).ravel(), method="DOP853", rtol=1e-11,
                  atol=1e-13)
    return r.y[:, -1].reshape(2, 2)


@pytest.mark.parametrize("omega, unstable", [(2.0, True), (1.9, True), (2.6, False), (1.0, False)])
def test_mathieu_tongue_floquet_hill_and_solve_ivp(omega, unstable):
    """Parametric resonance of x'' + 0.05 x' + (1 + 0.4 cos(Omega t)) x = small forcing: the
    first tongue (Omega near 2, eps = 0.4 > 2c) is unstable, outside it stable."""
    eps, c = 0.4, 0.05
    problem = _hb.hb_problem(oscillator(c=c, eps=eps, mean=0.0, amp=0.01), SETTINGS)
    sol = solve(problem, omega)
    assert bool(sol.converged)
    ref = mathieu_monodromy(eps, c, omega)
    np.testing.assert_allclose(monodromy(problem, sol.X, omega), ref, atol=1e-9)
    st = stability(problem, sol.X, omega)
    assert matched_error(st.multipliers, np.linalg.eigvals(ref)) < 1e-9
    assert matched_error(hill(problem, sol.X, omega), st.multipliers) < 1e-6
    assert bool(st.stable) == (not unstable)
    assert (float(st.max_abs) > 1.0) == unstable


def test_bifurcation_kind():
    eps, c = 0.4, 0.05
    problem = _hb.hb_problem(oscillator(c=c, eps=eps, mean=0.0, amp=0.01), SETTINGS)
    points = {}
    for omega in (2.6, 2.0):
        sol = solve(problem, omega)
        points[omega] = stability(problem, sol.X, omega)
    # entering the Mathieu tongue: a real multiplier leaves through -1
    assert _stability.bifurcation_kind(points[2.6], points[2.0]) == "period_doubling"
    assert _stability.bifurcation_kind(points[2.0], points[2.6]) == "period_doubling"
    assert _stability.bifurcation_kind(points[2.6], points[2.6]) is None
    assert _stability.bifurcation_kind([0.5, 0.98], [0.5, 1.03]) == "fold"
    assert _stability.bifurcation_kind([0.3, -0.97], [0.3, -1.02]) == "period_doubling"
    pair = np.exp(1j * np.array([1.0, -1.0]))
    kind = _stability.bifurcation_kind(np.r_[0.1, 0.98 * pair], np.r_[0.1, 1.02 * pair])
    assert kind == "neimark_sacker"
    assert _stability.bifurcation_kind([0.5, 1.5], [0.4, 1.6]) is None


# ---------------------------------------------------------------- clearance oscillator


def test_clearance_oscillator_contact_branch_is_stable():
    """At Omega = 0.5 the linear solution never leaves contact: mu = exp(lambda T) exactly."""
    omega = 0.5
    problem = _hb.hb_problem(oscillator(clearance=1.0), SETTINGS)
    sol = solve(problem, omega)
    x = _aft.synthesis(sol.X, 256)[:, 0]
    assert float(x.min()) > 1.0  # always in contact
    st = stability(problem, sol.X, omega)
    exact = np.exp(np.roots([1.0, 0.1, 1.0]) * 2 * np.pi / omega)
    assert matched_error(st.multipliers, exact) < 1e-12
    assert matched_error(hill(problem, sol.X, omega), exact) < 1e-12
    assert bool(st.stable)


def impacting_solution(system, omega=0.75):
    problem = _hb.hb_problem(system, SETTINGS)
    y0 = jnp.zeros(problem.size).at[0].set(1.1 / problem.x_scale[0]).at[1].set(
        -1.0 / problem.x_scale[0])  # a large-amplitude start: the resonant, impacting branch
    sol = solve(problem, omega, y0)
    assert bool(sol.converged)
    x = _aft.synthesis(sol.X, 512)[:, 0]
    assert float(x.min()) < 0.9 < 1.1 < float(x.max())  # it separates once per period
    return problem, sol


def variational_reference(X, omega, *, c, contact_damping, clearance=1.0):
    """Monodromy of the variational equations along the HB orbit: solve_ivp between the
    instants where |x| = clearance (brentq on the Fourier series), with the textbook saltation
    matrix I + (f+ - f-) n^T / (n . f-) where the vector field jumps (contact damping)."""
    x, v = orbit(X, omega)
    T = 2 * np.pi / omega
    grid = np.linspace(0, T, 2001)
    gap = np.array([abs(x(t)) - clearance for t in grid])
    cuts = [brentq(lambda t: abs(x(t)) - clearance, grid[i], grid[i + 1], xtol=1e-15)
            for i in range(len(grid) - 1) if gap[i] * gap[i + 1] < 0]

    def field(t, state, touching):  # the non-linear vector field with a given contact state
        xx, vv = state
        g = xx - clearance * np.sign(xx) if touching else 0.0
        damping = c * vv if (touching or not contact_damping) else 0.0
        return np.array([vv, 0.1 + 0.03 * np.cos(omega * t) - g - damping])

    Y = np.eye(2)
    edges = [0.0, *cuts, T]
    for a, b in zip(edges[:-1], edges[1:]):
        touching = abs(x(0.5 * (a + b))) > clearance
        cc = c if (touching or not contact_damping) else 0.0
        A = np.array([[0.0, 1.0], [-float(touching), -cc]])
        r = solve_ivp(lambda t, y: (A @ y.reshape(2, 2)).ravel(), (a, b), Y.ravel(),
                      method="DOP853", rtol=1e-12, atol=1e-14)
        Y = r.y[:, -1].reshape(2, 2)
        if b < T:
            state = np.array([x(b), v(b)])
            f_minus, f_plus = field(b, state, touching), field(b, state, not touching)
            normal = np.array([np.sign(state[0]), 0.0])
            Y = (np.eye(2) + np.outer(f_plus - f_minus, normal) / (normal @ f_minus)) @ Y
    return Y, len(cuts)


def shooting_reference(X, omega, c=0.1):
    """Periodic orbit of the non-linear flow itself (Newton on x(T) - x(0), solve_ivp with
    events at |x| = 1) and its monodromy: independent of the HB truncation."""
    T = 2 * np.pi / omega

    def rhs(t, y, touching):
        g = y[0] - np.sign(y[0]) if touching else 0.0
        Y = y[2:].reshape(2, 2)
        A = np.array([[0.0, 1.0], [-float(touching), -c]])
        return np.r_[y[1], 0.1 + 0.03 * np.cos(omega * t) - c * y[1] - g, (A @ Y).ravel()]

    def flow(z):
        y, t = np.r_[z, np.eye(2).ravel()], 0.0
        events = [lambda t, y, s: y[0] - 1.0, lambda t, y, s: y[0] + 1.0]
        for e in events:
            e.terminal = True
        while t < T:
            touching = abs(y[0]) > 1.0
            r = solve_ivp(rhs, (t, T), y, args=(touching,), events=events, method="DOP853",
                          rtol=1e-12, atol=1e-13)
            y, t = r.y[:, -1].copy(), r.t[-1]
            if r.status == 1:  # step just across the switching surface
                y[0] = np.sign(y[0]) * (1.0 - 1e-15 if touching else 1.0 + 1e-15)
        return y[:2], y[2:].reshape(2, 2)

    x, v = orbit(X, omega)
    z = np.array([x(0.0), v(0.0)])
    for _ in range(4):
        zT, Phi = flow(z)
        z = z - np.linalg.solve(Phi - np.eye(2), zT - z)
    return flow(z)[1]


def test_clearance_oscillator_impacting_solution():
    """Omega = 0.75, impacting branch: against the variational equations along the same orbit
    (the integrator's own error, with convergence in the step count) and against the
    monodromy of the exact periodic orbit of the non-linear flow (adds the HB truncation)."""
    omega = 0.75
    problem, sol = impacting_solution(oscillator(clearance=1.0))
    ref, switches = variational_reference(sol.X, omega, c=0.1, contact_damping=False)
    assert switches == 2
    mu_ref = np.linalg.eigvals(ref)
    assert _floquet.floquet_steps(problem) == 1024
    st = stability(problem, sol.X, omega)  # 1024 steps
    coarse = floquet(problem, sol.X, omega, n_steps=256)
    # error 2.8e-6 at 256 steps, 2.7e-8 at 1024: third order (the switching steps)
    assert matched_error(st.multipliers, mu_ref) < 1e-7
    assert matched_error(st.multipliers, mu_ref) < matched_error(coarse, mu_ref) / 30
    # a sweep's steps (512 here): third order between 256 and 1024
    sweep_steps = _floquet.floquet_steps(problem, _sweep.SWEEP_FLOQUET_STEPS)
    assert sweep_steps == 512
    assert matched_error(floquet(problem, sol.X, omega, n_steps=sweep_steps), mu_ref) < 1e-6
    assert bool(st.stable) and float(st.max_abs) == pytest.approx(0.6578, abs=1e-3)
    # the true periodic orbit of the non-linear system: HB (K = 32) error included
    assert matched_error(st.multipliers, np.linalg.eigvals(shooting_reference(sol.X, omega))) < 1e-4
    # Hill with backlash: the switching instants are only resolved by the AFT time grid
    assert matched_error(hill(problem, sol.X, omega), mu_ref) < 3e-2


@pytest.mark.parametrize("side, tol", [("contact", 3e-4), ("gap", 3e-5)])
def test_contact_or_gap_shorter_than_a_step(side, tol):
    """A contact (graze) or a gap that opens and closes inside one Floquet step: the step
    ends agree on the contact state, so only the cubic interpolant's interior extremum
    reveals it. The same impacting orbit with the clearance set just inside its largest
    (contact) or smallest (gap) deflection, 80% of the way from the turning point to the
    nearer step end: against the variational equations along the orbit (errors at the
    default 1024 steps 6.0e-5 and 5.9e-6, falling to 3e-10 and 1e-11 at 8192; a step
    that misses the switches: 6.5e-2 and 1.9e-3)."""
    omega = 0.75
    problem, sol = impacting_solution(oscillator(clearance=1.0))
    x, v = orbit(sol.X, omega)
    T = 2 * np.pi / omega
    h = T / _floquet.floquet_steps(problem)
    grid = np.linspace(0.0, T, 4001)
    i = int(np.argmax([(1 if side == "contact" else -1) * x(t) for t in grid]))
    t_turn = brentq(v, grid[i - 1], grid[i + 1], xtol=1e-15)
    half = 0.8 * min(t_turn / h % 1, 1 - t_turn / h % 1) * h
    b = 0.5 * (x(t_turn - half) + x(t_turn + half))
    switches = [brentq(lambda t: x(t) - b, *span, xtol=1e-15)
                for span in ((t_turn - 2 * half, t_turn), (t_turn, t_turn + 2 * half))]
    assert np.floor(switches[0] / h) == np.floor(switches[1] / h)  # inside one step
    problem_b = _hb.hb_problem(oscillator(clearance=b), SETTINGS)
    ref, n_switches = variational_reference(sol.X, omega, c=0.1, contact_damping=False,
                                            clearance=b)
    assert n_switches == 2  # the orbit touches (or leaves) the flank only there
    assert matched_error(floquet(problem_b, sol.X, omega), np.linalg.eigvals(ref)) < tol


def test_contact_damping_is_handled_by_the_momentum_variable():
    """Damping only in contact: the force jumps at contact changes (saltation matrices in the
    reference); Floquet handles it, Hill refuses it with a clear message."""
    omega = 0.75
    problem, sol = impacting_solution(oscillator(c=0.0, clearance=1.0, mesh_damping=0.1,
                                                 contact_damping=True))
    ref, switches = variational_reference(sol.X, omega, c=0.1, contact_damping=True)
    assert switches == 2
    mu = floquet(problem, sol.X, omega)
    assert matched_error(mu, np.linalg.eigvals(ref)) < 1e-7
    with pytest.raises(ValueError, match="hill_multipliers does not support contact_damping"):
        gj.hill_multipliers(problem, sol.X, omega)


def test_vmap_over_points_matches_single_points():
    problem = _hb.hb_problem(oscillator(clearance=1.0), SETTINGS)
    omegas = jnp.array([0.4, 0.5, 0.6, 1.6])
    X = jnp.stack([solve(problem, w).X for w in omegas])
    batch = jax.jit(jax.vmap(lambda X, w: gj.stability(problem, X, w)))(X, omegas)
    assert batch.multipliers.shape == (4, 2) and batch.stable.shape == (4,)
    for i, w in enumerate(omegas):
        single = stability(problem, X[i], float(w))
        np.testing.assert_allclose(batch.multipliers[i], single.multipliers, atol=1e-13)
        assert bool(batch.stable[i]) == bool(single.stable)


# ------------------------------------------------------------------------ paper gear


def test_paper_gear_at_3khz(paper_system):
    """K = 16 at a stage-1 mesh frequency of 3 kHz: 28 multipliers, the undamped near-rigid
    pair (1e2 N m/rad housing springs) recognised and excluded, the solution stable. The
    excluded Floquet modes are the model's rigid mode (share 1 - 1e-9, every other mode
    1e-7 or less) and strain no mesh (7.5e-5, every other mode 0.4 or more)."""
    problem = _hb.hb_problem(paper_system, _hb.HarmonicBalance(n_harmonics=32))
    omega = 2 * np.pi * 3000 / 7
    sol = jax.jit(gj.solve_hb)(problem, omega)
    assert bool(sol.converged)
    st = jax.block_until_ready(stability(problem, sol.X, omega))  # compile
    times = []
    for _ in range(3):
        start = time.perf_counter()
        st = jax.block_until_ready(stability(problem, sol.X, omega))
        times.append(time.perf_counter() - start)
    print(f"\npaper stability at 3 kHz, {_floquet.floquet_steps(problem)} steps: "
          f"{1e3 * min(times):.0f} ms per point after compile")
    assert min(times) < 1.0
    mu = np.asarray(st.multipliers)
    assert mu.shape == (28,)
    excluded = np.asarray(st.excluded)
    assert excluded.sum() == 2
    pair = mu[excluded]
    assert np.allclose(np.abs(pair), 1.0, atol=1e-6) and np.isclose(pair[0], np.conj(pair[1]))
    share, strain = np.asarray(st.rigid_share), np.asarray(st.mesh_strain)
    assert np.all(share[excluded] > 1 - 1e-6) and np.all(share[~excluded] < 1e-6)
    assert np.all(strain[excluded] < 1e-4) and np.all(strain[~excluded] > 0.4)
    # the pair turns by the near-rigid frequency (41.2 Hz) per period (T = 7 / 3000 s)
    lam = scipy.linalg.eigh(np.asarray(paper_system.mean_stiffness()), np.asarray(paper_system.M),
                            eigvals_only=True)
    f_rigid = np.sqrt(lam.min()) / (2 * np.pi)
    assert abs(np.angle(pair).max() - 2 * np.pi * f_rigid * 7 / 3000) < 1e-3
    assert bool(st.stable) and float(st.max_abs) < 0.5


def test_attractor_past_the_fold_is_stable_whatever_its_rigid_pair(paper_system):
    """Past the 3.27 kHz fold (0.05 mm backlash, K = 32, 3306.43 Hz) a time integration
    from the static contact state settles on an orbit, and harmonic balance from its
    harmonics converges: an attractor. Its near-rigid pair lies 6e-7 outside the unit
    circle (a parametric coupling through its mesh strain; the same at K = 48 and 64, and
    1.5e-6, beyond the verdict's margin of 1e-6, at K = 16, a balance without the
    stiffness's upper harmonics); every other multiplier has modulus 0.12. The pair is
    the model's rigid mode (share 1 - 2e-8, the others 1.2e-5 at most), so it is excluded
    and the verdict is stable, as the integration found. (A margin on ``|mu| - 1`` for
    mesh-free modes called such an orbit unstable.)"""
    problem = _hb.hb_problem(paper_system, _hb.HarmonicBalance(n_harmonics=32))
    omega = 2 * np.pi * 3306.43 / 7
    sol = _sweep.settled_start(problem, omega)
    assert bool(sol.converged)
    st = stability(problem, sol.X, omega)
    mu, excluded = np.abs(np.asarray(st.multipliers)), np.asarray(st.excluded)
    assert excluded.sum() == 2 and np.all(mu[excluded] > 1)
    assert np.all(np.asarray(st.rigid_share)[excluded] > 1 - 1e-6)
    assert np.all(np.asarray(st.rigid_share)[~excluded] < 1e-3)
    assert bool(st.stable) and float(st.max_abs) < 0.2


def test_sweep_post_processing_in_threads_matches_stability(paper_system):
    """The sweep's responses and stability run in threads, a chunk of points per compiled
    call, with the eigenvalues from NumPy: the same verdict as :func:`gj.stability` point
    by point (with the sweep's Floquet steps), and no LAPACK call in the threaded
    programs (jaxlib 0.10's CPU LAPACK kernels can deadlock XLA's thread pool when
    several run at once)."""
    problem = _hb.hb_problem(paper_system, _hb.HarmonicBalance(n_harmonics=32))
    # 2 chunks, one padded; the linear orbits are unstable in the parametric instability
    omegas = 2 * np.pi * np.r_[np.linspace(2500.0, 4000.0, 6), np.linspace(6700, 6880, 5)] / 7
    Xs = jnp.stack([_hb.linear_guess(problem, w).reshape(problem.shape) * problem.x_scale
                    for w in omegas])
    F_static = _sweep.static_mesh_forces(paper_system)
    rows = _sweep.point_rows(problem, Xs, jnp.asarray(omegas), np.zeros(11, int), F_static)
    n_steps = _floquet.floquet_steps(problem, _sweep.SWEEP_FLOQUET_STEPS)  # half the default
    assert 2 * n_steps == _floquet.floquet_steps(problem)
    for i, w in enumerate(omegas):
        st = stability(problem, Xs[i], float(w), n_steps=n_steps)
        assert matched_error(rows["multipliers"][i], st.multipliers) < 1e-10
        assert rows["stable"][i] == bool(st.stable)
        np.testing.assert_allclose(rows["max_multiplier"][i], float(st.max_abs), rtol=1e-10)
        excluded = np.asarray(st.multipliers)[np.asarray(st.excluded)]
        assert matched_error(rows["multipliers"][i][rows["excluded"][i]], excluded) < 1e-10
    assert len(set(rows["stable"])) == 2  # both verdicts occur among these points
    basis = _stability.verdict_basis(problem)
    chunk = (problem, basis, Xs[:8], jnp.asarray(omegas[:8]), F_static)
    mu = jnp.asarray(rows["multipliers"][:8])
    V = jnp.zeros((8, 28, 28), complex)
    for program in (_sweep.batch_monodromy.lower(*chunk),
                    _sweep.batch_verdict.lower(problem, basis, mu, V)):
        assert "lapack" not in program.as_text().lower()


def test_sweep_post_processing_streamed_equals_batch(paper_system):
    """A sweep post-processes full chunks of a segment's points in a background thread as
    the continuation finds them (``_sweep.PostStream``) and the rest at the end: the
    rows equal those of the whole segment at once, bit for bit, however the points came
    in (here 3 at a time, 11 points: one chunk streamed, one padded at the end)."""
    problem = _hb.hb_problem(paper_system, _hb.HarmonicBalance(n_harmonics=32))
    omegas = 2 * np.pi * np.r_[np.linspace(2500.0, 4000.0, 6), np.linspace(6700, 6880, 5)] / 7
    ys = [_hb.linear_guess(problem, w) for w in omegas]
    pts = [{"y": np.asarray(y), "lam": float(w) / 2.0} for y, w in zip(ys, omegas)]
    F_static = _sweep.static_mesh_forces(paper_system)
    Xs = jnp.stack([y.reshape(problem.shape) * problem.x_scale for y in ys])
    batch = _sweep.point_rows(problem, Xs, jnp.asarray(omegas), np.zeros(11, int), F_static)
    post = _sweep.PostStream(F_static)
    try:
        for n in range(3, 12, 3):
            post.feed(0, problem, 2.0, pts[:n])
        assert len(post._chunks[0]) == 1  # the first 8 points, submitted while feeding
        rows = post.rows(0, problem, 2.0, pts)
    finally:
        post.close()
    np.testing.assert_array_equal(rows["omega"], batch["omega"])
    for key in ("stable", "max_multiplier", "multipliers", "excluded", "K"):
        np.testing.assert_array_equal(rows[key], batch[key], err_msg=key)
    for a, b in zip(jax.tree.leaves(rows["responses"]), jax.tree.leaves(batch["responses"])):
        np.testing.assert_array_equal(a, b)


def test_step_count_must_be_a_power_of_two():
    problem = _hb.hb_problem(oscillator(clearance=1.0), SETTINGS)
    X = jnp.zeros(problem.shape)
    with pytest.raises(ValueError, match="n_steps must be a power of two >= 2"):
        gj.floquet_multipliers(problem, X, 0.5, n_steps=1000)


@pytest.mark.parametrize("contact_damping", [False, True])
def test_magnus_exponent_blocks_equal_the_full_commutator(contact_damping):
    """The step exponent assembled from n x n blocks equals ``A0 + (A1 A0 - A0 A1) / h``
    formed with full 2n x 2n products (random blocks, n = 5, a batch of 3 steps)."""
    rng = np.random.default_rng(3)
    c, n, h, ws = 3, 5, 0.7, 2.5
    D, D1, S, S1 = (jnp.asarray(rng.standard_normal((c, n, n))) for _ in range(4))
    if not contact_damping:
        D1 = None
    zero, eye = jnp.zeros((c, n, n)), jnp.broadcast_to(h * ws * jnp.eye(n), (c, n, n))
    A0 = jnp.block([[-D, eye], [-S, zero]])
    A1 = jnp.block([[zero if D1 is None else -D1, zero], [-S1, zero]])
    expected = A0 + (A1 @ A0 - A0 @ A1) / h
    np.testing.assert_allclose(_floquet._magnus_exponent(D, D1, S, S1, h, ws), expected,
                               rtol=1e-13, atol=1e-13)


def test_expm_taylor_18_in_five_products():
    """The five-product scheme is the Taylor polynomial of degree 18 (its coefficients, by
    polynomial arithmetic, equal 1/k! to round-off), and ``_expm`` with scaling and squaring
    matches scipy's Pade ``expm`` on batches of oscillator-like matrices (a dominant
    skew part, as the step exponents) from no squaring (norm 0.5) to five (norm 30)."""
    P = np.polynomial.polynomial
    powers = (0, 1, 2, 3, 6)

    def poly(coef):
        out = np.zeros(7)
        out[list(powers[:len(coef)])] = coef
        return out

    q31 = poly(_floquet._EXPM_A)
    q61, q62, q63, q64 = (poly(c) for c in _floquet._EXPM_B)
    q91 = P.polyadd(P.polymul(q31, q64), q63)
    t18 = P.polyadd(q61, P.polymul(P.polyadd(q62, q91), q91))
    taylor = 1.0 / np.array([float(np.prod(np.arange(1, k + 1))) for k in range(19)])
    assert t18.size == 19
    np.testing.assert_allclose(t18, taylor, rtol=1e-15)
    rng = np.random.default_rng(5)
    expm = jax.jit(_floquet._expm)
    for norm in (0.5, 1.13, 2.3, 4.5, 30.0):
        A = rng.standard_normal((8, 28, 28))
        A = 0.1 * A - 2 * (A - np.swapaxes(A, 1, 2))
        A *= norm / np.max(np.abs(A).sum(axis=1), axis=-1)[:, None, None]
        E = np.asarray(expm(jnp.asarray(A)))
        for a, e in zip(A, E):
            ref = scipy.linalg.expm(a)
            assert np.abs(e - ref).sum(axis=0).max() < 2e-14 * np.abs(ref).sum(axis=0).max()


def test_floquet_orbit_deflections_are_the_harmonic_balance_samples_with_a_mean_te():
    """The monodromy integrates along the orbit's mesh deflections ``w . x - e``: with a
    mean transmission error (``te_mean``) beside its harmonics they equal, sample for
    sample, those the harmonic balance's AFT uses, and so does the end point."""
    system = gj.system_from_matrices(
        [[1.0, 0.0], [0.0, 2.0]], [[0.05, 0.0], [0.0, 0.05]], [[2.0, -1.0], [-1.0, 2.0]],
        [[1.0, -1.0], [0.5, 1.0]], [1.0, 2.0], k_cos=[[0.2], [0.1]], mesh_mu=[1, 2],
        te_mean=[0.3, -0.2], te_cos=[[0.05], [0.02]], te_sin=[[0.01], [0.0]])
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=6))
    X = jnp.asarray(np.random.default_rng(0).normal(size=(13, 2)))
    omega = jnp.asarray(1.3)
    P = X @ system.W.T
    orbit = _floquet._Orbit(P=P, w0=omega, omega=omega, problem=problem)
    p, dp, _ = _hb.mesh_samples(problem, P, omega)
    on_grid = orbit.on_grid(problem.basis.n_samples)
    np.testing.assert_allclose(on_grid[0], p.T, rtol=0, atol=1e-13)
    np.testing.assert_allclose(on_grid[1], dp.T, rtol=0, atol=1e-13)
    np.testing.assert_allclose(orbit.deflection(0.0)[0], p[:, 0], rtol=0, atol=1e-13)
