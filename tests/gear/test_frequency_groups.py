"""Frequency groups (model.md, "Incommensurate stages"): small multiples of a base share a
group, incommensurate frequencies do not, and `gearjax info` reports them."""

import json
import warnings
from fractions import Fraction as Fr

import pytest

import gearjax as gj
from gearjax._cli import main
from gearjax._gear.frequency_groups import (
    MAX_MULTIPLIER,
    gear_frequency_groups,
    group_frequencies,
)


def test_the_paper_first_gear_is_one_group(paper_train):
    groups = gear_frequency_groups(gj.kinematics(paper_train, "first"))
    assert groups.G == 1
    (g,) = groups.groups
    assert g.members == ("stage 1", "stage 2") and g.multipliers == (7, 8)
    assert g.base == gj.kinematics(paper_train, "first").base


def test_stage_2_teeth_43_19_81_make_two_groups(paper_text, tmp_path):
    path = tmp_path / "t.toml"
    path.write_text(paper_text.replace("teeth = { sun = 44, planet = 18, ring = 80 }",
                                       "teeth = { sun = 43, planet = 19, ring = 81 }"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gj.GeometryWarning)
        kin = gj.kinematics(gj.load_train(path), "first")
    assert kin.mu == (70, 81)
    groups = gear_frequency_groups(kin)
    assert groups.G == 2 and [g.multipliers for g in groups.groups] == [(1,), (1,)]
    assert [g.base for g in groups.groups] == [s.mesh_frequency for s in kin.stages]


def test_small_ratios_join_and_large_ones_split():
    # 8/7: one group of base 1/7; 17/16 has no common base with multipliers <= 16
    assert [g.multipliers for g in group_frequencies({"a": Fr(1), "b": Fr(8, 7)}).groups] \
        == [(7, 8)]
    two = group_frequencies({"a": Fr(1), "b": Fr(17, 16)})
    assert two.G == 2
    # three frequencies: the two in ratio 3 share a group, the third is apart
    three = group_frequencies({"a": Fr(1), "b": Fr(3), "c": Fr(71, 50)})
    assert [g.members for g in three.groups] == [("a", "b"), ("c",)]
    assert three.group_of("b") == 0 and three.group_of("c") == 1
    # the fewest groups: 2 and 3 join 1 (multipliers 1, 2, 3) rather than two groups
    assert group_frequencies({"a": Fr(2), "b": Fr(3), "c": Fr(1)}).G == 1


def test_three_incommensurate_groups_and_ripple_orders():
    g = group_frequencies({"stage 1": Fr(70), "stage 2": Fr(81), "stage 3": Fr(997, 10),
                           "ripple 140": Fr(140)})
    assert g.G == 3
    assert g.group_of("ripple 140") == g.group_of("stage 1")
    assert g.groups[g.group_of("stage 1")].multipliers == (1, 2)


def test_near_commensurate_frequencies_without_a_base_are_refused():
    # 16/15 and 15/14 are each in a small ratio to 1, so all three must share an angle,
    # but their common base needs multipliers 210, 224, 225
    with pytest.raises(ValueError, match=f"multiple <= {MAX_MULTIPLIER}"):
        group_frequencies({"a": Fr(1), "b": Fr(16, 15), "c": Fr(15, 14)})
    with pytest.raises(ValueError, match="must be positive"):
        group_frequencies({"a": Fr(0)})


def test_info_reports_the_groups_and_the_solver(capsys, paper_train, paper_text, tmp_path):
    assert main(["info", "--json", "--input-rpm", "1200"]) == 0
    out = json.loads(capsys.readouterr().out)
    base = gj.kinematics(paper_train, "first").base
    assert [g["multipliers"] for g in out["frequency_groups"]] == [[7, 8]]
    assert out["frequency_groups"][0]["base_exact"] == str(base)
    assert out["frequency_groups"][0]["base_hz"] == pytest.approx(float(base) * 1200 / 60)
    assert out["solver_plan"].startswith("periodic harmonic balance with one base")
    path = tmp_path / "t.toml"
    path.write_text(paper_text.replace("teeth = { sun = 44, planet = 18, ring = 80 }",
                                       "teeth = { sun = 43, planet = 19, ring = 81 }"))
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "2: base" in text and "2 incommensurate groups" in text
