"""Root finders written for the gait searches: damped Newton for one member or a whole
batch in one loop (per-member convergence, inexact evaluations, chord steps), and thin
wrappers over optimistix's Levenberg-Marquardt and an optax minimiser; `diffeqsolve`
with storable save times."""

from ._implicit import (
    detach as detach,
    eigenvalues as eigenvalues,
    implicit_outputs as implicit_outputs,
    linearised as linearised,
)
from ._newton import (
    batch_jacobian as batch_jacobian,
    damped_newton as damped_newton,
    damped_newton_batch as damped_newton_batch,
    levenberg_marquardt as levenberg_marquardt,
    optax_minimise as optax_minimise,
)
from ._ode import diffeqsolve as diffeqsolve
