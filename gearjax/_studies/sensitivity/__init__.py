"""Sensitivities of harmonic-balance responses to train parameters, by implicit
differentiation.

- :mod:`.family`: the parametric maps ``theta -> System`` (:class:`GearFamily`, the
  parameters as TOML paths) and ``(problem, X, omega) -> response``
  (:class:`MeshResponse`);
- :mod:`.implicit`: the derivative at one converged point (:func:`implicit_gradient`,
  the implicit function theorem through :mod:`gearjax._engine.adjoint`) and the rule
  that refuses it at or near a fold or on an unstable solution (:func:`check_point`);
- :mod:`.point`: the study at one frequency (:func:`sensitivity`, :class:`Sensitivity`),
  on a gear prepared once (:class:`GearPoint`);
- :mod:`.band`: the smooth peak or the integral over a band of frequencies
  (:func:`band_sensitivity`, :class:`BandSensitivity`);
- :mod:`.steps`: the step of each parameter that ranks the derivatives
  (:func:`parameter_steps`: its value, or for an angle whose origin is a convention one
  assembly slot or one mesh cycle);
- :mod:`.output`: the ``sensitivity`` command's JSON (:func:`sensitivity_json`).
"""

from .band import BAND_OBJECTIVES as BAND_OBJECTIVES
from .band import BandSensitivity as BandSensitivity
from .band import band_sensitivity as band_sensitivity
from .family import RESPONSE_UNITS as RESPONSE_UNITS
from .family import RESPONSES as RESPONSES
from .family import GearFamily as GearFamily
from .family import MeshResponse as MeshResponse
from .family import check_paths as check_paths
from .family import response_field as response_field
from .implicit import FOLD_TOL as FOLD_TOL
from .implicit import PointGradient as PointGradient
from .implicit import SensitivityRefused as SensitivityRefused
from .implicit import check_point as check_point
from .implicit import implicit_gradient as implicit_gradient
from .implicit import point_status as point_status
from .implicit import response_at as response_at
from .implicit import slow_mode as slow_mode
from .implicit import solve_at as solve_at
from .output import path_unit as path_unit
from .output import sensitivity_json as sensitivity_json
from .point import GearPoint as GearPoint
from .point import Sensitivity as Sensitivity
from .point import mesh_index as mesh_index
from .point import normalise as normalise
from .point import sensitivity as sensitivity
from .steps import RANKING_RULE as RANKING_RULE
from .steps import parameter_steps as parameter_steps
from .steps import relative_change as relative_change
