"""gearjax: non-linear, time-varying dynamics of compound planetary gear trains in JAX."""

from . import _config  # noqa: F401  (float64 on import)
from ._engine import (
    AbstractParameter as AbstractParameter,
    aft_analysis as aft_analysis,
    aft_synthesis as aft_synthesis,
    backlash as backlash,
    Basis as Basis,
    bifurcation_kind as bifurcation_kind,
    bordered_factor as bordered_factor,
    bordered_solve as bordered_solve,
    BorderedFactors as BorderedFactors,
    Branch as Branch,
    compile_simulate_points as compile_simulate_points,
    CondensedLU as CondensedLU,
    contact_state as contact_state,
    ContinuationSettings as ContinuationSettings,
    continue_branch as continue_branch,
    continue_compiled as continue_compiled,
    distinct_folds as distinct_folds,
    FactorisedNewton as FactorisedNewton,
    floquet_multipliers as floquet_multipliers,
    floquet_steps as floquet_steps,
    fourier_series as fourier_series,
    FrequencyParameter as FrequencyParameter,
    generalized_eigvals as generalized_eigvals,
    harmonic_basis as harmonic_basis,
    HarmonicBalance as HarmonicBalance,
    hb_initial_state as hb_initial_state,
    hb_jacobian as hb_jacobian,
    hb_newton as hb_newton,
    hb_problem as hb_problem,
    hb_residual as hb_residual,
    HBJacobian as HBJacobian,
    HBProblem as HBProblem,
    HBSolution as HBSolution,
    hill_multipliers as hill_multipliers,
    implicit_coefficients as implicit_coefficients,
    in_contact as in_contact,
    KrylovHB as KrylovHB,
    pair_preconditioner as pair_preconditioner,
    PairPreconditioner as PairPreconditioner,
    uses_krylov as uses_krylov,
    linear_guess as linear_guess,
    mesh_force as mesh_force,
    mesh_responses as mesh_responses,
    mesh_time_history as mesh_time_history,
    MeshResponses as MeshResponses,
    ModalResult as ModalResult,
    mode_classes as mode_classes,
    modes as modes,
    monodromy as monodromy,
    omega_derivative as omega_derivative,
    responses_from_samples as responses_from_samples,
    simulate as simulate,
    simulate_points as simulate_points,
    simulate_sweep as simulate_sweep,
    solve_hb as solve_hb,
    solve_hb_linear as solve_hb_linear,
    Stability as Stability,
    stability as stability,
    static_deflection as static_deflection,
    state_scales as state_scales,
    require_periodic as require_periodic,
    simulate_windowed as simulate_windowed,
    simulate_windowed_points as simulate_windowed_points,
    torus_basis as torus_basis,
    TRUNCATIONS as TRUNCATIONS,
    Windowed as Windowed,
    WindowedResponse as WindowedResponse,
    WindowPlan as WindowPlan,
    window_plan as window_plan,
    window_reports as window_reports,
    static_mesh_forces as static_mesh_forces,
    RESULTS as RESULTS,
    result_from_word as result_from_word,
    result_word as result_word,
    System as System,
    system_from_matrices as system_from_matrices,
    SystemParameter as SystemParameter,
    TimeDomain as TimeDomain,
    Trajectory as Trajectory,
)
from ._gear.assembly import assemble as assemble
from ._gear.calibrate import CalibrationResult as CalibrationResult, calibrate as calibrate
from ._gear.campbell import Campbell as Campbell, Crossing as Crossing, campbell as campbell
from ._studies.design import (
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
from ._studies.harmonics import (
    TruncationWarning as TruncationWarning,
    excitation_floor as excitation_floor,
    harmonics_rule as harmonics_rule,
    orders_floor as orders_floor,
    response_cutoff_hz as response_cutoff_hz,
    settings_for as harmonics_settings,
    torus_orders_rule as torus_orders_rule,
)
from ._gear.kinematics import Kinematics as Kinematics, kinematics as kinematics
from ._gear.frequency_groups import (
    FrequencyGroup as FrequencyGroup,
    FrequencyGroups as FrequencyGroups,
    gear_frequency_groups as gear_frequency_groups,
    group_frequencies as group_frequencies,
)
from ._gear.phasing import (
    phasing_report as phasing_report,
    stiffness_amplitudes as stiffness_amplitudes,
)
from ._studies.optimize import (
    OptimizeResult as OptimizeResult,
    OptimizeSettings as OptimizeSettings,
    optimize as optimize,
    optimize_dataset as optimize_dataset,
)
from ._gear.paths import (
    get_path as get_path,
    set_path as set_path,
    continuous_paths as continuous_paths,
)
from ._io.results import (
    load_results as load_results,
    mesh_coordinates as mesh_coordinates,
    points_json as points_json,
    results_frame as results_frame,
    save_results as save_results,
    sweep_dataset as sweep_dataset,
)
from ._studies.simulate import simulate_gear as simulate_gear
from ._studies.study import (
    StudyResult as StudyResult,
    StudySpec as StudySpec,
    candidate_train as candidate_train,
    load_study as load_study,
    load_study_results as load_study_results,
    loads_study as loads_study,
    study as study,
)
from ._studies.study.report import (
    candidate_records as candidate_records,
    merit_values as merit_values,
    pareto as pareto,
)
from ._studies.validity import (
    ContactLossWarning as ContactLossWarning,
    contact_loss as contact_loss,
)
from ._studies.concurrency import threads as threads
from ._studies.sweep import (
    RefinementWarning as RefinementWarning,
    SweepResult as SweepResult,
    backlash_start as backlash_start,
    responses_and_stability as responses_and_stability,
    coexisting_bands as coexisting_bands,
    progress_bar as progress_bar,
    progress_printer as progress_printer,
    solve_hb_points as solve_hb_points,
    sweep as sweep,
)
from ._studies.sensitivity import (
    BandSensitivity as BandSensitivity,
    Sensitivity as Sensitivity,
    band_sensitivity as band_sensitivity,
    sensitivity as sensitivity,
)
from ._gear.static_loads import StaticLoads as StaticLoads, static_loads as static_loads
from ._gear.toml_io import (
    bundled_example_path as bundled_example_path,
    dumps_train as dumps_train,
    load_train as load_train,
    loads_train as loads_train,
    save_train as save_train,
)
from ._gear.train import (
    Coupling as Coupling,
    Gear as Gear,
    Housing as Housing,
    PerGear as PerGear,
    Stage as Stage,
    TipRelief as TipRelief,
    ToothGeometry as ToothGeometry,
    Train as Train,
)
from ._gear.involute import (
    MeshContact as MeshContact,
    ToothForm as ToothForm,
    mesh_contact as mesh_contact,
)
from ._gear.iso6336 import IsoStiffness as IsoStiffness, iso_stiffness as iso_stiffness
from ._gear.tooth_stiffness import (
    hertz_compliance as hertz_compliance,
    tooth_compliance as tooth_compliance,
)
from ._gear.mesh_stiffness import (
    MeshCycle as MeshCycle,
    MeshWave as MeshWave,
    mesh_cycle as mesh_cycle,
    mesh_wave as mesh_wave,
    stage_contacts as stage_contacts,
    tooth_forms as tooth_forms,
)
from ._gear.mesh_report import MeshSide as MeshSide, mesh_report as mesh_report
from ._gear.validate import (
    geometry_warnings as geometry_warnings,
    validate_train as validate_train,
)
from ._studies.verify import (
    VerifyResult as VerifyResult,
    compare_rms as compare_rms,
    verify_gear as verify_gear,
)

from ._gear.paper import TABLE2_KHZ as TABLE2_KHZ, compare_table2 as compare_table2
from ._gear.planet_sets import admissible_planet_sets as admissible_planet_sets
from ._gear.case import GearCase as GearCase, gear_case as gear_case
from ._plot.figures import (
    campbell_figure as campbell_figure,
    design_figure as design_figure,
    mesh_cycle_figure as mesh_cycle_figure,
    recheck_figure as recheck_figure,
    response_figure as response_figure,
    separation_figure as separation_figure,
)
from ._plot.study_figure import study_figure as study_figure
from ._plot.bearing_figure import bearing_figure as bearing_figure
from ._gear.load_sharing import load_sharing as load_sharing
from ._plot.save import (
    plot_mode_shapes as plot_mode_shapes,
    plot_optimize as plot_optimize,
    plot_points as plot_points,
    plot_results as plot_results,
    plot_sweep as plot_sweep,
    plot_verify as plot_verify,
)
from ._studies.optimize import (
    Recheck as Recheck,
    optimize_frame as optimize_frame,
    optimize_json as optimize_json,
    recheck as recheck,
)
from ._studies.sensitivity import GearFamily as GearFamily, sensitivity_json as sensitivity_json
from ._version import __version__ as __version__
