"""vhcjax: periodic gaits of passive walkers and other hybrid mechanical systems, in JAX.

Importing vhcjax enables float64 in JAX (`jax_enable_x64`): Newton solves to 1e-12 and
exact event location need it; float32 results are not meaningful here.
"""

import importlib.metadata

import jax

jax.config.update("jax_enable_x64", True)

from ._compass_gait import CompassGait as CompassGait
from ._compile import clear_caches as clear_caches, enable_compilation_cache as enable_compilation_cache
from ._hybrid import (
    DEFAULT_CONFIG as DEFAULT_CONFIG,
    FAST_CONFIG as FAST_CONFIG,
    Simulation as Simulation,
    SolverConfig as SolverConfig,
    StepResult as StepResult,
    simulate as simulate,
    simulate_batch as simulate_batch,
    step as step,
)
from ._mechanics import (
    acceleration as acceleration,
    augmented_impact as augmented_impact,
    coriolis_matrix as coriolis_matrix,
    gravity_vector as gravity_vector,
    mass_matrix as mass_matrix,
)
from ._model import WalkerModel as WalkerModel
from . import trig as trig  # vectorizable sin/cos for model kinematics
from ._results import RESULTS as RESULTS, result_codes as result_codes, result_names as result_names

try:
    __version__ = importlib.metadata.version("vhcjax")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

# ---- multi-domain hybrid systems and the passive kneed walker (issue 6) ----
from ._kneed_walker import KneedWalker as KneedWalker
from ._multidomain import (
    DomainInfo as DomainInfo,
    MultiDomainModel as MultiDomainModel,
    multidomain_step as multidomain_step,
    multidomain_trajectory as multidomain_trajectory,
)
from ._pendulum_walker import PendulumWalker as PendulumWalker
from ._vhc_search import (
    VHCGait as VHCGait,
    VHCOrbit as VHCOrbit,
    vhc_gait_search as vhc_gait_search,
    vhc_orbit as vhc_orbit,
)

# ---- robustness: contraction, basin of attraction, slope/terrain sensitivity, pushes (issue 5) ----
from ._basin import (
    BasinSlice as BasinSlice,
    BasinVolume as BasinVolume,
    basin_slice as basin_slice,
    basin_volume as basin_volume,
    max_converging_perturbation as max_converging_perturbation,
)
from ._bisection import Threshold as Threshold, bisect_threshold as bisect_threshold
from ._contraction import Contraction as Contraction, contraction as contraction
from ._push import (
    impulse_step as impulse_step,
    max_push as max_push,
    pulse_step as pulse_step,
    push_sensitivity_autodiff as push_sensitivity_autodiff,
    push_sensitivity_transverse as push_sensitivity_transverse,
)
from ._recovery import CONVERGED as CONVERGED, Recovery as Recovery, recover as recover
from ._slope_sensitivity import SlopeSensitivity as SlopeSensitivity, slope_sensitivity as slope_sensitivity
from ._terrain import (
    FloorStepCompassGait as FloorStepCompassGait,
    gait_sensitivity_norm as gait_sensitivity_norm,
    max_floor_step as max_floor_step,
    terrain_recovery as terrain_recovery,
)

# ---- figures and animation of a simulation (issue 2); matplotlib is imported lazily ----
from . import _plotting as plotting

# ---- stability: transverse linearization, multipliers, period doubling (issue 4) ----
from ._stability import (
    BifurcationDiagram as BifurcationDiagram,
    GaitMultipliers as GaitMultipliers,
    bifurcation_diagram as bifurcation_diagram,
    family_multipliers as family_multipliers,
    gait_multipliers as gait_multipliers,
    midswing_multipliers as midswing_multipliers,
    period1_family as period1_family,
    period2_branch as period2_branch,
    period_doubling_slope as period_doubling_slope,
    period_k_orbit as period_k_orbit,
)
from ._transverse import (
    TransverseLinearization as TransverseLinearization,
    transverse_linearization as transverse_linearization,
)

# ---- gait search: VHC search (Problem 1), shooting (Problem 2), batches, sweeps (issue 3) ----
from ._gait import (  # noqa: E402
    Gait as Gait,
    Sweep as Sweep,
    find_gait as find_gait,
    find_gaits as find_gaits,
    shooting_search as shooting_search,
    sweep as sweep,
    vhc_search as vhc_search,
)

# ---- differentiable gaits: multipliers with derivatives, walker design, the parameter atlas ----
from ._gait_spectrum import GaitSpectrum as GaitSpectrum, gait_spectrum as gait_spectrum  # noqa: E402
from .design import (  # noqa: E402
    Atlas as Atlas,
    DesignResult as DesignResult,
    FlipScan as FlipScan,
    atlas as atlas,
    design as design,
    flip_slope as flip_slope,
    flip_slopes as flip_slopes,
)
