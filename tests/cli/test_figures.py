"""Figures people read: one separation map however many branches, labelled axes, and
legends outside the data."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.image
import numpy as np
import pytest
import xarray as xr

from gearjax._plot import figures as _figures
from gearjax._plot import save as _save


def zigzag_sweep(turns: int):
    """A made-up sweep whose frequency turns ``turns`` times (folds), with a restart
    (``branch`` 1) after them; the unstable stretches are the ones going down."""
    f = [1000.0]
    for k in range(turns + 1):
        step = 10.0 if k % 2 == 0 else -5.0
        f += [f[-1] + step * (i + 1) for i in range(4)]
    f = np.array(f + [f[-1] + 5.0 + 20.0 * i for i in range(5)])
    P, m = f.size, 3
    going_down = np.r_[False, np.diff(f) < 0]
    branch = np.r_[np.zeros(P - 5, int), np.ones(5, int)]
    sep = np.linspace(0.0, 0.4, P * m).reshape(P, m)
    return xr.Dataset(
        {"mesh_frequency_hz": ("point", f),
         "stable": ("point", np.where(going_down, 0, 1).astype(np.int8)),
         "branch": ("point", branch),
         "converged": ("point", np.ones(P, bool)),
         "rms_force": (("point", "mesh"), 100.0 + 10.0 * np.arange(P)[:, None] * np.ones(m)),
         "separation": (("point", "mesh"), sep)},
        coords={"mesh": ["1.sp1", "1.rp1", "2.sp1"], "stage": ("mesh", ["1", "1", "2"]),
                "side": ("mesh", ["sun", "ring", "sun"]), "planet": ("mesh", [1, 1, 1])},
        attrs={"reference_stage": "1"})


@pytest.mark.parametrize("turns", [0, 3, 25])
def test_separation_figure_is_one_panel_and_a_colour_bar_however_many_branches(turns):
    ds = zigzag_sweep(turns)
    branches = _figures.separation_branches(ds)
    assert len(branches) == turns + 2  # between the folds, and the restart
    fig = _figures.separation_figure(ds)
    panel, bar = fig.axes
    assert [t.get_text() for t in panel.get_yticklabels()] == ["1.sp1", "1.rp1", "2.sp1"]
    assert "(kHz)" in panel.get_xlabel() and panel.get_ylabel() == "mesh"
    assert "share of period" in bar.get_ylabel()
    assert panel.get_legend() is None  # the legend is the figure's, below the panel
    if turns:
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any(l.startswith("fold") for l in labels)
        assert any(l.startswith("row split") for l in labels)  # stable states coexist


def test_a_restart_is_not_joined_to_the_branch_before():
    ds = zigzag_sweep(0)
    first, second = _figures.separation_branches(ds)
    assert first.points[-1] + 1 == second.points[0]  # no shared point across a jump


def test_separation_map_keeps_stable_states_and_the_smaller_response_on_top():
    ds = zigzag_sweep(1)  # up 1000-1040, back to 1020 (unstable), a jump, up 1025-1105
    smap = _figures._separation_map(ds, _figures.separation_branches(ds))
    centres = 0.5 * (smap.edges_hz[1:] + smap.edges_hz[:-1])
    inside = (centres > 1026) & (centres < 1039)  # both upward (stable) branches
    assert np.all(smap.count[inside] == 2) and not np.any(smap.unstable)
    assert np.all(smap.count[(centres > 1021) & (centres < 1024)] == 1)  # unstable one left
    # the first branch has the smaller RMS force: its (smaller) separation comes first
    assert np.all(smap.values[inside, 0, 0] < smap.values[inside, 1, 0])


def test_cli_figures_have_labelled_axes_and_the_legend_below(tmp_path, monkeypatch):
    ds = zigzag_sweep(3)
    ds["dlf"] = ds["rms_force"]
    ds["mean_torque"] = ds["rms_force"]
    kept = {}

    def keep(fig, path, **kw):
        kept["fig"] = fig
        fig.canvas.print_figure(path, **kw)

    for what in ("rms", "separation"):
        out = tmp_path / f"{what}.png"
        monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                            lambda self, path, **kw: keep(self, path, **kw))
        _save.plot_sweep(ds, str(out), what=what)
        fig = kept["fig"]
        panels = [ax for ax in fig.axes if ax.get_visible()]
        assert all(ax.get_ylabel() for ax in panels)
        assert all("mesh frequency (kHz)" in ax.get_xlabel() for ax in fig.axes[-2:])
        assert all(ax.get_legend() is None for ax in panels) and len(fig.legends) == 1
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert "stable" in labels and "unstable" in labels
        assert matplotlib.image.imread(out).shape[0] > 500


def test_the_legend_covers_every_planet_count_and_slow_gears_read_in_hz(tmp_path,
                                                                        monkeypatch):
    """Stage 1 with three planets, stage 2 with four, meshes at 30-45 Hz (a wind
    turbine's low-speed stage): every planet number is in the legend, in the colour it
    is drawn with, and the frequency axis reads in Hz, not 0.03-0.045 kHz."""
    meshes = ([f"1.sp{i}" for i in (1, 2, 3)] + [f"1.rp{i}" for i in (1, 2, 3)]
              + [f"2.sp{i}" for i in (1, 2, 3, 4)] + [f"2.rp{i}" for i in (1, 2, 3, 4)])
    f = np.linspace(30.0, 45.0, 6)
    ds = xr.Dataset(
        {"mesh_frequency_hz": ("point", f), "stable": ("point", np.ones(6, np.int8)),
         "branch": ("point", np.zeros(6, int)), "converged": ("point", np.ones(6, bool)),
         "rms_force": (("point", "mesh"), np.outer(1 + f / 100, np.arange(1, 15)))},
        coords={"mesh": meshes, "stage": ("mesh", [m[0] for m in meshes]),
                "side": ("mesh", ["sun" if ".sp" in m else "ring" for m in meshes]),
                "planet": ("mesh", [int(m[-1]) for m in meshes])},
        attrs={"reference_stage": "1"})
    figures = []
    monkeypatch.setattr("matplotlib.figure.Figure.savefig",
                        lambda fig, *a, **k: figures.append(fig))
    _save.plot_sweep(ds, str(tmp_path / "sweep.png"))
    (fig,) = figures
    legend = fig.legends[0]
    labels = [t.get_text() for t in legend.get_texts()]
    assert [l for l in labels if l.startswith("planet")] == [f"planet {p}" for p in (1, 2, 3, 4)]
    drawn = {line.get_color() for ax in fig.axes for line in ax.get_lines()}
    shown = {h.get_color() for h, l in zip(legend.legend_handles, labels)
             if l.startswith("planet")}
    assert drawn <= shown | {"0.3"}
    assert all(ax.get_xlabel().endswith("mesh frequency (Hz)") for ax in fig.axes[-2:])


def test_a_flat_response_is_drawn_flat(tmp_path, monkeypatch):
    """Forces that vary by 0.2 N on 9,631 N fill a twentieth of the panel at most, not
    its whole height."""
    ds = zigzag_sweep(0)
    ds["rms_force"] = ds["rms_force"] * 0 + 9631.0 + np.linspace(0, 0.2, ds.sizes["point"])[:, None]
    figures = []
    monkeypatch.setattr("matplotlib.figure.Figure.savefig",
                        lambda fig, *a, **k: figures.append(fig))
    _save.plot_sweep(ds, str(tmp_path / "flat.png"))
    for ax in figures[0].axes:
        if ax.get_lines():
            lo, hi = ax.get_ylim()
            assert hi - lo >= 0.02 * 9631.0 * 0.999 and lo < 9631.0 < hi


def test_a_sweep_stopped_by_its_point_budget_is_marked_where_it_stopped(tmp_path,
                                                                       monkeypatch):
    ds = zigzag_sweep(0)
    ds.attrs["stop"] = "max_points"
    figures = []
    monkeypatch.setattr("matplotlib.figure.Figure.savefig",
                        lambda fig, *a, **k: figures.append(fig))
    _save.plot_sweep(ds, str(tmp_path / "stopped.png"))
    labels = [t.get_text() for t in figures[0].legends[0].get_texts()]
    assert "stopped here: its budget of points used" in labels
    last = float(ds["mesh_frequency_hz"][-1]) / 1e3
    marks = [line for ax in figures[0].axes for line in ax.get_lines()
             if line.get_linestyle() == "-." and np.allclose(line.get_xdata(), last)]
    assert len(marks) == len([ax for ax in figures[0].axes if ax.get_lines()])


def wind_points(f, rpm_per_hz=None, converged=True):
    """Results at the mesh frequencies ``f`` (Hz) of a one-stage, three-planet gear, with
    ``input_rpm`` proportional to them where ``rpm_per_hz`` is given."""
    meshes = [f"1.sp{i}" for i in (1, 2, 3)] + [f"1.rp{i}" for i in (1, 2, 3)]
    f = np.asarray(f, float)
    data = {"mesh_frequency_hz": ("point", f),
            "converged": ("point", np.full(f.size, converged)),
            "rms_force": (("point", "mesh"), np.outer(1000 + f, np.arange(1, 7)))}
    if rpm_per_hz is not None:
        data["input_rpm"] = ("point", rpm_per_hz * f)
    return xr.Dataset(data, coords={
        "mesh": meshes, "stage": ("mesh", ["1"] * 6),
        "side": ("mesh", ["sun"] * 3 + ["ring"] * 3), "planet": ("mesh", [1, 2, 3] * 2)},
        attrs={"reference_stage": "1"})


def _kept_figures(monkeypatch):
    figures = []
    monkeypatch.setattr("matplotlib.figure.Figure.savefig",
                        lambda fig, *a, **k: figures.append(fig))
    return figures


def test_sweeps_carry_an_input_speed_axis_in_rpm(tmp_path, monkeypatch):
    """Mesh frequency and input speed are proportional for a gear: the top panels get a
    second axis in rpm (a run-up is read in input speed), where the results give it."""
    ds = wind_points(np.linspace(30.0, 45.0, 6), rpm_per_hz=0.4)
    ds["stable"] = ("point", np.ones(6, np.int8))
    ds["branch"] = ("point", np.zeros(6, int))
    figures = _kept_figures(monkeypatch)
    _save.plot_sweep(ds, str(tmp_path / "sweep.png"))
    _save.plot_sweep(ds.drop_vars("input_rpm"), str(tmp_path / "plain.png"))
    with_rpm, plain = figures
    top = [child for ax in with_rpm.axes for child in ax.child_axes]
    assert len(top) == 2 and all(t.get_xlabel() == "input speed (rpm)" for t in top)
    lo, hi = with_rpm.axes[0].get_xlim()
    forward = top[0]._functions[0]
    assert forward(np.asarray([lo, hi])) == pytest.approx([0.4 * lo, 0.4 * hi])
    assert not [child for ax in plain.axes for child in ax.child_axes]


def test_verify_points_without_a_curve_are_markers_where_solutions_are(tmp_path,
                                                                       monkeypatch):
    """Without a sweep to draw, the harmonic-balance points are markers at their own
    frequencies (in the same unit as the integration's), not a line guessed between
    them; a long title is wrapped, not clipped."""
    f = [30.0, 37.0, 45.0]
    hb, ni = wind_points(f), wind_points(f)
    figures = _kept_figures(monkeypatch)
    title = "wind turbine main gearbox, low-speed planetary stage: " * 4
    _save.plot_verify(hb, ni, str(tmp_path / "verify.png"), title=title)
    (fig,) = figures
    drawn = [line for ax in fig.axes for line in ax.get_lines() if len(line.get_xdata())]
    for line in drawn:
        assert line.get_linestyle() in ("None", "")  # no line joins the points
        np.testing.assert_allclose(line.get_xdata(), f)  # both in Hz
    assert {line.get_marker() for line in drawn} == {"+", "o"}
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "harmonic balance" in labels and "converged" in labels
    lines = fig._suptitle.get_text().split("\n")
    assert len(lines) > 1 and all(len(l) <= _save.TITLE_WIDTH for l in lines)
