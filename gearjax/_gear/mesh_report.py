"""What a gear's meshes are: contact, mean stiffness, the stiffness harmonics used.

One record per stage and mesh side, for ``gearjax info`` and ``gearjax mesh``: from
the tooth geometry where the stage has one (involute contact, potential-energy
stiffness at the gear's static load, ISO 6336-1 method B beside it), otherwise the
file's contact ratio and mean stiffness with the rectangular wave.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .iso6336 import iso_stiffness
from .kinematics import kinematics
from .mesh_stiffness import mesh_pair, mesh_wave, planet_load
from .phasing import stiffness_amplitudes
from .train import Stage, Train

TRUNCATION_HARMONICS = 64
"""Harmonics of the reference wave against which the kept ones are measured."""


@dataclasses.dataclass(frozen=True)
class MeshSide:
    """One mesh side of a stage in one gear.

    **Fields:** ``stage``, ``side`` (``sun`` | ``ring``); ``source``: ``"geometry"``
    (derived), ``"file"``, or ``"file, geometry checked"``; ``contact_ratio``;
    ``mean_stiffness`` (N/m, at ``load`` where tip relief makes it depend on load);
    ``load``: static normal load of one planet's mesh (N); ``harmonics``: ``(h,
    amplitude relative to the mean, phase deg)`` of the stiffness harmonics kept;
    ``truncation``: RMS of the stiffness variation beyond them, relative to the RMS of
    the whole variation; ``relief_te_um``: amplitude (um) of the tip relief's
    transmission error per kept harmonic (empty without relief). With geometry:
    ``pressure_angle_deg`` (operating), ``centre_distance_mm``, ``iso_single`` and
    ``iso_mesh`` (ISO 6336-1 ``c' b`` and ``c_gamma_alpha b``, N/m) and
    ``iso_difference`` (``mean / (c_gamma_alpha b) - 1``); ``None`` otherwise.
    """

    stage: str
    side: str
    source: str
    contact_ratio: float
    mean_stiffness: float
    load: float
    harmonics: tuple[tuple[int, float, float], ...]
    truncation: float
    relief_te_um: tuple[float, ...]
    pressure_angle_deg: float | None = None
    centre_distance_mm: float | None = None
    iso_single: float | None = None
    iso_mesh: float | None = None
    iso_difference: float | None = None

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["harmonics"] = [{"h": h, "amplitude": a, "phase_deg": p} for h, a, p in self.harmonics]
        d["relief_te_um"] = list(self.relief_te_um)
        return d


def mesh_report(train: Train, gear: str | None = None) -> list[MeshSide]:
    """Every stage's two meshes in ``gear`` (default: the first)."""
    g = train.gear(gear)
    kin = kinematics(train, g.name)
    H = train.stiffness_harmonics
    out = []
    for s, sk in zip(train.stages, kin.stages):
        load = float(planet_load(s, sk, g))
        for side in ("sun", "ring"):
            out.append(_side(s, side, H, load))
    return out


def _side(s: Stage, side: str, H: int, load: float) -> MeshSide:
    geo = s.geometry
    derived = s.stiffness_from_geometry
    if derived:
        wave = mesh_wave(s, side, H, load=load)
        full = mesh_wave(s, side, TRUNCATION_HARMONICS, load=load)
        a, b = np.asarray(wave.k_cos), np.asarray(wave.k_sin)
        fa, fb = np.asarray(full.k_cos), np.asarray(full.k_sin)
        mean, ratio = float(wave.mean), float(wave.contact_ratio)
        relief = tuple(float(x) * 1e6 for x in np.hypot(wave.te_cos, wave.te_sin)) \
            if geo.relieved else ()
    else:
        ratio = float(getattr(s.contact_ratio, side))
        mean = float(getattr(s.mesh_stiffness, side))
        a = np.asarray(stiffness_amplitudes(ratio, H))
        fa = np.asarray(stiffness_amplitudes(ratio, TRUNCATION_HARMONICS))
        b, fb = np.zeros_like(a), np.zeros_like(fa)
        relief = ()
    total = float(np.sum(fa**2 + fb**2))
    kept = float(np.sum(fa[:H] ** 2 + fb[:H] ** 2))
    harmonics = tuple((h + 1, float(np.hypot(a[h], b[h])),
                       float(np.degrees(np.arctan2(-b[h], a[h])))) for h in range(H))
    report = MeshSide(
        stage=s.id, side=side,
        source="geometry" if derived else ("file, geometry checked" if geo is not None
                                           else "file"),
        contact_ratio=ratio, mean_stiffness=mean, load=load, harmonics=harmonics,
        truncation=float(np.sqrt(max(total - kept, 0.0) / total)) if total > 0 else 0.0,
        relief_te_um=relief,
    )
    if geo is None:
        return report
    pair, _, contact = mesh_pair(s, side)
    # ISO's tangential load is at the reference circle: F_n r_b / r = F_n cos(alpha)
    iso = iso_stiffness(*pair, contact, geo.face_width_mm * 1e-3,
                        tangential_load_n=load * float(np.cos(np.radians(s.pressure_angle_deg))))
    iso_mesh = float(iso.mesh_per_width)
    return dataclasses.replace(
        report,
        pressure_angle_deg=float(np.degrees(contact.operating_pressure_angle)),
        centre_distance_mm=float(contact.centre_distance) * 1e3,
        iso_single=float(iso.single_per_width), iso_mesh=iso_mesh,
        iso_difference=mean / iso_mesh - 1.0,
    )
