"""Hybrid simulation against an independent scipy reference, the thesis walks, batching,
failure codes and dense output.

The reference (`benchmarks/scipy_reference.py`) integrates the thesis closed-form
equations (3.8)-(3.10) with `solve_ivp` (DOP853, rtol = atol = 1e-12) and a terminal event,
and applies the angular-momentum impact map (3.17): no JAX, no autodiff, no diffrax.
"""

import collections
import math

import _paths  # noqa: F401  (puts benchmarks/ on sys.path)
import _sim
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy_reference as ref

import vhcjax as vj
from vhcjax.hybrid._simulate import step_unchecked

GAIT_PERIOD = 0.73434639  # measured; checked below against the scipy reference


def ok(result):
    return np.asarray(result == vj.RESULTS.successful)


# ---- heel-strike time ------------------------------------------------------------------
def test_heel_strike_time_matches_scipy_dop853():
    """Step period (event time) and pre/post-impact states vs scipy at 1e-12, 8 states
    around the gait and at several slopes, batched with vmap."""
    rng = np.random.default_rng(7)
    slopes = np.array([3.0, 3.0, 3.0, 3.0, 2.0, 4.0, 5.0, 1.5])
    x0 = _sim.THESIS_7_5 + rng.normal(scale=[0.01, 0.0, 0.03, 0.03], size=(8, 4))
    x0[:, 1] = -x0[:, 0] - 2 * np.radians(slopes)  # on the post-impact section
    out = _sim.step_batch(_sim.batch_models(slopes), jnp.asarray(x0))
    assert ok(out.result).all(), vj.result_names(out.result)
    errs = []
    for i, s in enumerate(slopes):
        r = ref.step(ref.Params(psi=math.radians(s)), x0[i])
        assert r.ok
        errs.append(abs(float(out.period[i]) - r.period))
        np.testing.assert_allclose(out.x_minus[i], r.x_minus, rtol=0, atol=1e-8)
        np.testing.assert_allclose(out.x_plus[i], r.x_plus, rtol=0, atol=1e-8)
    assert max(errs) < 1e-9, errs


# ---- thesis walks -------------------------------------------------------------------------
def test_thesis_state_7_5_walks_20_steps_on_one_cycle():
    sim = _sim.thesis_walk("7.5")
    assert vj.result_names(sim.result) == "successful"
    assert int(sim.num_successful) == _sim.NUM_STEPS
    T = np.asarray(sim.steps.period)
    # "T about 0.735 s" (thesis Fig 7.4); (7.5) is rounded to 6 digits, so the periods
    # wander by ~1e-6 around the exact cycle's.
    assert np.all(np.abs(T - 0.735) < 1e-3), T
    assert np.ptp(T) < 1e-5, T
    xp = np.asarray(sim.steps.x_plus)
    assert np.abs(xp - _sim.THESIS_7_5).max() < 2e-5
    # Independent: the scipy reference walks the same 20 steps.
    r = ref.simulate(ref.Params(), _sim.THESIS_7_5, _sim.NUM_STEPS)
    assert len(r) == _sim.NUM_STEPS and all(s.ok for s in r)
    np.testing.assert_allclose(T, [s.period for s in r], rtol=0, atol=1e-8)
    np.testing.assert_allclose(xp, [s.x_plus for s in r], rtol=0, atol=1e-7)


def test_perturbed_state_7_7_converges_to_the_cycle():
    gait = np.asarray(_sim.thesis_walk("7.5").steps.x_plus[-1])
    sim = _sim.thesis_walk("7.7")
    assert vj.result_names(sim.result) == "successful"
    xp = np.asarray(sim.steps.x_plus)
    dist = np.abs(xp - gait).max(axis=1)
    assert dist[0] > 5e-3  # visibly perturbed at first
    assert dist[-1] < 1e-5, dist  # on the cycle after 20 steps (multipliers |.| < 0.6)
    assert np.abs(np.asarray(sim.steps.period[-1]) - GAIT_PERIOD) < 1e-5
    r = ref.simulate(ref.Params(), _sim.THESIS_7_7, _sim.NUM_STEPS)
    np.testing.assert_allclose(np.asarray(sim.steps.period), [s.period for s in r], atol=1e-8)


def test_gait_period_reference_value():
    """The period quoted above, from the scipy reference at the measured fixed point."""
    z = np.array([0.2186688, -1.09238359, -0.37737395])
    x0 = np.array([z[0], -z[0] - 2 * math.radians(3.0), z[1], z[2]])
    r = ref.step(ref.Params(), x0)
    assert abs(r.period - GAIT_PERIOD) < 1e-7
    np.testing.assert_allclose(r.x_plus, x0, atol=1e-7)  # a fixed point indeed


