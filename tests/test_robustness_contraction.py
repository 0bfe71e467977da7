"""Speed of contraction: the decay rate measured from simulated recoveries equals the
spectral radius of the autodiff Jacobian of the step map."""

import math

import numpy as np
import pytest
from _robust import stable_gait
from _text import assert_plain_text

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


def test_cli_labels_predicted_and_measured(capsys):
    """`vhcjax contraction` (the sizes above: the same programs) labels the predicted
    figures (asymptotic, from the multipliers) and the measured ones (medians over the
    recoveries, first steps included) so that a difference does not read as a
    contradiction."""
    from vhcjax.cli import main

    assert main(["contraction", "--perturbations", "8", "--steps", "30", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "spectral radius of the step-to-step map: 0.5799" in text
    assert "4.23 predicted (asymptotic rate)" in text
    assert "measured (median over the recoveries, counted from the perturbation" in text


def test_contraction_refuses_a_point_that_is_not_a_gait_and_a_fit_it_cannot_make():
    """The measures linearize about a fixed point of the step map: a point one step moves
    by 3e-2 is refused (`gait_multipliers` codes it `not_a_gait`), and so is a fit window
    past the simulated steps (an empty range, whose fit would be a rate of 1)."""
    model, z, _, _ = stable_gait()
    off = np.asarray(z) + np.array([0.01, 0.0, 0.0])
    assert vj.result_names(vj.gait_multipliers(model, off, transverse=False).result) == "not_a_gait"
    with pytest.raises(ValueError, match="contraction: z_star is not a period-1 gait"):
        vj.contraction(model, off, num_perturbations=4)
    for kw in ({"num_steps": 3}, {"fit_window": (10, 8)}, {"num_perturbations": 0}):
        with pytest.raises(ValueError, match="contraction"):
            vj.contraction(model, z, **kw)


def test_walkers_that_fall_have_no_measured_rate():
    """Near the unstable gait every perturbed walker falls, or leaves for the stable gait
    (its error grows tenfold): none measures a decay rate (NaN), nor does the median
    (a fit of the stopped or saturated errors would give about 1). The predicted spectral
    radius, from the Jacobian, is 4.3."""
    model = vj.CompassGait()
    zu = np.asarray(vj.find_gait(model, "unstable").z)
    c = vj.contraction(model, zu, num_perturbations=4, scale=1e-3, num_steps=30)
    assert float(c.spectral_radius) > 1.0
    # Its multipliers are all real, and still complex numbers (as JSON: [re, im] pairs),
    # equal to those of `gait_multipliers` (eigenvalues by JAX, not numpy).
    assert np.iscomplexobj(np.asarray(c.multipliers))
    assert not np.asarray(c.multipliers).imag.any()
    pm = np.asarray(vj.gait_multipliers(model, zu, transverse=False).poincare)
    np.testing.assert_allclose(np.asarray(c.multipliers), pm, atol=1e-9)
    assert np.isnan(np.asarray(c.measured_rates)).all() and np.isnan(float(c.measured_rate))
