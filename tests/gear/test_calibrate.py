"""Calibration of train parameters to natural frequencies."""

import warnings

import numpy as np
import pytest

import gearjax as gj
from gearjax._gear.calibrate import elastic_sensitivity

TRUE_FACTORS = {  # perturbation of the start; the truth is the bundled train
    "1.inertia.sun": 1.3,
    "2.inertia.carrier": 0.8,
    "1.inertia.planet": 1.15,
    "2.inertia.ring": 0.9,
}


@pytest.fixture(scope="module")
def paper(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


@pytest.fixture(scope="module")
def paper_hz(paper):
    hz = gj.modes(gj.assemble(paper)).elastic_hz
    assert len(hz) == 12
    return hz


@pytest.fixture(scope="module")
def recovery(paper, paper_hz):
    start = paper
    for path, factor in TRUE_FACTORS.items():
        start = gj.set_path(start, path, float(gj.get_path(paper, path)) * factor)
    return start, gj.calibrate(start, paper_hz, list(TRUE_FACTORS))


def test_recovers_known_inertias(paper, paper_hz, recovery):
    start, result = recovery
    assert isinstance(result, gj.CalibrationResult)
    assert result.converged, result.message
    assert result.free == tuple(TRUE_FACTORS)
    assert result.gear == "first"
    assert result.at_bound == ()
    assert result.nfev < 50
    for path, factor in TRUE_FACTORS.items():
        truth = float(gj.get_path(paper, path))
        assert result.initial[path] == pytest.approx(truth * factor, rel=1e-15)
        assert result.fitted[path] == pytest.approx(truth, rel=1e-6)
        assert float(gj.get_path(result.train, path)) == result.fitted[path]
    assert result.targets_hz == tuple(paper_hz)
    assert len(result.model_hz) == len(result.residual_hz) == len(result.residual_rel) == 12
    assert np.max(np.abs(result.residual_rel)) < 1e-6
    np.testing.assert_allclose(result.residual_hz, np.subtract(result.model_hz, paper_hz))
    # the calibrated train gives the fitted frequencies, and the start did not
    np.testing.assert_allclose(gj.modes(gj.assemble(result.train)).elastic_hz, result.model_hz,
                               rtol=1e-12)
    assert np.max(np.abs(np.subtract(gj.modes(gj.assemble(start)).elastic_hz, paper_hz))
                  / paper_hz) > 0.05


def test_calibrated_train_writes_and_reads_back(recovery, tmp_path):
    _, result = recovery
    path = tmp_path / "calibrated.toml"
    gj.save_train(result.train, path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        back = gj.load_train(path)
    for p, value in result.fitted.items():
        assert float(gj.get_path(back, p)) == value


def test_jacobian_matches_central_differences(paper):
    free = ["1.inertia.sun", "1.inertia.planet", "2.mesh_stiffness.ring", "1.module_mm",
            "couplings.0.stiffness"]
    hz, jac = elastic_sensitivity(paper, free)
    assert hz.shape == (12,) and jac.shape == (12, len(free))
    assert np.all(np.isfinite(jac))
    fd = np.empty_like(jac)
    for j, path in enumerate(free):
        p = float(gj.get_path(paper, path))
        h = 1e-4 * p  # balances truncation (h^2) and eigenvalue round-off (1e-12 / h)
        plus = gj.modes(gj.assemble(gj.set_path(paper, path, p + h))).elastic_hz
        minus = gj.modes(gj.assemble(gj.set_path(paper, path, p - h))).elastic_hz
        fd[:, j] = (np.asarray(plus) - np.asarray(minus)) / (2 * h)
    scale = np.max(np.abs(fd), axis=0)  # Hz per unit parameter, per column
    np.testing.assert_allclose(jac / scale, fd / scale, atol=1e-6)
    # mode 1 (3.87 kHz, single) and the triple planet mode of stage 1 (10.41 kHz)
    triple = [k for k in range(12) if abs(hz[k] - 10410.0) < 1.0]
    assert len(triple) == 3
    for k in [0] + triple:
        np.testing.assert_allclose(jac[k], fd[k], rtol=1e-6, atol=1e-9 * scale.max())
    assert np.all(jac[triple, 1] < 0) and np.ptp(jac[triple, 1]) < 1e-9 * abs(jac[triple[0], 1])


def test_fewer_targets_and_bounds(paper, paper_hz):
    truth = float(gj.get_path(paper, "1.inertia.sun"))
    start = gj.set_path(paper, "1.inertia.sun", 1.3 * truth)
    # two targets, one parameter: recovered
    result = gj.calibrate(start, paper_hz[:2], ["1.inertia.sun"])
    assert result.converged and result.fitted["1.inertia.sun"] == pytest.approx(truth, rel=1e-6)
    assert len(result.model_hz) == 2
    # a bound that excludes the truth: the fit stops on it and says so
    low = 1.2 * truth
    result = gj.calibrate(start, paper_hz[:2], ["1.inertia.sun"],
                          bounds={"1.inertia.sun": (low, 2 * truth)})
    assert result.at_bound == ("1.inertia.sun",)
    assert result.fitted["1.inertia.sun"] == pytest.approx(low, rel=1e-8)
    assert max(abs(r) for r in result.residual_rel) > 1e-3


def _message(call) -> str:
    with pytest.raises(gj.TrainError) as info:
        call()
    message = str(info.value)
    assert "\n" not in message
    return message


def test_targets_are_checked(paper, paper_hz):
    free = ["1.inertia.sun"]
    m = _message(lambda: gj.calibrate(paper, paper_hz[::-1], free))
    assert "argument targets_hz = " in m and "targets must be ascending" in m
    m = _message(lambda: gj.calibrate(paper, [1000.0, -5.0], free))
    assert "argument targets_hz = " in m and "> 0" in m
    m = _message(lambda: gj.calibrate(paper, [], free))
    assert "argument targets_hz = " in m and "at least one target" in m
    m = _message(lambda: gj.calibrate(paper, list(paper_hz) + [5e4], free))
    assert "argument targets_hz = " in m and "13 targets but gear 'first' has only 12 elastic modes" in m


def test_free_paths_are_checked(paper, paper_hz):
    def calibrate(free, train=paper):
        return _message(lambda: gj.calibrate(train, paper_hz, free))

    m = calibrate(["1.teeth.sun"])
    assert "argument free = '1.teeth.sun': " in m and "continuous keys of a stage are" in m
    m = calibrate(["1.inertia.moon"])
    assert "argument free = '1.inertia.moon': " in m and "sun, ring, carrier, planet" in m
    m = calibrate(["7.inertia.sun"])
    assert "argument free = '7.inertia.sun': no stage or section '7'" in m
    m = calibrate([])
    assert "argument free = []: at least one parameter path is required" in m
    m = calibrate(["1.inertia.sun", "2.planet_mass", "1.inertia.sun"])
    assert "given twice" in m
    m = calibrate(["couplings.lockup.stiffness", "couplings.2.stiffness"])
    assert "argument free = 'couplings.2.stiffness'" in m and "given twice" in m
    negative = gj.set_path(paper, "2.stage_phase_deg", -5.0)
    m = calibrate(["1.inertia.sun", "2.stage_phase_deg"], negative)
    assert "argument free = '2.stage_phase_deg': its value is -5" in m and "must be > 0" in m
    m = calibrate(["1.half_backlash.sun"])
    assert "'1.half_backlash.sun': changes none of the targeted natural frequencies" in m
    m = calibrate(["couplings.lockup.stiffness"])  # a clutch not engaged in the first gear
    assert "changes none of the targeted natural frequencies" in m


def test_bounds_are_checked(paper, paper_hz):
    p = float(gj.get_path(paper, "1.inertia.sun"))
    m = _message(lambda: gj.calibrate(paper, paper_hz, ["1.inertia.sun"],
                                      bounds={"1.inertia.sun": (2 * p, 3 * p)}))
    assert "must contain the start value" in m
    m = _message(lambda: gj.calibrate(paper, paper_hz, ["1.inertia.sun"],
                                      bounds={"1.inertia.sun": (0.0, 3 * p)}))
    assert "0 < low < high" in m
    m = _message(lambda: gj.calibrate(paper, paper_hz, ["1.inertia.sun"],
                                      bounds={"2.inertia.sun": (p, 3 * p)}))
    assert "is not a free path" in m
