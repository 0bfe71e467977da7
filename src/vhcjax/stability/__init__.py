"""Orbital stability: transverse linearization (thesis ch. 6) and the Poincare-map
Jacobian, period doubling, period-k orbits, bifurcation diagrams.
"""

from ._bifurcation import (
    BifurcationDiagram as BifurcationDiagram,
    bifurcation_diagram as bifurcation_diagram,
    detect_period as detect_period,
    period_doubling_slopes_from_diagram as period_doubling_slopes_from_diagram,
)
from ._family import Family as Family, period1_family as period1_family
from ._midswing import (
    midswing_map as midswing_map,
    midswing_multipliers as midswing_multipliers,
    to_midswing as to_midswing,
)
from ._multipliers import (
    AGREEMENT_RTOL as AGREEMENT_RTOL,
    GAIT_TOL as GAIT_TOL,
    MAX_CONDITION as MAX_CONDITION,
    GaitMultipliers as GaitMultipliers,
    family_multipliers as family_multipliers,
    finite_difference_jacobian as finite_difference_jacobian,
    gait_multipliers as gait_multipliers,
    returns_to as returns_to,
    transverse_note as transverse_note,
)
from ._period_doubling import (
    PeriodDoubling as PeriodDoubling,
    period2_branch as period2_branch,
    period_doubling_slope as period_doubling_slope,
)
from ._period_k import (
    PeriodKOrbit as PeriodKOrbit,
    period_k_orbit as period_k_orbit,
    settle as settle,
)
from ._spectrum import GaitSpectrum as GaitSpectrum, gait_spectrum as gait_spectrum
from ._transverse import (
    L_matrix as L_matrix,
    TransverseLinearization as TransverseLinearization,
    flow_projection as flow_projection,
    g_h as g_h,
    guard_normal as guard_normal,
    joint_state_units as joint_state_units,
    joint_vector_field as joint_vector_field,
    m_vector as m_vector,
    orbit_state as orbit_state,
    post_impact_normal as post_impact_normal,
    split_orbit_state as split_orbit_state,
    system_matrix as system_matrix,
    transverse_linearization as transverse_linearization,
)
