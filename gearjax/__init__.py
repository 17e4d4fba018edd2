"""gearjax: non-linear, time-varying dynamics of compound planetary gear trains in JAX."""

from . import _config  # noqa: F401  (float64 on import)
from ._assembly import assemble as assemble
from ._calibrate import CalibrationResult as CalibrationResult, calibrate as calibrate
from ._campbell import Campbell as Campbell, Crossing as Crossing, campbell as campbell
from ._design import (
    DesignSweep as DesignSweep,
    batched_rms as batched_rms,
    design_mesh as design_mesh,
    design_sweep as design_sweep,
)
from ._errors import (
    GeometryWarning as GeometryWarning,
    RangeWarning as RangeWarning,
    TrainError as TrainError,
    TrainWarning as TrainWarning,
)
from ._harmonics import TruncationWarning as TruncationWarning
from ._kinematics import Kinematics as Kinematics, kinematics as kinematics
from ._mesh import (
    backlash as backlash,
    fourier_series as fourier_series,
    mesh_force as mesh_force,
    phasing_report as phasing_report,
    stiffness_amplitudes as stiffness_amplitudes,
)
from ._modal import ModalResult as ModalResult, generalized_eigvals as generalized_eigvals, modes as modes
from ._optimize import (
    OptimizeResult as OptimizeResult,
    OptimizeSettings as OptimizeSettings,
    admissible_planet_sets as admissible_planet_sets,
    optimize as optimize,
    optimize_dataset as optimize_dataset,
)
from ._paths import get_path as get_path, set_path as set_path, continuous_paths as continuous_paths
from ._responses import (
    MeshResponses as MeshResponses,
    mesh_responses as mesh_responses,
    mesh_time_history as mesh_time_history,
    responses_from_samples as responses_from_samples,
    static_mesh_forces as static_mesh_forces,
)
from ._results import (
    load_results as load_results,
    mesh_coordinates as mesh_coordinates,
    points_json as points_json,
    results_frame as results_frame,
    save_results as save_results,
    sweep_dataset as sweep_dataset,
)
from ._stability import floquet_multipliers as floquet_multipliers, hill_multipliers as hill_multipliers, Stability as Stability, stability as stability
from ._simulate import simulate_gear as simulate_gear
from ._sweep import SweepResult as SweepResult, sweep as sweep
from ._sensitivity import (
    BandSensitivity as BandSensitivity,
    Sensitivity as Sensitivity,
    band_sensitivity as band_sensitivity,
    sensitivity as sensitivity,
)
from ._static import StaticLoads as StaticLoads, static_deflection as static_deflection, static_loads as static_loads
from ._system import System as System, system_from_matrices as system_from_matrices
from ._time_domain import (
    TimeDomain as TimeDomain,
    Trajectory as Trajectory,
    contact_state as contact_state,
    hb_initial_state as hb_initial_state,
    simulate as simulate,
    simulate_points as simulate_points,
    simulate_sweep as simulate_sweep,
)
from ._toml_io import (
    bundled_example_path as bundled_example_path,
    dumps_train as dumps_train,
    load_train as load_train,
    loads_train as loads_train,
    save_train as save_train,
)
from ._train import (
    Coupling as Coupling,
    Gear as Gear,
    Housing as Housing,
    Stage as Stage,
    Train as Train,
)
from ._validate import geometry_warnings as geometry_warnings, validate_train as validate_train
from ._verify import VerifyResult as VerifyResult, verify_gear as verify_gear

__version__ = "0.1.0"
