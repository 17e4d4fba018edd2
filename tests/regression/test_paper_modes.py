"""The paper's case: the first gear's natural frequencies against Table 2.

Al-shyyab et al. (2009), Table 2, as the bundled example reproduces it with its
identified inertias: the 12 elastic frequencies the example header lists, and the two
planet-mode triples (9.15 and 10.41 kHz) against the closed form
``omega^2 = r_p^2 (k_sp + k_rp) / I_p``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import gearjax as gj

HEADER_KHZ = [3.871, 8.558, 9.150, 9.150, 9.150, 10.410, 10.410, 10.410, 10.729, 15.024,
              38.77, 45.32]


def hz(lam):
    return math.sqrt(lam) / (2 * math.pi)


@pytest.fixture(scope="module")
def paper_modes(paper_train):
    return gj.modes(gj.assemble(paper_train, "first"))


def test_paper_first_gear_elastic_modes(paper_modes):
    elastic = paper_modes.elastic_hz
    assert len(elastic) == 12
    assert np.array(elastic) / 1e3 == pytest.approx(HEADER_KHZ, rel=1e-3)
    assert paper_modes.elastic_multiplicities() == [1, 1, 3, 3, 1, 1, 1, 1]
    assert sum(m.cls == "rigid" for m in paper_modes.modes) == 1
    assert sum(m.cls == "penalty" for m in paper_modes.modes) == 1
    assert len(paper_modes.modes) == 14  # 3 d + sum N


def test_paper_triples_are_planet_modes(paper_train, paper_modes):
    elastic = [m for m in paper_modes.modes if m.cls == "elastic"]
    for stage, khz, sl in (("2", 9.15, slice(2, 5)), ("1", 10.41, slice(5, 8))):
        triple = elastic[sl]
        s = paper_train.stage(stage)
        r_p = float(s.base_radii()[1])
        lam = r_p**2 * float(s.mesh_stiffness.sun + s.mesh_stiffness.ring) / float(s.inertia.planet)
        for m in triple:
            assert m.family == "planet"
            assert m.stage == stage
            assert m.multiplicity == 3
            assert m.hz == pytest.approx(hz(lam), rel=1e-9)
            assert m.hz / 1e3 == pytest.approx(khz, rel=1e-3)
    others = [m for m in elastic if m.family != "planet"]
    assert len(others) == 6
