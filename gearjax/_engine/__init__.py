"""The engine: harmonic balance, continuation, stability and time integration of a
:class:`System`. It knows matrices and mesh elements, never gears (design.md); the gear
model builds ``System`` objects for it. These are its public names; the rest of the
package goes through them or through a module's own public names.
"""

from .adjoint import implicit_coefficients as implicit_coefficients
from .aft import analysis as aft_analysis, synthesis as aft_synthesis
from .aft import Basis as Basis
from .aft import TRUNCATIONS as TRUNCATIONS
from .aft import torus_basis as torus_basis
from .bordered import Factors as BorderedFactors
from .bordered import factor as bordered_factor, solve as bordered_solve
from .results import RESULTS as RESULTS
from .results import result_from_word as result_from_word
from .results import result_word as result_word
from .continuation import AbstractParameter as AbstractParameter
from .continuation import Branch as Branch
from .continuation import FrequencyParameter as FrequencyParameter
from .continuation import Settings as ContinuationSettings
from .continuation import SystemParameter as SystemParameter
from .continuation import continue_branch as continue_branch
from .continuation import continue_compiled as continue_compiled
from .continuation import distinct_folds as distinct_folds
from .floquet import floquet_multipliers as floquet_multipliers
from .floquet import floquet_steps as floquet_steps
from .floquet import monodromy as monodromy
from .hb import HarmonicBalance as HarmonicBalance
from .hb import HBProblem as HBProblem
from .hb import HBSolution as HBSolution
from .hb import hb_problem as hb_problem
from .hb import harmonic_basis as harmonic_basis
from .hb import jacobian as hb_jacobian
from .hb import linear_guess as linear_guess
from .hb import omega_derivative as omega_derivative
from .hb import residual as hb_residual
from .hill import hill_multipliers as hill_multipliers
from .krylov import KrylovHB as KrylovHB
from .krylov import PairPreconditioner as PairPreconditioner
from .krylov import pair_preconditioner as pair_preconditioner
from .krylov import uses_krylov as uses_krylov
from .linear_solver import CondensedLU as CondensedLU
from .linear_solver import HBJacobian as HBJacobian
from .mesh_force import backlash as backlash
from .mesh_force import fourier_series as fourier_series
from .mesh_force import in_contact as in_contact
from .mesh_force import mesh_force as mesh_force
from .modal import ModalResult as ModalResult
from .modal import generalized_eigvals as generalized_eigvals
from .modal import mode_classes as mode_classes
from .modal import modes as modes
from .newton import FactorisedNewton as FactorisedNewton
from .newton import newton as hb_newton
from .newton import solve_hb as solve_hb
from .newton import solve_linear as solve_hb_linear
from .responses import MeshResponses as MeshResponses
from .responses import mesh_responses as mesh_responses
from .responses import mesh_time_history as mesh_time_history
from .responses import responses_from_samples as responses_from_samples
from .responses import static_mesh_forces as static_mesh_forces
from .verdict import Stability as Stability
from .verdict import bifurcation_kind as bifurcation_kind
from .verdict import stability as stability
from .static import static_deflection as static_deflection
from .system import System as System
from .system import system_from_matrices as system_from_matrices
from .time_domain import TimeDomain as TimeDomain
from .time_domain import compile_simulate_points as compile_simulate_points
from .time_domain import Trajectory as Trajectory
from .initial_state import contact_state as contact_state
from .initial_state import hb_initial_state as hb_initial_state
from .time_domain import simulate as simulate
from .time_domain import simulate_points as simulate_points
from .time_domain import simulate_sweep as simulate_sweep
from .time_domain import state_scales as state_scales
from .time_domain import require_periodic as require_periodic
from .windowed import Windowed as Windowed
from .windowed import WindowedResponse as WindowedResponse
from .windowed import WindowPlan as WindowPlan
from .windowed import simulate_windowed as simulate_windowed
from .windowed import simulate_windowed_points as simulate_windowed_points
from .windowed import window_reports as window_reports
from .windowed import window_plan as window_plan
