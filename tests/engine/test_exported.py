"""Programs kept whole between processes (gearjax/_engine/exported.py): the same results as
``jax.jit``, a kept program used by a later process (a fresh wrapper) without exporting
again, and a program kept only under a key that states everything it depends on."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gearjax._engine import aft as _aft
from gearjax._engine import exported as _exported


@pytest.fixture
def directory(tmp_path, monkeypatch):
    """A fresh compilation cache directory; the kept programs go beside it."""
    monkeypatch.setenv("GEARJAX_CACHE_DIR", str(tmp_path / "jax"))
    return tmp_path / "exported"


def coefficients(K=5, n=3):
    return jnp.asarray(np.random.default_rng(0).normal(size=(2 * K + 1, n)))


def test_a_kept_program_serves_a_later_process_with_the_same_result(directory, monkeypatch):
    X = coefficients()
    expected = _aft.synthesis(X, 16)
    first = _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))
    np.testing.assert_array_equal(np.asarray(first(X, 16)), np.asarray(expected))
    (kept,) = directory.glob("*.bin")
    # a later process: a fresh wrapper, which must load the program, not export it again
    monkeypatch.setattr(jax.export, "export", lambda *a, **k: pytest.fail("exported again"))
    later = _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))
    np.testing.assert_array_equal(np.asarray(later(X, 16)), np.asarray(expected))
    np.testing.assert_array_equal(np.asarray(later(2 * X, 16)), 2 * np.asarray(expected))
    assert list(directory.glob("*.bin")) == [kept]


def test_every_static_value_shape_type_and_source_is_in_the_key(directory, monkeypatch):
    wrapped = _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))
    X = coefficients()
    wrapped(X, 16)
    wrapped(X, 32)  # another static value
    wrapped(coefficients(K=6), 32)  # another shape
    wrapped(X.astype(jnp.float32), 16)  # another type
    assert len(list(directory.glob("*.bin"))) == 4
    # a changed source file: nothing kept before is used
    monkeypatch.setattr(_exported, "_sources_digest", lambda: b"edited")
    _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))(X, 16)
    assert len(list(directory.glob("*.bin"))) == 5


def user_function(x):
    return 2 * x


def test_what_cannot_be_keyed_by_content_runs_jitted_and_keeps_nothing(directory):
    """A lambda, a function of the caller's own module (kept by name, its code not in the
    key), traced arguments, a switched-off cache: the plain jitted function."""
    xs = jnp.arange(4.0)
    mapped = _exported.persistent_jit(jax.lax.map, static_argnums=(0,))
    np.testing.assert_array_equal(np.asarray(mapped(lambda x: 3 * x, xs)), 3 * np.arange(4.0))
    np.testing.assert_array_equal(np.asarray(mapped(user_function, xs)), 2 * np.arange(4.0))
    wrapped = _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))
    X = coefficients()
    grad = jax.grad(lambda X: jnp.sum(wrapped(X, 16) ** 2))(X)
    np.testing.assert_allclose(np.asarray(grad), np.asarray(
        jax.grad(lambda X: jnp.sum(_aft.synthesis(X, 16) ** 2))(X)), rtol=1e-12)
    assert not list(directory.glob("*.bin"))


def test_an_unreadable_kept_program_is_replaced(directory):
    X = coefficients()
    _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))(X, 16)
    (kept,) = directory.glob("*.bin")
    kept.write_bytes(b"not a program")
    later = _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))
    np.testing.assert_array_equal(np.asarray(later(X, 16)), np.asarray(_aft.synthesis(X, 16)))
    assert kept.read_bytes() != b"not a program"


def test_off_when_the_compilation_cache_is_off(tmp_path, monkeypatch):
    monkeypatch.setenv("GEARJAX_CACHE_DIR", "0")
    assert _exported.directory() is None
    X = coefficients()
    out = _exported.persistent_jit(_aft.synthesis, static_argnums=(1,))(X, 16)
    np.testing.assert_array_equal(np.asarray(out), np.asarray(_aft.synthesis(X, 16)))
