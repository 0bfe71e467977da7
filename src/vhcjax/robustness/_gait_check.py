"""The check each robustness measure makes of the gait it is given: the measures linearize
about, or converge to, a fixed point of the step map, and their numbers mean nothing
elsewhere."""

import jax.numpy as jnp
import numpy as np

from .._results import result_names
from ..hybrid import DEFAULT_CONFIG, check_section_shape, step_map
from ..stability import GAIT_TOL, returns_to


def check_returns(z_star, z_next, name, code="successful"):
    """Raise a `ValueError` unless the step from `z_star` completed (`code`) and returned
    to within `GAIT_TOL` $\\max(1, \\|z^*\\|_\\infty)$ of it (`gait_multipliers`' test)."""
    z = np.asarray(z_star, dtype=float)
    if code != "successful":
        raise ValueError(
            f"{name}: z_star is not a gait of this model: one step from it ends with "
            f"{code!r}; find a gait with find_gait"
        )
    if not bool(returns_to(z, z_next)):
        moved = float(np.max(np.abs(np.asarray(z_next, dtype=float) - z)))
        bound = GAIT_TOL * max(1.0, float(np.max(np.abs(z))))
        raise ValueError(
            f"{name}: z_star is not a period-1 gait of this model: one step moves it by "
            f"{moved:.3g} (a gait returns to within {bound:.0e}); find a gait with find_gait"
        )


def require_gait(model, z_star, name):
    """`check_returns` for one step of `model` from the section point `z_star`."""
    z = jnp.asarray(z_star, dtype=float)
    check_section_shape(model, z, f"{name}: z_star")
    mr = step_map(model, z, 1, DEFAULT_CONFIG)
    check_returns(z, mr.z_next, name, str(result_names(mr.result)))
