"""Hybrid simulation: one swing phase per step ended by a root-found heel-strike event,
the impact and relabelling, many steps, the step-to-step (Poincare) map and its fixed
points; multi-domain systems.
"""

from ._event_solve import (
    EventSolution as EventSolution,
    solve_to_event as solve_to_event,
)
from ._multidomain import (
    DomainInfo as DomainInfo,
    DomainView as DomainView,
    MultiDomainModel as MultiDomainModel,
    augmented_impact_locked as augmented_impact_locked,
    dense_cycle as dense_cycle,
    lock_impact as lock_impact,
    locked_acceleration as locked_acceleration,
    multidomain_step as multidomain_step,
    multidomain_trajectory as multidomain_trajectory,
)
from ._poincare import (
    FixedPoint as FixedPoint,
    MapResult as MapResult,
    continue_fixed_point as continue_fixed_point,
    fixed_point as fixed_point,
    jacobian as jacobian,
    multipliers as multipliers,
    step_map as step_map,
)
from ._simulate import (
    DEFAULT_CONFIG as DEFAULT_CONFIG,
    FAST_CONFIG as FAST_CONFIG,
    Simulation as Simulation,
    SolverConfig as SolverConfig,
    StepResult as StepResult,
    check_map_steps as check_map_steps,
    check_num_steps as check_num_steps,
    check_section_shape as check_section_shape,
    check_state_shape as check_state_shape,
    classify_solve as classify_solve,
    flow as flow,
    in_walker_units as in_walker_units,
    ode_solver as ode_solver,
    section_rates as section_rates,
    simulate as simulate,
    simulate_batch as simulate_batch,
    step as step,
    step_unchecked as step_unchecked,
)
