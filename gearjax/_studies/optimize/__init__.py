"""Phasing optimisation: planet positions, sun-ring and stage phases that minimise the
largest RMS dynamic mesh force over a band of mesh frequencies.

**Variables** (:mod:`.variables`): a stage's whole planet set, chosen among the
admissible sets (:mod:`gearjax._gear.planet_sets`: on assembly slots, not overlapping,
one per class of sets the torsional model cannot tell apart), its sun-ring phase and its
stage phase (deg).

**Objective:** the largest RMS of the alternating mesh force (N) over the band's
frequencies and the gear's meshes, with backlash over every stable state of a complete
sweep (:mod:`.nonlinear`); ties on the linear models are broken by the next largest
per-frequency peaks, then by the better-balanced planet set, then in favour of the
incumbent (:mod:`.ranking`). Three models, cheapest first, decide stage by stage
(:mod:`.driver`):

1. *proxy* (:mod:`.proxy`): every distinct set x a grid of sun-ring (and stage)
   phases, the forced response to first order in the stiffness variation;
2. *linear* (:mod:`.screen`): the ``screen`` best sets by the linear, time-varying
   harmonic balance (:mod:`gearjax._studies.design`: parametric coupling kept, no
   backlash), batched;
3. *non-linear* (:mod:`.nonlinear`): the ``nonlinear`` best (and the baseline, with the
   same settings) by complete sweeps with backlash (:func:`gearjax.sweep` with
   ``complete=True``, a fixed K): the peak is over every stable state the walk and its
   completion find (``stable == 1``, result ``converged``; runaway points left out).

The continuous relaxation (:mod:`.relaxation`) is reported for comparison. Baseline,
optimum and relaxation are compared on one grid: ``final_points`` geometric
frequencies, the resonance frequencies and each design's proxy peaks. The result says
which settings each step used (``models``) and whether the optimum beats the baseline
(``verdict``, :func:`.result.verdict`: by how much, or that no admissible phasing it
tried does, and the recommended design is then the baseline). Outputs: :mod:`.output`;
an independent re-check of baseline and optimum by fresh complete sweeps at the sweep's
own K, integration from their peak orbits, and its own verdict: :mod:`.rechecking`.
"""

from ..._gear.planet_sets import admissible_planet_sets as admissible_planet_sets
from .driver import optimize as optimize
from .driver import pick_nonlinear as pick_nonlinear
from .nonlinear import NONLINEAR_RTOL as NONLINEAR_RTOL
from .nonlinear import BandSettings as BandSettings
from .nonlinear import NonlinearBand as NonlinearBand
from .nonlinear import band_of as band_of
from .nonlinear import nonlinear_band as nonlinear_band
from .nonlinear import stable_points as stable_points
from .output import band_json as band_json
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
from .rechecking import recheck_json as recheck_json
from .relaxation import Relaxation as Relaxation
from .result import Design as Design
from .result import NO_BETTER as NO_BETTER
from .result import OptimizeResult as OptimizeResult
from .result import verdict as verdict
from .settings import OptimizeSettings as OptimizeSettings
from .variables import default_vary as default_vary
from .variables import theta_of as theta_of
from .variables import train_at as train_at
