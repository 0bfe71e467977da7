"""Hybrid simulation: one swing phase per step ended by a root-found heel-strike event,
the impact and relabelling, many steps, the step-to-step (Poincare) map and its fixed
points; multi-domain systems.
"""

from ._event_solve import (
    EventSolution as EventSolution,
    solve_to_event as solve_to_event,
)

from ._multidomain import (
    augmented_impact_locked as augmented_impact_locked,
    DomainInfo as DomainInfo,
    DomainView as DomainView,
    lock_impact as lock_impact,
    locked_acceleration as locked_acceleration,
    multidomain_step as multidomain_step,
    multidomain_trajectory as multidomain_trajectory,
    MultiDomainModel as MultiDomainModel,
)

from ._poincare import (
    fixed_point as fixed_point,
    fixed_point_jit as fixed_point_jit,
    FixedPoint as FixedPoint,
    jacobian as jacobian,
    jacobian_jit as jacobian_jit,
    MapResult as MapResult,
    multipliers as multipliers,
    multipliers_jit as multipliers_jit,
    step_map as step_map,
    step_map_jit as step_map_jit,
)

from ._simulate import (
    classify_solve as classify_solve,
    DEFAULT_CONFIG as DEFAULT_CONFIG,
    FAST_CONFIG as FAST_CONFIG,
    flow as flow,
    ode_solver as ode_solver,
    simulate as simulate,
    simulate_batch as simulate_batch,
    simulate_jit as simulate_jit,
    Simulation as Simulation,
    SolverConfig as SolverConfig,
    step as step,
    step_unchecked as step_unchecked,
    StepResult as StepResult,
)
