"""Slope sensitivity by implicit differentiation vs finite differences of re-solved
gaits; floor-step terrain: the gait sensitivity norm from the linearized step-to-step map
vs simulated step times, and the largest survivable step up/down bracketed by simulation."""

import ast
import json
import os
import subprocess
import sys

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from _robust import long_walk, returns_to, stable_gait
from _text import assert_plain_text

import vhcjax as vj
from vhcjax.hybrid._simulate import DEFAULT_CONFIG
from vhcjax.robustness._terrain import floor_step_model


@pytest.mark.slow
def test_slope_derivatives_vs_finite_differences():
    model, z, _, _ = stable_gait()
    s = vj.slope_sensitivity(model, z)
    h = 1e-4
    vals = []
    for sign in (1, -1):
        m = eqx.tree_at(lambda q: q.psi, model, model.psi + sign * h)
        fp = vj.fixed_point(m, z)
        assert vj.result_names(fp.result) == "successful"
        sr = vj.step(m, fp.x0)
        T = float(sr.period)
        L = float(np.linalg.norm(np.asarray(m.contact_point(sr.x_minus[:2]))))
        v = L / T
        ev = np.asarray(vj.poincare_multipliers(m, fp.z))
        vals.append((np.asarray(fp.z), float(T), float(L), float(v), ev[np.argsort(-np.abs(ev))]))
    fd = [(a - b) / (2 * h) for a, b in zip(vals[0], vals[1])]
    np.testing.assert_allclose(np.asarray(s.dz), fd[0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(float(s.dperiod), fd[1], rtol=1e-5)
    np.testing.assert_allclose(float(s.dstep_length), fd[2], rtol=1e-5)
    np.testing.assert_allclose(float(s.dspeed), fd[3], rtol=1e-5)
    # multipliers: compare the member with non-negative imaginary part of the pair and the
    # real one (conjugates come in either order from eig).
    lam = np.asarray(s.multipliers)
    for i in range(3):
        j = int(np.argmin(np.abs(vals[0][4] - lam[i]) + np.abs(vals[1][4] - lam[i])))
        fd_i = (vals[0][4][j] - vals[1][4][j]) / (2 * h)
        assert abs(s.dmultipliers[i] - fd_i) < 1e-4 * max(1.0, abs(fd_i))
    fd_mod = (np.abs(vals[0][4]) - np.abs(vals[1][4])) / (2 * h)
    np.testing.assert_allclose(np.sort(s.dmodulus), np.sort(fd_mod), rtol=1e-4)


def test_eigenvalue_derivatives_of_a_real_spectrum():
    """The multipliers and their derivatives are complex even when every eigenvalue is
    real (numpy returns a real array then, which JSON would print as a flat list), and
    they equal central differences of the eigenvalues along `dJ`."""
    from vhcjax.robustness._slope_sensitivity import eigenvalue_derivatives

    J = np.array([[4.0, 1.0, 0.0], [0.5, 0.4, 0.2], [0.0, 0.1, 0.07]])
    dJ = np.array([[1.0, -2.0, 0.5], [0.3, 0.2, 0.0], [1.0, 0.0, -0.4]])
    lam, dlam, dmod = eigenvalue_derivatives(J, dJ)
    assert np.iscomplexobj(lam) and np.iscomplexobj(dlam) and not lam.imag.any()
    h = 1e-6
    ev = [np.sort(np.linalg.eigvals(J + s * h * dJ).real)[::-1] for s in (1, -1)]
    np.testing.assert_allclose(dlam.real, (ev[0] - ev[1]) / (2 * h), rtol=1e-7)
    np.testing.assert_allclose(dmod, dlam.real * np.sign(lam.real), rtol=1e-12)


def test_gait_sensitivity_norm_vs_simulation():
    model, _, x_star, _ = stable_gait()
    g = vj.gait_sensitivity_norm(model, x_star, 40)
    h = 1e-6
    rec = vj.terrain_recovery(model, x_star, jnp.array([h, -h]), 40, 0.0, DEFAULT_CONFIG, False)
    assert (np.asarray(rec.label) != 1).all()
    fd = (np.asarray(rec.step_times[0]) - np.asarray(rec.step_times[1])) / (2 * h)
    np.testing.assert_allclose(np.asarray(g.dtimes)[:12], fd[:12], rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(float(g.norm), np.linalg.norm(fd), rtol=1e-4)


def test_slope_and_floor_sensitivity_refuse_or_flag_a_point_that_is_not_a_gait():
    """Implicit differentiation through the fixed-point equation needs a fixed point:
    `slope_sensitivity` refuses a point one step moves by 3e-2, and the (pure)
    `gait_sensitivity_norm` codes it `not_a_gait`; the gait itself is `successful`."""
    model, z, x_star, _ = stable_gait()
    off = np.asarray(z) + np.array([0.01, 0.0, 0.0])
    with pytest.raises(ValueError, match="slope_sensitivity: z_star is not a period-1 gait"):
        vj.slope_sensitivity(model, off)
    # A step that fails hands back its start: the step's code decides, not the distance.
    back = np.asarray(z) * np.array([1.0, -1.0, 1.0])  # the stance leg swings uphill
    with pytest.raises(ValueError, match="slope_sensitivity: z_star is not a gait .* ends with"):
        vj.slope_sensitivity(model, back)
    x_off = model.section_to_state(jnp.asarray(off))
    assert vj.result_names(vj.gait_sensitivity_norm(model, x_off, 40).result) == "not_a_gait"
    assert vj.result_names(vj.gait_sensitivity_norm(model, x_star, 40).result) == "successful"
    with pytest.raises(ValueError, match="num_steps"):
        vj.gait_sensitivity_norm(model, x_star, 0)


def test_floor_offset_zero_is_nominal_step():
    model, _, x_star, period = stable_gait()
    sr = vj.step(floor_step_model(model, 0.0), x_star)
    np.testing.assert_allclose(np.asarray(sr.x_plus), np.asarray(x_star), atol=1e-9)
    assert abs(float(sr.period) - period) < 1e-9


def test_max_floor_step_brackets():
    model, _, x_star, _ = stable_gait()
    th = vj.max_floor_step(model, x_star, h_max=0.1, iterations=8, scan=4, num_steps=40)
    assert th.bracketed.all()
    for i, sign in enumerate((-1.0, 1.0)):
        for mag, expect in ((th.lo[i], True), (th.hi[i], False)):
            first = vj.step(floor_step_model(model, sign * mag), x_star, throw=False)
            ok = vj.result_names(first.result) == "successful"
            survived = ok and returns_to(long_walk(model, first.x_plus), x_star)
            assert survived == expect, (sign, mag)


_NOISE_SCRIPT = """
import jax.numpy as jnp, vhcjax as vj
from vhcjax.robustness import label_names
x = jnp.array([0.2186688, -0.3233889, -1.09238359, -0.37737395])
rec = vj.terrain_recovery(vj.CompassGait(), x, jnp.array([0.01, -0.01]), 5)
print(label_names(rec.label))
"""


def test_floor_step_recovery_compiles_without_xla_noise():
    """Compiled in a fresh process with every cache off (so that XLA compiles it), the
    floor-step recovery leaves stderr empty: no "circular simplification loop" error of
    XLA's algebraic simplifier."""
    env = dict(
        os.environ,
        VHCJAX_CACHE_DIR="off",
        VHCJAX_PROGRAMS="off",
        JAX_ENABLE_COMPILATION_CACHE="false",
    )
    out = subprocess.run(
        [sys.executable, "-c", _NOISE_SCRIPT], env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    labels = ast.literal_eval(out.stdout.strip())  # 5 steps: the step down is undecided
    assert len(labels) == 2 and set(labels) <= {"converged", "fell", "undecided"}
    assert "circular simplification" not in out.stderr, out.stderr[-2000:]


def test_cli_says_when_the_step_budget_decides_the_threshold(capsys):
    from vhcjax.cli import main

    argv = ["slope-sensitivity", "--no-derivatives", "--steps", "5", "--heights-mm", "-5", "5"]
    assert main([*argv, "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    # 5 steps are too few to return within 1e-4 of the gait after all but the tiniest
    # floor steps: the thresholds (well below 1 mm) measure the budget, and it says so
    assert out["max_step_down_m"][1] < 1e-3 and out["max_step_up_m"][1] < 1e-3
    assert "raise --steps" in out["max_step_reason"]
    assert out["gait_stable"] is True and "gait_stable_reason" not in out
    # in words: each end of the bracket with the digits that tell them apart, and why
    # the first failing step failed; the recovery per floor step
    assert main([*argv, "--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "not back on the gait within 5 steps" in text and "falls at" not in text
    assert "-5 mm: " in text and "+5 mm: " in text


def test_cli_says_when_the_gait_is_unstable(capsys):
    """At 5 degrees the period-1 gait is unstable (past the flip near 4.3): a floor step
    survived measures the step budget, and the command says so."""
    from vhcjax.cli import main

    argv = ["slope-sensitivity", "--slope-deg", "5", "--no-derivatives", "--steps", "5"]
    assert main([*argv, "--heights-mm", "5", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["gait_stable"] is False and out["gait_spectral_radius"] > 1.0
    assert "step budget" in out["gait_stable_reason"]
