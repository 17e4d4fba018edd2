"""User-facing errors and warnings: one line naming file, field, value and rule."""

from __future__ import annotations

import warnings


class TrainError(ValueError):
    """Impossible train input. The message is one line: ``FILE: FIELD = VALUE: RULE``."""


class GeometryWarning(UserWarning):
    """Geometry rules of standard gears that a train breaks (data kept as given)."""


def field_message(source: str | None, field: str, value, rule: str) -> str:
    """``FILE: FIELD = VALUE: RULE`` on one line."""
    where = source if source is not None else "<train>"
    return f"{where}: {field} = {_show(value)}: {rule}"


def fail(source: str | None, field: str, value, rule: str) -> TrainError:
    """A :class:`TrainError` to raise."""
    return TrainError(field_message(source, field, value, rule))


def warn_geometry(message: str) -> None:
    warnings.warn(message, GeometryWarning, stacklevel=3)


def _show(value) -> str:
    if value is None:  # TOML has no null: None is a key that is absent
        return "(missing)"
    if isinstance(value, str):
        return repr(value)
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
