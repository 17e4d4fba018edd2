"""Kinematics of a gear in exact fractions: speeds, ratio, mesh frequencies, mu.

Nominal speeds follow from each stage's Willis equation
``Z_s (w_s - w_c) + Z_r (w_r - w_c) = 0``, the engaged couplings (coupled members
turn together), the brakes (``w = 0``) and the input speed (1). All speeds are per
unit input speed and exact (``fractions.Fraction``): with integer teeth every speed
ratio is rational, which is what makes a common base frequency exist.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

from .._errors import fail
from .train import MEMBERS, Train, member_paths

MAX_MU = 100
"""Largest harmonic multiplier of the base frequency a solver accepts."""


@dataclasses.dataclass(frozen=True)
class StageKinematics:
    """One stage in one gear, per unit input speed (exact).

    **Fields:** ``mesh_frequency``: ``Z_r |w_r - w_c|``, mesh cycles per input
    revolution (multiply by input rev/s for Hz); ``planet_speed``: planet speed relative
    to the carrier; ``sigma``: ``sign(w_s - w_c)`` (0 when the stage does not turn);
    ``load``: tooth load per unit input torque as ``sum_i F_i * m cos(alpha) / 2`` (the
    stage's sun torque is ``Z_s`` times it), ``None`` when the rigid statics is
    indeterminate; ``loaded``: meshes carry static load.
    """

    id: str
    sun: Fraction
    ring: Fraction
    carrier: Fraction
    planet_speed: Fraction
    mesh_frequency: Fraction
    sigma: int
    load: Fraction | None
    loaded: bool

    @property
    def turning(self) -> bool:
        return self.mesh_frequency != 0


@dataclasses.dataclass(frozen=True)
class Kinematics:
    """Kinematics of ``gear``: exact speeds per unit input speed.

    **Fields:** ``speeds``: member path -> speed; ``ratio``: input speed / output speed
    (signed); ``stages``: per stage; ``mu``: coprime integer multipliers of the base
    frequency per stage (0 for a stage that does not turn), ``None`` when no mesh turns;
    ``base``: base frequency in cycles per input revolution (stage mesh frequency =
    ``mu_n * base``); ``ripple_mu``: multipliers of the input-torque ripple orders.
    """

    gear: str
    speeds: dict[str, Fraction]
    ratio: Fraction
    stages: tuple[StageKinematics, ...]
    mu: tuple[int, ...] | None
    base: Fraction | None
    ripple_mu: tuple[int, ...]

    def stage(self, stage_id: str) -> StageKinematics:
        for s in self.stages:
            if s.id == stage_id:
                return s
        raise KeyError(stage_id)

    def mesh_frequency_hz(self, stage_id: str, input_rpm: float) -> float:
        """Mesh frequency (Hz) of a stage at an input speed (rpm)."""
        return float(self.stage(stage_id).mesh_frequency) * input_rpm / 60.0

    def input_rpm(self, stage_id: str, mesh_frequency_hz: float) -> float:
        """Input speed (rpm) at which stage ``stage_id`` meshes at ``mesh_frequency_hz``."""
        f = self.stage(stage_id).mesh_frequency
        if f == 0:
            raise ValueError(f"stage {stage_id!r} does not turn in gear {self.gear!r}")
        return 60.0 * mesh_frequency_hz / float(f)


def kinematics(train: Train, gear: str | None = None) -> Kinematics:
    """Exact kinematics of ``gear`` (default: the first gear).

    **Raises:** ``TrainError`` when the gear's brakes and clutches leave the speeds
    undetermined, lock a train that should turn, or hold the output still.
    """
    g = train.gear(gear)
    paths = member_paths(train)
    index = {p: i for i, p in enumerate(paths)}
    where = f"gears.{g.name}"
    rows: list[tuple[list[Fraction], Fraction]] = []
    n = len(paths)

    def row(coefs: dict[str, int], rhs=0):
        r = [Fraction(0)] * n
        for p, c in coefs.items():
            r[index[p]] += c
        rows.append((r, Fraction(rhs)))

    for s in train.stages:
        zs, zr = s.teeth.sun, s.teeth.ring
        row({f"{s.id}.sun": zs, f"{s.id}.ring": zr, f"{s.id}.carrier": -(zs + zr)})
    for c in train.engaged_couplings(g.name):
        row({c.members[0]: 1, c.members[1]: -1})
    for b in g.brakes:
        row({b: 1})
    row({g.input: 1}, 1)

    solution, free = _solve_exact(rows, n)
    if solution is None:
        raise fail(train.source, where, _config(g),
                   "brakes and clutches lock a train that should turn: the input cannot rotate")
    if free:
        names = ", ".join(paths[i] for i in free)
        raise fail(train.source, where, _config(g),
                   f"brakes and clutches leave the speeds undetermined ({names} can turn freely); "
                   "add a brake or engage a clutch")
    speeds = dict(zip(paths, solution))
    w_out = speeds[g.output]
    if w_out == 0:
        raise fail(train.source, where + ".output", g.output,
                   "the output is held still in this gear (its speed is 0), so the ratio is undefined")
    ratio = Fraction(1) / w_out
    loads = _rigid_loads(train, g, speeds, ratio)

    stages = []
    for k, s in enumerate(train.stages):
        ws, wr, wc = (speeds[f"{s.id}.{m}"] for m in MEMBERS)
        relative = -Fraction(s.teeth.sun, s.teeth.planet) * (ws - wc)
        load = None if loads is None else loads[k]
        stages.append(StageKinematics(
            id=s.id, sun=ws, ring=wr, carrier=wc, planet_speed=relative,
            mesh_frequency=s.teeth.ring * abs(wr - wc),
            sigma=(ws > wc) - (ws < wc),
            load=load,
            loaded=(load != 0) if load is not None else True,
        ))
    orders = [Fraction(str(o)) for o in g.ripple_orders]
    freqs = [st.mesh_frequency for st in stages]
    nonzero = [f for f in freqs if f != 0] + orders
    base = _rational_gcd(nonzero) if nonzero else None
    ripple_mu = tuple(int(o / base) for o in orders)
    # no turning mesh: nothing to solve at a mesh frequency (the ripple alone keeps a base)
    mu = tuple(int(f / base) for f in freqs) if any(f != 0 for f in freqs) else None
    return Kinematics(gear=g.name, speeds=speeds, ratio=ratio, stages=tuple(stages), mu=mu,
                      base=base, ripple_mu=ripple_mu)


def require_base(kin: Kinematics, source: str | None = None) -> tuple[int, ...]:
    """The gear's ``mu``, refusing a gear with no turning mesh or an impractical ``mu``."""
    if kin.mu is None:
        raise fail(source, f"gears.{kin.gear}", kin.gear,
                   "no mesh turns in this gear (every stage rotates as a block): nothing to solve "
                   "at a mesh frequency")
    big = max(kin.mu + kin.ripple_mu)
    if big > MAX_MU:
        raise fail(source, f"gears.{kin.gear}", f"mu = {list(kin.mu)}, ripple mu = "
                   f"{list(kin.ripple_mu)}",
                   f"the mesh frequencies and ripple orders have no common base with multipliers "
                   f"<= {MAX_MU}; the harmonic balance would need thousands of harmonics")
    return kin.mu


def _config(g) -> str:
    return f"input {g.input}, brakes {list(g.brakes)}"


def _rational_gcd(values: list[Fraction]) -> Fraction:
    num, den = 0, 1
    for v in values:
        v = abs(v)
        # gcd(a/b, c/d) = gcd(a d, c b) / (b d)
        num, den = math.gcd(num * v.denominator, v.numerator * den), den * v.denominator
        g = math.gcd(num, den)
        num, den = num // g, den // g
    return Fraction(num, den)


def _solve_exact(rows, n):
    """Gauss-Jordan over fractions. Returns (solution | None if inconsistent, free columns)."""
    a = [list(r) + [rhs] for r, rhs in rows]
    pivots = []
    r = 0
    for col in range(n):
        pivot = next((i for i in range(r, len(a)) if a[i][col] != 0), None)
        if pivot is None:
            continue
        a[r], a[pivot] = a[pivot], a[r]
        p = a[r][col]
        a[r] = [v / p for v in a[r]]
        for i in range(len(a)):
            if i != r and a[i][col] != 0:
                f = a[i][col]
                a[i] = [vi - f * vr for vi, vr in zip(a[i], a[r])]
        pivots.append(col)
        r += 1
    if any(all(v == 0 for v in row[:n]) and row[n] != 0 for row in a):
        return None, []
    free = [c for c in range(n) if c not in pivots]
    # members whose speed is not fixed: a free column, or any pivot row that depends on one
    undetermined = set(free)
    for i, col in enumerate(pivots):
        if any(a[i][c] != 0 for c in free):
            undetermined.add(col)
    solution = [Fraction(0)] * n
    for i, col in enumerate(pivots):
        solution[col] = a[i][n]
    return solution, sorted(undetermined)


def _rigid_loads(train: Train, g, speeds, ratio) -> list[Fraction] | None:
    """Static tooth load per stage and unit input torque, from rigid-body statics.

    Stage ``n`` exerts ``Z_s L_n``, ``Z_r L_n`` and ``-(Z_s + Z_r) L_n`` on sun, ring and
    carrier (tooth load times base radius, per ``m cos(alpha) / 2``). Each group of
    members joined by engaged couplings balances the external torques on it (input 1,
    output ``-ratio``) plus a brake reaction if it holds a braked member. ``None`` when
    that leaves the loads indeterminate (redundant load paths share by stiffness).
    """
    paths = member_paths(train)
    parent = {p: p for p in paths}

    def find(p):
        while parent[p] != p:
            parent[p] = parent[parent[p]]
            p = parent[p]
        return p

    for c in train.engaged_couplings(g.name):
        parent[find(c.members[0])] = find(c.members[1])
    groups = sorted({find(p) for p in paths})
    braked_groups = sorted({find(b) for b in g.brakes})
    d = len(train.stages)
    n = d + len(braked_groups)
    rows = []
    for grp in groups:
        r = [Fraction(0)] * n
        rhs = Fraction(0)
        for k, s in enumerate(train.stages):
            zs, zr = s.teeth.sun, s.teeth.ring
            for member, coef in (("sun", zs), ("ring", zr), ("carrier", -(zs + zr))):
                if find(f"{s.id}.{member}") == grp:
                    r[k] += coef
        if find(g.input) == grp:
            rhs += 1
        if find(g.output) == grp:
            rhs -= ratio
        if grp in braked_groups:
            r[d + braked_groups.index(grp)] = Fraction(-1)
        rows.append((r, rhs))
    solution, free = _solve_exact(rows, n)
    if solution is None or any(c < d for c in free):
        return None
    return solution[:d]
