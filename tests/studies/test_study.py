"""Design studies: each candidate's figures of merit, the refused candidates kept, the
same results on a Dask cluster as in one process, and nothing lost when a worker or
the client is killed."""

import os
import pathlib
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import xarray as xr

import gearjax as gj
from gearjax._studies.study.store import candidate_file

DATA = pathlib.Path(__file__).parents[1] / "data"
STUDY = DATA / "helicopter_study.toml"


def merits(ds: xr.Dataset) -> xr.Dataset:
    """A study's results without the wall time each candidate took."""
    return ds.drop_vars("seconds")


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    return gj.study(STUDY, tmp_path_factory.mktemp("serial") / "store", workers=0)


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client, LocalCluster

    from gearjax._studies.study.run import WORKER_ENV

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None, env=WORKER_ENV) as cluster, \
            Client(cluster) as c:
        yield c


def test_each_candidate_holds_its_own_trains_first_mode_and_a_refusal_keeps_its_reason(serial):
    ds = serial.dataset
    assert ds.sizes["candidate"] == 6 and ds.attrs["missing"] == 0
    assert list(ds["status"].values) == ["done", "done", "refused"] * 2
    base = (DATA / "helicopter_five_planets.toml").read_text()
    for k in (0, 1, 3, 4):
        row = ds.isel(candidate=k)
        angles = str(row["main.planet_angles_deg"].values)
        text = (base.replace("[0, 72, 144, 216, 288]", f"[{angles}]")
                .replace("sun = 1.0e9", f"sun = {float(row['main.mesh_stiffness.sun'])!r}"))
        train = gj.loads_train(text)
        want = gj.modes(gj.assemble(train, "flight")).elastic_hz[0]
        assert float(row["first_elastic_hz"]) == pytest.approx(want, rel=1e-12)
    refused = ds.isel(candidate=2)
    assert "planets 1 and 2 overlap" in str(refused["reason"].values)
    assert np.isnan(float(refused["first_elastic_hz"]))
    assert serial.refused == 2 and serial.ran == 4


@pytest.mark.slow
def test_a_study_on_a_two_worker_cluster_equals_the_serial_loop(serial, client, tmp_path):
    """Slow (about 15 s): the two workers import gearjax and compile."""
    result = gj.study(STUDY, tmp_path / "store", client=client)
    xr.testing.assert_allclose(merits(result.dataset), merits(serial.dataset), rtol=1e-12)
    assert list(result.dataset["status"].values) == list(serial.dataset["status"].values)


@pytest.mark.slow
def test_a_worker_killed_mid_study_leaves_the_results_unchanged(client, tmp_path):
    """Slow (about 10 s): a cluster study run twice, once with a worker killed."""
    whole = gj.study(STUDY, tmp_path / "whole", client=client)
    pids = client.run(os.getpid)
    killed = []

    def kill_one_busy_worker():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            for address, keys in client.processing().items():
                if keys and address in pids:
                    os.kill(pids[address], signal.SIGKILL)
                    killed.append(address)
                    return
            time.sleep(0.005)

    thread = threading.Thread(target=kill_one_busy_worker)
    thread.start()
    result = gj.study(STUDY, tmp_path / "killed", client=client)
    thread.join()
    assert killed, "no worker was seen busy"
    assert list(result.dataset["status"].values) == ["done", "done", "refused"] * 2
    xr.testing.assert_identical(merits(result.dataset), merits(whole.dataset))


@pytest.mark.slow
def test_a_killed_client_loses_only_candidates_in_flight_and_resume_completes_it(
        serial, tmp_path):
    """Slow (about 20 s): a study in a child process killed with SIGKILL after its first
    candidate, then resumed here."""
    store = tmp_path / "store"
    env = {**os.environ, "GEARJAX_CACHE_DIR": "0"}
    exe = pathlib.Path(sys.executable).with_name("gearjax")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "gearjax._cli"]
    child = subprocess.Popen([*cmd, "study", str(STUDY), "--out", str(store), "--workers", "0"],
                             env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not candidate_file(store, 0).exists() and child.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.002)
    child.send_signal(signal.SIGKILL)
    child.wait()
    before = gj.load_study_results(store)
    assert 0 < before.sizes["candidate"] < 6
    assert not list((store / "candidates").glob(".*.tmp*"))  # no half-written file kept
    with pytest.raises(gj.TrainError, match="finished candidates of this study: resume it"):
        gj.study(STUDY, store, workers=0)
    result = gj.study(STUDY, store, workers=0, resume=True)
    assert result.skipped == before.sizes["candidate"]
    xr.testing.assert_identical(merits(result.dataset), merits(serial.dataset))


