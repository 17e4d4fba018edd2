"""Functions compiled as one program each (``programs.one_program``)."""

import jax
import jax.numpy as jnp
import numpy as np

from gearjax._engine.programs import one_program


def test_a_number_is_a_value_and_a_call_in_a_trace_reuses_the_trace():
    traces = []

    @one_program
    def scaled(x, omega, negate=False):
        traces.append(x.shape)
        return -omega * x if negate else omega * x

    x = jnp.arange(3.0)
    # Python, NumPy and keyword numbers: values of one program, not one program each
    for omega in (1.0, 2.5, np.float64(-3.0), 4):
        np.testing.assert_array_equal(scaled(x, omega), omega * np.arange(3.0))
    assert len(traces) == 1
    for omega in (0.5, 1.5):
        np.testing.assert_array_equal(scaled(x, omega=omega), omega * np.arange(3.0))
    seen = len(traces)  # at most one more: the keyword call's signature
    assert seen <= 2
    # a bool stays static: it selects the branch in Python
    np.testing.assert_array_equal(scaled(x, 2.0, True), -2.0 * np.arange(3.0))
    assert len(traces) == seen + 1
    # called twice inside another trace with the shapes seen: traced no more
    both = jax.jit(lambda v: scaled(v, 1.0) + scaled(2 * v, 3.0))(x)
    np.testing.assert_array_equal(both, 7.0 * np.arange(3.0))
    assert len(traces) == seen + 1
    scaled(jnp.ones(4), 1.0)  # another shape: another trace
    assert traces[-1] == (4,)