# ---- batches ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def big_batch():
    """1,000 random starts around the gait (some fall), plus members 0..7 on other slopes."""
    rng = np.random.default_rng(11)
    n = 1000
    slopes = np.full(n, 3.0)
    slopes[:8] = np.linspace(1.0, 6.0, 8)
    x0 = _sim.THESIS_7_5 + rng.normal(scale=[0.05, 0.0, 0.3, 0.6], size=(n, 4))
    x0[:8] = _sim.THESIS_7_5
    x0[:, 1] = -x0[:, 0] - 2 * np.radians(slopes)
    sim = jax.block_until_ready(_sim.walk_batch(_sim.batch_models(slopes), jnp.asarray(x0)))
    return slopes, x0, sim


@pytest.mark.slow
def test_vmap_1000_states_fallers_flagged_others_identical(big_batch):
    slopes, x0, sim = big_batch
    names = np.array(vj.result_names(sim.result))
    count = collections.Counter(names.tolist())
    assert count["successful"] >= 100 and len(names) - count["successful"] >= 50, count
    assert set(count) <= {"successful", "fell", "no_impact", "bad_impact"}, count
    for field in ("x_plus", "x_minus", "period", "impulse"):
        assert np.all(np.isfinite(np.asarray(getattr(sim.steps, field))))
    # num_successful counts the steps before the first failure; after it the state freezes.
    nsucc = np.asarray(sim.num_successful)
    assert np.all((nsucc == _sim.NUM_STEPS) == (names == "successful"))
    rng = np.random.default_rng(3)
    fallers = np.flatnonzero(names != "successful")
    walkers = np.flatnonzero(names == "successful")
    sample = np.concatenate(
        [rng.choice(fallers, 4, replace=False), rng.choice(walkers, 3, replace=False), [0, 7]]
    )
    for i in sample:
        model = _sim.make_model(slopes[i])
        one = _sim.walk(model, x0[i])
        assert vj.result_names(one.result) == names[i]
        # Completed steps are identical to the unbatched run; so is the step of failure
        # (where the state at which a fall is detected may differ in the 8th digit).
        k = int(nsucc[i])
        assert int(one.num_successful) == k
        for field in ("x_plus", "x_minus", "period"):
            np.testing.assert_allclose(
                np.asarray(getattr(one.steps, field))[:k],
                np.asarray(getattr(sim.steps, field))[i, :k],
                rtol=1e-13,
                atol=1e-13,
            )
        # Independently, the scipy reference fails (or not) at the same step.
        r = ref.simulate(ref.Params(psi=math.radians(slopes[i])), x0[i], _sim.NUM_STEPS)
        assert sum(s.ok for s in r) == k, (i, names[i], k, [s.ok for s in r])
        if k:
            np.testing.assert_allclose(
                float(sim.steps.period[i, k - 1]), r[k - 1].period, atol=1e-8
            )
        if names[i] == "fell":
            # Falling means hip at/below the slope or legs out of range at x_minus.
            xm = np.asarray(sim.steps.x_minus[i, k])
            assert (
                math.cos(xm[0] + math.radians(slopes[i])) < 1e-6
                or abs(xm[1] - xm[0]) > math.pi - 1e-6
            ), xm


def test_vmap_over_slope_matches_scipy(big_batch):
    """Members 0..7 start at (7.5) on slopes 1..6 degrees (model parameter batched)."""
    slopes, x0, sim = big_batch
    for i in range(8):
        par = ref.Params(psi=math.radians(slopes[i]))
        r = ref.simulate(par, x0[i], 3)
        k = min(3, int(sim.num_successful[i]))
        assert sum(s.ok for s in r) >= k
        np.testing.assert_allclose(
            np.asarray(sim.steps.period[i, :k]), [s.period for s in r[:k]], atol=1e-8
        )
    # Different slopes give different gaits: the batch really varies the parameter.
    assert np.ptp(np.asarray(sim.steps.period[:8, 0])) > 1e-2


# ---- failure codes ------------------------------------------------------------------------
BAD_IMPACT_X0 = np.array([0.09994991, -0.20466966, -0.18651818, 2.35210202])  # swing leg kicks
FALL_X0 = np.array([0.1, -0.1 - 2 * math.radians(3.0), 1.5, 0.0])  # falls backward