def test_the_pareto_set_keeps_the_candidates_no_other_beats_in_both_merits(serial):
    ds = serial.dataset.copy()
    ds["linear_peak_rms_force"] = (("candidate", "stage"),
                                   np.array([[3.0], [1.0], [np.nan], [2.0], [2.5], [np.nan]]))
    ds["linear_points"] = ("candidate", np.full(6, 10))
    # first modes of the four done candidates, highest is best
    f = ds["first_elastic_hz"].values
    got = gj.pareto(ds, "first_elastic_hz", "linear_peak_rms_force")
    done = [0, 1, 3, 4]
    force = {0: 3.0, 1: 1.0, 3: 2.0, 4: 2.5}
    want = [i for i in done if not any(
        f[j] >= f[i] and force[j] <= force[i] and (f[j] > f[i] or force[j] < force[i])
        for j in done)]
    assert got == want and 1 in got


@pytest.mark.slow
def test_a_candidates_sweep_and_verify_merits_are_those_of_the_library_calls():
    """Slow (about 30 s): a linear sweep and a verification compiled once, each run by the
    study's analysis and by the library directly."""
    from gearjax._studies.study.analysis import analyse_candidate
    from gearjax._studies.sweep.summary import largest_responses

    text = (DATA / "helicopter_five_planets.toml").read_text()
    analysis = {"modes": False, "linear": {"band_hz": (1200.0, 1600.0), "points": 6,
                                           "harmonics": 4},
                "backlash": None, "verify": {"at_hz": (1500.0,), "linear": True}}
    got = analyse_candidate(text, "heli", "flight", analysis)
    assert got["status"] == "done", got["reason"]
    train = gj.loads_train(text)
    sweep = gj.sweep(train, "flight", 1200.0, 1600.0, linear=True, points=6, harmonics=4)
    row = largest_responses(sweep.dataset)[0]
    assert got["linear"]["peak_rms_force"] == [row["rms_force"]]
    assert got["linear"]["peak_hz"] == [row["mesh_frequency_hz"]]
    assert got["linear"]["points"] == sweep.dataset.sizes["point"]
    check = gj.verify_gear(train, "flight", [1500.0], linear=True)
    assert got["verify"] == {"max_rel_diff": float(np.nanmax(check.rel_diff)),
                             "ok": check.all_ok, "tolerance": check.tolerance, "points": 1}
    assert any("teeth would leave contact" in line for line in got["warnings"])


def test_a_store_another_process_is_running_a_study_on_is_refused(tmp_path):
    store = tmp_path / "store"
    spec = gj.load_study(STUDY)
    from gearjax._studies.study.store import open_store

    open_store(store, spec, 6, resume=False)
    code = ("import sys, time; from gearjax._io.journal import lock; "
            f"h = lock({str(store / 'study.json')!r}); print('held', flush=True); "
            "time.sleep(60)")
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "held"
        with pytest.raises(gj.TrainError, match=rf"argument store = '{store}': another "
                           rf"gearjax process \(pid {child.pid}\) is running this study now"):
            gj.study(spec, store, workers=0, resume=True)
    finally:
        child.kill()
        child.wait()


def test_a_complete_sweep_stopped_by_its_budget_is_flagged_in_the_dataset_and_json():
    from gearjax._studies.study.candidates import candidates
    from gearjax._studies.study.store import candidate_dataset

    spec = gj.load_study(STUDY)
    sweep = {"peak_rms_force": [5.0], "peak_hz": [2600.0], "coexisting_hz": 0.0, "jumps": [],
             "stop": "max_points", "points": 5, "failed": 0, "complete": False}
    merits = {"status": "done", "reason": "", "warnings": [], "seconds": 1.0,
              "backlash": sweep}
    ds = candidate_dataset(spec, candidates(spec)[0], merits)
    assert int(ds["backlash_complete"][0]) == 0
    (record,) = gj.candidate_records(ds)
    assert record["backlash"]["complete"] is False and record["backlash"]["stop"] == "max_points"
    ds = candidate_dataset(spec, candidates(spec)[0], {**merits, "backlash": None})
    assert int(ds["backlash_complete"][0]) == -1 and gj.candidate_records(ds)[0]["backlash"] is None
