"""vhcjax: periodic gaits of passive walkers and other hybrid mechanical systems, in JAX.

Importing vhcjax enables float64 in JAX (`jax_enable_x64`): Newton solves to 1e-12 and
exact event location need it; float32 results are not meaningful here.
"""

import importlib.metadata

import jax

jax.config.update("jax_enable_x64", True)

from . import trig as trig  # sin/cos computed once per evaluation, for model kinematics
from ._batching import report_progress as report_progress
from ._cache import (
    clear_caches as clear_caches,
    default_cache_dir as default_cache_dir,
    enable_compilation_cache as enable_compilation_cache,
)
from ._results import RESULTS as RESULTS, result_codes as result_codes, result_names as result_names
from .hybrid import (
    DEFAULT_CONFIG as DEFAULT_CONFIG,
    FAST_CONFIG as FAST_CONFIG,
    FixedPoint as FixedPoint,
    MapResult as MapResult,
    Simulation as Simulation,
    SolverConfig as SolverConfig,
    StepResult as StepResult,
    continue_fixed_point as continue_fixed_point,
    fixed_point as fixed_point,
    in_walker_units as in_walker_units,
    jacobian as poincare_jacobian,  # noqa: F401 (re-export)
    multipliers as poincare_multipliers,  # noqa: F401 (re-export)
    simulate as simulate,
    simulate_batch as simulate_batch,
    step as step,
    step_map as step_map,
)
from .mechanics import (
    WalkerModel as WalkerModel,
    acceleration as acceleration,
    augmented_impact as augmented_impact,
    coriolis_matrix as coriolis_matrix,
    gravity_vector as gravity_vector,
    mass_matrix as mass_matrix,
)
from .models import CompassGait as CompassGait

try:
    __version__ = importlib.metadata.version("vhcjax")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

# ---- multi-domain hybrid systems and the passive kneed walker ----
# ---- figures and animation of a simulation; matplotlib is imported lazily ----
from . import plotting as plotting
from ._cache import enable_default_cache as _enable_default_cache  # noqa: E402

# ---- control: orbital stabilization by transverse-linearization feedback ----
from .control import (  # noqa: E402
    TIGHT_CONFIG as TIGHT_CONFIG,
    ClosedLoopBasin as ClosedLoopBasin,
    ClosedLoopSimulation as ClosedLoopSimulation,
    HybridTransverseFeedback as HybridTransverseFeedback,
    HybridTransverseSystem as HybridTransverseSystem,
    RiccatiSolution as RiccatiSolution,
    Stabilization as Stabilization,
    TransverseFeedback as TransverseFeedback,
    TransverseSystem as TransverseSystem,
    ZeroFeedback as ZeroFeedback,
    actuated_vector_field as actuated_vector_field,
    closed_loop_basin as closed_loop_basin,
    closed_loop_jacobian as closed_loop_jacobian,
    closed_loop_max_push as closed_loop_max_push,
    closed_loop_multipliers as closed_loop_multipliers,
    closed_loop_multipliers_transverse as closed_loop_multipliers_transverse,
    closed_loop_push_step as closed_loop_push_step,
    closed_loop_step as closed_loop_step,
    closed_loop_step_map as closed_loop_step_map,
    default_weights as default_weights,
    in_domain as in_domain,
    input_matrix as input_matrix,
    jump_matrix as jump_matrix,
    riccati_backward as riccati_backward,
    riccati_hamiltonian as riccati_hamiltonian,
    simulate_closed_loop as simulate_closed_loop,
    stabilize as stabilize,
    step_torque as step_torque,
    transverse_feedback as transverse_feedback,
    transverse_system as transverse_system,
    with_torque_limit as with_torque_limit,
)

# ---- gait search: VHC search (Problem 1), shooting (Problem 2), batches, sweeps ----
from .gait import (  # noqa: E402
    Gait as Gait,
    Sweep as Sweep,
    VHCGait as VHCGait,
    VHCOrbit as VHCOrbit,
    find_gait as find_gait,
    find_gaits as find_gaits,
    shooting_search as shooting_search,
    sweep as sweep,
    vhc_gait_search as vhc_gait_search,
    vhc_orbit as vhc_orbit,
    vhc_search as vhc_search,
)
from .hybrid import (
    DomainInfo as DomainInfo,
    MultiDomainModel as MultiDomainModel,
    multidomain_step as multidomain_step,
    multidomain_trajectory as multidomain_trajectory,
)
from .models import (
    KneedWalker as KneedWalker,
    PendulumWalker as PendulumWalker,
    SimplestWalker as SimplestWalker,
)
from .parameters import (  # noqa: E402
    Atlas as Atlas,
    DesignResult as DesignResult,
    FlipScan as FlipScan,
    atlas as atlas,
    design as design,
    flip_slope as flip_slope,
    flip_slopes as flip_slopes,
)

# ---- robustness: contraction, basin of attraction, slope/terrain sensitivity, pushes ----
from .robustness import (
    CONVERGED as CONVERGED,
    FELL as FELL,
    LABEL_NAMES as LABEL_NAMES,
    OTHER_CYCLE as OTHER_CYCLE,
    UNDECIDED as UNDECIDED,
    BasinSlice as BasinSlice,
    BasinVolume as BasinVolume,
    Contraction as Contraction,
    FloorStepCompassGait as FloorStepCompassGait,
    GaitSensitivity as GaitSensitivity,
    PushThresholds as PushThresholds,
    Recovery as Recovery,
    SlopeSensitivity as SlopeSensitivity,
    Threshold as Threshold,
    basin_slice as basin_slice,
    basin_volume as basin_volume,
    bisect_threshold as bisect_threshold,
    contraction as contraction,
    gait_sensitivity_norm as gait_sensitivity_norm,
    impulse_step as impulse_step,
    max_converging_perturbation as max_converging_perturbation,
    max_floor_step as max_floor_step,
    max_push as max_push,
    pulse_past_strike as pulse_past_strike,
    pulse_step as pulse_step,
    push_bound as push_bound,
    push_sensitivity_autodiff as push_sensitivity_autodiff,
    push_sensitivity_transverse as push_sensitivity_transverse,
    recover as recover,
    slope_sensitivity as slope_sensitivity,
    terrain_recovery as terrain_recovery,
)

# ---- stability: transverse linearization, multipliers, period doubling ----
# ---- differentiable gaits: multipliers with derivatives, walker design, the parameter atlas ----
from .stability import (  # noqa: E402
    BifurcationDiagram as BifurcationDiagram,
    Family as Family,
    GaitMultipliers as GaitMultipliers,
    GaitSpectrum as GaitSpectrum,
    PeriodDoubling as PeriodDoubling,
    TransverseLinearization as TransverseLinearization,
    bifurcation_diagram as bifurcation_diagram,
    family_multipliers as family_multipliers,
    gait_multipliers as gait_multipliers,
    gait_spectrum as gait_spectrum,
    midswing_multipliers as midswing_multipliers,
    period1_family as period1_family,
    period2_branch as period2_branch,
    period_doubling_slope as period_doubling_slope,
    period_k_orbit as period_k_orbit,
    transverse_linearization as transverse_linearization,
)

_enable_default_cache()

# The hash of the sources just imported keys the stored programs (`_programs`): taken
# now, a source file edited later in this process's life cannot name its old code.
from ._programs import _source  # noqa: E402

_source()
del _source
