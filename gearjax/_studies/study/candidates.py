"""Candidates of a study: the variations combined by the design, each written into the
base train file and checked by the train file's own rules.

A variation's path names a key of the train file as written (interface.md): ``STAGE.KEY``
or ``STAGE.KEY.SUB`` for a stage (``STAGE`` its id: ``1.teeth.sun``,
``2.planet_angles_deg``, ``1.mesh_stiffness.ring``, ``2.half_backlash.sun``), and
``housing.KEY``, ``gears.NAME.KEY``, ``couplings.K.KEY`` (``K`` the coupling's ``id``,
else its 0-based position) for the other tables. Unlike the continuous paths of
:mod:`gearjax._gear.paths`, a study may vary structure too (tooth counts, planet counts
through the list of planet angles): each candidate is a train file of its own.
"""

from __future__ import annotations

import dataclasses
import itertools
import tomllib
import warnings

import numpy as np
import tomli_w

from ..._errors import TrainError, bad_argument, fail
from .spec import StudySpec


@dataclasses.dataclass(frozen=True)
class Candidate:
    """Candidate ``index`` (0-based, in design order) and its ``values``, one per
    variation of the study (numbers, or tuples of numbers)."""

    index: int
    values: tuple


def candidates(spec: StudySpec) -> list[Candidate]:
    """Every candidate of ``spec`` in design order: ``grid`` varies the last variation
    fastest; ``list`` takes the i-th value of each variation; ``lhs`` draws ``samples``
    points of a Latin hypercube over the ranges (SciPy's sampler, seeded with ``seed``:
    the same file gives the same candidates), integer ranges rounded."""
    vs = spec.variations
    if spec.design == "grid":
        rows = itertools.product(*(v.values for v in vs))
    elif spec.design == "list":
        rows = zip(*(v.values for v in vs))
    else:
        from scipy.stats import qmc

        unit = qmc.LatinHypercube(d=len(vs), seed=spec.seed).random(spec.samples)
        rows = []
        for u in unit:
            row = []
            for v, x in zip(vs, u):
                value = v.low + (v.high - v.low) * float(x)
                row.append(int(round(value)) if v.integer else value)
            rows.append(row)
    return [Candidate(index=i, values=tuple(row)) for i, row in enumerate(rows)]


def candidate_text(spec: StudySpec, candidate: Candidate) -> str:
    """The train file of ``candidate``: the base train with each varied key replaced.

    **Raises:** ``TrainError`` naming the variation's path where it names no key of the
    base train that holds a value of that kind."""
    raw = tomllib.loads(spec.train_text)
    for v, value in zip(spec.variations, candidate.values):
        set_value(raw, v.path, value, source=spec.source)
    return tomli_w.dumps(raw)


def candidate_train(spec: StudySpec, index: int):
    """The :class:`~gearjax.Train` of candidate ``index`` of the study ``spec`` (to look
    at one candidate closely: verify it, sweep it at finer settings, save it).

    **Raises:** ``ArgumentError`` (``index``) outside the study's candidates;
    ``TrainError`` where the candidate's train breaks a train-file rule (the study
    recorded it as refused)."""
    from ..._gear.toml_io import loads_train

    every = candidates(spec)
    if isinstance(index, bool) or not isinstance(index, int | np.integer) or not (
            0 <= index < len(every)):
        raise bad_argument("index", index, f"must be a candidate number 0 to {len(every) - 1}")
    return loads_train(candidate_text(spec, every[int(index)]),
                       source=f"{spec.source} candidate {int(index)}")


def set_value(raw: dict, path: str, value, *, source: str = "<study>") -> None:
    """Replace the key ``path`` (module docstring) of the parsed train file ``raw`` with
    ``value`` (a number, or a sequence of numbers), in place.

    **Raises:** ``TrainError`` naming ``path`` where it names no stage, table or key of
    ``raw``, or where the key holds a table or a list and ``value`` is not alike."""
    parts = path.split(".")
    head, rest = parts[0], parts[1:]
    stages = raw.get("stages", [])
    table = next((s for s in stages if isinstance(s, dict) and str(s.get("id")) == head), None)
    if table is None and head == "couplings":
        table, rest = _coupling(raw, rest, path, source), rest[1:]
    elif table is None and head in ("housing", "gears"):
        table = raw.setdefault(head, {})
    elif table is None:
        ids = [str(s.get("id")) for s in stages if isinstance(s, dict)]
        raise fail(source, "vary.path", path, f"{head!r} is no stage id ({', '.join(ids)}), "
                   "housing, gears or couplings")
    if not rest:
        raise fail(source, "vary.path", path, "names a table, not a key")
    for key in rest[:-1]:
        inner = table.get(key)
        if isinstance(inner, int | float) and not isinstance(inner, bool):
            inner = table[key] = {"sun": inner, "ring": inner}  # one number for both sides
        if not isinstance(inner, dict):
            raise fail(source, "vary.path", path, f"{key!r} is no table of the base train")
        table = inner
    key = rest[-1]
    old = table.get(key)
    if isinstance(value, tuple):
        if old is not None and not isinstance(old, list):
            raise fail(source, "vary.path", path, "holds one number in the base train, "
                       "not a list")
        table[key] = [_plain(x) for x in value]
    else:
        if isinstance(old, list | dict):
            raise fail(source, "vary.path", path, "holds a list or table in the base train, "
                       "not one number")
        table[key] = _plain(value)


def _coupling(raw: dict, rest: list, path: str, source: str) -> dict:
    couplings = raw.get("couplings", [])
    if not rest:
        raise fail(source, "vary.path", path, "names the couplings, not a key of one")
    key = rest[0]
    for c in couplings:
        if isinstance(c, dict) and c.get("id") == key:
            return c
    if key.isdigit() and int(key) < len(couplings):
        return couplings[int(key)]
    raise fail(source, "vary.path", path, f"no coupling has id or position {key!r} "
               f"(the base train has {len(couplings)})")


def _plain(x):
    """A TOML value: integers stay integers."""
    if isinstance(x, bool) or not isinstance(x, int | float | np.integer | np.floating):
        return x
    return int(x) if isinstance(x, int | np.integer) else float(x)


def check_paths(spec: StudySpec) -> None:
    """Refuse, before any work, a variation whose path names nothing in the base train:
    the design's first candidate is written and every path tried.

    **Raises:** ``TrainError`` naming the path."""
    first = candidates(spec)[:1]
    if first:
        candidate_text(spec, first[0])


def refusal(text: str, source: str) -> str | None:
    """The one-line reason the train file ``text`` breaks a train-file rule, ``None``
    where it loads (warnings are not refusals)."""
    from ..._gear.toml_io import loads_train

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loads_train(text, source=source)
    except TrainError as e:
        return str(e)
    return None


def value_words(value) -> str:
    """A candidate's value as the study's dataset shows it: a number as written, a list
    as ``a, b, c`` (12 significant digits)."""
    if isinstance(value, tuple):
        return ", ".join(f"{x:.12g}" for x in value)
    return f"{value:.12g}"
