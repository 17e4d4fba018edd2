"""JAX's and XLA's log messages stay off the command line's stderr unless GEARJAX_DEBUG=1,
and a plain ``import gearjax`` leaves them as JAX has them.

XLA's C++ log is made to speak on every compilation (``TF_CPP_MIN_LOG_LEVEL=0`` with
``TF_CPP_MAX_VLOG_LEVEL=1``: hundreds of ``I...`` lines for one small program), and a
JAX Python logger is given a warning; each process writes a marker on stderr once its
start-up is over, and only the lines after it count (the lines jaxlib writes while it
loads, before any code of gearjax runs, follow ``TF_CPP_MIN_LOG_LEVEL`` as the user set it).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import jax

import gearjax  # noqa: F401  (imported: the setting below must be JAX's default)

ROOT = Path(__file__).resolve().parents[2]
MARK = "<<started>>"
XLA_LINE = re.compile(r"^[IWEF]\d{4} ")
"""A line of XLA's C++ log (severity letter, month, day)."""

SCRIPT = f"""
import logging, sys
mode = sys.argv[1]
import gearjax._cli.app as cli  # console() calls this module's main
import jax, jax.numpy as jnp

def work():
    sys.stderr.write({MARK!r} + "\\n")
    sys.stderr.flush()
    logging.getLogger("jax._src.xla_bridge").warning("python-side jax warning")
    jax.jit(lambda x: jnp.sin(x) * 2.0)(jnp.arange(3.0)).block_until_ready()
    print(jax.config.jax_logging_level)
    return 0

if mode == "console":  # the console script, with a command that compiles one program
    cli.main = work
    cli.console()
else:  # a library user
    work()
"""


def run_all(*cases):
    """``{name: (code, stdout, stderr after the marker)}`` for ``(name, mode, env)`` cases,
    run side by side."""
    base = {k: v for k, v in os.environ.items()
            if not k.startswith(("GEARJAX_", "JAX_LOGGING", "TF_CPP"))}
    base.update(JAX_PLATFORMS="cpu", TF_CPP_MIN_LOG_LEVEL="0", TF_CPP_MAX_VLOG_LEVEL="1",
                GEARJAX_CACHE_DIR="0")  # no compilation cache: the program is compiled
    procs = {name: subprocess.Popen([sys.executable, "-c", SCRIPT, mode], env={**base, **env},
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, mode, env in cases}
    out = {}
    for name, p in procs.items():
        stdout, stderr = p.communicate(timeout=120)
        assert MARK in stderr, (name, stderr[-2000:])
        out[name] = (p.returncode, stdout.strip(), stderr.split(MARK, 1)[1])
    return out


def xla_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if XLA_LINE.match(line)]


def test_console_quiet_unless_debug_and_library_untouched():
    got = run_all(("quiet", "console", {}),
                  ("debug", "console", {"GEARJAX_DEBUG": "1"}),
                  ("library", "import", {}))
    code, level, err = got["quiet"]
    assert code == 0 and level == "CRITICAL"
    assert xla_lines(err) == [] and "python-side jax warning" not in err, err[:2000]
    assert err.strip() == ""
    for name in ("debug", "library"):  # JAX's own defaults: everything shows as before
        code, level, err = got[name]
        assert code == 0 and level in ("None", "NOTSET"), (name, level)
        assert len(xla_lines(err)) >= 10, (name, err[:2000])
        assert "python-side jax warning" in err, name


def test_a_jax_logging_level_the_user_set_is_kept(monkeypatch):
    from gearjax._config import quiet_jax_logs

    before = jax.config.jax_logging_level
    monkeypatch.setenv("JAX_LOGGING_LEVEL", "INFO")
    assert quiet_jax_logs() is False
    assert jax.config.jax_logging_level == before


def test_plain_import_and_main_leave_jax_logging_alone(capsys):
    before = jax.config.jax_logging_level
    assert before in (None, "NOTSET")
    from gearjax._cli import main

    assert main(["info", "--json"]) == 0
    capsys.readouterr()
    assert jax.config.jax_logging_level == before


def test_console_script_is_the_quiet_entry_point():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"gearjax": "gearjax._cli:console"}
