"""Fast end-to-end smoke test: the thesis stable gait at 3 degrees keeps walking."""

import jax.numpy as jnp
import numpy as np

import vhcjax as vj


def test_x64_enabled():
    assert jnp.zeros(1).dtype == jnp.float64


def test_thesis_stable_gait_walks(model):
    x0 = jnp.array([0.218669, -0.323389, -1.092386, -0.377377])  # thesis (7.5)
    sim = vj.simulate(model, x0, 5)
    assert vj.result_names(sim.result) == "successful"
    np.testing.assert_allclose(np.asarray(sim.steps.period), 0.7343464, atol=2e-5)
