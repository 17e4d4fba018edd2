"""Frequency groups of a gear: its stage mesh frequencies and torque-ripple orders
gathered into groups whose members are small multiples of a group base.

model.md, "Incommensurate stages": the response of a train driven at incommensurate
frequencies lives on a torus, one angle per group. Frequencies come exact from the
kinematics (``fractions.Fraction``, cycles per input revolution), so the grouping is
exact too. Its rule:

- two frequencies whose ratio ``p/q`` (lowest terms) has ``max(p, q) <=
  max_multiplier`` share a group: as two torus angles they would describe the same
  tones twice and make the balance singular;
- every member of a group is a multiple ``mu <= max_multiplier`` of the group's base
  (the greatest common divisor of its members);
- among the groupings that obey both, the fewest groups, then the smallest largest
  multiplier.

The paper's first gear, mesh frequencies in the ratio 7 : 8, is one group (a periodic
response, ``mu = (7, 8)``); stage-2 teeth 43/19/81 give 70 : 81, two groups.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Iterator, Mapping
from fractions import Fraction

from .._errors import fail
from .kinematics import Kinematics

MAX_MULTIPLIER = 16
"""Largest multiple of its group's base a member frequency may be."""

MAX_EXHAUSTIVE = 10
"""Most frequencies whose groupings are all tried; above, groups are merged greedily."""


@dataclasses.dataclass(frozen=True)
class FrequencyGroup:
    """One group: ``members`` (names, e.g. ``"stage 1"``, ``"ripple 2"``), their
    ``frequencies`` (cycles per input revolution, exact), the group's ``base`` (their
    greatest common divisor) and ``multipliers`` (``frequency / base``, integers)."""

    members: tuple[str, ...]
    frequencies: tuple[Fraction, ...]
    base: Fraction
    multipliers: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class FrequencyGroups:
    """A gear's frequency groups, in the order of their first member; ``G`` of them
    (one torus angle each; ``G = 1``: a periodic response with the one base)."""

    groups: tuple[FrequencyGroup, ...]
    max_multiplier: int

    @property
    def G(self) -> int:
        return len(self.groups)

    def group_of(self, member: str) -> int:
        """The index of the group holding ``member``. **Raises:** ``KeyError``."""
        for g, group in enumerate(self.groups):
            if member in group.members:
                return g
        raise KeyError(member)


def gear_frequency_groups(kin: Kinematics, source: str | None = None,
                          max_multiplier: int = MAX_MULTIPLIER) -> FrequencyGroups:
    """The frequency groups of a gear from its kinematics: every turning stage's mesh
    frequency (``"stage ID"``) and every ripple order (``"ripple ORDER"``).

    **Raises:** ``TrainError`` naming the gear where no grouping obeys the rule (module
    docstring), or where nothing turns and no ripple excites."""
    freqs = {f"stage {s.id}": s.mesh_frequency for s in kin.stages if s.turning}
    for mu in kin.ripple_mu:
        order = kin.base * mu
        freqs[f"ripple {_number(order)}"] = order
    if not freqs:
        raise fail(source, f"gears.{kin.gear}", kin.gear,
                   "no mesh turns and no ripple excites this gear: it has no frequency")
    try:
        return group_frequencies(freqs, max_multiplier)
    except ValueError as e:
        raise fail(source, f"gears.{kin.gear}", kin.gear, str(e)) from None


@dataclasses.dataclass(frozen=True)
class TorusLayout:
    """Where a gear's excitation sits on the torus of its frequency groups.

    **Fields:** ``stage`` ``{stage id: (angle, multiplier)}`` for every turning stage;
    ``ripple`` ``((angle, multiplier), ...)`` per ripple order, in the gear's order;
    ``ratio``: each angle's base frequency over angle 0's (exact); ``G``.
    """

    stage: Mapping[str, tuple[int, int]]
    ripple: tuple[tuple[int, int], ...]
    ratio: tuple[Fraction, ...]

    @property
    def G(self) -> int:
        return len(self.ratio)


