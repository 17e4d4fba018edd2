import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_programs():
    """Drop JAX's compiled programs after each test module. Every XLA:CPU program holds a
    few hundred memory mappings (its kernels' code), and the whole suite in one process
    compiles enough of them to reach the kernel's limit (``vm.max_map_count``, 65530 by
    default): XLA then fails to compile ("Cannot allocate memory") or crashes."""
    yield
    jax.clear_caches()


@pytest.fixture(scope="module")
def paper_system():
    """The assembled ``System`` of the bundled paper case's first gear (its geometry
    warning silenced)."""
    import warnings

    import gearjax as gj

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        return gj.assemble(gj.load_train())
