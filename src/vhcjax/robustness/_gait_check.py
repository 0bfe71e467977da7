"""The check each robustness measure makes of the gait it is given: the measures linearize
about, or converge to, a fixed point of the step map, and their numbers mean nothing
elsewhere."""

import jax.numpy as jnp

from .._results import result_names
from ..hybrid import DEFAULT_CONFIG, check_section_shape, step_map
from ..hybrid._simulate import state_distance
from ..stability import GAIT_TOL, returns_to


def check_returns(model, z_star, z_next, name, code="successful"):
    """Raise a `ValueError` unless the step from `z_star` completed (`code`) and returned
    to it (`returns_to`, `gait_multipliers`' test)."""
    z = jnp.asarray(z_star, dtype=float)
    if code != "successful":
        raise ValueError(
            f"{name}: z_star is not a gait of this model: one step from it ends with "
            f"{code!r}; find a gait with find_gait"
        )
    if not bool(returns_to(model, z, z_next)):
        moved, size = state_distance(
            model, model.section_to_state(jnp.asarray(z_next)), model.section_to_state(z)
        )
        raise ValueError(
            f"{name}: z_star is not a period-1 gait of this model: one step moves it by "
            f"{float(moved):.3g} in the walker's units (a gait returns to within "
            f"{GAIT_TOL * float(size):.0e}); find a gait with find_gait"
        )


def require_gait(model, z_star, name):
    """`check_returns` for one step of `model` from the section point `z_star`."""
    z = jnp.asarray(z_star, dtype=float)
    check_section_shape(model, z, f"{name}: z_star")
    mr = step_map(model, z, 1, DEFAULT_CONFIG)
    check_returns(model, z, mr.z_next, name, str(result_names(mr.result)))
