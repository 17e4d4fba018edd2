"""Branch switching at a period doubling.

The parametrically excited clearance oscillator ``x'' + 0.05 x' + (1 + 0.4 cos(w t))
g(x) = 0.1`` (gap 1, so ``x = 1 + u`` in contact): its period-one orbit stays in contact,
where it obeys the damped Mathieu equation ``u'' + 0.05 u' + (1 + 0.4 cos(w t)) u =
0.1``, whose principal parametric resonance loses stability through a Floquet
multiplier -1 at w near 1.80 and 2.19 rad/s. Between them a time integration settles to
a period-two orbit whose teeth separate. The sweep over 1.9-2.3 rad/s walks the
period-one branch through the upper doubling and must start there the period-two branch
(``eta`` 2) and trace it down the band. References: the doubling frequency of the
Mathieu equation from SciPy's integration of its monodromy (where the in-contact
period-two branch leaves the period-one orbit, vertically: in contact the equation is
linear), and ``gj.simulate`` (diffrax), which settles to period two.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
import scipy.optimize

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._engine.newton import newton_jit
from gearjax._engine.responses import static_mesh_forces
from gearjax._studies.harmonics import settings_for
from gearjax._studies.sweep import api as _api
from gearjax._studies.sweep import completion as _completion
from gearjax._studies.sweep import doubling as _doubling
from gearjax._studies.sweep import summary as _summary
from gearjax._studies.sweep import walk as _walk
from gearjax._studies.sweep.context import Context
from gearjax._studies.sweep.dataset import point_data
from gearjax._studies.sweep.post import PostStream, bifurcations
from gearjax._studies.sweep.record import SweepLog

K = 8
C, EPS, F = 0.05, 0.4, 0.1
W = 2.0  # rad/s, between the two doublings


def oscillator():
    return gj.system_from_matrices([[1.0]], [[C]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                                   k_cos=[[EPS]], mesh_mu=[1], f_mean=[F])


def hz(omega):
    return omega / (2 * math.pi)  # mu_ref = 1: the "mesh frequency" is the base one


def system_sweep(from_w, to_w, log=None):
    """The sweep's walk and completion on the oscillator, as test_completion runs them."""
    system = oscillator()
    F_static = static_mesh_forces(system)
    runaway = _walk.RUNAWAY * (np.abs(np.asarray(F_static)) / np.asarray(system.kbar)
                               + np.asarray(system.backlash))
    ctx = Context(system=system, eta=1, smoothing=0.0, from_hz=hz(from_w), to_hz=hz(to_w),
                  mu_ref=1.0, max_step_hz=hz(0.02), max_points=3000, max_detour=150,
                  runaway=runaway)
    walk = _walk.Walk(segments=[(hz(from_w), hz(to_w), K)])
    log = SweepLog([]) if log is None else log
    post = PostStream(F_static)
    pieces, records = _api._run_walk(ctx, walk, log, post, linear=False, points=2,
                                     progress=None, F_static=F_static, complete=True)
    data = point_data(walk, log, post, ctx, F_static, linear=False, pieces=pieces)
    data["records"] = records
    data["bifurcations"] = bifurcations(hz(data["omega"]), data["stable"], data["multipliers"],
                                        data["excluded"], data["branch"])
    return data


def mathieu_monodromy(w):
    """Monodromy matrix of ``u'' + C u' + (1 + EPS cos(w t)) u = 0`` over ``2 pi / w``
    (SciPy), on the state ``(u, u')``: the oscillator's linearisation in contact."""
    def rhs(t, z):
        u, v, a, b = z
        k = 1 + EPS * np.cos(w * t)
        return [v, -C * v - k * u, b, -C * b - k * a]

    return scipy.integrate.solve_ivp(rhs, (0, 2 * np.pi / w), [1, 0, 0, 1], rtol=1e-12,
                                     atol=1e-12).y[:, -1].reshape(2, 2).T


def mathieu_doublings():
    """Where a multiplier of the Mathieu equation is -1: trace + 1 + det = 0 (2 x 2)."""
    def crossing(w):
        P = mathieu_monodromy(w)
        return np.trace(P) + 1 + np.linalg.det(P)

    return [scipy.optimize.brentq(crossing, a, b, xtol=1e-12) for a, b in ((1.7, 1.9), (2.1, 2.3))]


@pytest.fixture(scope="module")
def swept():
    return system_sweep(1.9, 2.3)


@pytest.fixture(scope="module")
def settled():
    """The orbit a time integration from the static contact state settles to at W."""
    settings = gj.TimeDomain(max_periods=400, n_samples=128, sample_periods=2,
                             max_subharmonic=4)
    return gj.simulate(oscillator(), W, settings=settings)


