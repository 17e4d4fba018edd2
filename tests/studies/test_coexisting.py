"""Bands of coexisting stable states, from a sweep's points in branch order."""

import numpy as np
import xarray as xr

from gearjax._studies.sweep.summary import coexisting_bands


def dataset(f, stable, branch=None):
    data = {"mesh_frequency_hz": ("point", np.asarray(f, float)),
            "stable": ("point", np.asarray(stable, float))}
    if branch is not None:
        data["branch"] = ("point", np.asarray(branch))
    return xr.Dataset(data)


def test_hysteresis_between_two_folds():
    # up 1..5 stable, fold at 5, back to 3 unstable, fold at 3, up to 7 stable
    f = [1, 2, 3, 4, 5, 4.5, 4, 3.5, 3, 3.5, 4, 5, 6, 7]
    s = [1, 1, 1, 1, 1, 0, 0, 0, 0, 1, 1, 1, 1, 1]
    assert coexisting_bands(dataset(f, s)) == [(3.5, 5.0)]


def test_separate_branches_overlap_and_unknown_is_not_stable():
    f = [1, 2, 3, 4, 2.5, 3.5, 6, 7]
    s = [1, 1, 1, 1, 1, 1, np.nan, np.nan]
    b = [0, 0, 0, 0, 1, 1, 1, 1]
    assert coexisting_bands(dataset(f, s, b)) == [(2.5, 3.5)]


def test_one_state_everywhere_gives_no_band():
    assert coexisting_bands(dataset([1, 2, 3, 4], [1, 1, 0, 1])) == []
    # runs that only touch (a stability flicker) do not coexist
    assert coexisting_bands(dataset([1, 2, 3, 3, 4], [1, 1, 1, 1, 1], [0, 0, 0, 1, 1])) == []
