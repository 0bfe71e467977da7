"""Orbital stability: transverse linearization (thesis ch. 6) and the Poincare-map
Jacobian, period doubling, period-k orbits, bifurcation diagrams.
"""

from ._multipliers import (
    add_stability_columns as add_stability_columns,
    AGREEMENT_RTOL as AGREEMENT_RTOL,
    bifurcation_diagram as bifurcation_diagram,
    BifurcationDiagram as BifurcationDiagram,
    CSV_COLUMNS as CSV_COLUMNS,
    detect_period as detect_period,
    Family as Family,
    family_multipliers as family_multipliers,
    finite_difference_jacobian as finite_difference_jacobian,
    finite_difference_jacobian_jit as finite_difference_jacobian_jit,
    gait_multipliers as gait_multipliers,
    gait_multipliers_jit as gait_multipliers_jit,
    MAX_CONDITION as MAX_CONDITION,
    GaitMultipliers as GaitMultipliers,
    midswing_map as midswing_map,
    midswing_multipliers as midswing_multipliers,
    period1_family as period1_family,
    period2_branch as period2_branch,
    period_doubling_slope as period_doubling_slope,
    period_doubling_slopes_from_diagram as period_doubling_slopes_from_diagram,
    period_k_orbit as period_k_orbit,
    PeriodDoubling as PeriodDoubling,
    PeriodKOrbit as PeriodKOrbit,
    SEEDS_3DEG as SEEDS_3DEG,
    settle as settle,
    stability_csv_row as stability_csv_row,
    stability_json as stability_json,
    to_midswing as to_midswing,
    transverse_note as transverse_note,
    with_slope as with_slope,
)

from ._transverse import (
    joint_vector_field as joint_vector_field,
    split_orbit_state as split_orbit_state,
    flow_projection as flow_projection,
    g_h as g_h,
    guard_normal as guard_normal,
    L_matrix as L_matrix,
    m_vector as m_vector,
    orbit_state as orbit_state,
    post_impact_normal as post_impact_normal,
    system_matrix as system_matrix,
    transverse_linearization as transverse_linearization,
    TransverseLinearization as TransverseLinearization,
)
from ._spectrum import GaitSpectrum as GaitSpectrum, gait_spectrum as gait_spectrum
