"""Sensitivities by implicit differentiation against finite differences, refusal at folds,
and the ``sensitivity`` command.

Small harmonics (K = 8, with one stiffness harmonic so that K holds the excitation) keep
this fast: the check is self-consistency of the harmonic balance at that K (implicit
derivative = derivative of the re-solved response)."""

import json
import pathlib

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from sensitivity_differences import finite_differences
from gearjax._engine import hb as _hb
from gearjax import _cli
from gearjax._studies import sensitivity as S
from gearjax._engine.results import RESULTS

K = 8
AT = 3000.0  # Hz: contact is kept on every mesh at this K, with backlash too
PATHS = ("1.mesh_stiffness.sun", "2.inertia.sun", "1.inertia.planet", "2.sun_ring_phase_deg",
         "2.planet_angles_deg.2", "gears.first.input_torque", "2.half_backlash.sun")


@pytest.fixture(scope="module")
def train(paper_train_h1):
    """The paper case with one stiffness harmonic: K = 8 holds its excitation."""
    return paper_train_h1


@pytest.fixture(scope="module")
def backlash(train):
    return S.sensitivity(train, at_hz=AT, paths=PATHS, harmonics=K)


@pytest.fixture(scope="module")
def linear(train):
    return S.sensitivity(train, at_hz=AT, paths=PATHS, harmonics=K, linear=True)


@pytest.mark.parametrize("case", [pytest.param("backlash", marks=pytest.mark.slow),
                                  "linear"])
def test_implicit_gradient_matches_finite_differences(train, case, request):
    result = request.getfixturevalue(case)
    assert result.ok, result.message
    assert result.stable and result.fold_distance > S.FOLD_TOL
    fd, noise = finite_differences(train, result, case == "linear")
    d = result.derivative
    err = np.abs(d - fd)
    assert np.all(err <= 1e-5 * np.abs(fd) + noise), dict(zip(result.paths, zip(d, fd)))
    # the coupling through the solution matters: the explicit part alone is wrong
    k = result.paths.index("1.inertia.planet")
    assert abs(result.partial[k] - d[k]) > 0.1 * abs(d[k])


def test_linear_zeros_and_scaling(linear, backlash):
    k = linear.paths.index("2.half_backlash.sun")
    assert linear.derivative[k] == 0.0  # --linear drops the backlash: exactly no effect
    # contact kept: the backlash shifts the mean deflections, and only the 1e2 N m/rad
    # housing springs of the free members resist that shift: a tiny, non-zero effect
    assert 0 < abs(backlash.normalised[k]) < 1e-3
    # without backlash the alternating force is proportional to the load (no TE, ripple)
    t = linear.paths.index("gears.first.input_torque")
    assert linear.normalised[t] == pytest.approx(1.0, abs=1e-9)
    assert abs(backlash.normalised[t] - 1.0) < 1e-2
    # angles are per degree: the sun-ring phase at 0 deg has no relative sensitivity
    j = linear.paths.index("2.sun_ring_phase_deg")
    assert np.isnan(linear.normalised[j]) and linear.derivative[j] != 0


# ---------------------------------------------------------------- clearance oscillator


class Oscillator(eqx.Module):
    """``x'' + 0.1 x' + g(x; b) = 0.1 + a cos(Omega t)``, ``theta = (b, a)``."""

    def __call__(self, theta):
        return gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0],
                                       backlash=[theta[0]], f_mean=[0.1], f_cos=[[theta[1]]],
                                       f_sin=[[0.0]], forcing_mu=[1])


OSC_SETTINGS = _hb.HarmonicBalance(n_harmonics=15, n_time=256)
OSC_THETA = jnp.array([1.0, 0.03])
FOLD = 0.851968  # the lower branch folds back here (tests/test_continuation.py: 0.852)


def oscillator_point(omega):
    family = Oscillator()
    problem = _hb.hb_problem(family(OSC_THETA), OSC_SETTINGS)
    sol = S.solve_at(family, OSC_THETA, OSC_SETTINGS, jnp.asarray(omega))
    assert bool(sol.converged)
    grad = S.implicit_gradient(family, OSC_THETA, OSC_SETTINGS, sol.y, jnp.asarray(omega),
                               S.MeshResponse(field="rms_force", mesh=0))
    return problem, sol, grad


