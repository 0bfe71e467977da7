"""Lagrangian mechanics from the energies alone: mass matrix, Coriolis and gravity terms,
forward dynamics and the impact map (thesis ch. 2-3), for any number of degrees of freedom.
"""

from ._lagrangian import (
    acceleration as acceleration,
    augmented_impact as augmented_impact,
    bias_forces as bias_forces,
    contact_jacobian as contact_jacobian,
    coriolis_matrix as coriolis_matrix,
    coriolis_product as coriolis_product,
    det_small as det_small,
    energy as energy,
    extended_mass_matrix as extended_mass_matrix,
    gravity_vector as gravity_vector,
    mass_matrix as mass_matrix,
    solve_small as solve_small,
)
from ._model import (
    WalkerModel as WalkerModel,
)
