"""Pin position errors in motion: the torsional model's mean transmission errors
(``assembly.pin_te``) against the translational model with rigid bearings, its
harmonic balance against the project's time integration, and a derivative through them
against finite differences.

With pins 1e6 times stiffer than the meshes the translational model's planets move as
the torsional model's do, so the two models' mesh forces agree to that limit at every
frequency, not only in the statics (tests/gear/test_load_sharing.py).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import gearjax as gj
from gearjax import loads_train
from gearjax._studies import sensitivity as S
from sensitivity_differences import finite_differences
from train_refusals import mutate

DATA = Path(__file__).parent.parent / "data"
ERRORS_UM = [8.0, -4.0, 0.0, 0.0, 0.0]
"""Tangential pin errors of the helicopter stage's five planets (um)."""


def _helicopter(model: str) -> gj.Train:
    def change(raw):
        raw["model"] = model
        s = raw["stages"][0]
        s["mass"] = {"sun": 2.1, "ring": 9.0, "carrier": 12.0}
        s["bearing_stiffness"] = dict.fromkeys(("sun", "ring", "carrier", "planet"), 1e15)
        s["planet_position_error_um"] = {"tangential": ERRORS_UM}
    text = mutate((DATA / "helicopter_five_planets.toml").read_text(), change)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return loads_train(text, source="helicopter.toml")


def _sweep(train):
    """Linear, 1590-1610 Hz, K = 4 (twice the mesh frequency near the 3.2 kHz mode: the
    errors' dynamic part is amplified, so far that the linear result loses contact): the
    claim compares two models' linear harmonic balance equations at the same K, so neither
    the truncation nor the contact-loss warning is about it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.TruncationWarning)
        warnings.simplefilter("ignore", gj.ContactLossWarning)
        return gj.sweep(train, "flight", 1590.0, 1610.0, linear=True, points=3,
                        harmonics=4).dataset


@pytest.mark.slow
def test_torsional_pin_errors_move_the_meshes_as_rigid_translational_pins_do():
    """Slow (about 11 s alone on 2 cores: it compiles both models' sweep programs; less
    after tests/studies/test_translational_dynamics.py, which shares the translational
    ones). Mean and RMS sun- and ring-mesh forces agree within 1e-4 (the rigid limit leaves
    about 1e-6, the harmonic balance solves to its own tolerance) at the frequencies both
    sweeps solved (their steps differ). Pins ahead along the carrier's rotation unload
their planets here (the static closed form's sign): planet 2 (-4 um) carries the most,
planet 1 (+8 um) the least."""
    torsional, translational = (_sweep(_helicopter(m)) for m in ("torsional", "translational"))
    hz = [np.asarray(d["mesh_frequency_hz"].values) for d in (torsional, translational)]
    common = np.intersect1d(*hz)
    assert common.tolist() == [1590.0, 1600.0, 1610.0]
    a, b = ({"point": np.flatnonzero(np.isin(f, common))} for f in hz)
    for field in ("mean_force", "rms_force", "load_sharing"):
        np.testing.assert_allclose(torsional[field].isel(a).values,
                                   translational[field].isel(b).values, rtol=1e-4)
    mean = torsional["mean_force"].to_pandas().iloc[0]
    assert mean["main.sp2"] > mean["main.sp3"] > mean["main.sp1"]
    assert float(torsional["load_sharing"].min()) > 1.02


def test_torsional_pin_errors_agree_with_integration():
    """The mean transmission error enters the integration's deflections as the harmonic
    balance's: model.md's 1% (linear) at 1200 Hz (its orders 2-4 clear of the 3.2 and
    4.2 kHz modes: the teeth stay in contact), K = 16."""
    result = gj.verify_gear(_helicopter("torsional"), "flight", [1200.0], linear=True,
                            harmonics=16)
    assert result.all_ok and float(np.max(result.rel_diff)) < 0.01
    mean_hb = result.hb["mean_force"].values
    mean_ni = result.ni["mean_force"].values
    np.testing.assert_allclose(mean_ni, mean_hb, rtol=0.01)
    assert mean_hb[0, 1] > 1.05 * np.mean(mean_hb[0, :5]) > 1.05 * mean_hb[0, 0]


@pytest.mark.slow
def test_response_derivative_to_a_pin_error_matches_finite_differences():
    """Slow (10-15 s on 2 cores, nearly all compiling the implicit derivative's
    programs; the only derivative through ``te_mean``). d(RMS force of planet 1's sun
    mesh)/d(its pin error) through the mean transmission errors and the harmonic balance
    (torsional, linear, K = 4, 1200 Hz) against central differences of the re-solved
    response (the design use: how much a pin tolerance moves a dynamic force)."""
    train = _helicopter("torsional")
    paths = ("main.planet_position_error_um.tangential.1",)
    with warnings.catch_warnings():  # K = 4: the claim is the derivative of these
        warnings.simplefilter("ignore", gj.TruncationWarning)  # equations, at any K
        result = S.sensitivity(train, "flight", at_hz=1200.0, mesh="main.sp1",
                               paths=paths, harmonics=4, linear=True)
    assert result.ok, result.message
    fd, noise = finite_differences(train, result, linear=True)
    assert np.all(np.abs(fd * np.asarray(result.values)) > 1e-3 * abs(result.value))
    err = np.abs(np.asarray(result.derivative) - fd)
    assert np.all(err <= 1e-5 * np.abs(fd) + noise), (result.derivative, fd)
