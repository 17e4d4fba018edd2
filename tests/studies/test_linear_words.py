"""The words of a linear sweep, on a five-planet helicopter main
stage (tests/data/helicopter_five_planets.toml): a multiplier outside the unit circle is
a parametric instability (unbounded), never a bifurcation of the backlash model; the
largest force is taken over stable points inside the band; a result whose alternating
mesh force exceeds the static one carries a warning naming the first frequency.

One small linear sweep (K = 4, three grid points and the refinement's eleven more),
downwards from 7000 to 6000 Hz: stable at the top, parametrically unstable below about
6900 Hz (a multiplier through -1, near twice the 3.2 kHz in-phase mode), and the teeth
of every ring mesh would separate below about 6600 Hz (dynamic load factor 2.5).
"""

import contextlib
import dataclasses
import io
import json
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import gearjax as gj
from gearjax._cli import main
from gearjax._engine import hb as _hb
from gearjax._engine.responses import mesh_time_history
from gearjax._io import results as _results
from gearjax._studies.sweep import summary as _summary

TRAIN = pathlib.Path(__file__).parent.parent / "data" / "helicopter_five_planets.toml"
K = 4
BAND = ["--from", "7000", "--to", "6000", "--points", "3", "--harmonics", str(K)]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """``(JSON, stderr, dataset, text stdout, text stderr)`` of the linear sweep, asked
    for as JSON with a results file, then as text (the programs compiled already)."""
    nc = tmp_path_factory.mktemp("heli") / "lin.nc"
    out, err = _run(["sweep", str(TRAIN), "--linear", *BAND, "--json", "--out", str(nc)])
    text, text_err = _run(["sweep", str(TRAIN), "--linear", *BAND])
    return json.loads(out), err, gj.load_results(nc), text, text_err


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main(argv) == 0
    return out.getvalue(), err.getvalue()


def test_linear_instability_is_parametric_and_unbounded(swept):
    data, _, _, text, _ = swept
    changes = data["bifurcations"]
    assert changes, "the band crosses a boundary of the parametric instability"
    pts = data["points"]  # in sweep order: a change lies between two neighbours
    for b in changes:
        assert b["kind"] == "parametric_instability"
        assert b["crossing"] == "period_doubling"  # the multiplier leaves through -1
        (pair,) = [(p, q) for p, q in zip(pts, pts[1:]) if p["stable"] != q["stable"]
                   and (p["mesh_frequency_hz"] + q["mesh_frequency_hz"]) / 2
                   == pytest.approx(b["mesh_frequency_hz"])]
        (unstable,) = [p for p in pair if p["stable"] is False]
        assert b["multiplier"] == pytest.approx(unstable["max_multiplier"]) and b["multiplier"] > 1
    (note,) = data["bifurcation_notes"]
    assert note["kind"] == "parametric_instability"
    unstable = [p for p in data["points"] if p["stable"] is False]
    assert note["multiplier"] == pytest.approx(max(p["max_multiplier"] for p in unstable))
    assert note["from_hz"] == pytest.approx(min(p["mesh_frequency_hz"] for p in unstable))
    assert note["note"].startswith(f"parametric instability (unbounded) over "
                                   f"{note['from_hz']:.1f}-{note['to_hz']:.1f} Hz: largest "
                                   f"Floquet multiplier {note['multiplier']:.4f}")
    # the words of the backlash model appear nowhere
    for words in (json.dumps(data["bifurcation_notes"]), text):
        assert "Neimark" not in words and "torus" not in words
        assert "period doubling" not in words and "fold" not in words
    assert (f"parametric instability (unbounded), largest Floquet multiplier "
            f"{changes[0]['multiplier']:.4f} (through -1)") in text


def test_largest_force_over_stable_points_inside_the_band(swept):
    data, _, _, text, _ = swept
    (row,) = data["largest"]
    stable = [p for p in data["points"] if p["stable"] and p["converged"]]
    rms = {(p["mesh_frequency_hz"], m["name"]): m["rms_force"]
           for p in stable for m in p["meshes"]}
    (f, mesh), top = max(rms.items(), key=lambda kv: kv[1])
    assert (row["rms_force"], row["mesh_frequency_hz"]) == (top, f)
    assert row["points"] == len(stable) < row["of"] == len(data["points"])
    # an unstable point (not a state the gear settles to) has a larger force
    every = max(m["rms_force"] for p in data["points"] for m in p["meshes"])
    assert every > 1.5 * top
    assert (f"stage main: largest RMS mesh force {top:.1f} N at {f:.1f} Hz ({row['mesh']}); "
            f"largest separation share 0.000 (stable points inside 6000.0-7000.0 Hz: "
            f"{len(stable)} of {len(data['points'])})") in text


