"""The entry points: :func:`main` parses a command line, runs its command and maps what
the library raises to an exit code and one line on stderr; :func:`console` is the
``gearjax`` console script."""

from __future__ import annotations

import os
import pathlib
import sys
import warnings

from .._config import quiet_jax_logs
from .._environment import check_environment
from .._errors import TrainError, TrainWarning, one_line
from .outputs import check_outputs, study_store
from .parser import UsageError, build_parser
from .report import EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, brief, to_stderr
from .words import cli_message, flag_words


DEBUG_ENV = "GEARJAX_DEBUG"


def console() -> None:
    """The ``gearjax`` console script: :func:`main` on ``sys.argv``, with JAX's and XLA's
    log messages kept off stderr (:func:`~gearjax._config.quiet_jax_logs`) unless
    ``GEARJAX_DEBUG=1``; exits with :func:`main`'s code. Callers of :func:`main` in
    Python keep their own logging."""
    if os.environ.get(DEBUG_ENV, "") in ("", "0"):
        quiet_jax_logs()
    sys.exit(main())


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        return refuse(str(e))
    args.command_line = command_line(argv)
    if args.command is None:
        return refuse(f"command line: COMMAND = (missing): give one of "
                      f"{', '.join(args.commands)} (gearjax --help describes them)")
    notes: list[str] = []
    try:
        check_environment()
        check_outputs(args)
        with warnings.catch_warnings():
            warnings.simplefilter("always", TrainWarning)
            warnings.showwarning = warning_printer(notes, warnings.showwarning)
            if not args.needs_train:  # study and plot read other files
                return args.run(args, None, notes)
            from .._gear.toml_io import load_train

            train = load_train(args.train)
            return args.run(args, train, notes)
    except TrainError as e:
        return refuse(cli_message(e))
    except KeyboardInterrupt:
        to_stderr(interrupted_message(args))
        return EXIT_INTERRUPTED
    except Exception as e:  # noqa: BLE001  no traceback reaches a user
        if os.environ.get(DEBUG_ENV, "") not in ("", "0"):
            raise
        if out_of_memory(e):
            how = ("fewer harmonics (--harmonics K)" if hasattr(args, "harmonics")
                   else "a smaller problem")
            to_stderr(f"gearjax: error: the problem did not fit in memory ({brief(e, 160)}): "
                      f"try {how}, fewer points or a narrower band")
            return EXIT_INTERNAL
        if isinstance(e, OSError):
            return refuse(os_error_message(e))
        to_stderr(f"gearjax: internal error: {type(e).__name__}: {brief(e)} "
                  f"(set {DEBUG_ENV}=1 for the traceback)")
        return EXIT_INTERNAL


def refuse(message: str) -> int:
    to_stderr(f"gearjax: error: {one_line(message)}")
    return EXIT_INPUT


def command_line(argv: list[str] | None) -> str:
    """How this run was asked for, as the results files record it."""
    return " ".join(sys.argv if argv is None else ["gearjax", *argv])


def warning_printer(notes: list[str], fallback):
    """A ``warnings.showwarning`` that prints each distinct :class:`TrainWarning` (and
    any other warning of gearjax's own, e.g. a truncation estimate) once, as one line
    on stderr, and keeps it in ``notes`` (the JSON ``warnings``)."""

    def show(message, category, filename, lineno, file=None, line=None):
        ours = issubclass(category, TrainWarning) or category.__module__.startswith("gearjax")
        if not ours:
            return fallback(message, category, filename, lineno, file, line)
        text = flag_words(brief(message, 1000))
        if text not in notes:
            notes.append(text)
            to_stderr(f"warning: {text}")

    return show


def out_of_memory(e: BaseException) -> bool:
    if isinstance(e, MemoryError):
        return True
    text = str(e)
    return "RESOURCE_EXHAUSTED" in text or "out of memory" in text.lower()


def os_error_message(e: OSError) -> str:
    """One line naming the file and the operating system's reason."""
    reason = e.strerror or brief(e)
    if e.filename is not None:
        where = str(e.filename) + (f" -> {e.filename2}" if e.filename2 is not None else "")
        return f"{where}: {reason}"
    return f"{type(e).__name__}: {brief(e)}"


def interrupted_message(args) -> str:
    from .._io.journal import journal_path

    out = getattr(args, "out", None)
    if getattr(args, "command", None) == "study":
        store = study_store(args)
        if pathlib.Path(store).is_dir():
            return (f"gearjax: interrupted; the finished candidates are in {store}: run the "
                    "same command with --resume to go on")
    if getattr(args, "command", None) == "sweep" and out and journal_path(out).exists():
        return (f"gearjax: interrupted; the points found so far are in {journal_path(out)}: "
                "run the same command with --resume to go on")
    return "gearjax: interrupted"
