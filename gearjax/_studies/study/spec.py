"""The study file: a base train, a gear, the variations and the analysis per candidate.

A study file is TOML (keys in the project's docs, ``docs/study.md``)::

    train = "train.toml"        # relative to the study file; omitted: the bundled paper case
    gear = "first"              # omitted: the train file's first gear
    design = "grid"             # "grid" (every combination), "list" (the i-th value of
                                # each variation together) or "lhs" (Latin hypercube)
    samples = 16                # lhs: candidates
    seed = 0                    # lhs: the sampler's seed

    [[vary]]
    path = "1.mesh_stiffness.ring"       # a train-file path (:func:`~.candidates.set_value`)
    from = 4.0e8                         # a range: from, to and points (or step) ...
    to = 6.0e8
    points = 3
    [[vary]]
    path = "2.planet_angles_deg"
    values = [[0, 90, 180, 270], [0, 120, 240]]   # ... or the values themselves

    [analysis]
    modes = true                                       # the first elastic mode
    linear = { band_hz = [2000.0, 5000.0], points = 60 }
    backlash = { band_hz = [3290.0, 3450.0] }          # a complete sweep with backlash
    verify = { at_hz = [3300.0] }                      # harmonic balance against integration

Every rule is checked when the file is read, before any candidate runs
(:func:`load_study`): a breach raises ``TrainError`` with one line naming the file, the
field, the value and the rule.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import pathlib
import tomllib

from ..._errors import fail
from ..._gear.toml_reader import TomlReader, finite_number

DESIGNS = ("grid", "list", "lhs")
"""How the variations combine into candidates."""

_TOP_KEYS = {"train", "gear", "design", "samples", "seed", "vary", "analysis"}
_VARY_KEYS = {"path", "values", "from", "to", "points", "step"}
_ANALYSIS_KEYS = {"modes", "linear", "backlash", "verify"}
_SWEEP_KEYS = {"linear": {"band_hz", "points", "harmonics"},
               "backlash": {"band_hz", "max_points", "harmonics", "max_step_hz"}}
MAX_CANDIDATES = 1_000_000
"""The most candidates one study may hold."""


@dataclasses.dataclass(frozen=True)
class Variation:
    """One varied train-file ``path`` and the ``values`` it takes (numbers, or lists of
    numbers for a list-valued key such as ``STAGE.planet_angles_deg``); an ``lhs``
    variation has the range ``(low, high)`` instead, sampled by the design."""

    path: str
    values: tuple = ()
    low: float | None = None
    high: float | None = None
    integer: bool = False


@dataclasses.dataclass(frozen=True)
class Analysis:
    """What each candidate runs: ``modes`` (the first elastic mode), ``linear`` (a linear
    sweep: ``{"band_hz", "points", "harmonics"}``, ``None``: none) and ``backlash`` (a
    complete sweep with backlash: ``{"band_hz", "max_points", "harmonics",
    "max_step_hz"}``, ``None``: none) and ``verify`` (harmonic balance against time
    integration: ``{"at_hz", "linear", "harmonics"}``, ``None``: none)."""

    modes: bool = True
    linear: dict | None = None
    backlash: dict | None = None
    verify: dict | None = None


@dataclasses.dataclass(frozen=True)
class StudySpec:
    """A read and checked study file: ``source`` (its path), ``train_path`` (``None``: the
    bundled paper case), ``train_text`` (the base train file's text), ``gear``,
    ``design``, ``samples``, ``seed``, ``variations``, ``analysis``, and ``text`` (the
    study file's own text, which with ``train_text`` identifies the study)."""

    source: str
    train_path: str | None
    train_text: str
    gear: str | None
    design: str
    samples: int
    seed: int
    variations: tuple[Variation, ...]
    analysis: Analysis
    text: str

    @property
    def digest(self) -> str:
        """SHA-256 of the study file's text and the base train's text: a store holds the
        candidates of one study only."""
        h = hashlib.sha256(self.text.encode())
        h.update(b"\0")
        h.update(self.train_text.encode())
        return h.hexdigest()


def load_study(path) -> StudySpec:
    """Read and check the study file ``path`` (and read its base train file's text).

    **Raises:** ``TrainError`` (one line: file, field, value, rule) for a file that cannot
    be read, is not TOML, or breaks a rule of the module docstring."""
    path = pathlib.Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        reason = getattr(e, "strerror", None) or type(e).__name__
        raise fail(source, "file", source, f"cannot be read ({reason})") from None
    return loads_study(text, source, base=path.parent)


def loads_study(text: str, source: str = "<study>", base=".") -> StudySpec:
    """:func:`load_study` on the text of a study file; a relative ``train`` is found
    from the directory ``base``."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise fail(source, "file", "<TOML>", f"is not valid TOML ({e})") from None
    r = TomlReader(source)
    r.keys(raw, _TOP_KEYS, "")
    train_path, train_text = _train(raw, source, pathlib.Path(base))
    gear = raw.get("gear")
    if gear is not None and not isinstance(gear, str):
        raise fail(source, "gear", gear, "must be a gear name (a string)")
    design = raw.get("design", "grid")
    if design not in DESIGNS:
        raise fail(source, "design", design, f"must be one of {', '.join(DESIGNS)}")
    for key in ("samples", "seed"):
        if design != "lhs" and key in raw:
            raise fail(source, key, raw[key], f"is for design = \"lhs\" (this is {design!r})")
    samples = _integer(r, raw, "samples", "samples", low=1) if design == "lhs" else 0
    seed = _integer(r, raw, "seed", "seed", low=0, default=0)
    vary = raw.get("vary")
    if not isinstance(vary, list) or not vary or not all(isinstance(v, dict) for v in vary):
        raise fail(source, "vary", vary, "at least one [[vary]] table is required")
    variations = tuple(_variation(v, i, r, design) for i, v in enumerate(vary))
    paths = [v.path for v in variations]
    for i, p in enumerate(paths):
        if p in paths[:i]:
            raise fail(source, f"vary[{i}].path", p, "is varied twice")
    if design == "list":
        counts = {len(v.values) for v in variations}
        if len(counts) > 1:
            raise fail(source, "vary", [len(v.values) for v in variations],
                       "design = \"list\" takes the i-th value of every variation together: "
                       "every variation needs as many values")
    n = candidate_count(design, variations, samples)
    if n > MAX_CANDIDATES:
        raise fail(source, "vary", n, f"candidates; at most {MAX_CANDIDATES} per study")
    return StudySpec(source=source, train_path=train_path, train_text=train_text, gear=gear,
                     design=design, samples=samples, seed=seed, variations=variations,
                     analysis=_analysis(raw.get("analysis", {}), r), text=text)


def candidate_count(design: str, variations, samples: int) -> int:
    """How many candidates ``design`` makes of ``variations``."""
    if design == "lhs":
        return samples
    if design == "list":
        return len(variations[0].values)
    return math.prod(len(v.values) for v in variations)


def _train(raw: dict, source: str, base: pathlib.Path) -> tuple[str | None, str]:
    from ..._gear.toml_io import bundled_example_path

    value = raw.get("train")
    if value is None:
        return None, bundled_example_path().read_text(encoding="utf-8")
    if not isinstance(value, str) or not value:
        raise fail(source, "train", value, "must be the path of a train file (a string)")
    path = base / value
    try:
        return str(path), path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        reason = getattr(e, "strerror", None) or type(e).__name__
        raise fail(source, "train", value, f"cannot be read as {str(path)!r} ({reason})") from None


def _integer(r: TomlReader, raw: dict, key: str, field: str, *, low: int, **default) -> int:
    return r.integer(raw, key, field, low=low, rule=f"must be an integer >= {low}", **default)


def _variation(raw: dict, i: int, r: TomlReader, design: str) -> Variation:
    f = f"vary[{i}]"
    r.keys(raw, _VARY_KEYS, f)
    path = raw.get("path")
    if not isinstance(path, str) or not path:
        raise r.fail(f"{f}.path", path, "must be a train-file path such as "
                     "\"1.mesh_stiffness.ring\" or \"2.planet_angles_deg\"")
    if "values" in raw:
        if any(k in raw for k in ("from", "to", "points", "step")):
            raise r.fail(f"{f}.values", raw["values"],
                         "give either values or a range (from, to, points or step), not both")
        if design == "lhs":
            raise r.fail(f"{f}.values", raw["values"],
                         "design = \"lhs\" samples ranges: give from and to")
        values = raw["values"]
        ok = isinstance(values, list) and values and all(
            finite_number(v) or (isinstance(v, list) and v and all(finite_number(x) for x in v))
            for v in values)
        if not ok:
            raise r.fail(f"{f}.values", values,
                         "must be a non-empty list of numbers, or of lists of numbers")
        return Variation(path=path, values=tuple(tuple(v) if isinstance(v, list) else v
                                                 for v in values))
    low, high = raw.get("from"), raw.get("to")
    for key, value in (("from", low), ("to", high)):
        if not finite_number(value):
            raise r.fail(f"{f}.{key}", value,
                         "must be a finite number (or give values instead of a range)")
    integer = isinstance(low, int) and isinstance(high, int)
    if design == "lhs":
        if high <= low:
            raise r.fail(f"{f}.to", high, f"must exceed from = {low}")
        if "points" in raw or "step" in raw:
            raise r.fail(f"{f}.points", raw.get("points", raw.get("step")),
                         "design = \"lhs\" draws `samples` values of each range: no points or step")
        return Variation(path=path, low=float(low), high=float(high), integer=integer)
    return Variation(path=path, values=_range_values(raw, f, r, low, high, integer),
                     integer=integer)


def _range_values(raw: dict, f: str, r: TomlReader, low, high, integer: bool) -> tuple:
    if ("points" in raw) == ("step" in raw):
        raise r.fail(f"{f}.points", raw.get("points"),
                     "a range needs exactly one of points and step")
    if "points" in raw:
        n = _integer(r, raw, "points", f"{f}.points", low=1)
        if n == 1:
            return (low,)
        values = [low + (high - low) * k / (n - 1) for k in range(n)]
    else:
        step = raw["step"]
        if not finite_number(step) or step == 0 or (high - low) * step < 0:
            raise r.fail(f"{f}.step", step,
                         f"must be a non-zero number that leads from {low} to {high}")
        n = int(math.floor((high - low) / step * (1 + 1e-12))) + 1
        values = [low + k * step for k in range(n)]
    if integer:
        rounded = [int(round(v)) for v in values]
        if len(set(rounded)) < len(rounded) or any(abs(r - v) > 1e-9
                                                   for r, v in zip(rounded, values)):
            raise r.fail(f"{f}.points", len(values),
                         f"the range {low}..{high} of integers does not hold these even values")
        return tuple(rounded)
    return tuple(float(v) for v in values)


def _analysis(raw, r: TomlReader) -> Analysis:
    r.table(raw, "analysis")
    r.keys(raw, _ANALYSIS_KEYS, "analysis")
    modes = r.boolean(raw, "modes", "analysis.modes", default=True)
    sweeps = {kind: _sweep(raw.get(kind), kind, r) for kind in ("linear", "backlash")}
    verify = _verify(raw.get("verify"), r)
    if not modes and verify is None and all(v is None for v in sweeps.values()):
        raise r.fail("analysis", raw, "asks for nothing: set modes = true, or a "
                     "linear or backlash sweep, or verify")
    return Analysis(modes=modes, verify=verify, **sweeps)


def _verify(raw, r: TomlReader) -> dict | None:
    if raw is None:
        return None
    f = "analysis.verify"
    r.table(raw, f)
    r.keys(raw, {"at_hz", "linear", "harmonics"}, f)
    at = raw.get("at_hz")
    if not isinstance(at, list) or not at or not all(finite_number(x) and x > 0 for x in at):
        raise r.fail(f"{f}.at_hz", at,
                     "must be a non-empty list of positive frequencies (Hz)")
    out = {"at_hz": tuple(float(x) for x in at),
           "linear": r.boolean(raw, "linear", f"{f}.linear", default=False)}
    if "harmonics" in raw:
        out["harmonics"] = _integer(r, raw, "harmonics", f"{f}.harmonics", low=1)
    return out


def _sweep(raw, kind: str, r: TomlReader) -> dict | None:
    if raw is None:
        return None
    f = f"analysis.{kind}"
    r.table(raw, f)
    r.keys(raw, _SWEEP_KEYS[kind], f)
    band = raw.get("band_hz")
    if (not isinstance(band, list) or len(band) != 2 or not all(finite_number(b) for b in band)
            or min(band) <= 0 or band[0] == band[1]):
        raise r.fail(f"{f}.band_hz", band,
                     "must be two different positive frequencies [from, to] (Hz)")
    out = {"band_hz": (float(band[0]), float(band[1]))}
    for key, low in (("points", 2), ("max_points", 2), ("harmonics", 1)):
        if key in raw:
            out[key] = _integer(r, raw, key, f"{f}.{key}", low=low)
    if "max_step_hz" in raw:
        if not finite_number(raw["max_step_hz"]) or raw["max_step_hz"] <= 0:
            raise r.fail(f"{f}.max_step_hz", raw["max_step_hz"],
                         "must be a positive number (Hz)")
        out["max_step_hz"] = float(raw["max_step_hz"])
    return out
