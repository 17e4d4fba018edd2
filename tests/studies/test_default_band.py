"""The band of a sweep asked for without one: from the gear's modes and excitation
orders, on trains other than the paper's."""

from pathlib import Path

import numpy as np
import pytest

import gearjax as gj
from gearjax import _cli
from gearjax._gear.assembly import assemble
from gearjax._studies import sweep as sweep_module
from gearjax._studies.sweep.default_band import HIGH_MARGIN, LOW_MARGIN, resolve_band

DATA = Path(__file__).parents[1] / "data"


@pytest.mark.parametrize("name", ["geometry_stage.toml", "helicopter_five_planets.toml"])
def test_band_holds_the_lowest_superharmonic_and_the_highest_primary_resonance(name):
    """The band reaches from below the resonance of the lowest elastic mode with the
    highest kept stiffness harmonic to above the fundamental's resonance with the highest
    mesh-dominated mode (modes from `gj.modes`, independently of the band's code)."""
    train = gj.load_train(DATA / name)
    lo, hi, reason = resolve_band(train, None, None, True, None, None)
    modes = gj.modes(assemble(train))
    elastic = np.asarray(modes.elastic_hz)
    H = train.stiffness_harmonics
    assert lo == pytest.approx(LOW_MARGIN * elastic[0] / H, rel=1e-9)  # one stage: r = 1
    assert lo < elastic[0] / H < elastic[-1] < hi <= HIGH_MARGIN * elastic[-1] * (1 + 1e-9)
    assert "lowest" in reason and f"H = {H}" in reason


def test_the_band_asked_for_is_kept_and_one_end_alone_is_refused():
    train = gj.load_train(DATA / "geometry_stage.toml")
    assert resolve_band(train, None, None, True, 3000.0, 2000.0) == (3000.0, 2000.0, None)
    with pytest.raises(gj.TrainError, match="give both"):
        resolve_band(train, None, None, True, 3000.0, None)


def test_sweep_without_a_band_says_the_one_it_chose(monkeypatch, capsys):
    seen = {}

    def stop(train, gear, from_hz, to_hz, **kw):
        seen["band"] = (from_hz, to_hz)
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "sweep", stop)
    assert _cli.main(["sweep", str(DATA / "geometry_stage.toml"), "--linear"]) == 130
    err = capsys.readouterr().err
    lo, hi, _ = resolve_band(gj.load_train(DATA / "geometry_stage.toml"), None, None, True,
                             None, None)
    assert seen["band"] == (lo, hi)
    assert f"sweep: no --from/--to: band {lo:.1f}-{hi:.1f} Hz, chosen from the gear's" in err
    assert _cli.main(["sweep", str(DATA / "geometry_stage.toml"), "--from", "3000"]) == 2
    assert "--to = (missing): give both --from and --to" in capsys.readouterr().err
