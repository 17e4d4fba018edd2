"""A completed sweep: every stable state an up or down rig finds.

The clearance oscillator ``x'' + 0.1 x' + g(x) = 0.1 + 0.03 cos(w t)`` (gap 1) has a
hysteresis band between folds near 0.6365 and 0.852 rad/s: a low contact state (linear,
exact) and a high impacting one. The walk is made to leave its branch right after the
first fold (``max_detour`` 5), as it does where a gear's branch wanders, so that it
misses one of the two stable states; the completion must find it, whichever end the
sweep starts from. References: the exact linear response and a SciPy integration.

An isola (a closed branch that no continuation from the band's ends reaches) is found
from an integration seed and traced once round (:func:`isola_oscillator`).
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine.responses import static_mesh_forces
from gearjax._studies.sweep import api as _api
from gearjax._studies.sweep import completion as _completion
from gearjax._studies.sweep import summary as _summary
from gearjax._studies.sweep import walk as _walk
from gearjax._studies.sweep.context import Context
from gearjax._studies.sweep.dataset import point_data
from gearjax._studies.sweep.post import PostStream
from gearjax._studies.sweep.record import SweepLog

from clearance_oscillator import ivp_amplitude, oscillator

K = 15
W = 0.75  # rad/s, inside the hysteresis band


def hz(omega):
    return omega / (2 * math.pi)  # mu_ref = 1: the "mesh frequency" is the base one


def system_sweep(from_w, to_w, *, complete=True, max_detour=5, system=None, seeds=0):
    """The sweep's walk and completion on the oscillator (``sweep`` takes a train; the
    same machinery on a ``System``; ``system`` another one): per point omega, stable,
    branch, amplitude."""
    system = oscillator() if system is None else system
    F_static = static_mesh_forces(system)
    runaway = _walk.RUNAWAY * (np.abs(np.asarray(F_static)) / np.asarray(system.kbar)
                               + np.asarray(system.backlash))
    ctx = Context(system=system, eta=1, smoothing=0.0, from_hz=hz(from_w), to_hz=hz(to_w),
                  mu_ref=1.0, max_step_hz=hz(0.02), max_points=3000,
                  max_detour=max_detour, runaway=runaway)
    walk = _walk.Walk(segments=[(hz(from_w), hz(to_w), K)])
    log, post = SweepLog([]), PostStream(F_static)
    pieces, records = _api._run_walk(ctx, walk, log, post, linear=False, points=2,
                                     progress=None, F_static=F_static, complete=complete,
                                     seeds=seeds)
    data = point_data(walk, log, post, ctx, F_static, linear=False, pieces=pieces)
    x = np.array([np.asarray(_aft.synthesis(jnp.asarray(X), 256))[:, 0] for X in data["X"]])
    return {"omega": data["omega"], "stable": data["stable"], "branch": data["branch"],
            "amp": (x.max(1) - x.min(1)) / 2, "records": records, "walk": walk,
            "X": data["X"]}


def stable_amplitudes_at(s, w):
    """Amplitudes where a stretch of stable points of one branch crosses ``w``."""
    out = []
    om, st, br, amp = s["omega"], s["stable"] == 1, s["branch"], s["amp"]
    for i in range(len(om) - 1):
        if br[i] == br[i + 1] and st[i] and st[i + 1] and (om[i] - w) * (om[i + 1] - w) <= 0:
            t = 0.0 if om[i + 1] == om[i] else (w - om[i]) / (om[i + 1] - om[i])
            out.append(amp[i] + t * (amp[i + 1] - amp[i]))
    return sorted(out)


@pytest.fixture(scope="module")
def references():
    low = abs(0.03 / (1 - W**2 + 0.1j * W))  # in contact: linear
    high = ivp_amplitude(W, [1.9, 0.0])      # a large start: the impacting state
    assert high > 3 * low
    return low, high


@pytest.mark.parametrize("from_w, to_w", [(0.5, 1.2), (1.2, 0.5)], ids=["up", "down"])
def test_both_stable_states_of_the_hysteresis_band_from_one_sweep(from_w, to_w, references):
    bare = system_sweep(from_w, to_w, complete=False)
    assert bare["walk"].restarts  # the walk left its branch: one state is missing
    assert len(stable_amplitudes_at(bare, W)) == 1
    s = system_sweep(from_w, to_w)
    amps = stable_amplitudes_at(s, W)
    low, high = references
    assert len(amps) == 2
    assert amps[0] == pytest.approx(low, rel=5e-3)
    assert amps[1] == pytest.approx(high, rel=5e-3)
    found = [r["found"] for r in s["records"]]
    assert found[:2] == ["sweep", "restart"] and "back from restart" in found
    # no orbit twice: the branches' crossings of W are distinct states
    om, br, amp = s["omega"], s["branch"], s["amp"]
    at = sorted(amp[i] + (W - om[i]) / (om[i + 1] - om[i]) * (amp[i + 1] - amp[i])
                for i in range(len(om) - 1)
                if br[i] == br[i + 1] and (om[i] - W) * (om[i + 1] - W) < 0)
    assert np.all(np.diff(at) > 1e-2 * at[-1])


def test_coexisting_jumps_list_where_a_stable_state_ends():
    import xarray as xr

    f = [1, 2, 3, 4, 5, 3, 4, 5, 6]
    stable = [1, 1, 1, 1, 1, 1, 1, 1, 1]
    branch = [0, 0, 0, 0, 0, 1, 1, 1, 1]
    ds = xr.Dataset({"mesh_frequency_hz": ("point", f), "stable": ("point", stable),
                     "branch": ("point", branch)})
    (band,) = _summary.coexisting_jumps(ds)
    assert (band["from_hz"], band["to_hz"], band["states"]) == (3.0, 5.0, 2)
    assert band["jump_up_hz"] == [5.0] and band["jump_down_hz"] == [3.0]


def test_atlas_knows_a_traced_orbit_and_not_another():
    from gearjax._engine import hb as _hb
    from gearjax._engine.newton import solve_hb

    problem = _hb.hb_problem(oscillator(), _hb.HarmonicBalance(n_harmonics=K))
    lams = np.linspace(0.5, 0.6, 6)
    pts = [{"y": np.asarray(solve_hb(problem, w).y), "lam": float(w)} for w in lams]
    atlas = _completion.Atlas()
    atlas.add(_completion.Piece(key=0, K=K, pts=pts, branch=3))
    y = np.asarray(solve_hb(problem, 0.55).y)
    assert atlas.known(problem, 1.0, y, 0.55) == 3
    assert atlas.known(problem, 1.0, 1.5 * y, 0.55) is None


# The isola: x'' + 0.1 x' + g(x - e(t)) = 0.1 + f(t), the transmission error e = 0.07
# cos(w t) and the force f = -0.073 cos(w t) - 0.014 sin(w t) a second forcing term that
# nearly cancels it while the teeth touch: the response in contact (the only branch from
# either end of the band) stays small, at most 0.14 near w = 1, and never separates, but
# an impacting orbit, fed by f while the teeth are apart, lives on a closed branch
# between folds near 0.37 and 0.94 rad/s, stable along its upper half. A fine sweep (the
# walk, the jumps) never leaves the contact branch; an integration sweep down in steps
# of 0.1 rad/s (11 seeds over 0.3-1.3) steps from the peak at 1.0 to 0.9 and settles on
# the isola (as a SciPy integration of this equation does, found while building it).
ISOLA_BAND = (0.3, 1.3)
ISOLA_SEEDS = 11
W_I = 0.7  # rad/s, on the isola


def isola_oscillator():
    return gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                                   te_cos=[[0.07]], te_sin=[[0.0]], f_mean=[0.1],
                                   f_cos=[[-0.073]], f_sin=[[-0.014]], forcing_mu=[1])


def isola_ivp(omega, z0, periods):
    """SciPy integration of the isola oscillator: the state after ``periods`` and the
    amplitude over the last period."""
    def rhs(t, z):
        x, v = z
        c, s = math.cos(omega * t), math.sin(omega * t)
        p = x - 0.07 * c
        return [v, 0.1 - 0.073 * c - 0.014 * s - 0.1 * v - (p - min(max(p, -1.0), 1.0))]

    P = 2 * np.pi / omega
    sol = scipy.integrate.solve_ivp(rhs, (0, periods * P), z0, method="DOP853", rtol=1e-10,
                                    atol=1e-12,
                                    t_eval=np.linspace((periods - 1) * P, periods * P, 2001))
    return sol.y[:, -1], (sol.y[0].max() - sol.y[0].min()) / 2


def crossings(s, branch, w):
    """(amplitude, stable) where consecutive points of ``branch`` cross ``w``."""
    om, br, amp, st = s["omega"], s["branch"], s["amp"], s["stable"]
    out = []
    for i in range(len(om) - 1):
        if br[i] == br[i + 1] == branch and (om[i] - w) * (om[i + 1] - w) < 0:
            t = (w - om[i]) / (om[i + 1] - om[i])
            out.append((amp[i] + t * (amp[i + 1] - amp[i]), bool(st[i] == 1 and st[i + 1] == 1)))
    return sorted(out)


def hb_state(X, omega):
    """``(x, v)`` at ``t = 0`` of the coefficients ``X`` ``(2K+1, 1)``: mean, then cosine
    and sine of each harmonic."""
    X = np.asarray(X)[:, 0]
    k = np.arange(1, (len(X) - 1) // 2 + 1)
    return [X[0] + X[1::2].sum(), omega * (k * X[2::2]).sum()]


@pytest.mark.slow
def test_an_isola_is_found_from_an_integration_seed_and_traced_once():
    system = isola_oscillator()
    # the walk, the far end and the jumps alone: the contact branch only
    bare = system_sweep(*ISOLA_BAND, system=system, max_detour=150)
    assert [r["found"] for r in bare["records"]] == ["sweep"] and not bare["walk"].restarts
    assert np.all(bare["stable"] == 1) and bare["amp"].max() < 0.15
    s = system_sweep(*ISOLA_BAND, system=system, seeds=ISOLA_SEEDS, max_detour=150)
    records = s["records"]
    # the other seeds down (0.8, 0.7, ... rad/s) land on it too: no orbit twice
    assert [r["found"] for r in records] == ["sweep", "integration down"]
    assert records[1]["seed_hz"] == pytest.approx(hz(0.9))
    assert "closed_loop" in records[1]["stops"]
    on = s["branch"] == 1
    om, amp = s["omega"][on], s["amp"][on]
    assert ISOLA_BAND[0] < om.min() < 0.45 and 0.85 < om.max() < ISOLA_BAND[1]
    # closed, once round: its two ends meet, and it crosses W_I twice (the upper orbit
    # stable, the lower not), not four times
    step = np.hypot(np.diff(om), np.diff(amp)).max()
    assert np.hypot(om[0] - om[-1], amp[0] - amp[-1]) < 3 * step
    (lower, lower_stable), (upper, upper_stable) = crossings(s, 1, W_I)
    assert upper_stable and not lower_stable and lower < upper
    assert crossings(s, 0, W_I) == crossings(bare, 0, W_I)

    # independent: SciPy from a large start settles on the isola's upper orbit; from
    # the balance's own stable state near W_I it stays on that orbit, and from its
    # unstable one it leaves
    _, settled = isola_ivp(W_I, [2.5, 0.0], 40)
    assert upper == pytest.approx(settled, rel=2e-3)
    for want_stable in (True, False):
        i = np.flatnonzero(on & (s["stable"] == want_stable))
        i = i[np.argmin(np.abs(s["omega"][i] - W_I))]
        w = float(s["omega"][i])
        z0 = hb_state(s["X"][i], w)
        z, a = isola_ivp(w, z0, 40)
        if want_stable:
            assert a == pytest.approx(s["amp"][i], rel=2e-3)
            assert np.hypot(*(z - z0)) < 1e-3 * s["amp"][i]
        else:
            assert abs(a - s["amp"][i]) > 0.3 * s["amp"][i]
