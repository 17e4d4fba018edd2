"""A gear's operating input speed in the train file: `info` reports at it."""

import json
from pathlib import Path

import gearjax as gj
from gearjax import _cli

DATA = Path(__file__).parents[1] / "data"


def with_speed(tmp_path, rpm: str) -> Path:
    text = (DATA / "geometry_stage.toml").read_text().replace(
        "input_torque = 500.0", f"input_torque = 500.0\ninput_rpm = {rpm}")
    path = tmp_path / "stage.toml"
    path.write_text(text)
    return path


def test_info_reports_at_the_gears_input_speed_unless_told(tmp_path, capsys):
    path = with_speed(tmp_path, "1450.0")
    assert _cli.main(["info", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["input_rpm"] == 1450.0
    # one stage, sun input, ring braked: mesh frequency Z_r |w_r - w_c| with w_c = w_s / 5.714
    ratio = 1 + 99 / 21
    assert out["stages"][0]["mesh_frequency_hz"] == __import__("pytest").approx(
        99 * (1450.0 / 60) / ratio, rel=1e-12)
    assert _cli.main(["info", str(path), "--json", "--input-rpm", "600"]) == 0
    assert json.loads(capsys.readouterr().out)["input_rpm"] == 600.0
    assert _cli.main(["info", str(DATA / "geometry_stage.toml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["input_rpm"] == _cli.DEFAULT_INPUT_RPM
    again = gj.loads_train(gj.dumps_train(gj.load_train(path)))
    assert again.gear("reduction").input_rpm == 1450.0


def test_a_speed_that_is_not_positive_is_refused(tmp_path, capsys):
    assert _cli.main(["info", str(with_speed(tmp_path, "-5.0"))]) == 2
    assert "gears.reduction.input_rpm = -5.0: must be > 0" in capsys.readouterr().err