@pytest.mark.slow
def test_the_period_two_branch_is_traced_from_the_doubling(swept):
    upper = mathieu_doublings()[1]
    pd = [b for b in swept["bifurcations"] if b["kind"] == "period_doubling"]
    assert len(pd) == 1 and abs(2 * np.pi * pd[0]["mesh_frequency_hz"] - upper) < 0.02
    (rec,) = [r for r in swept["records"] if r["found"] == "period doubling"]
    assert rec["eta"] == 2 and rec["from_branch"] == 0
    # the same midpoint, rounded in two orders
    assert rec["doublings_hz"] == [pytest.approx(pd[0]["mesh_frequency_hz"], rel=1e-12)]
    mine = swept["branch"] == rec["branch"]
    assert np.all(swept["eta"][mine] == 2) and np.all(swept["eta"][~mine] == 1)
    # the period-one branch goes on through the doubling, unstable below it
    one = swept["branch"] == 0
    w1 = swept["omega"][one]
    assert w1.min() <= 1.9 + 1e-9 and w1.max() >= 2.3 - 1e-9
    assert np.all(swept["stable"][one][w1 < upper - 0.01] == 0)
    assert np.all(swept["stable"][one][w1 > upper + 0.01] == 1)
    # the doubled branch starts on the doubling: its in-contact stretch at the Mathieu
    # doubling, where its odd harmonics (the period-two part) vanish
    w2 = swept["omega"][mine]
    odd = np.array([np.linalg.norm(_doubling.odd_part(X.reshape(-1), 2 * K, 1))
                    for X in np.asarray(swept["X"], dtype=object)[mine]])
    at = np.abs(w2 - upper) < 1e-6 * upper
    assert at.sum() >= 3 and odd[at].min() < 1e-2 * odd.max()
    assert rec["stops"][0] == "period one" or rec["stops"][1] == "period one"
    # and down the band, away from it
    assert w2.min() <= 1.9 + 1e-9


@pytest.mark.slow
def test_the_period_two_branch_is_the_orbit_a_time_integration_settles_to(swept, settled):
    assert bool(settled.integrated) and int(settled.period) == 2
    (rec,) = [r for r in swept["records"] if r["found"] == "period doubling"]
    mine = np.flatnonzero(swept["branch"] == rec["branch"])
    w = swept["omega"][mine]
    (i,) = [k for k in range(len(mine) - 1) if (w[k] - W) * (w[k + 1] - W) <= 0]
    a, b = mine[i], mine[i + 1]
    assert swept["stable"][a] == 1 and swept["stable"][b] == 1
    problem = _hb.hb_problem(oscillator(), settings_for(oscillator(), 2 * K, eta=2))
    t = (W - swept["omega"][a]) / (swept["omega"][b] - swept["omega"][a])
    chord = ((1 - t) * swept["X"][a] + t * swept["X"][b]).reshape(-1) / problem.x_scale[0]
    sol = newton_jit(problem, jnp.asarray(W), jnp.asarray(chord))
    assert bool(sol.converged)
    y = np.asarray(sol.y)
    assert np.linalg.norm(chord - y) < 1e-2 * np.linalg.norm(y)  # the branch passes there
    # both over 2T from phase 0 of the excitation, on the same 256 samples; the
    # integration may have settled on the orbit half a period later (odd harmonics
    # negated). 16 harmonics of W / 2 leave 1e-5 of the span (against 64); the margin
    # is for the integration's settling (periodic_tol 1e-6)
    x_hb = np.asarray(_aft.synthesis(sol.X, 256))[:, 0]
    x_td = np.asarray(settled.x[0])
    span = x_td.max() - x_td.min()
    assert x_td.min() < 1.0 < x_td.max()  # the teeth separate (contact at x = 1)
    assert x_hb.max() - x_hb.min() == pytest.approx(span, rel=1e-3)
    errs = [np.max(np.abs(x - x_td)) for x in (x_hb, np.roll(x_hb, 128))]
    assert min(errs) < 1e-3 * span


def test_the_critical_direction_is_the_floquet_mode_of_the_multiplier_minus_one():
    system = oscillator()
    upper = mathieu_doublings()[1]
    one = _hb.hb_problem(system, settings_for(system, K))
    two = _hb.hb_problem(system, settings_for(system, 2 * K, eta=2))
    sol = newton_jit(one, jnp.asarray(upper), _hb.linear_guess(one, upper))
    y2 = _doubling.doubled(np.asarray(sol.y), K, 1)
    phi = _doubling.critical_mode(two, y2, upper)
    assert np.all(phi[~np.repeat(_doubling.odd_rows(2 * K), 1)] == 0)
    # the mode's state at t = 0 against the eigenvector of the multiplier -1 of the
    # orbit's linearisation (in contact: the Mathieu equation, integrated by SciPy)
    P = phi.reshape(4 * K + 1, 1) * np.asarray(two.x_scale)
    k = np.arange(1, 2 * K + 1)
    state = np.array([P[1::2, 0].sum(), (upper / 2) * (k * P[2::2, 0]).sum()])
    mu, V = np.linalg.eig(mathieu_monodromy(upper))
    j = np.argmin(np.abs(mu + 1))
    assert abs(mu[j] + 1) < 1e-8
    v = np.real(V[:, j])
    assert abs(state @ v) / (np.linalg.norm(state) * np.linalg.norm(v)) > 1 - 1e-8


