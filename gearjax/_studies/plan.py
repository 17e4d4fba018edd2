"""What the studies solve for a gear, as ``gearjax info`` reports it: its frequency
groups and the solver they call for, and the harmonic balance's floor and first cutoff."""

from __future__ import annotations

from .._engine.floquet import return_turns
from .._errors import TrainError
from .._gear.assembly import assemble
from .._gear.frequency_groups import gear_frequency_groups
from .._gear.kinematics import Kinematics
from .._gear.train import Train
from .harmonics import (
    CUTOFF_MARGIN,
    TORUS_TRUNCATION,
    excitation_floor,
    floor_reason,
    response_cutoff_hz,
)


def solver_plan(train: Train, kin: Kinematics, input_rpm: float) -> dict:
    """``frequency_groups`` (``[{members, multipliers, base_exact, base_hz}]``, base in
    cycles per input revolution and in Hz at ``input_rpm``; empty where nothing turns)
    and ``solver_plan``: what a sweep of this gear solves, in words."""
    rev_hz = input_rpm / 60.0
    try:
        groups = gear_frequency_groups(kin, train.source).groups
    except TrainError as e:
        return {"frequency_groups": [], "solver_plan": f"refused: {e}"}
    rows = [{"members": list(g.members), "multipliers": list(g.multipliers),
             "base_exact": str(g.base), "base_hz": float(g.base) * rev_hz} for g in groups]
    if kin.mu is None:
        plan = "refused: no mesh turns in this gear (nothing to solve at a mesh frequency)"
    elif len(groups) == 1:
        plan = (f"periodic harmonic balance with one base, {rows[0]['base_hz']:.2f} Hz, "
                f"mu = {list(kin.mu)}")
    else:
        G = len(groups)
        ratios = [g.base / groups[0].base for g in groups]
        q, d = return_turns([float(r) for r in ratios])
        common = (f"; a single common base would need mu = {list(kin.mu)}, the excitation "
                  f"alone reaching harmonic "
                  f"{max((train.stiffness_harmonics * max(kin.mu),) + kin.ripple_mu)} of it")
        plan = (f"{G} incommensurate groups: the response is quasi-periodic on a {G}-torus, "
                f"solved by the multi-frequency harmonic balance (one angle per group, "
                f"base ratios {', '.join(str(r) for r in ratios)}; {TORUS_TRUNCATION} "
                f"truncation sets of orders K_g per angle, chosen per segment and checked "
                f"by doubling each angle's order); stability from the monodromy over {q} "
                f"turns of the first group's base, after which the torus line returns within "
                f"{d:.3f} turns" + common)
    return {"frequency_groups": rows, "solver_plan": plan}


def harmonics_plan(train: Train, gear: str, kin: Kinematics) -> dict | None:
    """What the harmonic balance of ``gear`` needs: the excitation floor of K and the
    response cutoff of its first choice (Hz), ``None`` where no mesh turns."""
    if kin.mu is None:
        return None
    system = assemble(train, gear, kin)
    cutoff = response_cutoff_hz(system)
    return {"floor": excitation_floor(system), "floor_rule": floor_reason(system, 1),
            "cutoff_hz": cutoff, "mesh_mode_hz": cutoff / CUTOFF_MARGIN}
