"""Output paths checked before any work, and written atomically."""

from __future__ import annotations

import os
import pathlib

from .._errors import fail


RESULT_SUFFIXES = {"sweep": (".nc", ".csv"), "simulate": (".nc", ".csv"),
                   "verify": (".nc",), "optimize": (".nc",)}
SUFFIX_RULES = {(".nc", ".csv"): "must end in .nc or .csv",
                (".nc",): "must end in .nc (NetCDF)"}


def check_outputs(args) -> None:
    """Refuse, before any work, an output path that cannot be written: a directory, a
    missing or read-only directory, an unknown extension (one line, ``TrainError``)."""
    cmd = args.command
    out = getattr(args, "out", None)
    if cmd == "plot":
        results = pathlib.Path(args.results)
        fig = pathlib.Path(out) if out else results.with_suffix(".png")
        if os.path.abspath(fig) == os.path.abspath(results):
            raise fail("command line", "--out", str(fig), "would overwrite the results file")
        if results.exists():  # else plot_results says there is no such results file
            check_figure("--out" if out else "--out (default: RESULTS with .png)", str(fig))
    elif cmd == "study":
        if out is not None:
            check_store(out)
    elif out is not None:
        rule = SUFFIX_RULES[RESULT_SUFFIXES[cmd]]
        if cmd == "verify":
            rule = "must end in .nc (NetCDF, groups hb and ni)"
        check_output("--out", out, RESULT_SUFFIXES[cmd], rule)
    if getattr(args, "out_train", None) is not None:
        check_output("--out-train", args.out_train, (".toml",), "must end in .toml")
    if cmd != "plot" and getattr(args, "plot", None) is not None:
        check_figure("--plot", args.plot)
    if cmd == "sweep" and args.resume and not args.out:
        raise fail("command line", "--resume", True, "needs --out FILE: the run to resume "
                   "is the one whose journal FILE.journal is there")


def check_output(flag: str, value: str, suffixes: tuple[str, ...], rule: str) -> None:
    path = pathlib.Path(value)
    if path.is_dir():
        raise fail("command line", flag, value, "is a directory: name a file in it")
    if not value.lower().endswith(suffixes):
        raise fail("command line", flag, value, rule)
    parent = path.parent
    if not parent.exists():
        raise fail("command line", flag, value, f"its directory {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise fail("command line", flag, value, f"{str(parent)!r} is not a directory")
    probe = parent / f".{path.name}.{os.getpid()}.probe"
    try:  # really create a file there: permissions, read-only or special file systems
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as e:
        raise fail("command line", flag, value, f"its directory {str(parent)!r} is not "
                   f"writable ({e.strerror or e})") from None


def check_store(value: str) -> None:
    """A study store: a directory, or a name whose directory exists."""
    path = pathlib.Path(value)
    if path.exists() and not path.is_dir():
        raise fail("command line", "--out", value, "is a file: a study store is a directory")
    parent = path.parent
    if not parent.is_dir():
        raise fail("command line", "--out", value,
                   f"its directory {str(parent)!r} does not exist")


def check_figure(flag: str, value: str) -> None:
    formats = figure_formats()
    ext = pathlib.Path(value).suffix.lower().lstrip(".")
    rule = ("must end in a figure format matplotlib writes: "
            + ", ".join("." + f for f in formats))
    check_output(flag, value, ("." + ext,) if ext in formats else (), rule)


def figure_formats() -> list[str]:
    from matplotlib.figure import Figure

    return sorted(Figure().canvas.get_supported_filetypes())


def atomic(path):
    """Write ``path`` atomically (:func:`gearjax._io.results.atomic_path`)."""
    from .._io.results import atomic_path

    return atomic_path(path)


def study_store(args) -> str:
    """The study store: ``--out``, else the study file with ``.study``."""
    return args.out or str(pathlib.Path(args.study).with_suffix(".study"))
