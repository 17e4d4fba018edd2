"""Functions compiled as one program each.

An operation called outside a trace is a compiled program of its own, traced, lowered
and loaded from the compilation cache in every process; a function called several times
inside one trace is traced each time. :func:`one_program` makes a function one program,
traced once per argument shapes (and, inside another trace, once however often it is
called there), and kept between processes (:mod:`~gearjax._engine.kept`).
"""

from __future__ import annotations

import functools
import numbers

import jax.numpy as jnp

from .kept import kept_program


def one_program(fun):
    """``fun`` compiled as one program (``equinox.filter_jit``), with its arguments that
    are real numbers (Python or NumPy scalars, not ``bool``) passed as float arrays:
    under ``filter_jit`` a number is static, one compilation per value. Other
    arguments as ``filter_jit`` takes them (arrays traced, the rest static). Called
    outside any trace, the program is kept between processes
    (:func:`~gearjax._engine.kept.kept_program`)."""
    jitted = kept_program(fun, filtered=True)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        return jitted(*map(_value, args), **{k: _value(v) for k, v in kwargs.items()})

    return call


def _value(arg):
    """A real number as a float array; anything else as it is."""
    if isinstance(arg, numbers.Real) and not isinstance(arg, bool):
        return jnp.asarray(arg, dtype=float)
    return arg


def float_arrays(*values):
    """Each of ``values`` as a float array, ``None`` kept: a Python number would be
    static under ``filter_jit`` (one compilation per value)."""
    return tuple(None if v is None else jnp.asarray(v, dtype=float) for v in values)
