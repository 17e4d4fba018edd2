"""float64 cannot be forgotten: on at import, and solving refuses float32; compiled
programs are kept between runs in the user's cache directory."""

import os
import subprocess
import sys


def test_import_turns_on_float64():
    code = "import jax, gearjax; print(jax.numpy.zeros(1).dtype)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "float64"


def test_assembly_refuses_float32():
    code = (
        "import jax, gearjax\n"
        "t = gearjax.load_train()\n"
        "jax.config.update('jax_enable_x64', False)\n"
        "try:\n"
        "    gearjax.assemble(t)\n"
        "except RuntimeError as e:\n"
        "    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-W", "ignore", "-c", code], capture_output=True,
                         text=True, timeout=120)
    assert "gearjax needs float64" in out.stdout


CACHE_PROBE = (
    "import jax, gearjax\n"
    "print(jax.config.jax_compilation_cache_dir)\n"
    "jax.jit(lambda x: x * 2.0 + 1.0)(jax.numpy.arange(3.0)).block_until_ready()\n"
)


def run_probe(**env):
    out = subprocess.run([sys.executable, "-W", "ignore", "-c", CACHE_PROBE],
                         capture_output=True, text=True, timeout=120,
                         env={**os.environ, **env})
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


KEPT_PROBE = CACHE_PROBE + (
    "from gearjax._engine import kept\n"
    "from gearjax._engine.mesh_force import backlash\n"
    "print(kept.store_dir())\n"
    "kept.kept_program(backlash)(jax.numpy.arange(3.0), jax.numpy.ones(3))\n"
)


def run_kept_probe_unset(tmp_path):
    """:data:`KEPT_PROBE` in ``tmp_path`` with no cache setting at all, the user's cache
    home ``tmp_path / "xdg"``."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("GEARJAX_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR",
                        "GEARJAX_KEEP_PROGRAMS")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    return subprocess.run([sys.executable, "-W", "ignore", "-c", KEPT_PROBE],
                          capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)


def test_compiled_programs_are_kept_in_the_user_cache(tmp_path):
    """By default (no setting at all) the cache and the store of kept programs are in
    the user's cache directory, and a run writes both there."""
    out = run_kept_probe_unset(tmp_path)
    cache = tmp_path / "xdg" / "gearjax" / "jax"
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [str(cache), str(cache / "programs")]
    assert any(f.is_file() for f in cache.iterdir())  # the compiled programs, for the next run
    assert len(list((cache / "programs").glob("*.bin"))) == 1  # the kept program
    assert sorted(p.name for p in tmp_path.iterdir()) == ["xdg"]  # nothing in the cwd


def test_no_cache_and_no_store_where_the_cache_directory_cannot_be_made(tmp_path):
    """A cache home that cannot hold a directory (here a file; a read-only home alike):
    the run goes on without the cache, and without the store (which would export every
    program in every process and fail to save it)."""
    (tmp_path / "xdg").write_text("not a directory")
    out = run_kept_probe_unset(tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["None", "None"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["xdg"]


def test_cache_moved_or_switched_off(tmp_path):
    assert run_probe(GEARJAX_CACHE_DIR=str(tmp_path / "c")) == str(tmp_path / "c")
    assert any((tmp_path / "c").iterdir())
    assert run_probe(GEARJAX_CACHE_DIR="0") == "None"
