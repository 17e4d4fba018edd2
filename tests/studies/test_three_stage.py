"""A three-stage train whose first choice of harmonics is not enough.

tests/data/three_stage.toml: three planetary stages in series, mu = (7, 2, 1), mesh
modes up to 10.06 kHz. At a stage-A mesh frequency of 1 kHz the base is 142.9 Hz, the
rule's first choice is its cap K = 64 (9.14 kHz), and the stage-A modes near 9-10 kHz
are driven by harmonics 63 and 70 of the base: the linear harmonic balance with K = 64
is 5.2% off K = 128 on the stage-A sun meshes (the smallest alternating forces of the
train), K = 128 and 256 agree to 1e-8. The sweep's a-posteriori check must find that
and raise K (gearjax._studies.harmonics.truncation_change, gearjax._studies.sweep.segments.checked_segments).
"""

import dataclasses
import json
import math
import pathlib
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._studies import harmonics as _harmonics
from gearjax._engine import hb as _hb
from gearjax._engine.newton import newton_jit
from gearjax._cli import main
from gearjax._engine.responses import mesh_responses, static_mesh_forces
from gearjax._studies.sweep import sweep

TRAIN = pathlib.Path(__file__).parents[1] / "data" / "three_stage.toml"
F_HZ = 1000.0  # stage-A (reference stage) mesh frequency
MU_REF = 7


def linear_system(train):
    system = gj.assemble(train)
    return dataclasses.replace(system, backlash=jnp.zeros_like(system.backlash))


def reference_rms(system, f_hz, K):
    """RMS mesh forces (N) of the linear harmonic balance with ``K`` harmonics at
    stage-A mesh frequency ``f_hz``: Newton from the linear guess, with the jitted Newton
    the sweep and its truncation check use (compiled already where they solved that K)."""
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=K))
    omega = 2 * math.pi * f_hz / MU_REF
    sol = newton_jit(problem, jnp.asarray(omega), _hb.linear_guess(problem, omega))
    assert bool(sol.converged)
    return np.asarray(mesh_responses(problem, sol.X, omega, static_mesh_forces(system)).rms_force)


def test_three_stage_loads_and_info_gives_mu_7_2_1(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no geometry or range warning either
        train = gj.load_train(TRAIN)
    assert list(train.stage_ids) == ["A", "B", "C"]
    code = main(["info", str(TRAIN), "--json"])
    data = json.loads(capsys.readouterr().out)
    assert code == 0
    assert data["mu"] == [7, 2, 1]
    assert data["ratio_exact"] == "80/3"
    assert data["warnings"] == []
    assert [s["id"] for s in data["stages"]] == ["A", "B", "C"]
    assert all(s["loaded"] for s in data["stages"])  # no drag_torque needed
    hz = [s["mesh_frequency_hz"] for s in data["stages"]]
    assert hz == pytest.approx([350.0, 100.0, 50.0])  # 21 : 6 : 3 at 1000 rpm


def test_three_stage_mesh_modes_reach_10_khz(capsys):
    code = main(["modes", str(TRAIN), "--json"])
    data = json.loads(capsys.readouterr().out)
    assert code == 0
    mesh = [m["hz"] for m in data["modes"]
            if m["class"] == "elastic" and m["energy"]["mesh"] > 0.5]
    assert max(mesh) == pytest.approx(10.06e3, rel=0.01)


@pytest.mark.slow
@pytest.mark.long
def test_sweep_raises_k_until_truncation_meets_target():
    train = gj.load_train(TRAIN)
    system = linear_system(train)
    floor = _harmonics.excitation_floor(system)
    cutoff = _harmonics.response_cutoff_hz(system)
    K0 = _harmonics.harmonics_rule(F_HZ / MU_REF, floor, cutoff_hz=cutoff)
    assert K0 == 64  # the cap: 5/3 x 10.06 kHz would ask for 128

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sweep(train, None, F_HZ, 1.002 * F_HZ, linear=True, points=2)
    solver = json.loads(result.dataset.attrs["solver"])
    target = solver["truncation_target"]
    assert target == _harmonics.TRUNCATION_TARGET
    (f_a, _, K), = solver["segments"]
    assert f_a == F_HZ
    checks = [c for c in solver["truncation"] if c["from_hz"] == F_HZ]
    assert checks[0]["K"] == K0

    # the final K's RMS forces agree with an independent solve at 2K (at least 256) within
    # the target, on every mesh above RMS_FLOOR of the largest
    rms = result.dataset["rms_force"].values[0]
    assert result.dataset["mesh_frequency_hz"].values[0] == pytest.approx(F_HZ)
    ref = reference_rms(system, F_HZ, max(2 * K, 256))
    big = ref > _harmonics.RMS_FLOOR * ref.max()
    change = np.abs(rms - ref) / ref
    names = list(result.dataset["mesh"].values)
    assert np.all(change[big] <= target), {n: f"{c:.2%}" for n, c in zip(names, change)}

    # the first choice was not enough: by the reference, K0 is off by more than 1% on the
    # stage-A sun meshes (whose alternating force is the smallest of the train), and the
    # check raised K, one doubling per estimate above the target
    off = np.abs(reference_rms(system, F_HZ, K0) - ref) / ref
    sun_a = [i for i, n in enumerate(names) if str(n).startswith("A.sp")]
    assert len(sun_a) == 4
    assert ref[sun_a].max() < np.delete(ref, sun_a).min()
    assert off[sun_a].min() > 0.01
    assert checks[0]["change"] == pytest.approx(off.max(), rel=0.05)
    assert K > K0
    for c, nxt in zip(checks, checks[1:]):
        assert c["change"] > target and nxt["K"] == c["K_check"] == 2 * c["K"]

    # and the final K carries its own truncation estimate, within the target
    final = [c for c in checks if c["K"] == K]
    assert final, f"K = {K} has no truncation entry: {checks}"
    assert final[-1]["change"] is not None, (
        f"K = {K} kept without a truncation estimate: {final[-1]}; "
        f"warnings: {[str(w.message) for w in caught]}")
    assert final[-1]["K_check"] == 2 * K
    assert final[-1]["change"] <= target
