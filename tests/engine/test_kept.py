"""Programs kept between processes (``kept.kept_program``): loaded, not traced, in a
later process; the same values; every call the store cannot serve as plain ``jax.jit``."""

import dataclasses
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearjax as gj
from gearjax._engine import hb as _hb
from gearjax._engine import kept
from gearjax._engine import newton as _newton

pytestmark = pytest.mark.fresh_programs  # patches jax.export and the store's jitted


def oscillator(clearance=0.5):
    return gj.system_from_matrices([[1.0]], [[0.1]], [[0.0]], [[1.0]], [1.0],
                                   backlash=[clearance], f_mean=[0.1], f_cos=[[0.03]],
                                   f_sin=[[0.0]], forcing_mu=[1], mesh_mu=[1])


@pytest.fixture
def store(tmp_path, monkeypatch):
    """A fresh store (the compilation cache itself stays where it is)."""
    monkeypatch.setenv("GEARJAX_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv(kept.KEEP_ENV, raising=False)
    return tmp_path / "programs"


def problem_and_guess(tol=None):
    settings = _hb.HarmonicBalance(n_harmonics=5)
    if tol is not None:
        settings = dataclasses.replace(settings, rtol=tol)
    problem = _hb.hb_problem(oscillator(), settings)
    omega = jnp.asarray(0.8)
    return problem, omega, _hb.linear_guess(problem, omega)


def stored(store) -> set:
    return {f.name for f in store.glob("*.bin")}


def later_process(fun, monkeypatch, **kw):
    """``fun`` kept as a new process sees it (nothing in memory), with tracing and
    exporting made to fail: it can only load."""
    call = kept.kept_program(fun, **kw)

    def refuse(*a, **k):
        raise AssertionError("traced or exported in the later process")

    monkeypatch.setattr(jax.export, "export", refuse)
    monkeypatch.setattr(call.kept, "jitted", refuse)
    return call


def test_a_kept_program_is_loaded_not_traced_in_a_later_process(store, monkeypatch):
    problem, omega, y0 = problem_and_guess()
    reference = jax.jit(_newton.newton)(problem, omega, y0)
    before = stored(store)  # the linear guess is kept too
    first = kept.kept_program(_newton.newton)(problem, omega, y0)
    (name,) = stored(store) - before
    assert (store / name).read_bytes().startswith(kept.MAGIC)
    again = later_process(_newton.newton, monkeypatch)(problem, omega, y0)
    for sol in (first, again):
        assert type(sol) is type(reference) and sol.result == reference.result
        np.testing.assert_array_equal(sol.y, reference.y)
        np.testing.assert_array_equal(sol.stats["num_steps"], reference.stats["num_steps"])
    assert bool(again.converged)


def test_static_arguments_by_position_and_name(store, monkeypatch):
    problem, omega, y0 = problem_and_guess()
    settings = gj.ContinuationSettings(step=0.05)
    param = gj.FrequencyParameter(problem=problem, omega_ref=jnp.asarray(1.0))
    from gearjax._engine import continuation as _continuation

    ref = jax.jit(_continuation.start, static_argnums=(4,))(param, y0, 0.8, 1, settings)
    kept.kept_program(_continuation.start, static_argnums=(4,))(param, y0, 0.8, 1, settings)
    by_name = kept.kept_program(_continuation.start, static_argnums=(4,))(
        param, y0, 0.8, 1, settings=settings)  # static by name: another signature
    call = later_process(_continuation.start, monkeypatch, static_argnums=(4,))
    for state in (by_name, call(param, y0, 0.8, 1, settings),
                  call(param, y0, 0.8, 1, settings=settings)):
        np.testing.assert_array_equal(state.ty, ref.ty)
        np.testing.assert_array_equal(state.h, ref.h)


def test_a_static_value_is_part_of_the_key(store):
    call = kept.kept_program(_newton.newton)
    problems = [problem_and_guess(tol) for tol in (None, 1e-7)]
    big = _hb.hb_problem(oscillator(), _hb.HarmonicBalance(n_harmonics=6))
    problems.append((big, jnp.asarray(0.8), _hb.linear_guess(big, 0.8)))  # another shape
    before = stored(store)
    for args in problems:
        call(*args)
    assert len(stored(store) - before) == 3


def test_committed_or_fresh_arguments_one_compiled_program(store):
    """A kept program's outputs are committed to their device (jax.export's call), fresh
    arrays are not, and jax.jit compiles apart for each: fed both (here Newton from a
    guess that is another kept program's output, then from a fresh array), the program is
    compiled once, and gives what it gives from either."""
    problem, omega, _ = problem_and_guess()
    guess = kept.kept_program(_hb.linear_guess)(problem, omega)
    assert guess.committed  # the exported program's output
    call = kept.kept_program(_newton.newton)
    from_output = call(problem, omega, guess)
    from_fresh = call(problem, omega, jnp.asarray(np.asarray(guess)))
    np.testing.assert_array_equal(from_output.y, from_fresh.y)
    (entry,) = call.kept.entries.values()
    assert entry.call._cache_size() == 1


def test_calls_in_a_trace_and_code_outside_gearjax_run_as_jit(store):
    problem, omega, y0 = problem_and_guess()
    call = kept.kept_program(_newton.newton)
    omegas = jnp.asarray([0.7, 0.8])
    ys = jax.vmap(lambda w: call(problem, w, y0).y)(omegas)
    ref = jax.vmap(lambda w: jax.jit(_newton.newton)(problem, w, y0).y)(omegas)
    np.testing.assert_array_equal(ys, ref)
    before = stored(store)  # only the linear guess's: vmapped calls are traced

    def scaled(x, factor):  # the caller's own code may change between runs: not kept
        return factor * x

    out = kept.kept_program(scaled)(jnp.arange(3.0), 2.0)
    np.testing.assert_array_equal(out, [0.0, 2.0, 4.0])
    lam = kept.kept_program(lambda x: x + 1)(jnp.zeros(2))
    np.testing.assert_array_equal(lam, [1.0, 1.0])
    assert stored(store) == before


def test_stable_forms_tell_values_apart():
    a = np.zeros(10_000)
    b = a.copy()
    b[5000] = 1e-300  # the printed forms of both are the same
    assert kept._canon(a) != kept._canon(b)
    assert len({kept._canon(v) for v in (1, 1.0, True, "1", (1,), [1])}) == 6
    assert kept._canon(gj.ContinuationSettings(step=0.05)) != kept._canon(
        gj.ContinuationSettings(step=0.05000000000000001))
    assert kept._canon(kept.kept_program) == kept._canon(kept.kept_program)
    for unstable in (lambda x: x, test_stable_forms_tell_values_apart, object()):
        with pytest.raises(kept.Unstable):
            kept._canon(unstable)


def test_a_damaged_program_is_exported_again(store):
    problem, omega, y0 = problem_and_guess()
    before = stored(store)
    first = kept.kept_program(_newton.newton)(problem, omega, y0)
    (name,) = stored(store) - before
    (store / name).write_bytes(kept.MAGIC + b"\x05\x00")  # a truncated write
    again = kept.kept_program(_newton.newton)(problem, omega, y0)
    np.testing.assert_array_equal(again.y, first.y)
    assert kept._load(store / name) is not None


@pytest.mark.parametrize("env", [("GEARJAX_KEEP_PROGRAMS", "0"), ("GEARJAX_CACHE_DIR", "0")])
def test_the_store_switched_off(store, monkeypatch, env):
    monkeypatch.setenv(*env)
    problem, omega, y0 = problem_and_guess()
    sol = kept.kept_program(_newton.newton)(problem, omega, y0)
    assert bool(sol.converged) and not store.exists()


def test_the_store_drops_the_least_recently_used_beyond_its_size(store, monkeypatch, tmp_path):
    problem, omega, y0 = problem_and_guess()
    before = stored(store)
    kept.kept_program(_newton.newton)(problem, omega, y0)
    (name,) = stored(store) - before
    size = (store / name).stat().st_size
    other = tmp_path / "other"
    monkeypatch.setenv("GEARJAX_CACHE_DIR", str(other))
    (other / "programs").mkdir(parents=True)
    for i in range(4):  # four programs as large, used long ago, the first the longest
        f = other / "programs" / f"old{i}.bin"
        f.write_bytes(b"x" * size)
        os.utime(f, (1000 + i, 1000 + i))
    monkeypatch.setattr(kept, "STORE_MAX_BYTES", int(4.5 * size))
    kept.kept_program(_newton.newton)(problem, omega, y0)  # five: down to 3 3/8 of them
    left = sorted(f.name for f in (other / "programs").glob("*.bin"))
    assert left == sorted(["old2.bin", "old3.bin", name])
