"""Periodic gaits: the VHC search (thesis Problem 1), shooting (Problem 2), batches,
continuation and slope sweeps; the reduced dynamics of a virtual holonomic constraint.
"""

from ._continuation import (
    continue_to_model as continue_to_model,
)
from ._dispatch import (
    vhc_applies as vhc_applies,
)
from ._find import (
    find_gait as find_gait,
    find_gaits as find_gaits,
)
from ._gait import (
    ERROR_TOL as ERROR_TOL,
    FAMILIES as FAMILIES,
    METHODS as METHODS,
    SUCCESS_TOL as SUCCESS_TOL,
    VHC_CONFIG as VHC_CONFIG,
    Gait as Gait,
    accepted as accepted,
    family_sign as family_sign,
    gait_in_units as gait_in_units,
    section_in_units as section_in_units,
)
from ._problem1 import (
    BoundaryData as BoundaryData,
    impact_configuration as impact_configuration,
    impact_velocity_matrix as impact_velocity_matrix,
    quadratic_coefficients as quadratic_coefficients,
    solve_for_d as solve_for_d,
    velocity_relations as velocity_relations,
    vhc_boundary as vhc_boundary,
    vhc_residual as vhc_residual,
    vhc_search as vhc_search,
)
from ._shooting import (
    complete_guess as complete_guess,
    shooting_search as shooting_search,
)
from ._sweep import (
    MIN_SLOPE as MIN_SLOPE,
    Sweep as Sweep,
    sweep as sweep,
)
from ._vhc import (
    constraint as constraint,
    phi_second_derivative as phi_second_derivative,
    reduced_coefficients as reduced_coefficients,
    reduced_energy as reduced_energy,
    reduced_mass as reduced_mass,
    singularity_terms as singularity_terms,
    theta_dynamics_coefficients as theta_dynamics_coefficients,
)
from ._vhc_n import (
    VHCGait as VHCGait,
    VHCOrbit as VHCOrbit,
    vhc_gait_search as vhc_gait_search,
    vhc_orbit as vhc_orbit,
)
