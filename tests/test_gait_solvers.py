"""The gait search's other solvers (thesis Problem 1 with an optax gradient optimiser,
optimistix's Levenberg-Marquardt and Newton, Problem 2 with optimistix's Newton) give
the gait that the default damped Newton finds, unbatched and in batches (where they run
by `vmap`, one member at a time, instead of the batched Newton loop)."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax import gait as G

SEED = (0.20, -1.0)  # thesis (7.2)


@pytest.fixture(scope="module")
def newton():
    m = vj.CompassGait(psi=math.radians(3.0))
    return {method: G.find_gait(m, "stable", method, guess=SEED) for method in ("vhc", "shooting")}


@pytest.mark.slow
def test_optax_minimiser_finds_the_newton_gait(newton):
    """`solver="optax"` (L-BFGS on the squared residual (5.20)), unbatched."""
    g = G.find_gait(
        vj.CompassGait(psi=math.radians(3.0)), "stable", guess=SEED, solver="optax", throw=False
    )
    assert vj.result_names(g.result) == "successful"
    assert float(g.residual) < 1e-10 and int(g.iterations) > 0
    np.testing.assert_allclose(np.asarray(g.x_plus), np.asarray(newton["vhc"].x_plus), atol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("method, solver", [("vhc", "lm"), ("shooting", "optimistix")])
def test_other_solvers_in_a_batch(newton, method, solver):
    """A batch with a hopeless guess: the others are solved, to the Newton gait, and the
    hopeless one is flagged with a finite state (`vmap` over the members)."""
    m = vj.CompassGait()
    seed = (
        SEED
        if method == "vhc"
        else tuple(
            np.asarray(G.complete_guess(vj.CompassGait(psi=math.radians(3.0)), SEED, "stable"))
        )
    )
    hopeless = (2.5, 8.0) if method == "vhc" else (2.5, 8.0, 1.0)
    g = G.find_gaits(
        m,
        jnp.array([seed, seed, hopeless]),
        "stable",
        method,
        psi=jnp.radians(jnp.array([3.0, 2.5, 3.0])),
        solver=solver,
    )
    names = vj.result_names(g.result)
    assert names[:2] == ["successful", "successful"] and names[2] != "successful"
    np.testing.assert_allclose(
        np.asarray(g.x_plus[0]), np.asarray(newton[method].x_plus), atol=1e-10
    )
    assert float(np.max(np.asarray(g.residual)[:2])) < 1e-10
    assert np.all(np.isfinite(np.asarray(g.x_plus)))
