"""The stated discretisation rules: time samples (AFT) and solution harmonics (sweeps).

What they must achieve: RMS forces and fold frequencies change by
< 0.1% when the sample count doubles; RMS mesh forces change by < 0.5% when the
harmonics double. Each is checked here where it is hardest: with tooth separation
(samples) and at the low end of the paper's band (harmonics).
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import continuation as C
from gearjax._studies import harmonics as _harmonics
from gearjax._engine import hb as _hb
from gearjax._engine.responses import mesh_responses, static_mesh_forces
from gearjax._engine.results import RESULTS


def oscillator_folds(n_time):
    """Folds, and the RMS contact force on the impacting branch at Omega = 0.75, of the
    clearance oscillator (K = 15) with ``n_time`` samples (``None``: the rule)."""
    system = gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0], backlash=[1.0],
                                     f_mean=[0.1], f_cos=[[0.03]], f_sin=[[0.0]], forcing_mu=[1])
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=15, n_time=n_time))
    param = C.FrequencyParameter(problem=problem, omega_ref=jnp.asarray(1.0))
    settings = C.Settings(step=0.05, max_step=0.3, max_dlambda=0.02)
    y0 = gj.solve_hb(problem, 0.5).y
    b = jax.jit(lambda y: C.continue_compiled(param, y, 0.5, 1.5, settings, 400))(y0)
    ys, lams, folds, fold_lams, n, code = b.y, b.lam, b.fold, b.fold_lam, b.n_points, b.result
    n = int(n)
    assert bool(code == RESULTS.reached_end)
    f = C.distinct_folds(np.asarray(fold_lams[:n])[np.asarray(folds[:n])])
    # the upper (impacting) branch follows the last fold: re-solve at exactly 0.75 from
    # its first point past 0.75
    last_fold = int(np.flatnonzero(np.asarray(folds[:n]))[-1])
    i = last_fold + int(np.argmax(np.asarray(lams[last_fold:n]) > 0.75))
    sol = gj.solve_hb(problem, 0.75, ys[i])
    assert bool(sol.converged)
    rms = float(mesh_responses(problem, sol.X, 0.75, static_mesh_forces(system)).rms_force[0])
    return problem.n_time, np.sort(f), rms


def test_time_sample_rule_clearance_oscillator_folds():
    T, folds, rms = oscillator_folds(None)
    T2, folds2, rms2 = oscillator_folds(2 * T)
    assert T == 256 and T2 == 512  # 16 x 15 -> next power of two
    assert len(folds) == len(folds2) == 2
    np.testing.assert_allclose(folds, folds2, rtol=1e-3)
    assert rms == pytest.approx(rms2, rel=1e-3)
    assert rms > 0.1  # the impacting branch (the contact branch's is 0.03 / |1 - w^2 + i0.075|)


def rms_at(system, f_hz, K, n_time=None):
    """RMS mesh forces (N), every mesh, at stage-1 mesh frequency ``f_hz`` (paper: mu = 7)."""
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=K, n_time=n_time))
    omega = 2 * math.pi * f_hz / 7
    sol = jax.jit(gj.solve_hb)(problem, omega)
    assert bool(sol.converged)
    resp = mesh_responses(problem, sol.X, omega, static_mesh_forces(system))
    return problem.n_time, np.asarray(resp.rms_force), np.asarray(resp.separation)


def test_time_sample_rule_paper_with_separation(paper_system):
    # 2480 Hz with the example's 0.05 mm backlash: the stage-2 sun meshes lose contact
    # for about 2% of the period
    T, rms, sep = rms_at(paper_system, 2480.0, 32)
    T2, rms2, _ = rms_at(paper_system, 2480.0, 32, 2 * T)
    assert T == 512 and sep.max() > 0.01
    np.testing.assert_allclose(rms, rms2, rtol=1e-3)


@pytest.mark.parametrize("f_hz", [2000.0, 4800.0, 6000.0])
def test_harmonics_rule_doubling_changes_rms_by_less_than_half_a_percent(paper_system, f_hz):
    # 2000 Hz: K = 64, 4800 Hz: K = 48 (K = 32 would be off by 0.52%), 6000 Hz: K = 32
    linear = dataclasses.replace(paper_system, backlash=jnp.zeros_like(paper_system.backlash))
    K = _harmonics.harmonics_rule(f_hz / 7, _hb.highest_excitation(linear),
                                  cutoff_hz=_harmonics.response_cutoff_hz(linear))
    assert K == {2000.0: 64, 4800.0: 48, 6000.0: 32}[f_hz]
    _, rms, _ = rms_at(linear, f_hz, K)
    _, rms2, _ = rms_at(linear, f_hz, 2 * K)
    assert np.max(np.abs(rms - rms2) / rms2) < 5e-3


def test_harmonics_rule_with_tooth_separation(paper_system):
    # 4000 Hz with the 0.05 mm backlash: the stage-1 ring meshes separate for about 15%
    # of the period; the rule's K = 48 is 0.10% off K = 128 (K = 32: 2.8% off), and
    # doubling it must change the RMS forces by less than 0.5%
    K = _harmonics.harmonics_rule(4000.0 / 7, _hb.highest_excitation(paper_system),
                                  cutoff_hz=_harmonics.response_cutoff_hz(paper_system))
    assert K == 48
    _, rms, sep = rms_at(paper_system, 4000.0, K)
    _, rms2, sep2 = rms_at(paper_system, 4000.0, 2 * K)
    assert sep.max() > 0.1 and sep2.max() > 0.1
    assert np.max(np.abs(rms - rms2) / rms2) < 5e-3
