"""The phasing optimiser's objective with backlash is the peak over every stable state of a
complete sweep, and its output says plainly whether the optimum beats
the baseline.

The case: a three-planet single stage (tests/data/three_planets.toml with 1% mesh damping) over
2.5-3 kHz, K = 4. A sweep up from 2.5 kHz starts on the low branch of a softening
resonance, follows it round its fold and back along the unstable branch below the band's
start, gives up there (``detour``) and restarts beyond the fold: the walk alone never
reaches the resonant branch near 2.58 kHz. The completion traces the restarted branch
back down and finds it (``back from restart``), about 14% above the walk's peak (a walk
from 2 kHz reaches the same state from below). That the state is real is checked
independently: time integration started on it stays on it.
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest

import gearjax as gj
from gearjax import _cli
from gearjax._studies import optimize as O

BAND = (2500.0, 3000.0)
K = 4
TEXT = (pathlib.Path(__file__).parent.parent / "data" / "three_planets.toml").read_text(
    ).replace('"three planets"', '"three planets, light damping"').replace(
    "mesh_damping_ratio = 0.05", "mesh_damping_ratio = 0.01")
SETTINGS = O.OptimizeSettings(proxy_points=32, phase_grid=4, screen=2, screen_points=6,
                              final_points=6, harmonics=K, nonlinear=1, relax_iterations=0)


@pytest.fixture(scope="module")
def train():
    return gj.loads_train(TEXT)


@pytest.fixture(scope="module")
def complete(train):
    return gj.sweep(train, "low", *BAND, harmonics=K)


@pytest.fixture(scope="module")
def optimised(train):
    return O.optimize(train, "low", BAND, settings=SETTINGS)


def stable_peak(ds) -> float:
    ok = (ds["stable"].values == 1) & (ds["result"].values == "converged")
    return float(np.max(ds["rms_force"].values[ok]))


def test_objective_counts_the_stable_branch_the_walk_misses(train, complete):
    band = O.band_of(complete, *BAND, O.BandSettings(harmonics=K))
    walk = gj.sweep(train, "low", *BAND, harmonics=K, complete=False)
    # the walk alone: the same walk inside the complete sweep, and its peak is lower
    assert band.walk_peak == pytest.approx(stable_peak(walk.dataset), rel=1e-9)
    assert band.peak > 1.1 * band.walk_peak
    assert band.peak_found not in O.nonlinear.WALKED and band.complete
    ds = complete.dataset
    peak, f_peak, mesh, i = O.band_peak(ds)
    assert peak == band.peak and ds["stable"].values[i] == 1
    # independent: time integration started on that orbit stays on it
    x0, v0 = O.rechecking.point_state(ds, i)
    ni = gj.simulate_gear(train, "low", [f_peak], x0=x0, v0=v0)
    j = list(ds["mesh"].values).index(mesh)
    assert str(ni["result"].values[0]) == "converged"
    assert float(ni["rms_force"].values[0, j]) == pytest.approx(peak, rel=0.02)


def test_optimiser_baseline_and_candidates_use_complete_sweeps(optimised, complete):
    r = optimised
    b, o = r.baseline.nonlinear, r.optimum.nonlinear
    ref = O.band_of(complete, *BAND, O.BandSettings(harmonics=K))
    # the baseline's objective is the complete sweep's, the branch the walk misses included
    assert b.peak == pytest.approx(ref.peak, rel=1e-9) and b.peak > 1.1 * b.walk_peak
    assert b.settings == o.settings == O.BandSettings(harmonics=K)
    assert r.models["backlash"]["complete"] and r.models["backlash"]["harmonics"] == K
    assert r.models["linear"]["harmonics"] == K
    # the optimum beats it, and the output says by how much
    v = r.verdict
    assert v["beats_baseline"] and v["recommended"] == "optimum"
    assert o.peak < b.peak and v["reduction"] == pytest.approx(b.peak - o.peak)
    assert "below the baseline's" in v["text"] and f"{b.peak - o.peak:.1f} N" in v["text"]
    assert r.recommended_train is r.train
    data = O.optimize_json(r)
    assert data["verdict"]["text"] == v["text"] and data["models"]["backlash"]["complete"]
    assert data["baseline"]["nonlinear"]["peak_found"] == b.peak_found
    ds = O.optimize_dataset(r)
    assert ds.attrs["recommended"] == "optimum" and ds.attrs["verdict"] == v["text"]
    assert json.loads(ds.attrs["models"])["backlash"]["max_points"] == SETTINGS.max_points


def test_recheck_says_no_phasing_beats_the_baseline_where_the_optimum_is_worse(optimised):
    """Baseline and optimum swapped in the saved result: the 'optimum' is now the worse
    design, and the fresh complete sweeps say so; the recommended design is the baseline."""
    ds = O.optimize_dataset(optimised)
    ds.attrs["train_toml"], ds.attrs["baseline_train_toml"] = (
        ds.attrs["baseline_train_toml"], ds.attrs["train_toml"])
    rc = O.recheck(ds, verify_hz=[], harmonics=K)
    v = rc.verdict
    assert not v["beats_baseline"] and rc.recommended == "baseline"
    assert v["text"].startswith(O.NO_BETTER) and "recommended design is the baseline" in \
        v["text"]
    # the fresh sweeps at the optimiser's settings give the optimiser's peaks back
    assert rc.bands["baseline"].peak == pytest.approx(optimised.optimum.nonlinear_peak,
                                                      rel=1e-9)
    assert rc.bands["optimum"].peak == pytest.approx(optimised.baseline.nonlinear_peak,
                                                     rel=1e-9)
    assert v["integration_confirms"] and (rc.peaks["rel diff"] < 0.02).all()
    assert rc.recommended_train.stage("a").planet_angles_deg.tolist() == pytest.approx(
        optimised.train.stage("a").planet_angles_deg.tolist())
    out = O.recheck_json(rc)
    assert out["recommended"] == "baseline" and out["settings"]["complete"]


def band(peak, coverage=1.0, complete=True):
    return O.NonlinearBand(
        frequencies_hz=np.zeros(0), rms_force=np.zeros((0, 1)), branch=np.zeros(0, int),
        found=np.zeros(0, str), peak=peak, peak_hz=1.0, peak_mesh="m", peak_found="sweep",
        walk_peak=peak, stage_peaks={}, unstable=0, runaway=0, not_converged=0, points=1,
        branches=(), stop="reached_end", coverage=coverage, complete=complete,
        settings=O.BandSettings(), seconds=0.0)


def test_a_candidate_replaces_the_incumbent_only_where_it_is_lower_and_as_complete():
    rank = {0: 2, 1: 0, 2: 1}
    # one candidate, worse (or equal within the tolerance): the incumbent stays
    assert O.pick_nonlinear({0: band(100.0), 1: band(100.05)}, rank) == 0
    assert O.pick_nonlinear({0: band(100.0), 1: band(130.0)}, rank) == 0
    # lower, but its sweep incomplete or shorter than the incumbent's: not trusted
    assert O.pick_nonlinear({0: band(100.0), 1: band(80.0, complete=False)}, rank) == 0
    assert O.pick_nonlinear({0: band(100.0), 1: band(80.0, coverage=0.9)}, rank) == 0
    # the lowest wins; within the tolerance of it, the better linear rank
    assert O.pick_nonlinear({0: band(100.0), 1: band(90.0), 2: band(80.0)}, rank) == 2
    assert O.pick_nonlinear({0: band(100.0), 1: band(80.05), 2: band(80.0)}, rank) == 1
    # an incumbent with no stable state counted: any trusted candidate
    assert O.pick_nonlinear({0: band(float("nan")), 1: band(90.0)}, rank) == 1


def test_verdict_words():
    v = O.verdict(100.0, 80.0, same=False, rtol=1e-3, model="complete-sweep peak",
                  settings="K = 4")
    assert v["beats_baseline"] and v["text"] == (
        "the optimum's complete-sweep peak is 80.0 N, below the baseline's 100.0 N by "
        "20.0 N (20.0%) [K = 4]")
    for b, o, same in ((100.0, 100.05, False), (100.0, 120.0, False), (100.0, 100.0, True),
                       (float("nan"), 90.0, False)):
        v = O.verdict(b, o, same=same, rtol=1e-3, model="peak", incomplete=["optimum"])
        assert not v["beats_baseline"] and v["recommended"] == "baseline"
        assert v["text"].startswith(O.NO_BETTER + ":") and "not complete" in v["text"]


@pytest.mark.slow
def test_cli_optimize_rechecks_and_says_when_the_baseline_stays(tmp_path, capsys):
    """Only the sun-ring phase varied: no candidate beats the baseline, so the optimum is
    the baseline; the re-check sweeps it afresh (once), integrates from its peak orbit,
    and the text, the JSON and the saved results say that no admissible phasing beats
    the baseline; ``--out-train`` writes the baseline."""
    path = tmp_path / "small.toml"
    path.write_text(TEXT.replace("planet_angles_deg = [0, 90, 180]",
                                 "planet_angles_deg = [0, 120, 234]").replace(
        "sun_ring_phase_deg = 90.0", "sun_ring_phase_deg = 180.0"))
    out_train, out = tmp_path / "opt.toml", tmp_path / "opt.nc"
    argv = ["optimize", str(path), "--band", *map(str, BAND), "--harmonics", str(K),
            "--points", "6", "--final-points", "6", "--proxy-points", "32", "--phase-grid",
            "4", "--screen", "1", "--nonlinear", "1", "--relax-iterations", "0",
            "--vary", "a.sun_ring_phase_deg", "--recheck-harmonics", str(K),
            "--out-train", str(out_train), "--out", str(out)]
    assert _cli.main(argv) == 0
    text = capsys.readouterr().out
    assert f"optimiser: {O.NO_BETTER}" in text and f"re-check: {O.NO_BETTER}" in text
    assert "baseline train (the recommended design)" in text
    assert "with backlash: complete sweep, K = 4" in text
    assert gj.load_train(out_train).stage("a").sun_ring_phase_deg == 180.0
    saved = gj.load_results(out)
    assert saved.attrs["recommended"] == "baseline"
    assert saved.attrs["recheck_verdict"].startswith(O.NO_BETTER)
    recheck = json.loads(saved.attrs["recheck"])
    assert recheck["peaks"][0]["sweep peak (N)"] == pytest.approx(
        saved.attrs["baseline_peak_nonlinear"], rel=1e-9)  # the same settings here
    assert _cli.main([*argv[:-4], "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["recommended"] == "baseline" and data["conclusion"].startswith(O.NO_BETTER)
    assert data["recheck"]["verdict"]["recommended"] == "baseline"
