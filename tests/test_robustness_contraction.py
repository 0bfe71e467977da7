"""Speed of contraction: the decay rate measured from simulated recoveries equals the
spectral radius of the autodiff Jacobian of the step map."""

import math

import numpy as np
from _robust import stable_gait

import vhcjax as vj
from vhcjax.robustness._contraction import steps_to_shrink


def test_steps_to_shrink_formula():
    assert math.isclose(float(steps_to_shrink(0.1, 10.0)), 1.0)
    assert math.isclose(float(steps_to_shrink(0.5, 100.0)), math.log(100) / math.log(2))
    assert np.isinf(float(steps_to_shrink(1.2, 10.0)))


def test_measured_decay_matches_multipliers():
    model, z, _, _ = stable_gait()
    c = vj.contraction(model, z, num_perturbations=8, scale=1e-3, num_steps=30, fit_window=(5, 30))
    rho = float(c.spectral_radius)
    assert 0.5 < rho < 0.7  # the stable 3-degree gait: |-0.1997 +- 0.5445i| = 0.580
    rates = np.asarray(c.measured_rates)
    # Every simulated recovery decays at the rate of the dominant multiplier pair.
    np.testing.assert_allclose(rates, rho, rtol=0.02)
    assert abs(float(c.measured_rate) - rho) < 0.01 * rho
    assert math.isclose(float(c.steps_10x), math.log(0.1) / math.log(rho))
    # The errors really shrink 10x and 100x (measured, transients included).
    assert 0 < float(c.measured_steps_10x) < float(c.measured_steps_100x) <= 30
