"""The ``gearjax`` command line (interface.md): info, mesh, modes, calibrate, sweep,
simulate, verify, sensitivity, optimize, study, plot.

The one package that knows flag names and exit codes: :mod:`.parser` declares every
command's flags, :mod:`.words` translates the library's argument names into them, and
each command's module parses nothing, calls the library and renders its report. A
command is ``NAME_command(args, train, notes) -> exit code``: ``args`` the parsed
command line, ``train`` the loaded train (``None`` for ``study`` and ``plot``, which read
other files), ``notes`` the warnings said so far (the JSON ``warnings``).

Exit codes: 0 finished; 2 bad input or usage (one line on stderr, no traceback);
3 finished but nothing converged; 1 an internal error or a problem too large for the
memory (one line; ``GEARJAX_DEBUG=1`` shows the traceback); 130 interrupted.
JAX's and XLA's own log messages stay off stderr (the console script, :func:`console`)
unless ``GEARJAX_DEBUG=1``.
``--json`` prints one JSON object on stdout and nothing else there; warnings go to
stderr, one line each.

Refuse, don't guess: every output path (``--out``, ``--out-train``, ``--plot``,
``plot --out``) is checked before any work; results are written atomically; a sweep's
journal is locked while its run is live, so a second run on the same ``--out`` is
refused instead of racing the first.

The library speaks in Python terms: an :class:`~gearjax._errors.ArgumentError` names
the Python argument and writes other arguments as ``` `name` ```;
:data:`~gearjax._cli.words.ARGUMENT_FLAGS` translates both into flags
(``command line: --flag = VALUE: RULE``), and the backticked names in any other refusal
or warning of gearjax's.
"""

from .app import console, main
from .info import DEFAULT_INPUT_RPM

__all__ = ["DEFAULT_INPUT_RPM", "console", "main"]