@pytest.mark.slow
def test_orbits_of_period_two_are_known_apart_from_period_one_and_with_their_mirror(swept):
    (rec,) = [r for r in swept["records"] if r["found"] == "period doubling"]
    system = oscillator()
    one = _hb.hb_problem(system, settings_for(system, K))
    two = _hb.hb_problem(system, settings_for(system, 2 * K, eta=2))
    mine = np.flatnonzero(swept["branch"] == rec["branch"])
    pts = [{"y": swept["X"][i].reshape(-1) / float(two.x_scale[0]),
            "lam": float(swept["omega"][i])} for i in mine]
    atlas = _completion.Atlas()
    atlas.add(_completion.Piece(key="b1+0", K=2 * K, pts=pts, branch=rec["branch"], eta=2))
    i = len(pts) // 2
    y, lam = pts[i]["y"], pts[i]["lam"]
    assert atlas.known(two, 1.0, y, lam) == rec["branch"]
    assert atlas.known(two, 1.0, _doubling.mirror(y, 2 * K, 1), lam) == rec["branch"]
    z = np.append(_doubling.mirror(y, 2 * K, 1), lam)
    assert atlas.meets(2 * K, z, 0.0, eta=2) and not atlas.meets(2 * K, z, 0.0, eta=1)
    # the period-one orbit there, on its own basis and on the doubled one: not this branch
    y1 = np.asarray(newton_jit(one, jnp.asarray(lam), _hb.linear_guess(one, lam)).y)
    assert atlas.known(one, 1.0, y1, lam) is None
    assert atlas.known(two, 1.0, _doubling.doubled(y1, K, 1), lam) is None
    # where a doubled branch came back onto the period-one orbit, the doubling is its own
    atlas.returns.append((2 * K, 2, _doubling.doubled(y1, K, 1), lam, rec["branch"]))
    assert atlas.returned(two, _doubling.doubled(y1, K, 1), lam + 1e-4, 1e-3) == rec["branch"]
    assert atlas.returned(two, _doubling.doubled(y1, K, 1), lam + 1e-2, 1e-3) is None


@pytest.mark.slow
def test_a_resumed_sweep_traces_the_same_period_two_branch(tmp_path):
    """Interrupted inside the period-two branch (a torn record after the kept ones): the
    resumed run finds the same doubling and seed again, takes the journaled points and
    continues, to the same points and the same journal."""
    path = tmp_path / "sweep.journal"
    run = {"test": "period doubling"}
    log = SweepLog.open(path, run, False)
    full = system_sweep(1.9, 2.3, log)
    data = path.read_bytes()
    lines = data.splitlines(keepends=True)
    doubled = [k for k, line in enumerate(lines) if b'"b1+' in line or b'"b1-' in line]
    keep = doubled[len(doubled) // 2]
    path.write_bytes(b"".join(lines[:keep]) + lines[keep][:20])
    resumed = system_sweep(1.9, 2.3, SweepLog.open(path, run, True))
    assert path.read_bytes() == data
    for key in ("omega", "branch", "eta", "stable", "max_multiplier"):
        np.testing.assert_array_equal(resumed[key], full[key])
    assert resumed["records"] == full["records"]


def test_the_summary_says_where_each_doubling_leads():
    import xarray as xr

    ds = xr.Dataset(attrs={"bifurcations": '[{"mesh_frequency_hz": 3.0, "kind": '
                           '"period_doubling"}, {"mesh_frequency_hz": 5.0, "kind": '
                           '"period_doubling"}, {"mesh_frequency_hz": 7.0, "kind": '
                           '"neimark_sacker"}]'})
    branches = [{"branch": 0, "found": "sweep", "eta": 1,
                 "not_doubled": [{"doubling_hz": 5.0, "why": "too large"}]},
                {"branch": 1, "found": "period doubling", "eta": 2, "doublings_hz": [3.0]}]
    a, b, c = _summary.bifurcation_notes(ds, branches)
    assert a["branch"] == 1 and "branch 1 has twice the period" in a["note"]
    assert b["branch"] is None and "not followed (too large)" in b["note"]
    assert c["kind"] == "neimark_sacker" and "quasi-periodic" in c["note"]
    lines = _summary.bifurcation_lines([c, a, dict(c, mesh_frequency_hz=6.0), b])
    assert lines[:2] == [a["note"], b["note"]] and len(lines) == 3
    assert lines[2].startswith("Neimark-Sacker near 6.0, 7.0 Hz") and "quasi" in lines[2]
