"""Results as data: an ``xarray.Dataset`` per sweep or simulation, NetCDF / CSV / JSON.

Layout (interface.md, Results files):

- dimensions ``point`` (solution points in solve order), ``mesh`` (every mesh of
  every stage, flat, named like ``"1.sp1"``) and ``stage_id`` (stages in file
  order; not ``stage``, which is the name of the mesh coordinate below);
- coordinates ``point`` (0..P-1), ``mesh`` (names), ``stage``, ``side``
  (``sun``/``ring``), ``planet`` (1-based) along ``mesh``, ``stage_id``;
- per point: ``mesh_frequency_hz`` (reference stage, Hz), ``stage_mesh_frequency_hz``
  (``point, stage_id``, Hz), ``input_rpm`` (rpm), ``omega`` (base frequency Omega,
  rad/s), ``result`` (code, string), ``converged`` (bool), ``stable`` (int8: 1 stable,
  0 unstable, -1 unknown, e.g. time integration; CF ``flag_values`` /
  ``flag_meanings`` say so), optionally ``period`` (base periods per response
  period);
- per mesh, optionally: ``static_force`` (N);
- per point and mesh: the :class:`~gearjax._engine.responses.MeshResponses` fields
  ``mean_force``, ``rms_force``, ``max_force`` (N), ``dlf``, ``separation``,
  ``back_contact`` (1), ``mean_torque`` (N m);
- harmonic-balance sweeps also hold the member displacements
  (:func:`add_displacement_harmonics`): coordinates ``dof`` (member names, e.g.
  ``"1.sun"``) and ``harmonic`` (0..H), ``harmonics`` per point (its K; the segments of
  a sweep differ) and ``displacement_cos`` / ``displacement_sin`` (``point, dof,
  harmonic``; rad, or m for translations; zero above the point's K): ``x(t) = cos_0 +
  sum_k cos_k cos(k Omega t / eta) + sin_k sin(k Omega t / eta)``. They are left out of
  CSV.

Every variable has a ``units`` attribute. Global attributes: ``train_toml`` (the
train file text), ``gear``, ``solver`` (settings as a JSON string),
``gearjax_version``, ``created`` (ISO 8601, UTC), plus any the caller adds; sweeps
and simulations add ``kind`` (``"sweep"``, ``"simulate"``), which ``gearjax plot``
dispatches on (``gearjax._plot.save.RESULT_PLOTS``), and ``command`` (how the run was
asked for: the command line, or empty where a Python caller gave none).

CSV has one row per point and mesh with the columns ``point, mesh, stage, side,
planet, mesh_frequency_hz, stage_mesh_frequency_hz`` (the mesh's own stage),
``input_rpm, omega, result, converged, stable`` (``True``/``False``/empty),
``period`` and ``static_force`` when present, then the responses; units as above.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import math
import os
import pathlib
import secrets
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
import xarray as xr

from .._errors import TrainError
from .._version import __version__
from .bearing_results import bearings_json
from .journal import sync_directory
from .._engine.responses import RESPONSE_FIELDS, RESPONSE_UNITS, MeshResponses
from .._engine.system import System

SUFFIXES = (".nc", ".csv")
"""Result file suffixes :func:`save_results` writes."""

STABLE, UNSTABLE, UNKNOWN = 1, 0, -1

_POINT_VARS = {
    "mesh_frequency_hz": ("Hz", "mesh frequency of the reference stage"),
    "input_rpm": ("rpm", "input shaft speed"),
    "omega": ("rad/s", "base frequency Omega: every stage mesh frequency is mu_n Omega"),
}
_RESPONSE_NAMES = {
    "mean_force": "mean mesh force",
    "rms_force": "RMS of the alternating mesh force",
    "max_force": "peak absolute mesh force",
    "dlf": "dynamic load factor max|F| / |F_static|",
    "separation": "share of the period in tooth separation (|p| <= b)",
    "back_contact": "share of the period in contact on the unloaded flank",
    "mean_torque": "mean transmitted torque r F_mean",
}


def mesh_coordinates(system: System) -> dict:
    """The mesh keywords of :func:`sweep_dataset` from an assembled ``System``:
    ``mesh_labels``, ``mesh_stage``, ``mesh_side``, ``mesh_planet``, ``stage_ids``
    (stages in order of first appearance)."""
    return dict(
        mesh_labels=tuple(system.mesh_labels),
        mesh_stage=tuple(system.mesh_group),
        mesh_side=tuple(system.mesh_side),
        mesh_planet=tuple(int(i) for i in system.mesh_planet),
        stage_ids=tuple(dict.fromkeys(system.mesh_group)),
    )


def sweep_dataset(
    responses: MeshResponses,
    *,
    mesh_labels: Sequence[str],
    mesh_stage: Sequence[str],
    mesh_side: Sequence[str],
    mesh_planet: Sequence[int],
    stage_ids: Sequence[str],
    mesh_frequency_hz,
    stage_mesh_frequency_hz,
    input_rpm,
    omega,
    result: Sequence[str],
    converged=None,
    stable=None,
    period=None,
    static_force=None,
    train_toml: str = "",
    gear: str = "",
    solver: Mapping | None = None,
    attrs: Mapping | None = None,
) -> xr.Dataset:
    """The results of ``P`` solution points as a Dataset (layout in the module docstring).

    **Arguments** (NumPy or JAX arrays, or lists):

    - ``responses``: :class:`~gearjax._engine.responses.MeshResponses` with fields ``(P, m)``
      (e.g. ``jax.vmap`` of :func:`~gearjax._engine.responses.mesh_responses`); failed points
      keep whatever values the solver left (their ``result`` says so);
    - ``mesh_labels``, ``mesh_stage``, ``mesh_side``, ``mesh_planet``: ``m`` names,
      stage ids, sides and 1-based planet numbers; ``stage_ids``: the ``S`` stages
      (:func:`mesh_coordinates` gives all five from a ``System``);
    - ``mesh_frequency_hz`` ``(P,)`` (Hz, reference stage), ``stage_mesh_frequency_hz``
      ``(P, S)`` (Hz), ``input_rpm`` ``(P,)`` (rpm), ``omega`` ``(P,)`` (rad/s);
    - ``result``: ``P`` result words (``"converged"``, ``"max_steps"``, ...:
      :func:`gearjax.result_word`);
    - ``converged``: ``(P,)`` bool (default: ``result == "converged"``);
    - ``stable``: ``(P,)`` of bool, or of float with NaN / ``None`` for unknown; ``None``:
      all unknown. Stored as int8 (1, 0, -1 unknown);
    - ``period``: ``(P,)`` base periods per response period, or ``None`` (not stored);
    - ``static_force``: ``(m,)`` static mesh forces (N), or ``None`` (not stored);
    - ``train_toml``, ``gear``: the train file text and the gear name; ``solver``:
      settings, stored as a JSON string; ``attrs``: more global attributes (dicts,
      lists and booleans are stored as JSON strings).

    **Returns:** ``xarray.Dataset``. Raises ``ValueError`` naming the argument whose
    shape does not fit.
    """
    labels = [str(v) for v in mesh_labels]
    m = len(labels)
    fields = {name: np.asarray(getattr(responses, name), dtype=float) for name in RESPONSE_FIELDS}
    first = fields[RESPONSE_FIELDS[0]]
    if first.ndim != 2 or first.shape[1] != m:
        raise ValueError(
            f"responses must have fields of shape (points, meshes) = (P, {m}), not {first.shape}")
    P = first.shape[0]
    for name, value in fields.items():
        _check(f"responses.{name}", value, (P, m))
    stages = [str(v) for v in stage_ids]
    S = len(stages)
    mesh_stage = _strings("mesh_stage", mesh_stage, m)
    mesh_side = _strings("mesh_side", mesh_side, m)
    mesh_planet = _check("mesh_planet", np.asarray(mesh_planet, dtype=np.int64), (m,))
    result = _strings("result", result, P)
    if converged is None:
        converged = [r == "converged" for r in result]
    converged = _check("converged", np.asarray(converged, dtype=bool), (P,))

    data = {}
    for name, (unit, long_name) in _POINT_VARS.items():
        value = {"mesh_frequency_hz": mesh_frequency_hz, "input_rpm": input_rpm,
                 "omega": omega}[name]
        data[name] = ("point", _check(name, np.asarray(value, dtype=float), (P,)),
                      {"units": unit, "long_name": long_name})
    data["stage_mesh_frequency_hz"] = (
        ("point", "stage_id"),
        _check("stage_mesh_frequency_hz", np.asarray(stage_mesh_frequency_hz, dtype=float),
               (P, S)),
        {"units": "Hz", "long_name": "mesh frequency of every stage"})
    data["result"] = ("point", np.asarray(result, dtype=str),
                      {"units": "1", "long_name": "solver result code"})
    data["converged"] = ("point", converged, {"units": "1", "long_name": "point converged"})
    data["stable"] = ("point", _stable_codes(stable, P), {
        "units": "1", "long_name": "stability of the periodic solution",
        "flag_values": np.array([UNKNOWN, UNSTABLE, STABLE], dtype=np.int8),
        "flag_meanings": "unknown unstable stable"})
    if period is not None:
        data["period"] = ("point", _check("period", np.asarray(period, dtype=float), (P,)),
                          {"units": "1", "long_name": "base periods per response period"})
    if static_force is not None:
        data["static_force"] = (
            "mesh", _check("static_force", np.asarray(static_force, dtype=float), (m,)),
            {"units": "N", "long_name": "static mesh force (mean stiffness, no backlash)"})
    for name in RESPONSE_FIELDS:
        data[name] = (("point", "mesh"), fields[name],
                      {"units": RESPONSE_UNITS[name], "long_name": _RESPONSE_NAMES[name]})


    global_attrs = {
        "train_toml": str(train_toml),
        "gear": str(gear),
        "solver": json.dumps(dict(solver or {}), sort_keys=True, default=_json_default),
        "gearjax_version": __version__,
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }
    for key, value in (attrs or {}).items():
        global_attrs[str(key)] = netcdf_attr(value)
    coords = {
        "point": ("point", np.arange(P, dtype=np.int64)),
        "mesh": ("mesh", np.asarray(labels, dtype=str)),
        "stage": ("mesh", np.asarray(mesh_stage, dtype=str), {"long_name": "stage id"}),
        "side": ("mesh", np.asarray(mesh_side, dtype=str), {"long_name": "sun or ring mesh"}),
        "planet": ("mesh", mesh_planet, {"long_name": "planet number (1-based)"}),
        "stage_id": ("stage_id", np.asarray(stages, dtype=str)),
    }
    return xr.Dataset(data, coords=coords, attrs=global_attrs)


def add_displacement_waves(ds: xr.Dataset, X, dof_labels: Sequence[str], orders,
                           waves, rates, units: str = "rad") -> xr.Dataset:
    """``ds`` with the member displacement coefficients of its points on a torus
    (model.md, "Incommensurate stages"): the torus counterpart of
    :func:`add_displacement_harmonics`.

    **Arguments:** ``X``: one ``(2P_p+1, n)`` array per point (coefficient rows of the
    point's basis, :mod:`gearjax._engine.aft`); ``orders`` ``(P, G)``: each point's orders
    ``K_g``; ``waves``: per point the ``P_p`` wave vectors of its half set (tuples of
    ``G`` ints), row order; ``rates`` ``(G,)``: each angle's rate over ``Omega``.

    **Adds:** coordinate ``wave_vector`` ``(wave, angle)`` (the union of the points' wave
    vectors, the zero vector first) and ``wave_frequency`` ``(wave,)`` (``k . rates``,
    times ``Omega``); ``displacement_cos`` and ``displacement_sin`` ``(point, dof,
    wave)``: ``x_i(t) = sum_k cos[., i, k] cos(k . theta) + sin[., i, k] sin(k .
    theta)``, ``theta_g = rates[g] Omega t`` (0 where a point's set lacks ``k``); and
    ``harmonics`` ``(point, angle)``, the orders.
    """
    P = ds.sizes["point"]
    K = np.asarray(orders, dtype=np.int64).reshape(P, -1)
    G = K.shape[1]
    union = [(0,) * G]
    index = {union[0]: 0}
    for ws in waves:
        for k in ws:
            if tuple(k) not in index:
                index[tuple(k)] = len(union)
                union.append(tuple(int(v) for v in k))
    n = len(dof_labels)
    cos = np.zeros((P, n, len(union)))
    sin = np.zeros((P, n, len(union)))
    for p, (Xp, ws) in enumerate(zip(X, waves)):
        Xp = _check(f"X[{p}]", np.asarray(Xp, dtype=float), (2 * len(ws) + 1, n))
        cols = np.asarray([index[tuple(k)] for k in ws], dtype=np.int64)
        cos[p, :, 0] = Xp[0]
        cos[p, :, cols] = Xp[1::2]
        sin[p, :, cols] = Xp[2::2]
    vectors = np.asarray(union, dtype=np.int64)
    ds = ds.assign_coords(dof=("dof", np.asarray(list(dof_labels), dtype=str)),
                          wave_vector=(("wave", "angle"), vectors),
                          wave_frequency=("wave", vectors @ np.asarray(rates, float)))
    ds["wave_vector"].attrs.update(units="1", long_name="wave vector k of the torus angles")
    ds["wave_frequency"].attrs.update(units="1", long_name="k . rates: the frequency of the "
                                      "wave over Omega")
    ds["harmonics"] = (("point", "angle"), K, {
        "units": "1", "long_name": "orders K_g of the point's truncation set, per torus angle"})
    for name, value, what in (("displacement_cos", cos, "cosine"),
                              ("displacement_sin", sin, "sine")):
        ds[name] = (("point", "dof", "wave"), value, {
            "units": units,
            "long_name": f"{what} coefficient of the member displacement per wave vector "
                         "(the zero vector: the mean)"})
    return ds


def add_displacement_harmonics(ds: xr.Dataset, X, dof_labels: Sequence[str],
                               harmonics, units: str = "rad") -> xr.Dataset:
    """``ds`` with the member displacement harmonics of its points.

    **Arguments:** ``X``: one ``(2K_p+1, n)`` array of real Fourier coefficients per point
    (:mod:`gearjax._engine.aft` layout; ``K_p`` may differ between points: the harmonics rule
    changes K along a sweep); ``dof_labels``: the ``n`` coordinate names (e.g.
    ``"1.sun"``, ``"2.planet3"``); ``harmonics``: ``(P,)`` the ``K_p``; ``units`` of the
    coordinates.

    **Adds:** ``displacement_cos`` and ``displacement_sin`` ``(point, dof, harmonic)``:
    ``x_i(t) = cos[., i, 0] + sum_k cos[., i, k] cos(k w0 t) + sin[., i, k] sin(k w0 t)``,
    ``w0 = Omega / eta`` (``harmonic`` 0 is the mean; ``sin`` is 0 there); harmonics
    above a point's ``K_p`` are 0, as in its truncated solution; and ``harmonics``
    ``(point,)``, the ``K_p``. CSV leaves them out (one row per point and mesh).
    """
    P = ds.sizes["point"]
    K = np.asarray(harmonics, dtype=np.int64)
    _check("harmonics", K, (P,))
    n = len(dof_labels)
    top = int(K.max()) if P else 0
    cos = np.zeros((P, n, top + 1))
    sin = np.zeros((P, n, top + 1))
    for k, Xp in enumerate(X):
        Xp = _check(f"X[{k}]", np.asarray(Xp, dtype=float), (2 * int(K[k]) + 1, n))
        cos[k, :, 0] = Xp[0]
        cos[k, :, 1:K[k] + 1] = Xp[1::2].T
        sin[k, :, 1:K[k] + 1] = Xp[2::2].T
    ds = ds.assign_coords(dof=("dof", np.asarray(list(dof_labels), dtype=str)),
                          harmonic=("harmonic", np.arange(top + 1, dtype=np.int64)))
    ds["harmonics"] = ("point", K, {"units": "1",
                                    "long_name": "solution harmonics K of the point"})
    for name, value, what in (("displacement_cos", cos, "cosine"),
                              ("displacement_sin", sin, "sine")):
        ds[name] = (("point", "dof", "harmonic"), value, {
            "units": units,
            "long_name": f"{what} coefficient of the member displacement per harmonic of "
                         "Omega / eta (harmonic 0: the mean)"})
    return ds


def displacement_coefficients(ds: xr.Dataset, i: int) -> np.ndarray:
    """The real Fourier coefficients ``(2K_i+1, n)`` (:mod:`gearjax._engine.aft` layout) of point
    ``i``'s member displacements, from the Dataset variables that
    :func:`add_displacement_harmonics` wrote: the inverse of that layout."""
    K = int(ds["harmonics"].values[i])
    cos = np.asarray(ds["displacement_cos"].values[i], dtype=float)  # (n, H + 1)
    sin = np.asarray(ds["displacement_sin"].values[i], dtype=float)
    X = np.zeros((2 * K + 1, cos.shape[0]))
    X[0] = cos[:, 0]
    X[1::2] = cos[:, 1:K + 1].T
    X[2::2] = sin[:, 1:K + 1].T
    return X


def save_results(ds: xr.Dataset, path) -> pathlib.Path:
    """Write ``ds`` to ``path``: NetCDF (h5netcdf engine) for ``.nc``, CSV (one row per
    point and mesh) for ``.csv``; any other suffix is refused with a ``ValueError``.
    The file is written atomically (:func:`atomic_path`): an interrupted write leaves
    any earlier file at ``path`` as it was, never half a file. **Returns:** the path
    written."""
    path = pathlib.Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".nc", ".csv"):
        raise ValueError(
            f"results file {str(path)!r} has suffix {path.suffix!r}: use one of "
            f"{', '.join(SUFFIXES)} (NetCDF or CSV)")
    with atomic_path(path) as tmp:
        if suffix == ".nc":
            ds.to_netcdf(tmp, engine="h5netcdf", encoding=checksummed(ds))
        else:
            results_frame(ds).to_csv(tmp, index=False)
    return path


@contextlib.contextmanager
def atomic_path(path):
    """``with atomic_path(path) as tmp:`` write the file ``tmp`` (a new name in the same
    directory, with ``path``'s suffix); when the block ends without an exception ``tmp``
    is synced to disk and renamed to ``path`` (``os.replace``: atomic, so a reader
    sees the old file or the whole new one, and two writers never mix), else removed."""
    path = pathlib.Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}")
    try:
        yield tmp
        try:
            fd = os.open(tmp, os.O_RDONLY)
        except FileNotFoundError:
            raise OSError(f"{tmp} was not written") from None
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException as e:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(e, OSError) and e.filename in (None, tmp, str(tmp)):
            # name the file the caller asked for, not the temporary one (and name it
            # where the writer did not: h5py's "No space left on device" names none)
            reason = e.strerror or " ".join(str(e).replace(str(tmp), str(path)).split())
            raise OSError(e.errno, reason, str(path)) from e
        raise
    sync_directory(path)


def checksummed(ds: xr.Dataset) -> dict:
    """The ``encoding`` argument of ``to_netcdf`` (h5netcdf) that writes every numeric
    array of ``ds`` (one dimension or more) with HDF5's Fletcher-32 checksum, so that a
    value changed after writing is refused when read (:func:`read_netcdf`)."""
    return {name: {"fletcher32": True} for name, v in ds.variables.items()
            if v.ndim >= 1 and v.dtype.kind in "biufcmM"}


def read_netcdf(path, group: str | None = None) -> xr.Dataset:
    """The Dataset of a NetCDF file (``group`` of it), loaded into memory.

    **Raises:** ``FileNotFoundError`` where it does not exist; :class:`~gearjax.TrainError`
    (one line naming the file) where it is not NetCDF, or is damaged (a checksum of
    :func:`checksummed` does not match its values)."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"results file {str(path)!r} does not exist")
    try:
        return xr.load_dataset(path, group=group, engine="h5netcdf")
    except Exception as e:  # noqa: BLE001  h5py, netCDF and xarray raise many kinds
        reason = " ".join(str(e).split()) or type(e).__name__
        if "filter returned failure" in reason:
            raise TrainError(f"{path}: damaged: the checksum of a stored array does not "
                             "match its values (the file changed after it was written); "
                             "run the command that wrote it again") from None
        raise TrainError(f"{path}: not a NetCDF results file ({reason[:120]})") from None


def load_results(path) -> xr.Dataset:
    """Read a NetCDF results file written by :func:`save_results` (loaded into memory).

    **Raises:** ``ValueError`` for another suffix than ``.nc``; as :func:`read_netcdf`."""
    path = pathlib.Path(path)
    if path.suffix.lower() != ".nc":
        raise ValueError(
            f"results file {str(path)!r} has suffix {path.suffix!r}: only NetCDF (.nc) "
            "results can be read back")
    return read_netcdf(path)


def results_frame(ds: xr.Dataset) -> pd.DataFrame:
    """One row per point and mesh (the CSV layout in the module docstring)."""
    P, m = ds.sizes["point"], ds.sizes["mesh"]
    point = np.repeat(np.arange(P), m)
    mesh = np.tile(np.arange(m), P)
    stage_col = {s: i for i, s in enumerate(ds["stage_id"].values.tolist())}
    own_stage = np.array([stage_col[s] for s in ds["stage"].values.tolist()], dtype=int)
    stable = ds["stable"].values if "stable" in ds else np.full(P, UNKNOWN, np.int8)
    cols = {
        "point": ds["point"].values[point],
        "mesh": ds["mesh"].values[mesh].astype(str),
        "stage": ds["stage"].values[mesh].astype(str),
        "side": ds["side"].values[mesh].astype(str),
        "planet": ds["planet"].values[mesh],
        "mesh_frequency_hz": ds["mesh_frequency_hz"].values[point],
        "stage_mesh_frequency_hz": ds["stage_mesh_frequency_hz"].values[point, own_stage[mesh]],
        "input_rpm": ds["input_rpm"].values[point],
        "omega": ds["omega"].values[point],
        "result": ds["result"].values[point].astype(str),
        "converged": ds["converged"].values[point],
        "stable": pd.array([None if v == UNKNOWN else bool(v == STABLE) for v in stable[point]],
                           dtype="boolean"),
    }
    if "period" in ds:
        cols["period"] = ds["period"].values[point]
    if "static_force" in ds:
        cols["static_force"] = ds["static_force"].values[mesh]
    for name in RESPONSE_FIELDS:
        cols[name] = ds[name].values.reshape(-1)
    if "load_sharing" in ds:  # the mesh's stage's factor
        cols["load_sharing"] = ds["load_sharing"].values[point, own_stage[mesh]]
    return pd.DataFrame(cols)


def points_json(ds: xr.Dataset) -> list[dict]:
    """interface.md's JSON ``points`` of a results Dataset.

    Each point: ``mesh_frequency_hz``, ``stage_mesh_frequency_hz`` (list, stage order),
    ``input_rpm``, ``result``, ``converged``, ``stable`` (bool or ``None``), ``period``
    (``None`` unless stored), for a sweep ``branch`` (its solution branch number) and,
    where the sweep was completed, ``found`` (how that branch was found), for a
    harmonic-balance sweep ``max_multiplier`` (the largest Floquet multiplier modulus,
    rigid-body modes excluded), and ``meshes``: ``{name, stage, side, planet, mean_force,
    rms_force, max_force, dlf, separation, back_contact, mean_torque}``; in the
    translational model ``bearings`` (:func:`~gearjax._io.bearing_results.bearings_json`);
    for a sweep ``load_sharing`` (stage id -> dynamic load-sharing factor).
    NaN and infinities become ``None``; a mesh with a ``None`` value gets a ``reason``.
    """
    names = ds["mesh"].values.tolist()
    stage = ds["stage"].values.tolist()
    side = ds["side"].values.tolist()
    planet = ds["planet"].values.tolist()
    static = ds["static_force"].values if "static_force" in ds else None
    values = {name: ds[name].values for name in RESPONSE_FIELDS}
    points = []
    for k in range(ds.sizes["point"]):
        result = str(ds["result"].values[k])
        converged = bool(ds["converged"].values[k])
        meshes = []
        for j, name in enumerate(names):
            mesh = {"name": str(name), "stage": str(stage[j]), "side": str(side[j]),
                    "planet": int(planet[j])}
            for field in RESPONSE_FIELDS:
                mesh[field] = json_number(values[field][k, j])
            if any(mesh[field] is None for field in RESPONSE_FIELDS):
                if not converged:
                    mesh["reason"] = f"point not converged ({result})"
                elif static is not None and static[j] == 0:
                    mesh["reason"] = "no static load: dlf and back_contact are undefined"
                else:
                    mesh["reason"] = "not finite"
            meshes.append(mesh)
        points.append({
            "mesh_frequency_hz": json_number(ds["mesh_frequency_hz"].values[k]),
            "stage_mesh_frequency_hz": [json_number(v)
                                        for v in ds["stage_mesh_frequency_hz"].values[k]],
            "input_rpm": json_number(ds["input_rpm"].values[k]),
            "result": result,
            "converged": converged,
            "stable": _stable_json(ds["stable"].values[k]) if "stable" in ds else None,
            "period": json_number(ds["period"].values[k]) if "period" in ds else None,
            "meshes": meshes,
        })
        if "branch" in ds:  # a sweep: the solution branch, and how it was found
            points[-1]["branch"] = int(ds["branch"].values[k])
            if "found" in ds:
                points[-1]["found"] = str(ds["found"].values[k])
        if "load_sharing" in ds:
            points[-1]["load_sharing"] = dict(zip(
                ds["stage_id"].values.tolist(), map(json_number, ds["load_sharing"].values[k])))
        if "bearing_mean_force" in ds:  # the translational model
            points[-1]["bearings"] = bearings_json(ds, k, json_number)
        if "max_multiplier" in ds:  # a harmonic-balance sweep: its stability's measure
            points[-1]["max_multiplier"] = json_number(ds["max_multiplier"].values[k])
        if "period" in ds and not ds["period"].values[k] > 0:  # 0: no repeat found
            points[-1]["period"] = None
            points[-1]["period_reason"] = ("the orbit did not repeat within the integrated "
                                           "base periods (quasi-periodic, chaotic or not settled)")
    return points


# --------------------------------------------------------------------------- helpers


def _check(name: str, value: np.ndarray, shape: tuple) -> np.ndarray:
    if value.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, not {value.shape}")
    return value


def _strings(name: str, values, n: int) -> list[str]:
    out = [str(v) for v in values]
    if len(out) != n:
        raise ValueError(f"{name} must have {n} entries, not {len(out)}")
    return out


def _stable_codes(stable, P: int) -> np.ndarray:
    """int8 codes (1 stable, 0 unstable, -1 unknown) of bools, floats with NaN, or Nones."""
    if stable is None:
        return np.full(P, UNKNOWN, dtype=np.int8)
    values = list(np.asarray(stable, dtype=object).reshape(-1))
    if len(values) != P:
        raise ValueError(f"stable must have shape ({P},), not ({len(values)},)")
    codes = []
    for v in values:
        if v is None or (isinstance(v, (float, np.floating)) and math.isnan(v)):
            codes.append(UNKNOWN)
        elif isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) and v < 0:
            codes.append(UNKNOWN)
        else:
            codes.append(STABLE if bool(v) else UNSTABLE)
    return np.asarray(codes, dtype=np.int8)


def _stable_json(code) -> bool | None:
    code = float(code)
    if math.isnan(code) or code < 0:
        return None
    return bool(code > 0)


def json_number(x) -> float | None:
    """``x`` as a JSON number: a ``float``, or ``None`` where it is not finite (NaN marks a
    missing value in the results, and JSON has no NaN)."""
    x = float(x)
    return x if math.isfinite(x) else None


def netcdf_attr(value):
    """A NetCDF-storable global attribute: strings and numbers as they are, the rest JSON."""
    if isinstance(value, (bool, np.bool_)) or value is None or isinstance(
            value, (Mapping, list, tuple)):
        return json.dumps(value, sort_keys=True, default=_json_default)
    if isinstance(value, (str, int, float, np.integer, np.floating)):
        return value
    return json.dumps(value, default=_json_default)


def _json_default(value):
    if isinstance(value, np.ndarray) or hasattr(value, "tolist"):
        return value.tolist()
    return str(value)
