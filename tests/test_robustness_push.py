"""Hip pushes: the linear sensitivity of the next post-impact state by autodiff through
the simulation equals the transverse linearization with an input term and central finite
differences of pushed simulations; the largest survivable push is bracketed by simulation."""

import json

import jax.numpy as jnp
import numpy as np
import pytest
from _robust import long_walk, returns_to, stable_gait
from _text import assert_plain_text

import vhcjax as vj
from vhcjax import _programs
from vhcjax.robustness._push import direction, impulse_step, pulse_step

PHASES = jnp.array([0.0, 0.3, 0.6, 0.9])


@pytest.fixture(scope="module")
def autodiff_sensitivity():
    model, _, x_star, period = stable_gait()
    return vj.push_sensitivity_autodiff(model, x_star, period, PHASES)


def test_zero_push_is_nominal_step():
    model, _, x_star, period = stable_gait()
    sr = impulse_step(model, x_star, 0.5 * period, jnp.zeros(2))
    np.testing.assert_allclose(np.asarray(sr.x_plus), np.asarray(x_star), atol=1e-9)
    assert abs(float(sr.period) - period) < 1e-9


def test_push_sensitivity_autodiff_vs_finite_differences(autodiff_sensitivity):
    model, _, x_star, period = stable_gait()
    D = np.asarray(autodiff_sensitivity)
    h = 1e-6
    for i in (1, 3):
        for j in range(2):
            e = jnp.zeros(2).at[j].set(h)
            xp = impulse_step(model, x_star, PHASES[i] * period, e).x_plus
            xm = impulse_step(model, x_star, PHASES[i] * period, -e).x_plus
            np.testing.assert_allclose(D[i, :, j], (xp - xm) / (2 * h), rtol=1e-5, atol=1e-7)


@pytest.mark.slow
def test_push_sensitivity_transverse_vs_autodiff(autodiff_sensitivity):
    model, _, x_star, period = stable_gait()
    x_minus = vj.step(model, x_star).x_minus
    Z, lin = vj.push_sensitivity_transverse(model, x_star, x_minus, period, PHASES)
    zeta_ad = np.einsum("ij,sjk->sik", np.asarray(lin.P_plus), np.asarray(autodiff_sensitivity))
    np.testing.assert_allclose(np.asarray(Z), zeta_ad, rtol=1e-6, atol=1e-8)


@pytest.mark.slow
def test_short_pulse_approaches_impulse():
    model, _, x_star, period = stable_gait()
    P = 0.5 * direction(0.0)
    tau = 1e-4
    a = impulse_step(model, x_star, 0.3 * period, P).x_plus
    b = pulse_step(model, x_star, 0.3 * period - tau / 2, P / tau, tau).x_plus
    np.testing.assert_allclose(np.asarray(b), np.asarray(a), atol=1e-4)


def test_max_push_brackets():
    model, _, x_star, period = stable_gait()
    phases, angles = np.array([0.2, 0.7]), np.array([0.0, np.pi])
    res = vj.max_push(model, x_star, period, phases, angles, p_max=20.0, iterations=8, scan=4)
    th = res.threshold
    assert th.bracketed.all()
    for k, (s, a) in enumerate([(s, a) for s in phases for a in angles]):
        for mag, expect in ((th.lo[k], True), (th.hi[k], False)):
            sr = impulse_step(model, x_star, s * period, mag * direction(a))
            ok = vj.result_names(sr.result) == "successful"
            assert (ok and returns_to(long_walk(model, sr.x_plus), x_star)) == expect
    assert res.largest.shape == (2, 2)
    # at another step period (a gait at another slope, given as a Python float) the same
    # stored program runs: nothing is traced, exported or loaded again
    before = dict(_programs.stats)
    vj.max_push(model, x_star, period * (1 + 1e-6), phases, angles, iterations=1)
    assert _programs.stats == before


