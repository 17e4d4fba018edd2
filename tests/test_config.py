"""float64 cannot be forgotten: on at import, and solving refuses float32."""

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
