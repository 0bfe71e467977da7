"""Bad arguments to the library's host-side entry points: one clear `ValueError` naming
the argument, before any computation (no error from inside JAX, no NaN result)."""

import math

import numpy as np
import pytest

import vhcjax as vj

Z3 = np.array([0.2186688, -1.09238359, -0.37737395])  # the stable gait at 3 degrees
M3 = vj.CompassGait(psi=math.radians(3.0))
X3 = np.asarray(M3.section_to_state(Z3))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: vj.fixed_point(M3, Z3, k=0), "positive integer"),
        (lambda: vj.fixed_point(M3, Z3, k=-1), "positive integer"),
        (lambda: vj.fixed_point(M3, Z3, k=1.5), "positive integer"),
        (lambda: vj.step_map(M3, Z3, k=0), "positive integer"),
        (lambda: vj.continue_fixed_point(M3, Z3, vj.CompassGait(psi=math.nan)), "finite"),
        (lambda: vj.continue_fixed_point(M3, Z3, vj.CompassGait(mH=math.nan)), "finite"),
        (lambda: vj.continue_fixed_point(M3, Z3[:2], vj.CompassGait(psi=0.06)), "section"),
        (lambda: vj.continue_fixed_point(M3, Z3, M3, k=0), "positive integer"),
        (lambda: vj.bifurcation_diagram([0.05], Z3[None], num_record=0), "num_record"),
        (lambda: vj.bifurcation_diagram([0.05], Z3[None], num_record=1), "num_record"),
        (lambda: vj.bifurcation_diagram([0.05], Z3[None], num_transient=-1), "num_transient"),
        (lambda: vj.bifurcation_diagram([0.05, 0.06], Z3[None]), "one gait per slope"),
        (lambda: vj.basin_slice(M3, Z3, shape=(2, 2), num_steps=0), "num_steps"),
        (lambda: vj.recover(M3, X3[None], X3, num_steps=0), "num_steps"),
        (lambda: vj.recover(M3, X3[None], X3, max_period=0), "max_period"),
        (lambda: vj.recover(M3, X3, X3), r"shape \(batch, 4\)"),
        (lambda: vj.recover(M3, X3[None], X3 * math.nan), "x_star must be finite"),
        (lambda: vj.max_push(M3, X3, 0.73, [], [0.0]), "at least one phase"),
        (lambda: vj.max_push(M3, X3, 0.73, [math.nan], [0.0]), "finite"),
        (lambda: vj.max_push(M3, X3, 0.73, [0.1], [0.0], p_max=0.0), "p_max"),
        (lambda: vj.max_push(M3, X3, 0.73, [0.1], [0.0], iterations=0), "iterations"),
        (lambda: vj.flip_slope(M3, Z3, step=0.0), "step must be positive"),
        (lambda: vj.flip_slope(M3, Z3, step=math.nan), "step must be positive"),
        (lambda: vj.max_floor_step(M3, X3, h_max=0.0), "search interval"),
        (lambda: vj.max_floor_step(M3, X3, h_max=-0.01), "search interval"),
        (lambda: vj.max_floor_step(M3, X3, iterations=0), "iterations"),
        (lambda: vj.sweep(M3, [[0.05, 0.06]]), "one-dimensional"),
        (lambda: vj.contraction(M3, Z3, scale=0.0), "scale"),
        (lambda: vj.contraction(M3, Z3, scale=math.nan), "scale"),
    ],
)
def test_bad_arguments_are_one_value_error(call, match):
    with pytest.raises(ValueError, match=match):
        call()
