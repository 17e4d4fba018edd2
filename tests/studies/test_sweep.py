"""The gear-train sweep surface: refusals, harmonics rule, a short linear sweep end to end."""

import dataclasses
import json
import math
import threading
import time

import jax.numpy as jnp
import numpy as np
import pytest
import threadpoolctl
import xarray as xr

import gearjax as gj
from gearjax._engine import aft as _aft
from gearjax._engine import hb as _hb
from gearjax._io import results as _results
from gearjax._studies import concurrency
from gearjax._studies import harmonics as _harmonics
from gearjax._studies import sweep as _sweep
from gearjax._studies.sweep import segments, speculation, starts, walk
from gearjax._cli import main
from gearjax._engine.results import RESULTS


@pytest.fixture(scope="module")
def train(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


def test_gear_where_no_mesh_turns_is_refused(train):
    with pytest.raises(gj.TrainError, match="no mesh turns"):
        _sweep.sweep(train, "third", 2000, 3000)


@pytest.mark.parametrize("gear, stage", [("second", "1"), ("fourth", "2"), ("reverse", "2")])
def test_unloaded_stage_with_backlash_needs_drag(train, gear, stage):
    with pytest.raises(gj.TrainError) as e:
        _sweep.sweep(train, gear, 2000, 3000)
    msg = str(e.value)
    assert f"gears.{gear}.drag_torque = 0.0" in msg and f"stage {stage!r}" in msg
    assert "\n" not in msg


def test_bad_stage_and_frequency_are_refused(train):
    with pytest.raises(gj.TrainError, match="stage = '7': no such stage"):
        _sweep.sweep(train, "first", 2000, 3000, stage="7")
    with pytest.raises(gj.TrainError, match="argument from_hz = -1"):
        _sweep.sweep(train, "first", -1, 3000)


def test_harmonics_rule_and_segments(train):
    # paper first gear, mu_ref = 7: base = f / 7; the cutoff from its modes
    cutoff = _harmonics.response_cutoff_hz(gj.assemble(train, "first"))
    assert _harmonics.harmonics_rule(2000 / 7, 32, cutoff_hz=cutoff) == 64
    assert _harmonics.harmonics_rule(15000 / 7, 32, cutoff_hz=cutoff) == 32
    segs = segments.band_segments(2000, 15000, 7, 32, 1, None, cutoff)
    assert segs[0][0] == 2000 and segs[-1][1] == 15000
    assert [k for *_, k in segs] == sorted([k for *_, k in segs], reverse=True)
    assert len(segs) <= 3
    down = segments.band_segments(15000, 2000, 7, 32, 1, None, cutoff)
    assert down[0][0] == 15000 and down[-1][1] == 2000


def test_linear_sweep_json_and_files(capsys, tmp_path, paper_train_h1, paper_toml_h1):
    # one stiffness harmonic: K = 16 holds its excitation
    nc, fig = tmp_path / "lin.nc", tmp_path / "lin.png"
    code = main(["sweep", str(paper_toml_h1), "--linear", "--from", "5000", "--to", "5400", "--points", "3",
                 "--harmonics", "16", "--json", "--out", str(nc), "--plot", str(fig)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["stop"] == "reached_end" and len(out["points"]) == 3
    assert list(out["phase_seconds"]) == ["gear", "check", "walk", "results"]  # no completion
    p = out["points"][0]
    assert {"mesh_frequency_hz", "stage_mesh_frequency_hz", "input_rpm", "result", "converged",
            "stable", "meshes"} <= set(p)
    assert p["mesh_frequency_hz"] == pytest.approx(5000)
    assert p["stage_mesh_frequency_hz"][1] == pytest.approx(5000 * 8 / 7)
    assert p["input_rpm"] == pytest.approx(5000 / 226.4705882 * 1000, rel=1e-6)
    mesh = {m["name"]: m for m in p["meshes"]}
    assert set(mesh) >= {"1.sp1", "2.rp4"}
    # linear: no separation, and the mean transmitted torque is the static one (the 1e2
    # housing springs are linear too, so HB's mean row is the static equation)
    assert mesh["1.sp1"]["separation"] == 0.0
    assert mesh["1.sp1"]["mean_force"] == pytest.approx(8942.2, rel=1e-4)
    ds = gj.load_results(nc)
    assert ds.sizes["point"] == 3 and ds.sizes["mesh"] == 16
    assert fig.stat().st_size > 10_000
    assert all(math.isfinite(m["rms_force"]) for m in p["meshes"])
    assert np.all(ds["converged"].values)
    # the member displacement harmonics, read back from the file, are the solution:
    # its mesh responses come out again
    assert ds["displacement_cos"].dims == ("point", "dof", "harmonic")
    assert ds.sizes["harmonic"] == 17 and np.all(ds["harmonics"].values == 16)
    system = dataclasses.replace(gj.assemble(paper_train_h1, "first"), backlash=jnp.zeros(16))
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=16))
    c, s = ds["displacement_cos"].values[1], ds["displacement_sin"].values[1]
    assert list(ds["dof"].values[:3]) == list(system.dof_labels[:3]) and np.all(s[:, 0] == 0)
    X = np.zeros((33, system.n_dof))
    X[0], X[1::2], X[2::2] = c[:, 0], c[:, 1:].T, s[:, 1:].T
    np.testing.assert_array_equal(_results.displacement_coefficients(ds, 1), X)
    resp = gj.mesh_responses(problem, jnp.asarray(X), float(ds["omega"].values[1]),
                             gj.static_mesh_forces(system))
    np.testing.assert_allclose(resp.rms_force, ds["rms_force"].values[1], rtol=1e-10)


def test_nonlinear_sweep_keeps_mean_load_and_reports_stability(paper_train_h1):
    """A short continuation with backlash: every point converged, stability and
    bifurcations reported, no back-side contact, and the mean mesh forces summed over
    the planets equal the static ones (equilibrium of the mean, whatever the dynamics)."""
    r = _sweep.sweep(paper_train_h1, "first", 2400, 2550, harmonics=16, max_step_hz=20)
    ds = r.dataset
    assert r.stop == "reached_end" and ds.sizes["point"] >= 8
    assert np.all(ds["converged"].values) and set(np.unique(ds["stable"].values)) <= {0, 1}
    assert "bifurcations" in _sweep.summary_json(r)
    # where the time went, phase by phase in the order run, adding up to the whole
    assert list(r.phase_seconds) == ["gear", "check", "walk", "completion", "results"]
    assert all(t >= 0 for t in r.phase_seconds.values())
    assert sum(r.phase_seconds.values()) == pytest.approx(r.seconds, abs=0.05)
    assert np.all(ds["back_contact"].values == 0.0)
    for stage in ("1", "2"):
        for side in ("sun", "ring"):
            cols = (ds["stage"].values == stage) & (ds["side"].values == side)
            mean = ds["mean_force"].values[:, cols].sum(axis=1)
            np.testing.assert_allclose(mean, ds["static_force"].values[cols].sum(), rtol=1e-3)
    f = ds["mesh_frequency_hz"].values  # --max-step bounds the predictor; the corrector
    assert np.all(np.diff(f) <= 1.05 * 20)  # moves the frequency by a few percent of it


TWO_SEGMENTS = [(2400.0, 2475.0, 16), (2475.0, 2550.0, 16)]


def test_last_segment_speculated_in_a_thread_as_without_one(paper_train_h1, monkeypatch):
    """The band of the test above cut in two segments: the second is continued in a
    thread from its own start while the first runs, and adopted, since the branch
    arriving from the first enters it on the same orbit. The result is that of the same
    walk without a thread (one core), to the last bit, and starts the second segment on
    its boundary. Where the orbits are taken as different the speculation is called off
    and the walk goes on from the start it found, the same orbit within Newton's
    tolerance: the same points to 1e-7."""
    monkeypatch.setattr(segments, "band_segments", lambda *a: list(TWO_SEGMENTS))
    adopted, names = [], set()
    real_adopt, real_walk = speculation.Speculation.adopt, walk.walk_segment

    def adopt(self, *args):
        adopted.append(real_adopt(self, *args))
        return adopted[-1]

    def walk_in_thread(*args, **kwargs):
        names.add(threading.current_thread().name)
        return real_walk(*args, **kwargs)

    monkeypatch.setattr(speculation.Speculation, "adopt", adopt)
    monkeypatch.setattr(walk, "walk_segment", walk_in_thread)
    kw = dict(harmonics=16, max_step_hz=20)
    threaded = _sweep.sweep(paper_train_h1, "first", 2400, 2550, **kw)
    assert adopted == [True]
    assert ("gearjax-speculation" in names) == concurrency.parallel()
    monkeypatch.setenv(concurrency.THREADS_ENV, "1")  # every thread off
    names.clear()
    inline = _sweep.sweep(paper_train_h1, "first", 2400, 2550, **kw)
    assert adopted == [True, True] and names == {"MainThread"}
    a, b = threaded.dataset.copy(), inline.dataset.copy()
    for ds in (a, b):
        ds.attrs.pop("created", None)
        ds.attrs.pop("command", None)
    xr.testing.assert_identical(a, b)
    f = a["mesh_frequency_hz"].values
    assert np.sum(np.isclose(f, 2475.0, rtol=0, atol=1e-9)) == 1
    assert np.all(np.diff(f) > 0) and np.all(a["branch"].values == 0)

    monkeypatch.delenv(concurrency.THREADS_ENV)
    monkeypatch.setattr(speculation, "SAME_ORBIT", -1.0)
    own = _sweep.sweep(paper_train_h1, "first", 2400, 2550, **kw).dataset
    assert adopted[-1] is False
    assert own.sizes["point"] == a.sizes["point"]
    np.testing.assert_allclose(own["mesh_frequency_hz"].values, f, rtol=1e-7)
    np.testing.assert_allclose(own["rms_force"].values, a["rms_force"].values, rtol=1e-7)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(
            t.name == "gearjax-speculation" for t in threading.enumerate()):
        time.sleep(0.05)
    assert not any(t.name == "gearjax-speculation" for t in threading.enumerate())


def blas_threads() -> set[int]:
    return {i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"}


def test_continuation_runs_blas_on_all_cores_but_one_and_restores_it(paper_train_h1):
    """While a continuation sweep runs, BLAS keeps one core free for the post-processing
    thread (``concurrency.limit_blas``); the limits come back after it, also when the sweep
    is interrupted, and the post-processing thread stops then (interrupted at the 8th
    point, when the first chunk has just gone to it; the band and settings of the test
    above, whose compiled programs this reuses)."""
    before = blas_threads()
    during = []

    def progress(n, f_hz):
        during.append(blas_threads())
        if n == 8:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _sweep.sweep(paper_train_h1, "first", 2400, 2550, harmonics=16, max_step_hz=20,
                     progress=progress)
    assert len(during) == 8
    assert all(d == {max(1, concurrency.threads() - 1)} for d in during)
    assert blas_threads() == before
    assert not any(t.name.startswith("gearjax-post") and t.is_alive() for t in
                   _wait_for_post_threads())


def _wait_for_post_threads(timeout=10.0):
    """Live threads after the post-processing threads had ``timeout`` s to finish."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(
            t.name.startswith("gearjax-post") for t in threading.enumerate()):
        time.sleep(0.05)
    return threading.enumerate()


@pytest.mark.slow
def test_start_past_the_fold_by_time_integration(train):
    """Just past the 3.27 kHz fold (paper, 0.05 mm backlash, K = 32) Newton from the linear,
    in-contact guess fails: the stage-2 sun meshes separate 36% of the period. The start
    integrates from the static contact state until the orbit repeats, and Newton from
    that orbit's harmonics converges in a few steps, to a stable orbit (an attractor, as
    the integration found it; Floquet, independently of the start) that separates as
    described. (The homotopy in backlash reached the same orbit within 7e-12 at K = 64,
    after 374 continuation points.)"""
    system = gj.assemble(train)
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=32))
    omega = 2 * math.pi * 3306.43 / 7
    guess = _hb.linear_guess(problem, omega)
    assert not bool(starts.newton(problem, jnp.asarray(omega), guess).converged)
    sol = starts.settled_start(problem, omega)
    assert bool(sol.converged) and int(sol.stats["num_steps"]) <= 6
    assert bool(gj.stability(problem, sol.X, omega).stable)
    p = np.asarray(_aft.synthesis(sol.X @ system.W.T, 512))
    separated = np.mean(np.abs(p) <= np.asarray(system.backlash), axis=0)
    np.testing.assert_allclose(separated[4:8], 0.365, atol=0.01)
    assert np.all(np.delete(separated, np.s_[4:8]) == 0)
    y, code = starts.start_point(problem, omega)  # the sweep's start goes the same way
    assert bool(code == RESULTS.successful) and np.allclose(y, sol.y, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_walk_starts_from_the_truncation_checks_point(train, monkeypatch):
    """A band that starts just past the 3.27 kHz fold (K = 32: Newton from the linear
    guess fails there, above): the truncation check solves the band's first point with
    backlash, by the integration start, and judges it (``backlash`` true, not the
    system without backlash); the walk starts from that point and does not solve it
    again. Its first point is the integration start's orbit. With the separation judged
    the fixed K = 32 is 0.59% off against K = 64, over the 0.5% target: warned about."""
    entered = []
    real_enter = starts.enter_segment

    def enter(*args, **kwargs):
        entered.append(args[2])
        return real_enter(*args, **kwargs)

    monkeypatch.setattr(starts, "enter_segment", enter)
    with pytest.warns(_harmonics.TruncationWarning, match="K = 32: truncation estimate"):
        r = _sweep.sweep(train, "first", 3306.43, 3308, harmonics=32, max_points=3,
                         complete=False)
    (check,) = json.loads(r.dataset.attrs["solver"])["truncation"]
    assert check["backlash"] is True and check["K"] == 32
    np.testing.assert_allclose(check["change"], 0.0059, atol=5e-4)
    assert entered == []
    system = gj.assemble(train)
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=32))
    omega = 2 * math.pi * 3306.43 / 7
    sol = starts.settled_start(problem, omega)
    rms = gj.mesh_responses(problem, sol.X, omega, gj.static_mesh_forces(system)).rms_force
    assert bool(sol.converged) and r.dataset["converged"].values[0]
    np.testing.assert_allclose(r.dataset["rms_force"].values[0], rms, rtol=1e-9)


@pytest.mark.slow
def test_branch_past_a_fold_restarts_beyond_it_with_doubling_gaps(train, monkeypatch):
    """Up through the fold at 3271.1 Hz (K = 32) the branch turns back; after ``max_detour`` points
    without passing the furthest frequency the sweep keeps them and restarts a fresh branch
    beyond it, 2.5 Hz (a quarter of the 10 Hz step) further, the gap doubling after each
    start that fails. Every fresh start after the sweep's first (the truncation check's
    point) is replaced here by an immediate failure, so that the gaps double (a real start
    past this fold converges, from the integration of the furthest point's state)."""
    tried = []

    def no_start(problem, omega, state=None):
        tried.append(float(omega))
        return None, RESULTS.nonlinear_max_steps_reached

    monkeypatch.setattr(starts, "start_point", no_start)
    r = _sweep.sweep(train, "first", 3240, 3300, harmonics=32, max_step_hz=10, max_detour=10,
                     complete=False)  # the walk alone: the completion would start more
    ds = r.dataset
    f, branch = ds["mesh_frequency_hz"].values, ds["branch"].values
    assert np.all(branch == 0) and np.all(ds["converged"].values)
    # 3271.1 Hz at K = 32, the fewest harmonics that hold the excitation (3273.9 at K = 64;
    # the 3272.2 Hz this test had at K = 16 came from a balance without the stiffness's
    # upper harmonics)
    assert len(r.folds_hz) == 1 and abs(r.folds_hz[0] - 3271.1) < 0.5
    reached = f.max()
    assert [x["reason"] for x in r.restarts][0] == "detour"
    gaps = np.diff([reached] + [x["at_hz"] for x in r.restarts])
    np.testing.assert_allclose(gaps, [2.5, 5.0, 10.0], rtol=1e-9)
    assert len(tried) == 3 and r.stop.startswith("no converged start at 3288.")
    assert "restarts" in _sweep.summary_json(r)
