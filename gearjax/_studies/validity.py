"""Where a linear result stops describing the gear: teeth that would leave contact.

A linear run (``linear``: the backlash dropped) keeps every pair of teeth in contact
whatever the load: its mesh force ``F = k(t) p + c p'`` may change sign, which real
teeth cannot do. Where the alternating mesh force exceeds the static one, the teeth
of the real gear leave contact (they separate, and may strike the back flank), and
the linear result no longer describes it: the backlash model does.

The test is the one the backlash model's contact uses (``gearjax._engine.mesh_force``:
contact while ``|p| > b``): with the backlash dropped (``b = 0``) the teeth would leave
contact wherever the mesh deflection ``p`` has the sign opposite to the static force,
which is the ``back_contact`` share of a linear result (the share of the period spent
on the flank opposite the loaded one, :class:`~gearjax.MeshResponses`). A mesh without
static load (an idling set) has no loaded flank and is left out.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np

__all__ = ["ContactLossWarning", "contact_loss", "result_band", "warn_contact_loss"]


class ContactLossWarning(UserWarning):
    """A linear result whose alternating mesh force exceeds the static one somewhere: the
    teeth would leave contact there (:func:`contact_loss`; kept, flagged)."""


def result_band(ds) -> tuple[float, float] | None:
    """The band ``(from_hz, to_hz)`` (reference-stage mesh Hz, in the order asked) a sweep's
    results ``ds`` were asked for: its solver's ``band_hz``, else the first and last
    frequency of its segments; ``None`` where neither is stored (a simulation)."""
    solver = _solver(ds)
    band = solver.get("band_hz")
    if band is not None:
        return float(band[0]), float(band[1])
    segments = solver.get("segments")
    if segments:
        ends = [float(x) for a, b, *_ in segments for x in (a, b)]
        up = float(segments[0][1]) >= float(segments[0][0])
        return (min(ends), max(ends)) if up else (max(ends), min(ends))
    return None


def contact_loss(ds) -> dict | None:
    """Where the linear results ``ds`` (a sweep's or a simulation's Dataset) stop being
    valid: the first converged point, in the order of the run (a sweep's points inside
    its band, :func:`result_band`, in the direction asked; a simulation's in the order
    given), at which a loaded mesh's deflection reverses (module docstring).

    **Returns:** ``None`` for results with backlash (``solver.linear`` false) or where no
    point loses contact; otherwise ``{"mesh_frequency_hz", "mesh", "reversed_share",
    "dlf", "points", "of", "warning"}``: the first such point's frequency, its mesh
    with the largest share of the period reversed, that share and that mesh's dynamic
    load factor, how many of the ``of`` converged points lose contact somewhere, and
    one line saying so (the ``warning`` of a :class:`ContactLossWarning`)."""
    if not _solver(ds).get("linear", False) or "back_contact" not in ds:
        return None
    f = np.asarray(ds["mesh_frequency_hz"].values, float)
    order = np.arange(f.size)
    band = result_band(ds)
    if band is not None:
        lo, hi = min(band), max(band)
        tol = 1e-9 * max(abs(hi), 1.0)
        inside = (f >= lo - tol) & (f <= hi + tol)
        order = order[inside]
        order = order[np.argsort(f[order] * (1.0 if band[1] >= band[0] else -1.0),
                                 kind="stable")]
    converged = np.asarray(ds["converged"].values, bool)
    order = order[converged[order]]
    back = np.asarray(ds["back_contact"].values, float)
    lost = np.nan_to_num(back, nan=0.0) > 0  # NaN: a mesh without static load
    hit = [k for k in order if lost[k].any()]
    if not hit:
        return None
    k = hit[0]
    j = int(np.nanargmax(back[k]))
    name = str(ds["mesh"].values[j])
    dlf = float(ds["dlf"].values[k, j])
    out = {"mesh_frequency_hz": float(f[k]), "mesh": name,
           "reversed_share": float(back[k, j]),
           "dlf": dlf if math.isfinite(dlf) else None,
           "points": len(hit), "of": int(order.size)}
    out["warning"] = (
        f"linear result past its validity, first at {f[k]:.1f} Hz: the alternating mesh "
        f"force exceeds the static one there (mesh {name}: deflection reversed for "
        f"{100 * back[k, j]:.1f}% of the period, dynamic load factor "
        + (f"{dlf:.2f}" if math.isfinite(dlf) else "undefined")
        + f"), so the teeth would leave contact, which a linear run does not model; "
        f"{len(hit)} of {order.size} points are affected (a run with backlash models "
        "the separation)")
    return out


def _solver(ds) -> dict:
    text = ds.attrs.get("solver", "{}")
    if isinstance(text, dict):
        return text
    try:
        return json.loads(text or "{}")
    except (TypeError, ValueError):
        return {}


def warn_contact_loss(ds, stacklevel: int = 2):
    """``ds``, after a :class:`ContactLossWarning` where its linear results lose contact
    (:func:`contact_loss`); ``stacklevel`` as :func:`warnings.warn`'s, counted from the
    caller."""
    loss = contact_loss(ds)
    if loss is not None:
        warnings.warn(ContactLossWarning(loss["warning"]), stacklevel=stacklevel + 1)
    return ds
