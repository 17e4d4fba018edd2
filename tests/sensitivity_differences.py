"""Central differences of a sensitivity's response, re-solved by Newton from the nominal
solution: the independent check of implicit derivatives (tests/studies/test_sensitivity.py,
tests/gear/test_tooth_geometry_file.py)."""

import jax.numpy as jnp
import numpy as np

from gearjax._engine import hb as _hb
from gearjax._engine.results import RESULTS
from gearjax._studies import sensitivity as S


def finite_differences(train, result, linear):
    """Central differences of the re-solved response, Newton from the nominal solution."""
    family = S.GearFamily.of(train, result.paths, result.gear, linear)
    settings = _hb.HarmonicBalance(n_harmonics=result.harmonics)
    theta = family.theta()
    omega = jnp.asarray(result.omega)
    X0 = S.solve_at(family, theta, settings, omega).X
    resp = S.MeshResponse(field=S.RESPONSES[result.response],
                          mesh=result.meshes.index(result.mesh))
    fd, noise = [], []
    for k, p in enumerate(np.asarray(theta)):
        h = 1e-3 if S.path_unit(result.paths[k]) == "deg" else 1e-5 * abs(p)
        e = jnp.zeros(theta.shape).at[k].set(h)
        r_plus, c_plus = S.response_at(family, theta + e, settings, omega, resp, X0)
        r_minus, c_minus = S.response_at(family, theta - e, settings, omega, resp, X0)
        assert bool(c_plus == RESULTS.successful) and bool(c_minus == RESULTS.successful)
        fd.append((r_plus - r_minus) / (2 * h))
        noise.append(1e-10 * abs(result.value) / h)  # Newton's converged noise over h
    return np.asarray(fd), np.asarray(noise)
