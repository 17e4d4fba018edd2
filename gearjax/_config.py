"""float64 is switched on when gearjax is imported: tight Newton tolerances stall in float32."""

import jax

jax.config.update("jax_enable_x64", True)


def require_x64() -> None:
    """Refuse to solve in float32 (someone switched x64 off after importing gearjax)."""
    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            "gearjax needs float64: jax_enable_x64 was turned off after importing gearjax; "
            "call jax.config.update('jax_enable_x64', True)"
        )
