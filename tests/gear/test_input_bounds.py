"""Refuse, don't guess: bounds on every train-file input, and train files that fail to read.

Every case starts from the bundled paper case and breaks one thing. Impossible values
are refused at load with one line naming file, field, value and rule (``TrainError``);
possible but unusual ones are ``RangeWarning`` s with the numbers. The corpus test at the
end breaks every numeric key in every way (NaN, inf, sign, zero, 1e300, wrong types) and
checks that nothing but a one-line ``TrainError`` (or a clean load) comes out.
"""

from __future__ import annotations

import copy
import math
import os
import re
import subprocess
import sys
import tomllib
import warnings
from pathlib import Path

import pytest
import tomli_w

import gearjax
from gearjax import GeometryWarning, TrainError
from gearjax._errors import RangeWarning, TrainWarning
from gearjax._gear.toml_io import load_train
from gearjax._gear.bounds import BOUNDS, MAX_HARMONICS, check_ranges

import train_refusals
from train_refusals import SOURCE, mutate

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "examples" / "al_shyyab_2009.toml"


def load(text: str, source: str = SOURCE):
    """Load ``text``; return the train and the range warnings it gave."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        train = gearjax.loads_train(text, source=source)
    return train, [str(w.message) for w in record if issubclass(w.category, RangeWarning)]


def refuse(text: str, field: str, value: str, *words: str) -> str:
    """Expect a TrainError with a one-line ``bad.toml: FIELD = VALUE: RULE`` message."""
    return train_refusals.refuse(load, text, field, value, *words, value_at_field=True)


def warned(text: str, field: str, *words: str) -> str:
    """Expect a clean load with one RangeWarning for ``field`` holding ``words``."""
    _, notes = load(text)
    ours = [n for n in notes if f": {field} = " in n]
    assert len(ours) == 1, notes
    note = ours[0]
    assert "\n" not in note and note.startswith(SOURCE + ": "), note
    for w in words:
        assert w in note, note
    return note


# ------------------------------------------------------------------ 1. brake and couplings


def test_braked_zero_refused(paper_text):
    msg = refuse(mutate(paper_text, lambda r: r["housing"].update(braked=0.0)),
                 "housing.braked", "0.0", "> 0", "cannot hold")
    assert "undetermined" in msg


def test_coupling_zero_refused(paper_text):
    msg = refuse(mutate(paper_text, lambda r: r["couplings"][0].update(stiffness=0)),
                 "couplings[0].stiffness", "0", "> 0", "transmits no torque")
    assert "1.carrier" in msg and "2.ring" in msg  # the members it joins
    assert "remove the coupling" in msg and "gears = [...]" in msg


def test_soft_brake_warned(paper_text):
    # Carrier 1 (braked in reverse): N (k_s r_s^2 + k_r r_r^2) = 5.67e6 N m/rad, so a brake
    # of 1e6 N m/rad is below 10 x that.
    note = warned(mutate(paper_text, lambda r: r["housing"].update(braked=1.0e6)),
                  "housing.braked", "1000000.0", "10 x", "5.67e+06", "1.carrier", "reverse")
    assert "5.67e+07" in note


def test_stiff_free_housing_warned(paper_text):
    # Sun 1 has the smallest mesh torsional stiffness, N k_s r_s^2 = 7.91e5 N m/rad.
    warned(mutate(paper_text, lambda r: r["housing"].update(free=1.0e5)),
           "housing.free", "0.01 x", "7.91e+05", "1.sun")


def test_bundled_and_shared_examples_give_no_range_warning(paper_text):
    _, notes = load(paper_text)
    assert notes == []
    if SHARED.exists():
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            gearjax.load_train(SHARED)
        kinds = {w.category for w in record}
        assert kinds <= {GeometryWarning}, [str(w.message) for w in record]


# ------------------------------------------------------------------ 2. ranges


def _stage(i, key, value):
    return lambda r: r["stages"][i].update({key: value})


def _sub(i, key, member, value):
    return lambda r: r["stages"][i][key].update({member: value})


@pytest.mark.parametrize(
    "change, field, value, rule",
    [
        (_sub(0, "mesh_stiffness", "sun", 1e300), "1.mesh_stiffness.sun", "1e+300", "<= 1e+13 N/m"),
        (_sub(1, "mesh_stiffness", "ring", 10.0), "2.mesh_stiffness.ring", "10.0", ">= 100"),
        (_stage(0, "mesh_damping_ratio", 1e6), "1.mesh_damping_ratio", "1000000.0", "< 1"),
        (_stage(0, "mesh_damping_ratio", 1.0), "1.mesh_damping_ratio", "1.0", "over-critically"),
        (_sub(0, "inertia", "sun", 1e300), "1.inertia.sun", "1e+300", "<= 1e+09 kg m^2"),
        (_sub(1, "inertia", "planet", 1e-30), "2.inertia.planet", "1e-30", ">= 1e-20"),
        (_stage(1, "planet_mass", 1e300), "2.planet_mass", "1e+300", "<= 1e+07 kg"),
        (_sub(0, "teeth", "sun", 10**9), "1.teeth.sun", "1000000000", "<= 10000"),
        (_stage(0, "module_mm", 5000.0), "1.module_mm", "5000.0", "<= 1000 mm"),
        (_stage(0, "pressure_angle_deg", 60.0), "1.pressure_angle_deg", "60.0", "<= 45 deg"),
        (_stage(0, "carrier_radius_mm", 1e9), "1.carrier_radius_mm", "1000000000.0",
         "<= 100000 mm"),
        (_stage(0, "contact_ratio", 30.0), "1.contact_ratio.sun", "30.0", "<= 20"),
        (_stage(0, "half_backlash", 3e-3), "1.half_backlash.sun", "0.003", "base pitch"),
        (_stage(1, "stage_phase_deg", 1e300), "2.stage_phase_deg", "1e+300", "<= 10000 deg"),
        (_stage(0, "transmission_error", {"ring": [[0.01, 0.0]]}),
         "1.transmission_error.ring[0] amplitude", "0.01", "1 module = 0.0015 m"),
        (lambda r: r["housing"].update(braked=1e300), "housing.braked", "1e+300", "<= 1e+14"),
        (lambda r: r["couplings"][1].update(stiffness=1e20), "couplings[1].stiffness", "1e+20",
         "<= 1e+14 N m/rad"),
        (lambda r: r["gears"]["first"].update(input_torque=-1e12), "gears.first.input_torque",
         "-1000000000000.0", "|value| must be <= 1e+10 N m"),
        (lambda r: r["gears"]["third"].update(drag_torque=1e300), "gears.third.drag_torque",
         "1e+300", "<= 1e+10 N m"),
    ],
)
def test_out_of_range_refused(paper_text, change, field, value, rule):
    refuse(mutate(paper_text, change), field, value, rule)


@pytest.mark.parametrize(
    "change, field, words",
    [
        (_sub(0, "mesh_stiffness", "sun", 2e11), "1.mesh_stiffness.sun",
         ("200000000000.0", "1e+06 to 1e+11 N/m")),
        (_stage(1, "mesh_damping_ratio", 0.3), "2.mesh_damping_ratio", ("0.3", "0.005 to 0.2")),
        (_stage(1, "mesh_damping_ratio", 0.0), "2.mesh_damping_ratio", ("0.0", "0.005 to 0.2")),
        (_stage(0, "module_mm", 0.05), "1.module_mm", ("0.05", "0.1 to 50 mm")),
        (_stage(1, "contact_ratio", 5.0), "2.contact_ratio.sun", ("5.0", "above the usual 4")),
        (_stage(0, "pressure_angle_deg", 35.0), "1.pressure_angle_deg", ("35.0", "14.5 to 30 deg")),
        (_sub(1, "teeth", "planet", 5), "2.teeth.planet", ("= 5:", "7 to 1000")),
        (_stage(0, "half_backlash", 3e-4), "1.half_backlash.sun", ("0.0003", "0.1 module")),
        (_stage(0, "transmission_error", {"sun": [[1e-6, 0.0], [1e-4, 0.0]]}),
         "1.transmission_error.sun[1] amplitude", ("0.0001", "0.05 module = 7.5e-05 m")),
        (_stage(0, "carrier_radius_mm", 50.0), "1.carrier_radius_mm", ("43.5 mm", "+6.5 mm")),
        (lambda r: r["gears"]["first"].update(drag_torque=100.0), "gears.first.drag_torque",
         ("100.0", "0.1 x the input torque 750")),
        (lambda r: r["gears"]["first"].update(input_torque_ripple=[[1000.0, 0.0, 2.0]]),
         "gears.first.input_torque_ripple", ("1000 N m", "750 N m", "reverses")),
        (lambda r: r["gears"]["first"].update(input_torque=5e8), "gears.first.input_torque",
         ("500000000.0", "above the usual 1e+08 N m")),
    ],
)
def test_unusual_value_warned(paper_text, change, field, words):
    note = warned(mutate(paper_text, change), field, *words)
    assert "data kept as given" in note


def test_validate_train_returns_range_warnings(paper_text):
    bad = mutate(paper_text, lambda r: r["stages"][1].update(mesh_damping_ratio=0.3))
    train = gearjax.loads_train(bad, source=SOURCE, validate=False)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        messages = gearjax.validate_train(train, emit_warnings=False)
    assert record == []
    assert any("2.mesh_damping_ratio = 0.3" in m for m in messages)
    assert any("concentricity" in m for m in messages)  # geometry first, then ranges
    assert messages[: len(gearjax.geometry_warnings(train))] == gearjax.geometry_warnings(train)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        with pytest.warns(RangeWarning):
            assert gearjax.validate_train(train) == messages


def test_code_built_train_checked_too(paper_text):
    import dataclasses

    train = gearjax.loads_train(paper_text, source=SOURCE, validate=False)
    bad = dataclasses.replace(train, housing=dataclasses.replace(train.housing, braked=0.0))
    with pytest.raises(TrainError, match=r"housing\.braked = 0\.0: must be > 0"):
        gearjax.validate_train(bad, emit_warnings=False)


def test_warning_classes():
    assert issubclass(TrainWarning, UserWarning)
    assert issubclass(GeometryWarning, TrainWarning)
    assert issubclass(RangeWarning, TrainWarning)
    assert not issubclass(RangeWarning, GeometryWarning)


def test_bounds_listed_in_docs():
    doc = (REPO / "docs" / "input_bounds.md").read_text()
    for b in BOUNDS:
        assert f"`{b.key}`" in doc, b.key


# ------------------------------------------------------------------ 3. sizes, orders


def test_stiffness_harmonics_bounded(paper_text):
    refuse(mutate(paper_text, lambda r: r.update(stiffness_harmonics=1000)),
           "stiffness_harmonics", "1000", f"<= {MAX_HARMONICS}", "H x max(mu)", "square")


def test_transmission_error_pairs_bounded(paper_text):
    rows = [[1e-7, 0.0]] * (MAX_HARMONICS + 1)
    refuse(mutate(paper_text, _stage(0, "transmission_error", {"sun": rows})),
           "1.transmission_error.sun", "[[1e-07, 0.0]", f"at most {MAX_HARMONICS} pairs",
           f"got {MAX_HARMONICS + 1}", "square")


def test_ripple_rows_bounded(paper_text):
    rows = [[1.0, 0.0, 2.0]] * (MAX_HARMONICS + 1)
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(input_torque_ripple=rows)),
           "gears.first.input_torque_ripple", "[[1.0, 0.0]", f"at most {MAX_HARMONICS} rows")


@pytest.mark.parametrize("order, rule", [(2000.0, "<= 1000"), (1e-3, ">= 0.01"), (0.0, "> 0")])
def test_ripple_order_bounded(paper_text, order, rule):
    refuse(mutate(paper_text, lambda r: r["gears"]["first"].update(
        input_torque_ripple=[[1.0, 0.0, 2.0], [1.0, 0.0, order]])),
        "gears.first.input_torque_ripple", "", rule)


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "+nan"])
def test_nan_and_inf_refused(paper_text, bad):
    t = paper_text.replace("mesh_stiffness = { sun = 4.1e8", f"mesh_stiffness = {{ sun = {bad}")
    assert t != paper_text
    refuse(t, "2.mesh_stiffness.sun", bad.lstrip("+"), "finite number")


# ------------------------------------------------------------------ 4. integers and types


def test_teeth_integer_overflow(paper_text):
    t = paper_text.replace("teeth = { sun = 30,", "teeth = { sun = 99999999999999999999,")
    assert t != paper_text
    refuse(t, "1.teeth.sun", "99999999999999999999", "<= 10000")


@pytest.mark.parametrize(
    "value, shown, rule",
    [(30.0, "30.0", "no decimal point"), (True, "True", "integer"), ("30", "'30'", "integer"),
     ([30], "[30]", "integer"), ({"n": 30}, "{'n': 30}", "integer"), (1e300, "1e+300", "integer")],
)
def test_integer_key_wrong_type(paper_text, value, shown, rule):
    refuse(mutate(paper_text, _sub(0, "teeth", "ring", value)), "1.teeth.ring", shown, rule)


def test_float_key_integer_too_large(paper_text):
    t = paper_text.replace("planet_mass = 0.300", "planet_mass = 1" + "0" * 400)
    assert t != paper_text
    refuse(t, "1.planet_mass", "1000", "finite number")


# ------------------------------------------------------------------ 5. files


def file_refused(path, *words) -> str:
    with pytest.raises(TrainError) as info:
        load_train(path)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert msg.startswith(f"{path}: file = "), msg
    for w in words:
        assert w in msg, msg
    return msg


def test_binary_file_refused(tmp_path):
    p = tmp_path / "binary.toml"
    p.write_bytes(bytes(range(256)) * 4)
    file_refused(p, "NUL bytes")
    p.write_bytes(b"name = '\xe4\xf6'\n")  # Latin-1
    file_refused(p, "not UTF-8", "0xe4", "line 1")


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le"])
def test_utf16_file_refused(tmp_path, paper_text, encoding):
    p = tmp_path / "utf16.toml"
    p.write_bytes(paper_text.encode(encoding))
    file_refused(p, "UTF-16" if encoding == "utf-16" else "NUL bytes", "UTF-8")


def test_directory_missing_and_unreadable_refused(tmp_path, monkeypatch):
    file_refused(tmp_path, "cannot be read", "directory")
    file_refused(tmp_path / "nope.toml", "cannot be read", "No such file")
    p = tmp_path / "locked.toml"
    p.write_text("x = 1\n")

    def denied(self):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_bytes", denied)
    file_refused(p, "cannot be read", "Permission denied")


def test_utf8_byte_order_mark_accepted(tmp_path, paper_text):
    p = tmp_path / "windows.toml"
    p.write_bytes(b"\xef\xbb\xbf" + paper_text.replace("\n", "\r\n").encode())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        train = load_train(p)
        assert train.stage_ids == ("1", "2")
        assert gearjax.loads_train("\ufeff" + paper_text).stage_ids == ("1", "2")


@pytest.mark.parametrize(
    "bad, words",
    [("x = [1, 2\n", ("line", "column")), ("[stages\nid = 1\n", ("line 1", "column")),
     ('name = "open\n', ("line",)), ("a = " + "[" * 50_000, ("nested too deeply",))],
)
def test_malformed_toml_one_line(bad, words):
    with pytest.raises(TrainError) as info:
        gearjax.loads_train(bad, source=SOURCE)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(SOURCE + ": file = "), msg
    for w in words:
        assert w in msg, msg


def test_message_stays_one_line_with_odd_names(paper_text):
    raw = tomllib.loads(paper_text)
    raw["gears"]["bad\ngear"] = raw["gears"].pop("second")
    raw["gears"]["bad\ngear"]["input_torque"] = float("nan")
    with pytest.raises(TrainError) as info:
        load(tomli_w.dumps(raw), source="odd\nname.toml")
    msg = str(info.value)
    assert "\n" not in msg and "bad\\ngear" in msg and "odd\\nname.toml" in msg


# ------------------------------------------------------------------ 7. corpus

# Keys where a value the corpus makes is legitimately allowed ("zero": 0, "negative": < 0).
ZERO_OK = re.compile(r"(half_backlash|housing\.free|phase_deg|input_torque$|drag_torque|"
                     r"mesh_damping_ratio|stiffness_harmonics|planet_angles_deg\[0\]|"
                     r"transmission_error\.\w+\[\d+\]\[[01]\]|input_torque_ripple\[\d+\]\[[01]\])")
NEGATIVE_OK = re.compile(r"(phase_deg|input_torque$|transmission_error\.\w+\[\d+\]\[1\]|"
                         r"input_torque_ripple\[\d+\]\[[01]\])")


def _corpus_base(text: str) -> dict:
    raw = tomllib.loads(text)
    raw["stages"][0]["transmission_error"] = {"sun": [[1.0e-6, 30.0]]}
    raw["gears"]["first"]["input_torque_ripple"] = [[10.0, 45.0, 2.0]]
    raw["gears"]["first"]["drag_torque"] = 1.0
    return raw


def _numeric_leaves(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _numeric_leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numeric_leaves(v, path + (i,))
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield path, node


def _name(path) -> str:
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (("." if out else "") + p)
    return out


def _set(raw, path, value):
    node = raw
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value


def corpus(text: str):
    """(name, bytes, allowed) for every broken file; ``allowed``: it may load."""
    base = _corpus_base(text)
    for path, v in _numeric_leaves(base):
        key = _name(path)
        variants = {
            "nan": math.nan, "inf": math.inf, "-inf": -math.inf,
            "negative": -abs(v) if v else -1.0, "zero": type(v)(0), "huge": 1e300,
            "string": str(v), "bool": True, "array": [v], "table": {"value": v},
        }
        for kind, value in variants.items():
            raw = copy.deepcopy(base)
            _set(raw, path, value)
            allowed = ((kind == "zero" and (ZERO_OK.search(key) or v == 0))
                       or (kind == "negative" and NEGATIVE_OK.search(key) is not None))
            yield f"{key}={kind}", tomli_w.dumps(raw).encode(), bool(allowed)
    yield "toml:unclosed-array", b"x = [1, 2\n", False
    yield "toml:bad-header", b"[stages\nid = 1\n", False
    yield "toml:duplicate-key", b"name = 'a'\nname = 'b'\n", False
    yield "toml:bare-text", b"this is not toml at all\n", False
    yield "toml:empty", b"", False
    yield "toml:deep", b"a = " + b"[" * 50_000, False
    yield "binary", bytes(range(256)) * 8, False
    yield "binary-no-nul", bytes(range(128, 256)) * 8, False
    yield "utf-16", text.encode("utf-16"), False
    yield "utf-16-be", text.encode("utf-16-be"), False


def test_corpus_every_break_refused_on_one_line(tmp_path, paper_text):
    p = tmp_path / "broken.toml"
    problems, n = [], 0
    for name, data, allowed in corpus(paper_text):
        n += 1
        p.write_bytes(data)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", TrainWarning)
                load_train(p)
        except TrainError as e:
            msg = str(e)
            if allowed:
                problems.append(f"{name}: refused although allowed: {msg}")
            elif "\n" in msg or not msg.startswith(f"{p}: "):
                problems.append(f"{name}: not one line naming the file: {msg!r}")
        except Exception as e:  # noqa: BLE001  anything else is a bug
            problems.append(f"{name}: {type(e).__name__}: {e}")
        else:
            if not allowed:
                problems.append(f"{name}: loaded although it should be refused")
    assert n > 500
    assert not problems, "\n".join(problems)


# ------------------------------------------------------------------ CLI


def test_cli_refuses_broken_files_on_one_line(tmp_path, paper_text):
    cases = {
        "braked0.toml": mutate(paper_text, lambda r: r["housing"].update(braked=0.0)).encode(),
        "nan.toml": paper_text.replace("mesh_stiffness = { sun = 4.1e8",
                                       "mesh_stiffness = { sun = nan").encode(),
        "teeth.toml": paper_text.replace("teeth = { sun = 30,",
                                         "teeth = { sun = 99999999999999999999,").encode(),
        "binary.toml": bytes(range(256)) * 4,
        "utf16.toml": paper_text.encode("utf-16"),
    }
    exe = Path(sys.executable).with_name("gearjax")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "gearjax._cli"]
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    procs = {}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        procs[name] = subprocess.Popen([*cmd, "info", str(tmp_path / name)], env=env,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, (name, err)
        lines = err.splitlines()
        assert len(lines) == 1, (name, err)
        assert "Traceback" not in err and out == "", (name, err)
        assert str(tmp_path / name) in lines[0], (name, err)


def test_check_ranges_passes_bundled(paper_text):
    train = gearjax.loads_train(paper_text, source=SOURCE, validate=False)
    assert check_ranges(train) == []