def test_a_pulse_past_the_heel_strike_is_refused(capsys):
    """A pulse still acting at the gait's heel strike cannot be simulated (`pulse_step`
    integrates it without the impact): the library raises, the command exits 2 with one
    line, before any bisection; a pulse that ends in time is accepted."""
    from vhcjax.cli import main

    model, _, x_star, period = stable_gait()
    with pytest.raises(ValueError, match="after the heel strike"):
        vj.max_push(model, x_star, period, np.array([0.0, 0.5]), np.zeros(1), duration=0.5)
    assert vj.pulse_past_strike(np.array([0.0, 0.5]), period, 0.3) == ""
    assert vj.pulse_past_strike(np.array([0.0]), period, period) != ""
    argv = ["push", "--phases", "2", "--directions-deg", "0", "--duration", "0.5"]
    assert main(argv + ["--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "after the heel strike" in err and "\n" not in err


def test_cli_says_when_the_step_budget_decides_the_largest_push(capsys):
    from vhcjax.cli import main

    assert main(["push", "--phases", "2", "--steps", "3", "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    # 3 steps are too few to come back within 1e-4 of the gait after any real push: every
    # first failing push is undecided, and the command says the budget decides
    assert max(max(row) for row in out["largest"]) < 1.5  # N s (0.89 to 20 at 30 steps)
    assert "at 8 of 8" in out["largest_reason"] and "raise --steps" in out["largest_reason"]
    assert out["gait_stable"] is True and out["gait_spectral_radius"] < 1.0
    assert all(p in (0.0, 0.5) for p in out["most_fragile_phase"])
    # the same in words: per direction the smallest and largest over the phases, labelled
    assert main(["push", "--phases", "2", "--steps", "3", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "over 2 phases of the step" in text and "smallest over the phases" in text
    assert text.count("deg: ") == 4
    # every push up to --max survived: `largest` is the search bound, and it says so
    assert main(["push", "--phases", "2", "--steps", "3", "--max", "0.001", "--json"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert all(v is None for row in out["falls_at"] for v in row)
    assert all(v == 0.001 for row in out["largest"] for v in row)
    assert "at 8 of 8" in out["falls_at_reason"] and "raise --max" in captured.err
    # and no phase is known to be more fragile than another
    assert out["most_fragile_phase"] == [None] * 4 and "most_fragile_phase_reason" in out
    assert "null_fields" not in out


def test_cli_says_when_the_gait_is_unstable(capsys):
    """`push` and `basin` at the unstable 3-degree gait: a warning and `gait_stable: false`
    with the spectral radius of the Poincare map (4.29), beside the figures."""
    from vhcjax.cli import main

    unstable = ["--gait", "0.20467554", "-1.21057184", "-0.71248882"]
    argv = ["push", *unstable, "--phases", "1", "--directions-deg", "0", "--iterations", "2"]
    assert main(argv + ["--steps", "3", "--json", "--quiet"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["gait_stable"] is False
    np.testing.assert_allclose(out["gait_spectral_radius"], 4.2915, atol=1e-3)
    assert "the gait is unstable" in captured.err and "step budget" in out["gait_stable_reason"]
    argv = ["basin", *unstable, "--grid", "3", "3", "--steps", "5", "--quiet"]
    assert main([*argv, "--json"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["gait_stable"] is False and "stable manifold" in out["gait_stable_reason"]
    assert "the gait is unstable" in captured.err
    # the same slice in words: counts by outcome, offsets and area with units
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "of 9 starts, within 5 steps: " in text and "rad^2/s" in text and "+q1 " in text


def test_cli_gait_by_shooting_where_the_vhc_search_fails_and_an_error_where_both_do(
    monkeypatch, capsys
):
    """Without `--gait` the robustness commands take the stable gait from `find_gait`
    (`--method auto`): a warning where shooting found it because the VHC search failed;
    where no method finds it, one line with the result and exit status 1. (The search
    results are stand-ins here: the VHC gait labelled as found by shooting, and a failed
    search; the fallback itself is tested with the library.)"""
    import dataclasses

    import jax.numpy as jnp

    import vhcjax.gait as G
    from vhcjax.cli import main

    real = G.find_gait

    def by_shooting(model, family, method, guess=None, throw=False):
        g = real(model, family, method, guess, throw=throw)
        return dataclasses.replace(g, shooting=jnp.asarray(True))

    monkeypatch.setattr(G, "find_gait", by_shooting)
    assert main(["push", "--phases", "2", "--steps", "3", "--json", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "the VHC search (Problem 1) did not find this gait" in captured.err
    assert json.loads(captured.out)["gait_stable"] is True

    def fails(model, family, method, guess=None, throw=False):
        g = real(model, family, method, guess, throw=throw)
        return dataclasses.replace(
            g, result=vj.RESULTS.where(True, vj.RESULTS.not_converged, g.result)
        )

    monkeypatch.setattr(G, "find_gait", fails)
    assert main(["push", "--phases", "2", "--steps", "3", "--json", "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert "no stable gait found at slope 3 deg by the VHC search or by shooting" in err
    assert "(not_converged:" in err and "\n" not in err
