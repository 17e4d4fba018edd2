"""User-facing errors and warnings: one line naming file, field, value and rule."""

from __future__ import annotations

import warnings


class TrainError(ValueError):
    """Impossible train input. The message is one line: ``FILE: FIELD = VALUE: RULE``."""


class TrainWarning(UserWarning):
    """Train input that is possible but unusual (data kept as given). The message is one
    line naming file, field, value and the rule or usual range, with the numbers; the CLI
    prints every ``TrainWarning`` on stderr as ``warning: ...``."""


class GeometryWarning(TrainWarning):
    """Geometry rules of standard gears that a train breaks (data kept as given)."""


class RangeWarning(TrainWarning):
    """A value outside the range of ordinary gears, or a stiffness that does not do its job
    (a brake not much stiffer than what it holds), but not impossible (data kept as given)."""


def field_message(source: str | None, field: str, value, rule: str) -> str:
    """``FILE: FIELD = VALUE: RULE`` on one line."""
    where = source if source is not None else "<train>"
    return one_line(f"{where}: {field} = {_show(value)}: {rule}")


def one_line(text: str) -> str:
    """``text`` with line breaks and other unprintable characters escaped (``\\n``), so a
    message stays one line whatever a file name, key or stage id holds."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def fail(source: str | None, field: str, value, rule: str) -> TrainError:
    """A :class:`TrainError` to raise."""
    return TrainError(field_message(source, field, value, rule))


class ArgumentError(TrainError):
    """A function argument outside its rule, in Python terms: the message is one line
    ``argument NAME = VALUE: RULE``; ``argument``, ``value`` and ``rule`` are kept, and
    other arguments a rule mentions are written as ``` `name` ``` so that a front end
    (the CLI) can say the same thing in its own words."""

    def __init__(self, argument: str, value, rule: str):
        super().__init__(one_line(f"argument {argument} = {_show(value)}: {rule}"))
        self.argument = argument
        self.value = value
        self.rule = rule


def bad_argument(argument: str, value, rule: str) -> ArgumentError:
    """An :class:`ArgumentError` to raise: ``argument`` is the Python parameter name."""
    return ArgumentError(argument, value, rule)


def warn_geometry(message: str) -> None:
    warnings.warn(message, GeometryWarning, stacklevel=3)


def warn_range(message: str) -> None:
    warnings.warn(message, RangeWarning, stacklevel=3)


def _show(value) -> str:
    if value is None:  # TOML has no null: None is a key that is absent
        return "(missing)"
    if isinstance(value, str):
        return repr(value)
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
