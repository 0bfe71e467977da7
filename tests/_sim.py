"""Shared, cached simulations for the tests (compiled once per session)."""

import functools

import jax.numpy as jnp
import numpy as np

import vhcjax as vj
from vhcjax._hybrid import simulate_jit

THESIS_7_5 = np.array([0.218669, -0.323389, -1.092386, -0.377377])  # thesis (7.5)
THESIS_7_7 = THESIS_7_5 + 0.01  # thesis (7.7): every entry perturbed by 0.01


@functools.lru_cache(maxsize=None)
def thesis_walk(which="7.5", num_steps=20):
    """`num_steps` steps from the thesis state (7.5) or (7.7) at 3 degrees, default config."""
    x0 = THESIS_7_5 if which == "7.5" else THESIS_7_7
    return simulate_jit(vj.CompassGait(), jnp.asarray(x0), num_steps)
