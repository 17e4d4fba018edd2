"""A sweep's points gathered from its records into the results Dataset
(:mod:`gearjax._io.results` layout, plus ``branch`` and ``max_multiplier``)."""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..._engine.results import RESULTS, legacy_words, result_word
from ..._gear.load_sharing import stage_load_sharing
from ..._gear.translational import bearing_table
from ..._io.bearing_results import add_bearing_forces
from ..._io.results import (add_displacement_harmonics, add_displacement_waves,
                               mesh_coordinates, sweep_dataset)
from .. import harmonics as _harmonics
from .completion import piece_rows
from .post import bifurcations, point_rows
from .walk import exceeds, walked_stretches


def point_data(walk, log, post, ctx, F_static, *, linear: bool, pieces=None) -> dict:
    """Per-point arrays of the walk's segments, in sweep order: ``responses``,
    ``omega``, ``result``, ``X`` (list: K differs between segments), ``K``, ``stable``,
    ``max_multiplier``, ``multipliers``, ``excluded``, ``branch``. A segment continued by
    the next ends with a point past the boundary, which the next one starts on (or,
    where it could not, from that point): that point is left out. ``pieces``: the
    branches of a completed sweep (:func:`~gearjax._studies.sweep.completion.complete`,
    rows computed), taken instead of the walk's segments.

    **Raises:** ``RuntimeError`` where the sweep found no point."""
    rows: list[dict] = []
    if pieces is not None:
        rows = [piece_rows(p) for p in pieces]
    elif linear:
        for j, problem in enumerate(walk.problems):
            batch = log.batch(j)
            rows.append(point_rows(problem, jnp.asarray(batch["X"]),
                                   jnp.asarray(batch["omega"]),
                                   legacy_words(batch["result"], "hb"), F_static))
            rows[-1]["branch"] = np.zeros(len(batch["omega"]), int)
    else:
        for j, problem, pts, branch in walked_stretches(walk, log):
            rows.append(post.rows(j, problem, ctx.omega_ref, pts))
            rows[-1]["branch"] = np.full(len(pts), branch)
    post.close()
    if not rows:
        raise RuntimeError(f"sweep produced no point: {walk.stop}")
    data = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]
            if k not in ("responses", "X")}
    data["X"] = [X for r in rows for X in r["X"]]
    # a point past the runaway bound (the first of a restarted branch, or the last of one
    # that ran away) is no state to sign: flagged, its stability unknown
    over = np.array([exceeds(ctx.system, X, ctx.runaway) for X in data["X"]], dtype=bool)
    if over.any():
        data["result"] = np.where(over, result_word(RESULTS.runaway), data["result"])
        data["stable"] = np.where(over, np.nan, np.asarray(data["stable"], dtype=float))
    data["responses"] = jax.tree.map(lambda *a: np.concatenate(a),
                                     *[r["responses"] for r in rows])
    return data


def sweep_result_dataset(data: dict, case, *, F_static, train_toml: str, solver: dict,
                         folds: list, stop: str, restarts: list, command: str,
                         branches: list | None = None):
    """The results Dataset of the sweep points ``data`` (:func:`point_data`) of the
    gear ``case`` (:class:`gearjax._gear.case.GearCase`) with static mesh forces
    ``F_static`` ``(m,)`` (N): frequencies from the base frequencies ``omega``,
    bifurcations along each branch, the ``solver`` settings, and the attributes
    ``kind = "sweep"``, ``folds_hz``, ``stop``, ``reference_stage``, ``bifurcations``,
    ``restarts`` and ``command`` (how the sweep was asked for); with ``branches`` (a
    completed sweep's records, :func:`~gearjax._studies.sweep.completion.complete`) the
    attribute ``branches`` (JSON: per branch ``branch``, ``found``, ``seed_hz``,
    ``stops``) and the point variable ``found`` (how the point's branch was found)."""
    omegas = data["omega"]
    f_ref = omegas * case.mu_ref / (2 * math.pi)
    stage_hz = np.outer(omegas / (2 * math.pi), np.asarray(case.mu, float))
    system = case.system
    bif = bifurcations(f_ref, data["stable"], data["multipliers"], data["excluded"],
                       data["branch"], torus=system.n_angles > 1, linear=bool(case.linear))
    ds = sweep_dataset(
        data["responses"], **mesh_coordinates(system),
        mesh_frequency_hz=f_ref,
        stage_mesh_frequency_hz=stage_hz,
        input_rpm=np.array([case.kin.input_rpm(case.stage, f) for f in f_ref]),
        omega=omegas,
        result=list(data["result"]),
        stable=data["stable"],
        static_force=np.asarray(F_static),
        train_toml=train_toml,
        gear=case.gear.name,
        solver=solver,
        attrs={"kind": "sweep", "folds_hz": folds, "stop": stop,
               "reference_stage": case.stage, "bifurcations": bif, "restarts": restarts,
               "command": command},
    )
    ds["branch"] = ("point", data["branch"], {
        "units": "1", "long_name": "solution branch (a new one after each restart)"})
    eta = data.get("eta", np.full(len(omegas), solver.get("eta", 1)))
    ds["eta"] = ("point", np.asarray(eta, dtype=np.int64), {
        "units": "1", "long_name": "period of the solution in base periods 2 pi / Omega (2: "
                                   "a branch born at a period doubling); its harmonics are "
                                   "of Omega / eta"})
    if branches is not None:
        ds.attrs["branches"] = json.dumps(branches)
        how = {b["branch"]: b["found"] for b in branches}
        ds["found"] = ("point", np.array([how.get(int(b), "") for b in data["branch"]],
                                         dtype=str),
                       {"units": "1",
                        "long_name": "how the point's branch was found: sweep, restart, far "
                                     "end, jump up, jump down, integration up or down, "
                                     "period doubling"})
    _, sharing = stage_load_sharing(system, ds["max_force"].values)
    ds["load_sharing"] = (("point", "stage_id"), sharing.T, {
        "units": "1", "long_name": "dynamic load-sharing factor: the largest planet's peak "
                                   "sun-mesh force over the mean of its planets' peaks"})
    ds["max_multiplier"] = ("point", data["max_multiplier"], {
        "units": "1", "long_name": "largest Floquet multiplier modulus (rigid-body excluded)"})
    if system.n_angles > 1:
        waves = [_harmonics.torus_basis_of(system, K).orders for K in map(tuple, data["K"])]
        ds = add_displacement_waves(ds, data["X"], system.dof_labels, data["K"], waves,
                                    system.angle_ratio)
    else:
        ds = add_displacement_harmonics(ds, data["X"], system.dof_labels, data["K"])
    if case.train.translational:
        ds = add_bearing_forces(ds, **bearing_table(case.train))
    return ds
