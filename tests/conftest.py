import os

os.environ.setdefault("MPLBACKEND", "Agg")
# Programs are not kept between processes in the suite (tests/engine/test_kept.py and
# tests/studies/test_config.py turn the store on where they test it): tests patch module
# globals that programs trace, and the store, keyed by gearjax's source on disk, would
# keep a program traced under a patch for every later run that shares the cache.
os.environ.setdefault("GEARJAX_KEEP_PROGRAMS", "0")

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")


MAP_FRACTION = 0.5
"""Share of the kernel's memory-mapping limit past which compiled programs are dropped."""


def _mappings() -> tuple[int, int] | None:
    """``(mappings this process holds, the kernel's limit)``; ``None`` where the system
    does not say (not Linux)."""
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            limit = int(f.read())
        with open("/proc/self/maps", "rb") as f:
            held = sum(1 for _ in f)
    except (OSError, ValueError):
        return None
    return held, limit


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_programs(request):
    """Drop JAX's compiled programs after a test module once the process holds more than
    :data:`MAP_FRACTION` of the kernel's memory-mapping limit (``vm.max_map_count``,
    65530 by default; after every module where the system does not say). Every XLA:CPU
    program holds a few hundred mappings (its kernels' code), and the whole suite in one
    process compiles enough of them to reach the limit: XLA then fails to compile
    ("Cannot allocate memory") or crashes. Dropping them only then keeps the programs
    that later modules share (the solver's programs for the same shapes, and the
    thousands of one-operation programs of eager array code) instead of compiling them
    again in every module.

    A module marked ``fresh_programs`` starts and ends with none kept: it patches what a
    program traces (a function or constant read while tracing must be traced again under
    the patch, and no program traced under a patch may serve a later module) or counts
    traces. A patch of Python-level work (the walk's steps, a file write, an
    environment variable) needs no mark: no compiled program holds it."""
    fresh = request.node.get_closest_marker("fresh_programs") is not None
    if fresh:
        jax.clear_caches()
    yield
    maps = _mappings()
    if fresh or maps is None or maps[0] > MAP_FRACTION * maps[1]:
        jax.clear_caches()


@pytest.fixture(scope="module")
def paper_train():
    """The bundled paper case (its geometry warning silenced)."""
    import warnings

    import gearjax as gj

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.load_train()


@pytest.fixture(scope="module")
def paper_text():
    """The bundled paper case's train file, as text."""
    import gearjax as gj

    return gj.bundled_example_path().read_text()


@pytest.fixture(scope="module")
def paper_system():
    """The assembled ``System`` of the bundled paper case's first gear (its geometry
    warning silenced)."""
    import warnings

    import gearjax as gj

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.assemble(gj.load_train())


@pytest.fixture(scope="module")
def paper_system_h1(paper_train_h1):
    """The paper case's first gear with one stiffness harmonic per mesh: its excitation
    reaches harmonic 8 of the base (mu = (7, 8)), so the harmonic balance may use as few
    as 8 harmonics (fast tests of solvers and plumbing; K = 32 with the four harmonics)."""
    import gearjax as gj

    return gj.assemble(paper_train_h1)


@pytest.fixture(scope="session")
def paper_toml_h1(tmp_path_factory):
    """The bundled paper case with ``stiffness_harmonics = 1``, as a train file (for the
    command line)."""
    import gearjax as gj

    text = gj.bundled_example_path().read_text()
    assert "stiffness_harmonics = 4" in text
    path = tmp_path_factory.mktemp("paper_h1") / "paper_h1.toml"
    path.write_text(text.replace("stiffness_harmonics = 4", "stiffness_harmonics = 1", 1))
    return path


@pytest.fixture(scope="module")
def paper_train_h1():
    """The bundled paper case with ``stiffness_harmonics = 1`` (its geometry warning
    silenced)."""
    import dataclasses
    import warnings

    import gearjax as gj

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return dataclasses.replace(gj.load_train(), stiffness_harmonics=1)


@pytest.fixture(scope="module")
def torus_h1_file(tmp_path_factory):
    """tests/data/two_stage_14_17.toml (mesh frequencies 14 : 17, two frequency groups)
    with one stiffness harmonic per mesh, written to a temporary file: its path."""
    import pathlib

    data = pathlib.Path(__file__).parent / "data" / "two_stage_14_17.toml"
    path = tmp_path_factory.mktemp("torus") / "two_stage_h1.toml"
    path.write_text(data.read_text().replace("stiffness_harmonics = 4",
                                             "stiffness_harmonics = 1", 1))
    return path


@pytest.fixture(scope="module")
def torus_h1_train(torus_h1_file):
    """The train of :func:`torus_h1_file` (its geometry warning silenced)."""
    import warnings

    import gearjax as gj

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.load_train(torus_h1_file)
