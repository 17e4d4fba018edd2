"""The batched design study checks its truncation a posteriori at each design's peak, as
a sweep checks a segment: K chosen by the study is raised until the estimate meets the
target; a K given by the user is kept and warned about. On the five-planet helicopter
stage (not the paper's train), whose floor K = 2 (two stiffness harmonics) misses its
peaks by tens of percent."""

import pathlib
import warnings

import numpy as np
import pytest

import gearjax as gj
from gearjax._studies import harmonics as H

TRAIN = pathlib.Path(__file__).parents[1] / "data" / "helicopter_five_planets.toml"
PATHS = ["main.planet_angles_deg.2"]
THETAS = [[72.0], [75.0]]
FREQS = [1500.0, 2500.0, 3500.0]


@pytest.fixture(scope="module")
def train():
    return gj.load_train(TRAIN)


@pytest.fixture(scope="module")
def fixed(train):
    """The batch at the user's K = 2 and at K = 4, warnings recorded."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        short = gj.design_sweep(train, "flight", PATHS, THETAS, FREQS, harmonics=2)
    wide = gj.design_sweep(train, "flight", PATHS, THETAS, FREQS, harmonics=4)
    return short, wide, [w for w in caught if issubclass(w.category, gj.TruncationWarning)]


@pytest.mark.slow
def test_a_given_K_is_kept_and_its_estimate_is_the_change_at_doubled_K(fixed):
    """Slow (about 15 s on 2 cores): its fixture compiles the batch and its check at
    K = 2, 4 and 8, the shapes the second test then reuses."""
    short, wide, caught = fixed
    assert short.harmonics == 2
    t = short.truncation
    assert t["target"] == H.TRUNCATION_TARGET
    assert [(c["K"], c["K_check"]) for c in t["checks"]] == [(2, 4)]
    # independently: each design's RMS at its peak, from the batch at K = 2 and at K = 4
    for b in range(len(THETAS)):
        j = int(np.nanargmax(np.nanmax(short.rms_force[b], axis=-1)))
        assert t["frequency_hz"][b] == pytest.approx(short.omega[j] / (2 * np.pi))
        a, w = short.rms_force[b, j], wide.rms_force[b, j]
        change = np.max(np.abs(a - w) / np.maximum(w, H.RMS_FLOOR * w.max()))
        assert t["change"][b] == pytest.approx(change, rel=1e-9)
    assert np.nanmax(t["change"]) > 0.05  # two harmonics miss this stage's peaks
    [warning] = caught
    b = int(np.nanargmax(t["change"]))
    assert (f"design sweep: K = 2: truncation estimate {t['change'][b]:.2%} at design {b}'s "
            "peak") in str(warning.message)
    assert "against K = 4; target 0.5%): raise `harmonics`" in str(warning.message)


def test_the_study_s_own_K_is_raised_until_the_estimate_meets_the_target(train):
    with warnings.catch_warnings():
        warnings.simplefilter("error", gj.TruncationWarning)
        chosen = gj.design_sweep(train, "flight", PATHS, THETAS, FREQS)
    assert chosen.harmonics > H.orders_floor(chosen_system(train))
    [check] = chosen.truncation["checks"]
    assert check["K"] == chosen.harmonics and check["K_check"] == 2 * chosen.harmonics
    assert np.all(np.asarray(chosen.truncation["change"]) <= H.TRUNCATION_TARGET)
    # the K the study settled on, given by the user: the same responses
    again = gj.design_sweep(train, "flight", PATHS, THETAS, FREQS,
                            harmonics=chosen.harmonics)
    np.testing.assert_allclose(again.rms_force, chosen.rms_force, rtol=1e-12)


def chosen_system(train):
    return gj.gear_case(train, "flight", None, True, torus=True).system
