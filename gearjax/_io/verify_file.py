"""A verification's results file: NetCDF with the comparison in the root group and the
two results Datasets (harmonic balance, time integration) in groups ``hb`` and ``ni``."""

from __future__ import annotations

import json
import pathlib

import numpy as np
import xarray as xr

from .._version import __version__
from .results import checksummed, read_netcdf


def save_verify(result, path) -> pathlib.Path:
    """Write ``result`` (a :class:`gearjax._studies.verify.VerifyResult`: ``hb``, ``ni``,
    ``rel_diff``, ``ok``, ``tolerance``) to the NetCDF file ``path`` (h5netcdf): the root group holds
    ``rel_diff`` and ``ok`` ``(point, mesh)`` and the attributes ``kind = "verify"``,
    ``tolerance``, ``gear``, ``train_toml``, ``gearjax_version`` (and ``reference``, JSON,
    where the integration reference is windowed statistics); the groups ``hb`` and
    ``ni`` hold the two results Datasets (``_results`` layout). Any other suffix than
    ``.nc`` is refused with a ``ValueError``. **Returns:** the path written."""
    path = pathlib.Path(path)
    if path.suffix.lower() != ".nc":
        raise ValueError(f"verify results file {str(path)!r} has suffix {path.suffix!r}: "
                         "use .nc (NetCDF, groups hb and ni)")
    hb = result.hb
    root = xr.Dataset(
        {"rel_diff": (("point", "mesh"), np.asarray(result.rel_diff, float), {
            "units": "1", "long_name": "|rms_ni - rms_hb| / largest rms_hb of the stage"}),
         "ok": (("point", "mesh"), np.asarray(result.ok, bool), {
             "units": "1", "long_name": "both converged and rel_diff <= tolerance"})},
        coords=hb.coords.to_dataset()[["point", "mesh", "stage", "side", "planet"]].coords,
        attrs={"kind": "verify", "tolerance": float(result.tolerance),
               "gear": hb.attrs.get("gear", ""), "train_toml": hb.attrs.get("train_toml", ""),
               "reference_stage": hb.attrs.get("reference_stage", ""),
               "gearjax_version": __version__})
    if getattr(result, "reference", None) is not None:  # a quasi-periodic gear's windows
        root.attrs["reference"] = json.dumps(result.reference)
    root.to_netcdf(path, mode="w", engine="h5netcdf", encoding=checksummed(root))
    for group, ds in (("hb", result.hb), ("ni", result.ni)):
        ds.to_netcdf(path, mode="a", group=group, engine="h5netcdf", encoding=checksummed(ds))
    return path


def load_verify(path):
    """``(root, hb, ni)`` Datasets of a file written by :func:`save_verify`.

    **Raises:** as :func:`~gearjax._io.results.read_netcdf`."""
    return tuple(read_netcdf(path, group=g) for g in (None, "hb", "ni"))