def test_failure_codes_fell_bad_impact_nonfinite_no_impact():
    # Batch of 8 (padded with the gait) so that the compiled batched step is reused.
    # Standing still with both legs vertical is an equilibrium: no heel strike, no fall.
    rest = [0.0, 0.0, 0.0, 0.0]
    x0 = np.stack([FALL_X0, BAD_IMPACT_X0, [np.nan, 0, 0, 0], rest] + [_sim.THESIS_7_5] * 4)
    out = _sim.step_batch(_sim.batch_models([3.0] * 8), jnp.asarray(x0))
    assert vj.result_names(out.result) == (
        ["fell", "bad_impact", "nonfinite", "no_impact"] + ["successful"] * 4
    )
    assert abs(float(out.period[3]) - 10 * math.sqrt(1.0 / 9.81)) < 1e-9  # the time limit
    assert np.all(np.isfinite(np.asarray(out.x_plus)))  # never NaN, even for NaN input
    par = ref.Params()
    # fell: the scipy reference finds no heel strike with the hip above the slope.
    assert not ref.step(par, FALL_X0).ok
    # bad_impact: the reference strikes at the same state; the impulse, computed as the
    # change of linear momentum from the reference momentum map, pulls into the slope.
    r = ref.step(par, BAD_IMPACT_X0)
    assert r.ok
    np.testing.assert_allclose(np.asarray(out.x_minus[1]), r.x_minus, atol=1e-8)
    a, b, l = par.a, par.b, par.l

    def momentum(q, dq, m_stance, m_swing):
        q1, q2 = q
        vs = -b * dq[0] * np.array([math.cos(q1), math.sin(q1)])
        vh = -l * dq[0] * np.array([math.cos(q1), math.sin(q1)])
        vw = vh + a * dq[1] * np.array([math.cos(q2), math.sin(q2)])
        return m_stance * vs + par.mH * vh + m_swing * vw

    F = momentum(r.x_plus[:2], r.x_plus[2:], par.m2, par.m1) - momentum(
        r.x_minus[:2], r.x_minus[2:], par.m1, par.m2
    )
    normal = np.array([math.sin(par.psi), math.cos(par.psi)])
    assert F @ normal < 0


def test_failure_code_max_steps():
    model = _sim.make_model()
    few = vj.SolverConfig(max_steps=4)
    out = eqx.filter_jit(step_unchecked)(model, jnp.asarray(_sim.THESIS_7_5), few)
    assert vj.result_names(out.result) == "max_steps_reached"
    assert np.all(np.isfinite(np.asarray(out.x_plus)))


# ---- dense output --------------------------------------------------------------------------
def test_dense_output_consistent_with_event_states():
    sim = _sim.thesis_walk_dense()
    t, x = np.asarray(sim.dense_t), np.asarray(sim.dense_x)
    T = np.asarray(sim.steps.period)
    np.testing.assert_allclose(t[:, 0], 0.0)
    np.testing.assert_allclose(t[:, -1], T, rtol=1e-14)
    starts = np.concatenate([np.asarray(sim.x0)[None], np.asarray(sim.steps.x_plus)[:-1]])
    np.testing.assert_allclose(x[:, 0], starts, atol=1e-14)
    np.testing.assert_allclose(x[:, -1], np.asarray(sim.steps.x_minus), atol=1e-8)
    # Interior points vs the scipy dense solution.
    par = ref.Params()
    r = ref.step(par, starts[1], dense=True)
    sol1, sol2 = r.sols
    for tt, xx in zip(t[1, 1:-1], x[1, 1:-1]):
        ref_x = sol1.sol(tt) if tt <= sol1.t[-1] else sol2.sol(tt)
        np.testing.assert_allclose(xx, ref_x, atol=1e-8)
    # Once the swing leg is ahead (gate open) the guard stays positive until the strike.
    psi = math.radians(3.0)
    inner = x[:, 1:-1]
    ahead = inner[..., 1] > inner[..., 0]
    assert ahead.any() and (~ahead).any()
    assert np.all((inner[..., 0] + inner[..., 1] + 2 * psi)[ahead] > 0)


def test_simulate_batch_splits_over_host_workers(monkeypatch):
    """On a CPU the batch runs as one chunk per core from host threads (here 2 workers,
    5 walkers: chunks of 3 and 2, the second padded): the same results as one call per
    walker."""
    import jax.numpy as jnp
    import numpy as np

    import vhcjax as vj

    monkeypatch.setenv("VHCJAX_HOST_WORKERS", "2")
    m = vj.CompassGait()
    x_star = jnp.array([0.2186688, -0.3373965, -1.0923836, -0.3773739])
    X = x_star + jnp.linspace(-0.01, 0.01, 5)[:, None] * jnp.array([1.0, 0.0, 0.0, 0.0])
    batch = vj.simulate_batch(m, X, 3, config=vj.FAST_CONFIG)
    assert batch.steps.x_plus.shape == (5, 3, 4)
    for i in range(5):
        one = vj.simulate(m, X[i], 3, config=vj.FAST_CONFIG)
        np.testing.assert_allclose(
            np.asarray(batch.steps.x_plus[i]), np.asarray(one.steps.x_plus), rtol=1e-12, atol=1e-13
        )
        assert vj.result_names(batch.result)[i] == vj.result_names(one.result)
