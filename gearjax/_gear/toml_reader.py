"""Typed access to parsed TOML values that fails with one line naming the file, the
field, the value and the rule (``_errors.fail``)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._errors import fail
from .train import SunRing


class TomlReader:
    """Typed access to raw TOML values, failing with file, field, value and rule."""

    _MISSING = object()

    def __init__(self, source: str | None):
        self.source = source

    def fail(self, field: str, value, rule: str):
        return fail(self.source, field, value, rule)

    def table(self, value, field: str) -> None:
        if not isinstance(value, dict):
            raise self.fail(field, value, "must be a table")

    def keys(self, raw: dict, allowed: set[str], field: str) -> None:
        """Refuse a key of ``raw`` not in ``allowed`` (``field``: the table, ``""`` for the
        file's top level)."""
        for key in raw:
            if key not in allowed:
                raise self.fail(f"{field} key" if field else "key", key,
                                f"unknown key; known keys are {', '.join(sorted(allowed))}")

    def sub(self, raw: dict, key: str, field: str, keys: set[str]) -> dict:
        value = raw.get(key, self._MISSING)
        if value is self._MISSING:
            raise self.fail(field, None, "is required")
        self.table(value, field)
        self.keys(value, keys, field)
        return value

    def _get(self, raw: dict, key: str, field: str, default):
        value = raw.get(key, self._MISSING)
        if value is self._MISSING:
            if default is self._MISSING:
                raise self.fail(field, None, "is required")
            return default
        return value

    def number(self, raw, key, field, *, default=_MISSING, low=None, strict=False, rule=None):
        value = self._get(raw, key, field, default)
        if not finite_number(value):
            raise self.fail(field, value, "must be a finite number")
        if low is not None and (value <= low if strict else value < low):
            raise self.fail(field, value, rule or f"must be {'>' if strict else '>='} {low:g}")
        return jnp.asarray(float(value))

    def integer(self, raw, key, field, *, default=_MISSING, low=None, rule=None) -> int:
        value = self._get(raw, key, field, default)
        if isinstance(value, bool) or not isinstance(value, int):
            # a type error names the type rule, never the range rule (30.5 teeth is not "< 1")
            if isinstance(value, float) and value.is_integer():
                raise self.fail(field, value, "must be an integer (no decimal point)")
            raise self.fail(field, value, "must be an integer")
        if low is not None and value < low:
            raise self.fail(field, value, rule or f"must be >= {low}")
        return value

    def boolean(self, raw, key, field, *, default=_MISSING) -> bool:
        value = self._get(raw, key, field, default)
        if not isinstance(value, bool):
            raise self.fail(field, value, "must be true or false")
        return value

    def string(self, raw, key, field, *, default=_MISSING) -> str:
        value = self._get(raw, key, field, default)
        if not isinstance(value, str):
            raise self.fail(field, value, "must be a string")
        return value

    def choice(self, raw, key, field, options, *, default=_MISSING) -> str:
        value = self._get(raw, key, field, default)
        if value not in options:
            raise self.fail(field, value, f"must be one of {', '.join(map(repr, options))}")
        return value

    def vector(self, raw, key, field) -> np.ndarray:
        value = self._get(raw, key, field, self._MISSING)
        if not isinstance(value, list) or not all(finite_number(v) for v in value):
            raise self.fail(field, value, "must be a list of finite numbers")
        return np.asarray(value, dtype=np.float64)

    def matrix(self, raw, key, field, columns: int, what: str) -> np.ndarray:
        value = raw.get(key, [])
        ok = isinstance(value, list) and all(
            isinstance(row, list) and len(row) == columns
            and all(finite_number(v) for v in row)
            for row in value
        )
        if not ok:
            raise self.fail(field, value, f"must be a list of {what}")
        return np.asarray(value, dtype=np.float64).reshape(len(value), columns)

    def sun_ring(self, raw, key, f, *, low=None, strict=False, default=_MISSING, rule=None):
        value = self._get(raw, key, f + key, default)
        if isinstance(value, int | float) and not isinstance(value, bool):
            value = {"sun": value, "ring": value}  # one number for both sides
        self.table(value, f + key)
        self.keys(value, {"sun", "ring"}, f + key)
        return SunRing(**{
            side: self.number(value, side, f"{f}{key}.{side}", low=low, strict=strict,
                              default=default, rule=rule)
            for side in ("sun", "ring")
        })


def finite_number(value) -> bool:
    """A TOML number that is a finite float64 (not a bool, not an integer too large)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:  # an integer beyond 1.8e308
        return False
