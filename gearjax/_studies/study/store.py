"""The study store: a directory with one NetCDF file per finished candidate.

Layout of ``STORE/``: ``study.json`` (the study's identity: the digest of the study and
base train files, the design, the number of candidates) and ``candidates/NNNNNN.nc``,
the result of candidate ``NNNNNN`` (0-based), each written atomically when the candidate
finishes (:func:`gearjax._io.results.save_results`), so a killed run loses only the
candidates in flight, and a resumed one runs only the candidates without a file.
:func:`load_study_results` gathers the files into one Dataset with a ``candidate``
dimension.
"""

from __future__ import annotations

import json
import math
import pathlib
import tomllib

import numpy as np
import xarray as xr

from ..._errors import bad_argument, fail
from ..._io.results import atomic_path, read_netcdf, save_results
from .candidates import Candidate, value_words
from .spec import StudySpec

IDENTITY = "study.json"
CANDIDATES = "candidates"


def open_store(path, spec: StudySpec, n: int, *, resume: bool) -> pathlib.Path:
    """Create the store ``path`` for ``spec`` (``n`` candidates), or reopen it where
    ``resume``.

    **Raises:** ``ArgumentError`` (``store`` or ``resume``) where ``path`` exists and is
    not this study's store, or holds candidates and ``resume`` is false, or does not
    exist and ``resume`` is true."""
    path = pathlib.Path(path)
    ident = path / IDENTITY
    mine = {"digest": spec.digest, "study": spec.source, "design": spec.design,
            "candidates": n}
    if path.exists():
        if not ident.is_file():
            if path.is_dir() and not any(path.iterdir()):
                return _create(path, mine)
            raise bad_argument("store", str(path), "exists and is not a study store")
        theirs = json.loads(ident.read_text())
        if theirs.get("digest") != spec.digest:
            raise bad_argument("store", str(path),
                               f"holds another study ({theirs.get('study')}: its study or train "
                               "file differs): choose another store")
        done = len(done_indices(path))
        if done and not resume:
            raise bad_argument("resume", False,
                               f"{path} holds {done} finished candidates "
                               "of this study: resume it, or choose another store")
        return path
    if resume:
        raise bad_argument("resume", True, f"{path} does not exist: nothing to resume")
    return _create(path, mine)


def _create(path: pathlib.Path, identity: dict) -> pathlib.Path:
    (path / CANDIDATES).mkdir(parents=True, exist_ok=True)
    with atomic_path(path / IDENTITY) as tmp:
        tmp.write_text(json.dumps(identity, indent=1))
    return path


def candidate_file(store, index: int) -> pathlib.Path:
    return pathlib.Path(store) / CANDIDATES / f"{index:06d}.nc"


def done_indices(store) -> set[int]:
    """Indices of the candidates whose result file is in ``store``."""
    folder = pathlib.Path(store) / CANDIDATES
    if not folder.is_dir():
        return set()
    return {int(p.stem) for p in folder.glob("[0-9]*.nc") if p.stem.isdigit()}


def base_stages(spec: StudySpec) -> list[str]:
    """Stage ids of the study's base train, in file order."""
    return [str(s.get("id")) for s in tomllib.loads(spec.train_text).get("stages", [])]


