"""Campbell diagram: rays from the exact kinematics, crossings, and the phasing rule
checked against the modal projection of the stiffness excitation."""

import math

import numpy as np
import pytest

import gearjax as gj
from gearjax._plot import figures as _figures

TRAIN = gj.load_train()


def test_rays_and_crossings_follow_the_kinematics():
    d = gj.campbell(TRAIN, "first", (0.0, 60000.0), 3)
    assert d.stages == ("1", "2") and d.loaded == (True, True)
    # 226.47 and 258.82 Hz at 1000 rpm (README validation table)
    np.testing.assert_allclose(d.mesh_hz_per_rpm * 1000, [231 / 17 * 1000 / 60,
                                                         264 / 17 * 1000 / 60], rtol=1e-14)
    assert d.excitation_hz.shape == (2, 3, 2)
    np.testing.assert_allclose(d.excitation_hz[:, :, -1],
                               60000 * d.mesh_hz_per_rpm[:, None] * np.arange(1, 4))
    assert d.crossings and all(0 <= c.rpm <= 60000 for c in d.crossings)
    for c in d.crossings:
        assert math.isclose(c.harmonic * d.mesh_hz_per_rpm[d.stages.index(c.stage)] * c.rpm,
                            c.hz, rel_tol=1e-12)
        assert c.hz == d.mode_hz[c.mode]
    # every crossing in range is listed once: count them independently
    expected = sum(1 for f in d.mode_hz for k in d.mesh_hz_per_rpm for h in (1, 2, 3)
                   if f / (h * k) <= 60000)
    assert len(d.crossings) == expected
    assert [c.rpm for c in d.crossings] == sorted(c.rpm for c in d.crossings)


def test_phasing_rule_matches_the_modal_projection_of_the_stiffness_excitation():
    """A crossing is marked excited exactly when the first-order stiffness excitation
    of that harmonic (``kbar kappa_h p_static`` on every mesh of the stage) has a
    non-zero projection on the mode (on any vector of a repeated mode)."""
    d = gj.campbell(TRAIN, "first", (0.0, 1e6), 4)
    system = gj.assemble(TRAIN, "first")
    x, _ = gj.static_deflection(system)
    p = np.asarray(system.W) @ np.asarray(x)
    kc, ks = np.asarray(system.k_cos), np.asarray(system.k_sin)
    modal = gj.modes(system)
    labels = system.dof_labels
    elastic = [m for m in modal.modes if m.cls == "elastic"]
    checked = 0
    for c in d.crossings:
        rows = np.array([g == c.stage for g in system.mesh_group])
        amp = np.where(rows, np.asarray(system.kbar) * (kc[:, c.harmonic - 1]
                                                         - 1j * ks[:, c.harmonic - 1]) * p, 0)
        force = -np.asarray(system.W).T @ amp
        vectors = [np.array([m.shape[l] for l in labels]) for m in elastic
                   if abs(m.hz - c.hz) < 1e-6 * c.hz]
        share = max(abs(v @ force) / (np.linalg.norm(v) * np.linalg.norm(force))
                    for v in vectors)
        assert (share > 1e-6) == c.excited, (c, share)
        assert share > 1e-3 or share < 1e-9  # a clean yes or no, not a borderline case
        checked += 1
    assert checked > 30
    assert any(c.excited for c in d.crossings) and not all(c.excited for c in d.crossings)


def test_unloaded_stage_and_locked_gear():
    d = gj.campbell(TRAIN, "fourth", (0.0, 40000.0))
    assert d.loaded == (True, False)
    assert all(not c.excited for c in d.crossings if c.stage == "2")
    locked = gj.campbell(TRAIN, "third", (0.0, 40000.0))
    assert locked.stages == () and locked.crossings == () and locked.mode_hz.size > 0
    _figures.campbell_figure([d, locked])  # draws the empty panel too


def test_harmonics_beyond_the_model_drive_nothing():
    d = gj.campbell(TRAIN, "first", (0.0, 60000.0), 6, max_hz=20000.0)
    assert d.phasing[0][4:] == ("beyond model", "beyond model")
    assert all(not c.excited for c in d.crossings if c.harmonic > 4)
    assert d.mode_hz.max() <= 20000.0


@pytest.mark.parametrize("kwargs, field, rule", [
    ({"rpm_range": (100.0, 50.0)}, "rpm_range", "0 <= low < high"),
    ({"rpm_range": (-1.0, 50.0)}, "rpm_range", "0 <= low < high"),
    ({"harmonics": 0}, "harmonics", "integer >= 1"),
    ({"harmonics": 2.5}, "harmonics", "integer >= 1"),
    ({"points": 1}, "points", "integer >= 2"),
])
def test_bad_arguments_are_refused_with_one_line(kwargs, field, rule):
    with pytest.raises(gj.TrainError) as e:
        gj.campbell(TRAIN, "first", **kwargs)
    message = str(e.value)
    assert "\n" not in message and message.startswith(f"campbell: {field} = ") and rule in message


def test_figures_draw_saved_sweeps():
    """The notebook figures draw a sweep Dataset with a fold (two branches)."""
    import xarray as xr

    P, m = 7, 2
    f = np.array([1.0, 2.0, 3.0, 2.5, 2.0, 3.0, 4.0]) * 1e3
    ds = xr.Dataset(
        {"mesh_frequency_hz": ("point", f),
         "stable": ("point", np.array([1, 1, 0, 0, 0, 1, 1], np.int8)),
         "converged": ("point", np.ones(P, bool)),
         "rms_force": (("point", "mesh"), np.random.default_rng(0).random((P, m))),
         "mean_torque": (("point", "mesh"), np.ones((P, m))),
         "separation": (("point", "mesh"), np.linspace(0, 0.2, P * m).reshape(P, m))},
        coords={"mesh": ["1.sp1", "1.rp1"], "stage": ("mesh", ["1", "1"]),
                "side": ("mesh", ["sun", "ring"]), "planet": ("mesh", [1, 1])},
        attrs={"reference_stage": "1"})
    branches = _figures.separation_branches(ds)
    assert [list(b.points) for b in branches] == [[0, 1, 2], [2, 3, 4], [4, 5, 6]]
    fig = _figures.separation_figure(ds)
    assert len(fig.axes) == 2  # one panel for the three branches, and the colour bar
    fig = _figures.response_figure(ds, reference=ds, points=ds.isel(point=[0, 6]), what="torque")
    assert len(fig.axes) == 1
