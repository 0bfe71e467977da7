"""Shared, cached simulations for the tests (each function compiles once per session).

Models are built with array leaves so that every parameter value reuses one compilation.
"""

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import vhcjax as vj
from vhcjax.hybrid import step_unchecked

THESIS_7_5 = np.array([0.218669, -0.323389, -1.092386, -0.377377])  # thesis (7.5)
THESIS_7_7 = THESIS_7_5 + 0.01  # thesis (7.7): every entry perturbed by 0.01
NUM_STEPS = 20


def make_model(slope_deg=3.0, **kw):
    """A `CompassGait` whose leaves are float64 arrays."""
    prm = dict(psi=math.radians(slope_deg), **kw)
    return vj.CompassGait(**{k: jnp.asarray(v, float) for k, v in prm.items()})


def walk(model, x0):
    """`NUM_STEPS` steps, default config, unbatched (one compilation)."""
    return vj.simulate(model, jnp.asarray(x0, float), NUM_STEPS)


@functools.cache
def thesis_walk(which="7.5"):
    """`NUM_STEPS` steps from the thesis state (7.5) or (7.7) at 3 degrees."""
    return walk(make_model(), THESIS_7_5 if which == "7.5" else THESIS_7_7)


# One step, batched over states and models (vmap), default config.
step_batch = eqx.filter_jit(eqx.filter_vmap(lambda m, x: step_unchecked(m, x)))
# `NUM_STEPS` steps batched over states and models.
walk_batch = eqx.filter_jit(eqx.filter_vmap(lambda m, x: vj.simulate(m, x, NUM_STEPS)))


def batch_models(slopes_deg):
    """A batched `CompassGait` (leading axis on every leaf) for `filter_vmap`."""
    slopes = np.asarray(slopes_deg, float)
    ones = np.ones_like(slopes)
    base = vj.CompassGait()
    return vj.CompassGait(
        m1=jnp.asarray(base.m1 * ones),
        m2=jnp.asarray(base.m2 * ones),
        mH=jnp.asarray(base.mH * ones),
        a=jnp.asarray(base.a * ones),
        b=jnp.asarray(base.b * ones),
        g=jnp.asarray(base.g * ones),
        psi=jnp.asarray(np.radians(slopes)),
        min_strike_angle=jnp.asarray(0.0 * ones),
    )


@functools.cache
def thesis_walk_dense(num_steps=4, dense_points=60):
    """A short dense simulation from (7.5), for dense-output checks and figures."""
    return jax.block_until_ready(
        vj.simulate(make_model(), jnp.asarray(THESIS_7_5), num_steps, dense_points=dense_points)
    )