def test_oscillator_backlash_derivative_is_zero_in_contact():
    # in one-sided contact with no spring to ground, x -> x + db leaves every force
    # unchanged: the backlash has no effect on the force at all
    _, _, grad = oscillator_point(0.5)
    d_b, d_a = np.asarray(grad.gradient)
    assert abs(d_b) <= 1e-12 * abs(d_a)
    # linear there: rms = |a| / |1 - Omega^2 + 0.1 i Omega| / sqrt(2)
    assert d_a == pytest.approx(1 / abs(1 - 0.25 + 0.05j) / np.sqrt(2), rel=1e-9)


def test_refused_at_a_fold_accepted_away():
    problem, sol, _ = oscillator_point(0.5)
    stable, distance = S.point_status(problem, sol.X, jnp.asarray(0.5))
    S.check_point(stable, distance, "Omega = 0.5")  # far from any fold: accepted
    omega = FOLD - 1e-6
    problem, sol, grad = oscillator_point(omega)
    stable, distance = S.point_status(problem, sol.X, jnp.asarray(omega))
    assert float(distance) < S.FOLD_TOL
    assert abs(float(grad.gradient[1])) > 30  # what would have been returned
    with pytest.raises(S.SensitivityRefused, match=r"Omega = 0\.851967.*fold") as e:
        S.check_point(stable, distance, f"Omega = {omega:.6f}")
    assert e.value.result == "fold"


# ------------------------------------------------------------------------------- CLI


def run(capsys, *argv):
    code = _cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_json_ranked(capsys, backlash, paper_toml_h1):
    code, out, _ = run(capsys, "sensitivity", str(paper_toml_h1), "--at", str(AT),
                       "--harmonics", str(K),
                       "--vary", *PATHS, "--json")
    assert code == 0
    data = json.loads(out)
    for key in ("gear", "reference_stage", "mesh_frequency_hz", "response", "unit", "mesh",
                "value", "result", "converged", "stable", "fold_distance", "derivatives",
                "mesh_values", "warnings"):
        assert key in data
    assert data["result"] == "ok" and data["mesh"] == backlash.mesh
    rows = data["derivatives"]
    assert sorted(r["path"] for r in rows) == sorted(PATHS)
    norm = [abs(r["normalised"]) for r in rows if r["normalised"] is not None]
    assert norm == sorted(norm, reverse=True)
    # ranked by the relative change over each parameter's step, whatever an angle's
    # origin: the angles' elasticities, which depend on it, are not given
    rel = [abs(r["relative"]) for r in rows]
    assert rel == sorted(rel, reverse=True)
    by_path = {r["path"]: r for r in rows}
    for path in ("2.sun_ring_phase_deg", "2.planet_angles_deg.2"):
        assert by_path[path]["normalised"] is None and "origin" in by_path[path]["reason"]
    for k, p in enumerate(backlash.paths):
        assert by_path[p]["derivative"] == pytest.approx(backlash.derivative[k], rel=1e-9)
    assert by_path["2.planet_angles_deg.2"]["derivative_unit"] == "N per deg"
    # the point's truncation checked as a sweep checks a segment's; the user's K kept and
    # its estimate warned about where it misses the target
    (check,) = data["truncation"]
    assert check["K"] == K and check["K_check"] == 2 * K and data["harmonics"] == K
    assert data["truncation_target"] == 0.005
    warned = [w for w in data["warnings"] if w.startswith("sensitivity: ")]
    assert bool(warned) == (check["change"] > 0.005)
    assert all("omit --harmonics to let sensitivity choose K" in w for w in warned)


@pytest.mark.parametrize("argv, field", [
    (["--vary", "1.teeth"], "--vary"),
    (["--vary", "1.mesh_stiffness.sun", "1.mesh_stiffness.sun"], "--vary"),
    (["--mesh", "9.sp1"], "--mesh"),
    (["--at=-5"], "--at"),
    (["--harmonics", "0"], "--harmonics"),
])
def test_cli_bad_input(capsys, argv, field):
    code, out, err = run(capsys, "sensitivity", "--at", "3000", *argv, "--json")
    assert code == 2 and out == ""
    errors = [line for line in err.splitlines() if not line.startswith("warning:")]
    assert len(errors) == 1 and field in errors[0] and "Traceback" not in err


