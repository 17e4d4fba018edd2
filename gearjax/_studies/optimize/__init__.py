"""Phasing optimisation: planet positions, sun-ring and stage phases that minimise the
largest RMS dynamic mesh force over a band of mesh frequencies.

**Variables** (:mod:`.variables`): a stage's whole planet set, chosen among the
admissible sets (:mod:`gearjax._gear.planet_sets`: on assembly slots, not overlapping,
one per class of sets the torsional model cannot tell apart), its sun-ring phase and its
stage phase (deg).

**Objective:** the largest RMS of the alternating mesh force (N) over the band's
frequencies and the gear's meshes; ties are broken by the next largest per-frequency
peaks, then by the better-balanced planet set, then in favour of the incumbent
(:mod:`.ranking`). Three models, cheapest first, decide stage by stage
(:mod:`.driver`):

1. *proxy* (:mod:`.proxy`): every distinct set x a grid of sun-ring (and stage)
   phases, the forced response to first order in the stiffness variation;
2. *linear* (:mod:`.screen`): the ``screen`` best sets by the linear, time-varying
   harmonic balance (:mod:`gearjax._studies.design`: parametric coupling kept, no
   backlash), batched;
3. *non-linear* (:mod:`.nonlinear`): the ``nonlinear`` best by sweeps with backlash,
   restarted above each early stop; the peak is over the stable, plausible points.

The continuous relaxation (:mod:`.relaxation`) is reported for comparison. Baseline,
optimum and relaxation are compared on one grid: ``final_points`` geometric
frequencies, the resonance frequencies and each design's proxy peaks. Outputs:
:mod:`.output`; an independent re-check of baseline and optimum: :mod:`.rechecking`.
"""

from ..._gear.planet_sets import admissible_planet_sets as admissible_planet_sets
from .driver import NONLINEAR_RTOL as NONLINEAR_RTOL
from .driver import optimize as optimize
from .nonlinear import MAX_DLF as MAX_DLF
from .nonlinear import NonlinearBand as NonlinearBand
from .nonlinear import nonlinear_band as nonlinear_band
from .output import optimize_dataset as optimize_dataset
from .output import optimize_frame as optimize_frame
from .output import optimize_json as optimize_json
from .proxy import FirstOrder as FirstOrder
from .proxy import first_order as first_order
from .proxy import first_order_rms as first_order_rms
from .proxy import proxy_screen as proxy_screen
from .rechecking import Recheck as Recheck
from .rechecking import band_peak as band_peak
from .rechecking import recheck as recheck
from .rechecking import recheck_designs as recheck_designs
from .relaxation import Relaxation as Relaxation
from .result import Design as Design
from .result import OptimizeResult as OptimizeResult
from .settings import OptimizeSettings as OptimizeSettings
from .variables import default_vary as default_vary
from .variables import theta_of as theta_of
from .variables import train_at as train_at
