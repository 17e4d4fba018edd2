"""The ``GEARJAX_*`` environment variables and their rules, checked before any work.

Each variable is read where it acts (:mod:`gearjax._config`, :mod:`gearjax._engine.kept`,
:mod:`gearjax._studies.concurrency`, the command line, the notebooks); this module holds
the table of names and rules, so that a command refuses a bad or misspelt setting at its
start, in one line, instead of failing late or ignoring it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

from ._errors import TrainError, field_message
from ._studies.concurrency import THREADS_ENV, THREADS_RULE, threads_setting

PREFIX = "GEARJAX_"

SWITCH = "0 or 1 (empty: unset)"

RULES: dict[str, str] = {
    THREADS_ENV: THREADS_RULE,
    "GEARJAX_KEEP_PROGRAMS": f"must be {SWITCH}",
    "GEARJAX_DEBUG": f"must be {SWITCH}",
    "GEARJAX_CACHE_DIR": "must be a directory (made where it does not exist) or 0 (no cache)",
    "GEARJAX_NOTEBOOK_QUICK": f"must be {SWITCH}",
}
"""Every ``GEARJAX_*`` variable gearjax reads, and the rule its value must follow."""


def _holds(name: str, value: str) -> bool:
    value = value.strip()
    if name == THREADS_ENV:
        try:
            threads_setting(value)
        except ValueError:
            return False
        return True
    if name == "GEARJAX_CACHE_DIR":
        path = os.path.expanduser(value)
        return value in ("", "0") or not os.path.exists(path) or os.path.isdir(path)
    return value in ("", "0", "1")


def check_environment(environ: Mapping[str, str] | None = None) -> None:
    """Check every ``GEARJAX_*`` variable of ``environ`` (default ``os.environ``) against
    :data:`RULES`.

    **Raises:** :class:`~gearjax.TrainError` (one line ``environment: NAME = VALUE:
    RULE``) for the first value that breaks its rule, or a name gearjax does not read
    (a misspelling would otherwise be ignored)."""
    environ = os.environ if environ is None else environ
    for name in sorted(k for k in environ if k.startswith(PREFIX)):
        value = environ[name]
        if name not in RULES:
            raise TrainError(field_message(
                "environment", name, value,
                f"not a gearjax setting (gearjax reads {', '.join(RULES)})"))
        if not _holds(name, value):
            raise TrainError(field_message("environment", name, value, RULES[name]))
