"""TOML paths to train leaves: lookup, replacement, listing, errors, gradients."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._gear.paths import leaf_selector


@pytest.fixture(scope="module")
def paper(paper_train):
    """The bundled paper case (conftest's ``paper_train``)."""
    return paper_train


def test_values_match_the_file(paper):
    expected = {
        "1.inertia.sun": 1.360e-4,
        "2.inertia.planet": 4.068e-5,
        "2.planet_mass": 0.350,
        "1.mesh_stiffness.ring": 5.1e8,
        "1.contact_ratio.sun": 1.25,
        "1.half_backlash.sun": 5.0e-5,
        "1.mesh_damping_ratio": 0.04,
        "1.module_mm": 1.5,
        "1.pressure_angle_deg": 21.3,
        "1.sun_ring_phase_deg": 0.0,
        "2.stage_phase_deg": 0.0,
        "1.planet_angles_deg.2": 90.0,  # planet 2, 1-based
        "2.planet_angles_deg.4": 270.0,
        "housing.braked": 1e10,
        "housing.free": 1e2,
        "couplings.0.stiffness": 1e8,
        "couplings.1.stiffness": 1e8,
        "couplings.lockup.stiffness": 1e8,
        "couplings.2.stiffness": 1e8,  # the lock-up clutch by position
        "gears.first.input_torque": 750.0,
        "gears.first.drag_torque": 0.0,
    }
    for path, value in expected.items():
        got = gj.get_path(paper, path)
        assert got.shape == ()
        assert float(got) == value, path


def test_every_listed_path_round_trips(paper):
    paths = gj.continuous_paths(paper)
    assert len(paths) == len(set(paths))
    assert "1.inertia.sun" in paths and "couplings.lockup.stiffness" in paths
    assert "1.planet_angles_deg.1" not in paths and "1.planet_angles_deg.4" in paths
    assert "1.carrier_radius_mm" not in paths  # not set in the file
    before = {p: float(gj.get_path(paper, p)) for p in paths}
    for path in paths:
        new = before[path] * 1.5 + 0.25
        train = gj.set_path(paper, path, new)
        assert float(gj.get_path(train, path)) == new
        changed = [p for p in paths if float(gj.get_path(train, p)) != before[p]]
        assert changed == [path]
        assert float(gj.get_path(paper, path)) == before[path]  # the original is untouched


def test_set_path_keeps_structure_and_file_round_trip(paper, tmp_path):
    train = gj.set_path(paper, "2.planet_angles_deg.3", 181.0)
    train = gj.set_path(train, "couplings.lockup.stiffness", 2.5e8)
    train = gj.set_path(train, "1.inertia.carrier", 3e-4)
    assert jax.tree_util.tree_structure(train) == jax.tree_util.tree_structure(paper)
    np.testing.assert_array_equal(train.stages[1].planet_angles_deg, [0.0, 90.0, 181.0, 270.0])
    path = tmp_path / "t.toml"
    gj.save_train(train, path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        back = gj.load_train(path)
    for p in ("2.planet_angles_deg.3", "couplings.lockup.stiffness", "couplings.2.stiffness",
              "1.inertia.carrier"):
        assert float(gj.get_path(back, p)) == float(gj.get_path(train, p))


def test_aliases_resolve_to_one_leaf(paper):
    assert leaf_selector(paper, "couplings.2.stiffness").path == "couplings.lockup.stiffness"
    train = gj.set_path(paper, "couplings.2.stiffness", 7.0)
    assert float(gj.get_path(train, "couplings.lockup.stiffness")) == 7.0


def test_carrier_radius_is_a_path_when_set(paper):
    text = gj.bundled_example_path().read_text().replace(
        'module_mm = 1.5\n', 'module_mm = 1.5\ncarrier_radius_mm = 43.5\n', 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        train = gj.loads_train(text)
    assert "1.carrier_radius_mm" in gj.continuous_paths(train)
    assert float(gj.get_path(train, "1.carrier_radius_mm")) == 43.5


@pytest.mark.parametrize(
    "path, rule",
    [
        ("1.teeth.sun", "tooth counts are integers"),
        ("1.inertia.moon", "1.inertia has no 'moon'; it has sun, ring, carrier, planet"),
        ("7.inertia.sun", "no stage or section '7'; a path starts with a stage id (1, 2)"),
        ("1.planet_angles_deg.1", "planet 1 is the reference"),
        ("1.planet_angles_deg.5", "stage '1' has 4 planets"),
        ("1.planet_angles_deg[2]", "not with brackets"),
        ("1.planet_angles_deg", "name one planet"),
        ("1.carrier_radius_mm", "does not set carrier_radius_mm"),
        ("1.module_mm.x", "is one number"),
        ("1.transmission_error.sun", "table of harmonics"),
        ("1.nonsense", "stage '1' has no key 'nonsense'; continuous keys of a stage are"),
        ("housing.medium", "housing.braked and housing.free"),
        ("couplings.shaft.stiffness", "no coupling 'shaft'; couplings.ID.KEY or"),
        ("couplings.3.stiffness", "no coupling '3'"),
        ("couplings.0.damping", "coupling '1.carrier-2.ring' has no damper; set damping"),
        ("couplings.0.mass", "a coupling's parameters are stiffness, and damping or"),
        ("gears.first.input", "continuous gear keys are input_torque, drag_torque"),
        ("gears.tenth.input_torque", "no gear 'tenth'"),
        ("", "a TOML path such as"),
    ],
)
def test_bad_paths_are_refused(paper, path, rule):
    for call in (lambda: gj.get_path(paper, path), lambda: gj.set_path(paper, path, 1.0)):
        with pytest.raises(gj.TrainError) as info:
            call()
        message = str(info.value)
        assert "\n" not in message
        assert message.startswith(f"argument path = {path!r}: ")
        assert rule in message


def test_message_names_the_argument(paper):
    with pytest.raises(gj.TrainError, match=r"argument vary = .1.teeth.sun.: "):
        gj.get_path(paper, "1.teeth.sun", argument="vary")


def test_set_path_needs_a_scalar(paper):
    with pytest.raises(ValueError, match="scalar"):
        gj.set_path(paper, "1.inertia.sun", jnp.ones(2))


def _elastic_sum(train):
    system = gj.assemble(train)
    lam = gj.generalized_eigvals(system.mean_stiffness(), system.M)
    return jnp.sum(jnp.sqrt(lam[1:13])) / (2 * jnp.pi)  # the 12 elastic modes (Hz)


def test_gradient_through_set_path(paper):
    paths = ("1.mesh_stiffness.sun", "2.inertia.planet")
    p0 = jnp.array([float(gj.get_path(paper, p)) for p in paths])

    def f(p):
        train = paper
        for path, value in zip(paths, p):
            train = gj.set_path(train, path, value)
        return _elastic_sum(train)

    value_and_grad = jax.jit(jax.value_and_grad(f))
    _, grad = value_and_grad(p0)
    assert np.all(np.isfinite(grad)) and np.all(grad != 0.0)
    for j in range(len(paths)):
        h = 1e-4 * p0[j]
        fd = (value_and_grad(p0.at[j].add(h))[0] - value_and_grad(p0.at[j].add(-h))[0]) / (2 * h)
        assert float(grad[j]) == pytest.approx(float(fd), rel=1e-6)


def test_set_path_under_jit_and_vmap(paper):
    get = jax.jit(lambda v: gj.get_path(gj.set_path(paper, "1.planet_angles_deg.3", v),
                                        "1.planet_angles_deg.3"))
    assert float(get(175.0)) == 175.0
    values = jnp.array([1e-4, 2e-4, 3e-4])
    out = jax.vmap(lambda v: gj.get_path(gj.set_path(paper, "2.inertia.sun", v),
                                         "2.inertia.sun"))(values)
    np.testing.assert_array_equal(out, values)