def test_cli_not_converged(capsys, monkeypatch, paper_toml_h1):
    solve = S.GearPoint.solve

    def failing(self, f_hz, X0=None):
        sol = solve(self, f_hz, X0)
        return eqx.tree_at(lambda s: s.result, sol, RESULTS.nonlinear_max_steps_reached)

    monkeypatch.setattr(S.GearPoint, "solve", failing)
    code, out, err = run(capsys, "sensitivity", str(paper_toml_h1), "--at", str(AT),
                         "--harmonics", str(K), "--vary", *PATHS, "--json")
    assert code == 3
    data = json.loads(out)  # no NaN: json.loads would accept it, so check the text
    assert "NaN" not in out and data["value"] is None
    assert data["result"] == "not_converged" and data["derivatives"] is None
    assert "3000 Hz" in data["reason"] and "did not converge" in err


# ------------------------------------------------------------------- stage phase


@pytest.mark.slow
def test_stage_phase_derivative_resolved_and_a_time_shift():
    # A stage phase shifts one stage's excitation in time. The stage-1 meshes vary at
    # 7 h and the stage-2 meshes at 8 h times the base frequency, so the two stages'
    # responses only meet in combination tones; K = 8 keeps h = 1 of each and the
    # derivative is round-off (~1e-13), K = 32 resolves every stiffness harmonic
    # (H = 4: orders up to 32) and the sweep's rule gives K = 48 at 3000 Hz.
    train = gj.load_train(gj.bundled_example_path())  # H = 4
    paths = ("2.stage_phase_deg", "1.stage_phase_deg")
    result = S.sensitivity(train, at_hz=AT, paths=paths, harmonics=32, linear=True)
    assert result.ok, result.message
    d2, d1 = result.derivative
    assert abs(d2) > 1e-6 * result.value  # N per deg: non-zero
    fd, noise = finite_differences(train, result, linear=True)
    assert np.all(np.abs(result.derivative - fd) <= 1e-5 * np.abs(fd) + noise), (result.derivative,
                                                                               fd)
    # a common time shift t changes Gamma_n by w_n t and no RMS: w_1 dR/dG_1 + w_2 dR/dG_2 = 0
    mu = gj.kinematics(train, "first").mu
    assert mu[0] * d1 + mu[1] * d2 == pytest.approx(0.0, abs=1e-8 * abs(mu[1] * d2))


@pytest.mark.slow
def test_default_paths_are_those_of_the_gear(train):
    every = gj.continuous_paths(train)
    first = gj.continuous_paths(train, "first")
    assert "gears.first.input_torque" in first and "gears.second.input_torque" not in first
    assert "couplings.lockup.stiffness" in every and "couplings.lockup.stiffness" not in first
    assert "1.half_backlash.sun" in first
    assert "1.half_backlash.sun" not in gj.continuous_paths(train, "first", linear=True)
    third = gj.continuous_paths(train, "third")  # nothing turns: no phasing, no brake
    assert "couplings.lockup.stiffness" in third and "housing.braked" not in third
    assert not any(p.split(".")[1] in ("planet_angles_deg", "stage_phase_deg", "contact_ratio")
                   for p in third if p[0].isdigit())
    # every path left out has exactly no effect on the assembled system (jacfwd)
    import jax

    family = S.GearFamily.of(train, every, "first", linear=True)
    leaves = lambda th: jax.tree_util.tree_leaves(  # noqa: E731
        eqx.filter(family(th), eqx.is_inexact_array))
    J = jax.jacfwd(lambda th: jnp.concatenate([x.reshape(-1) for x in leaves(th)]))(
        family.theta())
    moves = np.any(np.asarray(J) != 0, axis=0)
    linear = gj.continuous_paths(train, "first", linear=True)
    assert [p for p, m in zip(every, moves) if m] == linear
    result = S.sensitivity(train, "first", AT, harmonics=K, linear=True)
    assert result.paths == tuple(linear)


# ------------------------------------------------- a train with an idling set on a quill

IDLER = pathlib.Path(__file__).parent.parent / "data" / "two_stage_idler.toml"
IDLER_PATHS = ("drive.planet_angles_deg.2", "drive.planet_angles_deg.3",
               "drive.sun_ring_phase_deg", "drive.mesh_stiffness.sun",
               "couplings.quill.stiffness")


@pytest.fixture(scope="module")
def idler():
    return gj.load_train(IDLER)


