"""Frequency-response sweeps of a gear: the gear-train surface of the harmonic balance.

Frequencies are the mesh frequency (Hz) of a reference stage; with the gear's
coprime ``mu``, ``Omega = 2 pi f / mu_ref`` is the base frequency of every
excitation. The number of solution harmonics depends on frequency
(:func:`gearjax._studies.harmonics.harmonics_rule`): low base frequencies need many
harmonics to reach the modes the excitation drives, high ones few. It is fixed within a
segment of the band, so each segment compiles once; at a segment boundary the solution
is padded or truncated to the next segment's harmonics and re-converged on the boundary.
Each segment's K is checked at its first frequency by the truncation estimate
(:func:`gearjax._studies.harmonics.truncation_change`) and doubled until the estimate
meets the target, before the walk starts.

Linear sweeps (no backlash) are independent points: the periodic solution of a
linear time-periodic system is unique wherever it exists, so a grid of frequencies
is solved in one batched call and no continuation is needed (near a parametric
instability boundary the response grows without bound; those points are unstable).
Non-linear sweeps are pseudo-arclength continuations through the folds.

One module per job: :mod:`.api` (the entry point :func:`sweep`), :mod:`.arguments`
(argument checks), :mod:`.context` (what the segments share), :mod:`.segments` (the
harmonics plan and its truncation check), :mod:`.starts` (branch starts),
:mod:`.walk` (segments, continuation, restarts), :mod:`.speculation` (the last segment
ahead of time), :mod:`.post` (responses, stability, bifurcations), :mod:`.record`
(the journal's records), :mod:`.dataset`, :mod:`.summary` and :mod:`.progress`.
"""

from ..._engine.responses import static_mesh_forces as static_mesh_forces
from .api import sweep as sweep
from .post import POST_CHUNK as POST_CHUNK
from .post import SWEEP_FLOQUET_STEPS as SWEEP_FLOQUET_STEPS
from .post import PostStream as PostStream
from .post import batch_monodromy as batch_monodromy
from .post import batch_verdict as batch_verdict
from .post import bifurcations as bifurcations
from .post import point_rows as point_rows
from .post import point_rows as responses_and_stability
from .progress import SweepProgress as SweepProgress
from .progress import progress_bar as progress_bar
from .progress import progress_printer as progress_printer
from .record import SweepLog as SweepLog
from .refine import RefinementWarning as RefinementWarning
from .starts import backlash_start as backlash_start
from .starts import newton as newton
from .starts import resize_harmonics as resize_harmonics
from .starts import settled_start as settled_start
from .starts import solve_points as solve_points
from .starts import solve_points as solve_hb_points
from .starts import start_point as start_point
from .summary import SweepResult as SweepResult
from .summary import coexisting_bands as coexisting_bands
from .summary import summary_json as summary_json
from .walk import MAX_DETOUR as MAX_DETOUR
from .walk import MAX_RESTARTS as MAX_RESTARTS
from .walk import RESTART_STOPS as RESTART_STOPS
from .walk import RUNAWAY as RUNAWAY
