"""Properties over random models: a gait found repeats under simulation; the
transverse and Poincare multipliers agree or the transverse ones are flagged; no NaN in
any result; every code is a documented one; invalid models and inputs are `bad_input`.

Hypothesis draws few examples (each is a gait search and a multiplier computation; the
compiled programs are shared, so the first example pays the compilations).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st

import vhcjax as vj
from vhcjax.cli._multiplier_fields import stability_json
from vhcjax.stability import AGREEMENT_RTOL, gait_multipliers

FLAGS = {
    "phase_not_monotone",
    "ill_conditioned",
    "methods_disagree",
    "no_impact",
    "max_steps_reached",
    "nonfinite",
}
SETTINGS = {"deadline": None, "derandomize": True, "suppress_health_check": list(HealthCheck)}


def _documented(names):
    names = [names] if isinstance(names, str) else list(np.ravel(names))
    for n in names:
        item = getattr(vj.RESULTS, n)  # raises for an undocumented code
        assert n == "successful" or len(vj.RESULTS[item]) > 20, n


def _no_nan(tree, what):
    for leaf in jax.tree_util.tree_leaves(tree):
        if eqx.is_inexact_array(leaf):
            assert not np.any(np.isnan(np.asarray(leaf))), what


def _nearest(a, b):
    d = np.abs(np.asarray(a)[:, None] - np.asarray(b)[None, :])
    return max(d.min(axis=1).max(), d.min(axis=0).max()) / np.abs(b).max()


models = st.builds(
    lambda m, mH, a, b, g, deg: vj.CompassGait(
        m1=m, m2=m, mH=mH, a=a, b=b, g=g, psi=math.radians(deg)
    ),
    st.floats(0.5, 10.0),
    st.floats(0.1, 20.0),
    st.floats(0.3, 0.7),
    st.floats(0.3, 0.7),
    st.floats(1.0, 25.0),
    st.floats(0.5, 29.0),
)


@settings(max_examples=4, **SETTINGS)
@given(models)
@example(
    vj.CompassGait(m1=4.0, m2=4.0, mH=12.0, a=0.45, b=0.55, g=9.0, psi=math.radians(4.0))
)  # a gait exists: the checks run
def test_random_models_gaits_repeat_and_multipliers_hold_or_are_flagged(model):
    g = vj.find_gait(model, "stable", "vhc", throw=False)
    _no_nan(g, "gait")
    _documented(vj.result_names(g.result))
    if vj.result_names(g.result) != "successful":
        return
    # the gait repeats under the hybrid simulator
    sim = vj.simulate(model, g.x_plus, 3)
    assert vj.result_names(sim.result) == "successful"
    scale = max(1.0, float(np.abs(g.x_plus).max()))
    np.testing.assert_allclose(
        np.asarray(sim.steps.x_plus),
        np.broadcast_to(np.asarray(g.x_plus), (3, 4)),
        atol=1e-6 * scale,
    )
    np.testing.assert_allclose(np.asarray(sim.steps.period), float(g.T), rtol=1e-6)
    gm = gait_multipliers(model, model.state_to_section(g.x_plus))
    _no_nan(gm, "multipliers")
    tcode = vj.result_names(gm.transverse_result)
    _documented(tcode)
    assert vj.result_names(gm.result) == "successful"
    pc = np.asarray(gm.poincare)
    # the verdict is the Poincare one
    assert bool(gm.stable) == (np.abs(pc).max() < 1)
    js = stability_json(gm)
    if tcode == "successful":
        assert _nearest(gm.transverse, pc) <= AGREEMENT_RTOL
        assert js["multipliers"] is not None
    else:
        assert tcode in FLAGS
        assert js["multipliers"] is None and tcode in js["multipliers_reason"]


def test_light_hip_heavy_legs_transverse_flagged_poincare_decides():
    """The light-hip case (mH = 0.1, m = 10, 3 deg, shooting gait): dq1 changes sign
    along the step, so the transverse linearization (1.3e6, 1.33, 2.4e-4 before) is not
    used; the Poincare Jacobian (-1.065, 0.748, 0.221) decides: unstable."""
    model = vj.CompassGait(m1=10.0, m2=10.0, mH=0.1)
    z = jnp.array([0.08746059606983951, -0.29956712894520626, 2.0239753024603226])
    assert vj.result_names(vj.simulate(model, model.section_to_state(z), 2).result) == "successful"
    gm = gait_multipliers(model, z)
    assert vj.result_names(gm.transverse_result) == "phase_not_monotone"
    np.testing.assert_allclose(
        np.sort(np.asarray(gm.poincare).real), [-1.0652440, 0.2205511, 0.7482446], atol=1e-6
    )
    assert not bool(gm.stable)
    # (central differences of the step map give the same three values to 1e-7; not
    # recomputed here: its compilation would double the test's time)
    _no_nan(gm, "multipliers")


bad_models = st.one_of(
    st.floats(-10.0, 0.0).map(lambda m: vj.CompassGait(m1=m)),
    st.floats(-10.0, 0.0).map(lambda m: vj.CompassGait(mH=m)),
    st.floats(-0.5, 0.0).map(lambda a: vj.CompassGait(a=a)),
    st.sampled_from([float("nan"), float("inf"), -9.81, 0.0]).map(lambda g: vj.CompassGait(g=g)),
    st.floats(-0.5, 0.0).map(lambda p: vj.CompassGait(psi=p)),
)


@settings(max_examples=6, **SETTINGS)
@given(bad_models)
def test_simulate_invalid_model_is_bad_input(model):
    x0 = jnp.array([0.218669, -0.323389, -1.092386, -0.377377])
    sim = vj.simulate(model, x0, 3)
    assert vj.result_names(sim.result) == "bad_input"
    assert vj.result_names(sim.steps.result) == ["bad_input"] * 3
    assert int(sim.num_successful) == 0
    _no_nan(sim, "simulation")


def test_simulate_names_the_expected_shape():
    x0 = jnp.array([0.218669, -0.323389, -1.092386, -0.377377])
    with pytest.raises(ValueError, match=r"shape \(4,\).*got shape \(3,\)"):
        vj.simulate(vj.CompassGait(), x0[:3], 5)


def test_find_gaits_nonfinite_guesses_bad_input_no_nan(capsys):
    guesses = jnp.array([[0.2, -1.0], [jnp.nan, -1.0], [0.2, jnp.inf]])
    g = vj.find_gaits(vj.CompassGait(), guesses)
    assert vj.result_names(g.result) == ["successful", "bad_input", "bad_input"]
    for leaf in jax.tree_util.tree_leaves(g):
        if eqx.is_inexact_array(leaf):
            assert np.all(np.isfinite(np.asarray(leaf)))
    g1 = vj.find_gait(vj.CompassGait(), guess=(0.5, 2.0), throw=False)
    assert vj.result_names(g1.result) != "successful"
    for leaf in jax.tree_util.tree_leaves(g1):
        if eqx.is_inexact_array(leaf):
            assert np.all(np.isfinite(np.asarray(leaf)))
    # the command line prints the failure, and no gait table (T = 0, speed inf before)
    from vhcjax.cli import main

    capsys.readouterr()
    assert main(["gait", "--slope-deg", "3", "--guess", "0.5", "2.0"]) == 1
    captured = capsys.readouterr()
    assert "no stable gait found from --guess" in captured.err
    assert "T =" not in captured.out and "speed" not in captured.out


def test_model_repr_shows_values():
    text = repr(vj.CompassGait(mH=12.5))
    assert "mH=12.5" in text and "psi=0.0523599" in text and "f64[]" not in text


states = st.tuples(
    st.floats(-1.2, 1.2), st.floats(-1.2, 1.2), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0)
)


@settings(max_examples=12, **SETTINGS)
@given(states)
def test_simulate_random_states_no_nan_documented_codes(x0):
    sim = vj.simulate(vj.CompassGait(), jnp.asarray(x0), 3)
    _no_nan(sim, "simulation")
    names = vj.result_names(sim.steps.result)
    _documented(names)
    k = int(sim.num_successful)
    assert names[:k] == ["successful"] * k
    assert vj.result_names(sim.result) == ("successful" if k == 3 else names[k])


def test_bisection_keeps_the_label_of_the_failure():
    # survives below 1; fails by label 1 (fell) up to 2, by label 3 (undecided) beyond
    def labels(m):
        m = np.asarray(m)
        return np.where(m < 1.0, 0, np.where(m < 2.0, 1, 3))

    th = vj.bisect_threshold(labels, np.zeros(3), np.array([0.5, 1.5, 5.0]), iterations=30)
    assert th.survives_max[0] and th.hi_label[0] == -1
    assert abs(th.hi[1] - 1.0) < 1e-8 and th.hi_label[1] == 1
    scan = vj.bisect_threshold(labels, np.zeros(1), np.full(1, 5.0), iterations=30, scan=9)
    assert abs(scan.hi[0] - 1.0) < 1e-8 and scan.hi_label[0] == 1
    plain = vj.bisect_threshold(lambda m: labels(m) == 0, np.zeros(1), np.ones(1) * 5.0)
    assert plain.hi_label[0] == -1  # a boolean predicate has no labels