def test_linear_refusal_names_the_near_rigid_mode(capsys, idler):
    """A linear run has no fold: a multiplier near +1 comes from the idling set swinging
    on its quill shaft (38 Hz, undamped: it strains no mesh), which the refusal names."""
    code, out, err = run(capsys, "sensitivity", str(IDLER), "--at", "6000", "--linear",
                         "--harmonics", "2", "--vary", *IDLER_PATHS, "--json")
    assert code == 3
    data = json.loads(out)
    assert data["result"] == "lightly_damped_mode" and data["derivatives"] is None
    mode = data["mode"]
    # the quill mode of the modal analysis (the lowest elastic mode), near-rigid
    elastic = [m.hz for m in gj.modes(gj.assemble(idler)).modes if m.cls == "elastic"]
    assert mode["hz"] == pytest.approx(elastic[0], rel=1e-9) and mode["harmonic"] == 0
    assert mode["damping_ratio"] < 1e-6 and mode["share"] > 0.99
    # an undamped mode of frequency f over one period T: |exp(2 pi i f T) - 1|
    assert data["fold_distance"] == pytest.approx(
        abs(np.exp(2j * np.pi * mode["hz"] / 6000) - 1), rel=1e-3)
    said = [e for e in err.splitlines() if e.startswith("sensitivity: ")]
    assert said[0].startswith("sensitivity: solving gear ") and "6000 Hz (K = " in said[0]
    assert said[-1].startswith("sensitivity: done in ")
    (line,) = [e for e in err.splitlines() if not e.startswith(("warning:", "sensitivity: "))]
    assert line.startswith("gearjax: the linear response at 6000 Hz has no fold, but a "
                           f"lightly damped near-rigid mode ({mode['hz']:.4g} Hz, damping "
                           "ratio ")
    assert "fold of the response" not in line


def test_angles_ranked_by_their_step_in_absolute_units(idler):
    """Angles are ranked by the change over one assembly slot (planet angles) or one
    mesh cycle (the sun-ring phase), beside the others' elasticities."""
    r = S.sensitivity(idler, at_hz=2000.0, paths=IDLER_PATHS, harmonics=2, linear=True)
    assert r.ok, r.message
    slot = 360 / (28 + 80)
    np.testing.assert_allclose(r.steps, [slot, slot, 360.0, 3.0e8, 1.6e3])
    np.testing.assert_allclose(r.relative, r.derivative * r.steps / r.value, rtol=1e-12)
    assert np.all(np.isnan(r.normalised[:3])) and np.all(np.isfinite(r.normalised[3:]))
    np.testing.assert_allclose(r.relative[3:], r.normalised[3:], rtol=1e-12)
    rel = np.abs(r.relative)
    assert [rel[k] for k in r.ranking()] == sorted(rel, reverse=True)
    data = S.sensitivity_json(r)
    assert "one assembly slot" in data["ranking"]
    rows = {row["path"]: row for row in data["derivatives"]}
    row = rows["drive.planet_angles_deg.3"]
    assert row["derivative_unit"] == "N per deg" and row["unit"] == "deg"
    assert row["step"] == pytest.approx(slot) and row["step_rule"].startswith(
        "one assembly slot, 360/(28 + 80)")
    assert rows["drive.sun_ring_phase_deg"]["step_rule"] == "one mesh cycle, 360 deg"
    assert rows["drive.mesh_stiffness.sun"]["step_rule"] is None


@pytest.mark.slow
def test_a_point_whose_truncation_misses_the_target_is_solved_again_with_more(monkeypatch):
    """The five-planet helicopter stage at 533 Hz (its 6th harmonic on the 3.2 kHz
    in-phase mode), linear, starting from K = 4 as if the rule had chosen it: the check
    raises K until the estimate meets the target (K = 4 misses by 87%), and the
    derivatives are those of the kept K. Slow (12 s warm, more cold, on 2 cores): four
    orders of this train are solved, which no other test builds."""
    from gearjax._studies import harmonics as _harmonics

    monkeypatch.setattr(_harmonics, "harmonics_rule", lambda *a, **k: 4)
    heli = gj.load_train(pathlib.Path(__file__).parent.parent / "data"
                         / "helicopter_five_planets.toml")
    r = S.sensitivity(heli, "flight", 533.0, linear=True, paths=["main.mesh_stiffness.sun"])
    first, *_, last = r.truncation
    assert (first["K"], first["K_check"]) == (4, 8) and first["change"] > 0.5
    assert last["change"] <= _harmonics.TRUNCATION_TARGET and last["K"] == r.harmonics
    assert r.harmonics > 4 and r.ok and np.all(np.isfinite(r.derivative))