def candidate_dataset(spec: StudySpec, candidate: Candidate, merits: dict) -> xr.Dataset:
    """One candidate's result (:func:`~.analysis.analyse_candidate`'s ``merits``) as a
    Dataset with a ``candidate`` dimension of length 1: the varied values as
    coordinates named by their paths (numbers, or ``a, b, c`` for lists), ``status``,
    ``reason``, ``notes``, ``seconds``, ``first_elastic_hz`` and, per sweep kind
    (``linear``, ``backlash``), ``KIND_peak_rms_force`` and ``KIND_peak_hz`` over
    ``stage``, ``KIND_coexisting_hz``, ``KIND_jumps`` (JSON), ``KIND_stop``,
    ``KIND_points``, ``KIND_failed``; ``backlash_complete`` (1: the complete sweep ran
    to its end, 0: stopped by its budget); ``verify_max_rel_diff``, ``verify_ok`` (1, 0) and
    ``verify_tolerance``. Values an analysis did not give are NaN (or -1 for counts and
    flags), ``status`` and ``notes`` saying why."""
    stages = base_stages(spec)
    coords = {"candidate": [candidate.index], "stage": stages}
    for v, value in zip(spec.variations, candidate.values):
        coords[v.path] = ("candidate", [value_words(value) if isinstance(value, tuple)
                                        else value])
    one = ("candidate",)
    data = {"status": (one, [merits["status"]]), "reason": (one, [merits["reason"]]),
            "notes": (one, ["\n".join(merits["warnings"])]),
            "seconds": (one, [float(merits.get("seconds", math.nan))]),
            "first_elastic_hz": (one, [_number(merits.get("first_elastic_hz"))])}
    for kind in ("linear", "backlash"):
        m = merits.get(kind) or {}
        per_stage = len(stages)
        data[f"{kind}_peak_rms_force"] = (("candidate", "stage"), [_numbers(
            m.get("peak_rms_force"), per_stage)])
        data[f"{kind}_peak_hz"] = (("candidate", "stage"), [_numbers(m.get("peak_hz"),
                                                                     per_stage)])
        data[f"{kind}_coexisting_hz"] = (one, [_number(m.get("coexisting_hz"))])
        data[f"{kind}_jumps"] = (one, [json.dumps(m.get("jumps", []))])
        data[f"{kind}_stop"] = (one, [m.get("stop", "")])
        data[f"{kind}_points"] = (one, np.asarray([m.get("points", -1)], np.int64))
        data[f"{kind}_failed"] = (one, np.asarray([m.get("failed", -1)], np.int64))
    complete = (merits.get("backlash") or {}).get("complete")
    data["backlash_complete"] = (one, np.asarray([-1 if complete is None else int(complete)],
                                                 np.int64))
    check = merits.get("verify") or {}
    data["verify_max_rel_diff"] = (one, [_number(check.get("max_rel_diff"))])
    data["verify_ok"] = (one, np.asarray([-1 if not check else int(check["ok"])], np.int64))
    data["verify_tolerance"] = (one, [_number(check.get("tolerance"))])
    return xr.Dataset(data, coords=coords, attrs={"study_digest": spec.digest})


def _number(x) -> float:
    return math.nan if x is None else float(x)


def _numbers(xs, n: int) -> list[float]:
    return [math.nan] * n if xs is None else [_number(x) for x in xs]


def write_candidate(store, spec: StudySpec, candidate: Candidate, merits: dict) -> None:
    """Write candidate ``candidate``'s result to ``store``, atomically."""
    save_results(candidate_dataset(spec, candidate, merits),
                 candidate_file(store, candidate.index))


def load_study_results(store) -> xr.Dataset:
    """Every finished candidate of the study store ``store`` as one Dataset along
    ``candidate`` (ascending), with the attributes ``study`` (its file), ``design``,
    ``candidates`` (how many the study has) and ``missing`` (how many have no result
    yet).

    **Raises:** ``TrainError`` where ``store`` is not a study store or holds no finished
    candidate, or a file in it is damaged."""
    store = pathlib.Path(store)
    ident = store / IDENTITY
    if not ident.is_file():
        raise fail(str(store), "study store", str(store), "is not a study store (no "
                   f"{IDENTITY}): run gearjax study with --out there first")
    identity = json.loads(ident.read_text())
    done = sorted(done_indices(store))
    if not done:
        raise fail(str(store), "study store", str(store), "holds no finished candidate yet")
    parts = [read_netcdf(candidate_file(store, i)) for i in done]
    ds = xr.concat(parts, dim="candidate", data_vars="all", coords="different",
                   compat="equals", join="exact", combine_attrs="drop_conflicts")
    ds.attrs.update(study=identity["study"], design=identity["design"],
                    candidates=int(identity["candidates"]),
                    missing=int(identity["candidates"]) - len(done))
    return ds