def test_contact_loss_is_warned_at_the_first_frequency(swept):
    data, err, ds, _, text_err = swept
    loss = data["contact_loss"]
    # sweeping down: the first point (from 7000 Hz) whose loaded deflection reverses
    pts = sorted(data["points"], key=lambda p: -p["mesh_frequency_hz"])
    lost = [any(m["back_contact"] for m in p["meshes"]) for p in pts]
    first = lost.index(True)
    assert first > 0 and loss["mesh_frequency_hz"] == pts[first]["mesh_frequency_hz"]
    assert loss["points"] == sum(lost) and loss["of"] == len(pts)
    line = loss["warning"]
    assert line.startswith(f"linear result past its validity, first at "
                           f"{loss['mesh_frequency_hz']:.1f} Hz: the alternating mesh force "
                           f"exceeds the static one there (mesh {loss['mesh']}: ")
    assert "teeth would leave contact" in line and "\n" not in line
    assert data["warnings"] == [line]  # the JSON, and one line on stderr, text and JSON
    assert f"warning: {line}" in err.splitlines()
    assert f"warning: {line}" in text_err.splitlines()
    # independently, from the member displacements in the results file: the total force
    # of that mesh changes sign there, and no loaded mesh's does at the point before
    system = gj.assemble(gj.load_train(TRAIN))
    system = dataclasses.replace(system, backlash=jnp.zeros(system.n_meshes))
    problem = _hb.hb_problem(system, _hb.HarmonicBalance(n_harmonics=K))
    f_ds = ds["mesh_frequency_hz"].values

    def forces(f_hz):
        k = int(np.argmin(np.abs(f_ds - f_hz)))
        X = jnp.asarray(_results.displacement_coefficients(ds, k))
        return np.asarray(mesh_time_history(problem, X, float(ds["omega"].values[k]))[2])

    j = list(system.mesh_labels).index(loss["mesh"])
    assert forces(loss["mesh_frequency_hz"])[j].min() < 0
    assert forces(pts[first - 1]["mesh_frequency_hz"]).min() > 0


def test_jumps_and_largest_ignore_the_band_edges_and_points_outside():
    """A backlash sweep asked for 1800-2400 Hz whose continuation stepped round a fold
    below the band (to 1562.7 Hz, unstable, with the largest force) and past its top
    end: the band's ends are no jumps, and the largest force is the stable in-band one."""
    f = [1800.0, 1900.0, 2000.0, 2100.0, 2200.0, 1562.7, 1700.0, 1900.0, 2000.0, 2300.0,
         2400.5]
    stable = [1, 1, 1, 1, 0, 1, 1, 1, 1, 1, 1]
    branch = [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1]
    stable[5] = 0  # the excursion below the band: unstable, with the largest force
    rms = [[10.0], [12.0], [14.0], [16.0], [30.0], [99.0], [11.0], [20.0], [21.0], [18.0],
           [50.0]]
    ds = xr.Dataset(
        {"mesh_frequency_hz": ("point", f), "stable": ("point", stable),
         "branch": ("point", branch), "converged": ("point", [True] * len(f)),
         "rms_force": (("point", "mesh"), rms), "separation": (("point", "mesh"),
                                                               np.zeros((len(f), 1)))},
        coords={"mesh": ["main.sp1"], "stage": ("mesh", ["main"])},
        attrs={"solver": json.dumps({"linear": False, "band_hz": [1800.0, 2400.0]})})
    (band,) = _summary.coexisting_jumps(ds)
    assert (band["from_hz"], band["to_hz"]) == (1800.0, 2100.0)
    assert band["jump_up_hz"] == [2100.0] and band["jump_down_hz"] == []
    (row,) = _summary.largest_responses(ds)
    assert (row["rms_force"], row["mesh_frequency_hz"]) == (21.0, 2000.0)


def test_a_linear_time_integration_is_warned_too():
    """``simulate --linear`` at 2.5 kHz, below the resonances: the ring meshes' force
    (dynamic load factor 1.9) reverses for a sixth of the period."""
    train = gj.load_train(TRAIN)
    with pytest.warns(gj.ContactLossWarning, match=r"first at 2500\.0 Hz: .*\(mesh main\.rp"):
        ds = gj.simulate_gear(train, at_hz=[2500.0], linear=True)
    loss = gj.contact_loss(ds)
    assert 0.1 < loss["reversed_share"] < 0.25 and loss["points"] == loss["of"] == 1
    # results with backlash model the separation themselves: nothing to warn of
    ds.attrs["solver"] = json.dumps({**json.loads(ds.attrs["solver"]), "linear": False})
    assert gj.contact_loss(ds) is None


@pytest.mark.slow
def test_a_linear_verification_is_warned_too():
    """``verify --linear`` at the same 2.5 kHz (the integration's program above reused):
    harmonic balance and integration agree, and the harmonic-balance result is warned
    about where the teeth would leave contact, as a sweep's would be. Slow (about 18 s on
    2 cores): it compiles verify's harmonic-balance programs for this train, which no
    other test builds; the claim needs a verification, not a sweep."""
    train = gj.load_train(TRAIN)
    with pytest.warns(gj.ContactLossWarning, match=r"first at 2500\.0 Hz: .*\(mesh main\.rp"):
        result = gj.verify_gear(train, at_hz=[2500.0], linear=True, harmonics=K)
    assert bool(np.all(result.ok))
    assert gj.contact_loss(result.hb)["mesh"] == gj.contact_loss(result.ni)["mesh"]
