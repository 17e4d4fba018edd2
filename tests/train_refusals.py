"""Helpers for the tests that break one thing in the bundled train file and check the
one-line refusal (``tests/gear/test_validation.py``, ``tests/gear/test_input_bounds.py``).

Imported as a top-level module: ``tests/`` is on ``sys.path`` because ``tests/conftest.py``
sits in a folder without ``__init__.py`` (pytest's default ``prepend`` import mode).
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable

import pytest
import tomli_w

from gearjax import TrainError

SOURCE = "bad.toml"
"""The source name the broken texts are loaded under."""

MESSAGE = re.compile(r"^bad\.toml: (?P<field>.+?) = (?P<value>.+?): (?P<rule>.+)$")
"""A refusal: ``bad.toml: FIELD = VALUE: RULE``."""


def mutate(text: str, change) -> str:
    """Parse, let ``change`` edit the dict in place, re-serialise."""
    raw = tomllib.loads(text)
    change(raw)
    return tomli_w.dumps(raw)


def refuse(load: Callable[[str], object], text: str, field: str, value: str, *words: str,
           value_at_field: bool = False) -> str:
    """Expect ``load(text)`` to raise a TrainError with a one-line ``bad.toml: FIELD = VALUE:
    RULE`` message: ``field`` in FIELD, ``value`` in the message (``value_at_field``: right
    after ``field =`` or in VALUE), each of ``words`` in RULE. Returns the message."""
    with pytest.raises(TrainError) as info:
        load(text)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert msg.startswith(SOURCE + ": "), msg
    m = MESSAGE.match(msg)
    assert m is not None, msg
    assert field in m["field"], msg
    if value_at_field:
        assert f"{field} = {value}" in msg or value in m["value"], msg
    else:
        assert value in msg, msg
    for w in words:
        assert w in m["rule"], msg
    return msg
