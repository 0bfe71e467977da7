"""Shared, cached objects for the robustness tests (compiled once per session)."""

import functools

import jax.numpy as jnp
import numpy as np

import vhcjax as vj
from vhcjax.hybrid import DEFAULT_CONFIG

SEED = (0.2187, -1.092, -0.377)  # Newton seed (rounded) for the stable 3-degree gait


@functools.cache
def stable_gait():
    """`(model, z_star, x_star, period)` of the stable 3-degree gait (Newton, 1e-12)."""
    model = vj.CompassGait()
    fp = vj.fixed_point(model, jnp.asarray(SEED))
    assert vj.result_names(fp.result) == "successful"
    return model, fp.z, fp.x0, float(fp.periods[0])


def long_walk(model, x0, num_steps=80):
    """Independent check: plain `simulate` at the default tolerances (1e-10)."""
    return vj.simulate(model, jnp.asarray(x0, float), num_steps, config=DEFAULT_CONFIG)


def returns_to(sim, x_star, tol=1e-6):
    """True if the walk completed every step and ends within `tol` of the gait."""
    ok = vj.result_names(sim.result) == "successful"
    return ok and float(np.max(np.abs(np.asarray(sim.steps.x_plus[-1]) - np.asarray(x_star)))) < tol