def torus_layout(kin: Kinematics, groups: FrequencyGroups) -> TorusLayout:
    """The torus angle and multiplier of every turning stage and ripple order of ``kin``
    (grouped by :func:`gear_frequency_groups`); angle 0 is the first group."""
    def place(name: str) -> tuple[int, int]:
        g = groups.group_of(name)
        return g, groups.groups[g].multipliers[groups.groups[g].members.index(name)]

    stage = {s.id: place(f"stage {s.id}") for s in kin.stages if s.turning}
    ripple = tuple(place(f"ripple {_number(kin.base * mu)}") for mu in kin.ripple_mu)
    base = groups.groups[0].base
    return TorusLayout(stage=stage, ripple=ripple,
                       ratio=tuple(g.base / base for g in groups.groups))


def group_frequencies(frequencies: Mapping[str, Fraction],
                      max_multiplier: int = MAX_MULTIPLIER) -> FrequencyGroups:
    """Group named positive exact ``frequencies`` by the rule of the module docstring.

    **Raises:** ``ValueError`` for a frequency that is not positive, or for
    frequencies that must share a group (their ratios are small) but have no common
    base within ``max_multiplier``."""
    names = list(frequencies)
    values = [Fraction(frequencies[n]) for n in names]
    for n, v in zip(names, values):
        if v <= 0:
            raise ValueError(f"the frequency of {n} is {v}: frequencies must be positive")
    blocks = _forced_blocks(values, max_multiplier)
    for block in blocks:
        if _largest_multiplier([values[i] for i in block]) > max_multiplier:
            members = ", ".join(f"{names[i]} ({values[i]})" for i in block)
            raise ValueError(
                f"{members} are pairwise in small ratios, so they must share one torus "
                f"angle, but have no common base of which each is a multiple <= "
                f"{max_multiplier}")
    best = None
    for partition in _groupings(blocks, values, max_multiplier):
        merged = [sorted(i for b in part for i in b) for part in partition]
        if any(_largest_multiplier([values[i] for i in m]) > max_multiplier for m in merged):
            continue
        score = (len(merged), max(_largest_multiplier([values[i] for i in m]) for m in merged))
        if best is None or score < best[0]:
            best = (score, merged)
    groups = []
    for members in sorted(best[1], key=min):
        vals = [values[i] for i in members]
        base = _gcd(vals)
        groups.append(FrequencyGroup(members=tuple(names[i] for i in members),
                                     frequencies=tuple(vals), base=base,
                                     multipliers=tuple(int(v / base) for v in vals)))
    return FrequencyGroups(groups=tuple(groups), max_multiplier=max_multiplier)


def _forced_blocks(values: list[Fraction], bound: int) -> list[list[int]]:
    """Indices joined where two values are in a small ratio (transitively)."""
    parent = list(range(len(values)))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in itertools.combinations(range(len(values)), 2):
        r = values[i] / values[j]
        if max(r.numerator, r.denominator) <= bound:
            parent[root(i)] = root(j)
    blocks: dict[int, list[int]] = {}
    for i in range(len(values)):
        blocks.setdefault(root(i), []).append(i)
    return list(blocks.values())


def _groupings(blocks, values, bound) -> Iterator[list[list[list[int]]]]:
    """Candidate groupings of the forced ``blocks``: every set partition of them while
    there are at most :data:`MAX_EXHAUSTIVE` values, else one greedy grouping (each
    block joins the first group it fits, in order of frequency)."""
    if len(values) <= MAX_EXHAUSTIVE:
        yield from _set_partitions(blocks)
        return
    groups: list[list[list[int]]] = []
    for block in sorted(blocks, key=lambda b: min(values[i] for i in b)):
        for group in groups:
            joined = [values[i] for b in group + [block] for i in b]
            if _largest_multiplier(joined) <= bound:
                group.append(block)
                break
        else:
            groups.append([block])
    yield groups


def _set_partitions(items: list) -> Iterator[list[list]]:
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for partition in _set_partitions(rest):
        yield [[first]] + partition
        for k in range(len(partition)):
            yield partition[:k] + [[first] + partition[k]] + partition[k + 1:]


def _gcd(values: list[Fraction]) -> Fraction:
    """Greatest common divisor of positive fractions: gcd of numerators over lcm of
    denominators."""
    num = math.gcd(*(v.numerator for v in values))
    den = math.lcm(*(v.denominator for v in values))
    return Fraction(num, den)


def _largest_multiplier(values: list[Fraction]) -> int:
    base = _gcd(values)
    return max(int(v / base) for v in values)


def _number(x: Fraction) -> str:
    return str(x.numerator) if x.denominator == 1 else f"{float(x):g}"
