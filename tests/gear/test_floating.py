"""A gear whose static load presses no tooth pair together (no input torque, or one too
small for the harmonic balance to resolve): recognised before any work, by `info` and by
the sweep, in one line with the numbers."""

import json

import pytest

import gearjax as gj
from gearjax._cli import main

TORQUE_LINE = "input_torque = 750.0      # N m; the output load"


def _paper_with_torque(tmp_path, torque: float):
    """The bundled paper case with the first gear's input torque ``torque`` (N m)."""
    text = gj.bundled_example_path().read_text()
    assert TORQUE_LINE in text
    path = tmp_path / f"torque_{torque:g}.toml"
    path.write_text(text.replace(TORQUE_LINE, f"input_torque = {torque!r}  # N m; the output load", 1))
    return path


@pytest.mark.parametrize("torque", [0.0, 1e-6])
def test_a_floating_gear_is_refused_before_work_and_named_by_info(tmp_path, capsys, torque):
    """Zero torque, and 1e-6 N m (static mesh deflections about 1e-14 m against a 5e-5 m
    backlash): the sweep refuses in one line naming the field, its value, the largest
    static deflection and what to do (exit 2); `info` still reports the gear, with the
    same finding among its warnings."""
    path = _paper_with_torque(tmp_path, torque)
    code = main(["sweep", str(path), "--from", "3000", "--to", "3010"])
    _, err = capsys.readouterr()
    assert code == 2
    lines = [line for line in err.splitlines() if not line.startswith("warning: ")]
    assert len(lines) == 1, err
    assert f"gears.first.input_torque = {torque!r}: every mesh with backlash floats" in lines[0]
    assert "largest static mesh deflection" in lines[0] and lines[0].endswith("solve with --linear")
    assert main(["info", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr()[0])
    found = [w for w in out["warnings"] if "floats in its clearance" in w]
    assert len(found) == 1 and "gears.first.input_torque" in found[0]


def test_a_loaded_gear_and_a_linear_sweep_do_not_float(tmp_path):
    """1 N m presses the teeth together (deflections of order 1e-8 m, far above the
    resolution): accepted; without backlash (`linear`) nothing floats, whatever the
    torque."""
    gj.gear_case(gj.load_train(_paper_with_torque(tmp_path, 1.0)))
    case = gj.gear_case(gj.load_train(_paper_with_torque(tmp_path, 0.0)), linear=True)
    assert not case.has_backlash
