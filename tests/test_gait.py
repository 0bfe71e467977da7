"""Gait search: VHC (Problem 1) vs shooting (Problem 2) vs the hybrid simulator, thesis
(7.4), (7.9) and (7.18), batches, Jacobians, continuation."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax import gait as G, solvers as S
from vhcjax.gait import _find, _problem1, _shooting, _vhc as _vhc

SEED = (0.20, -1.0)  # thesis (7.2)
SLOPES_DEG = (2.0, 3.0, 4.0)


@pytest.fixture(scope="module")
def gaits():
    """VHC and shooting gaits, both families, at several slopes. VHC starts from the thesis
    seed (7.2). Shooting starts from (a0, b0) completed algebraically to (a0, b0, f0) (no
    VHC integration involved): the thesis seed for the stable family; for the unstable
    family, from the thesis seed Newton on the step map lands on the stable gait (flagged
    `other_cycle`, tested below), so it starts from the 3-degree (a, b) of the unstable
    gait (thesis 7.9, rounded to 3 digits)."""
    out = {}
    for deg in SLOPES_DEG:
        m = vj.CompassGait(psi=math.radians(deg))
        for fam in ("stable", "unstable"):
            out[deg, fam, "vhc"] = G.find_gait(m, fam, "vhc", guess=SEED, throw=False)
            seed = SEED if fam == "stable" else (0.205, -1.211)
            out[deg, fam, "shooting"] = G.find_gait(m, fam, "shooting", guess=seed, throw=False)
    return out


def test_shooting_from_thesis_seed_unstable_is_flagged():
    """Shooting from the thesis seed with the unstable completion converges to the stable
    gait; it is labelled `other_cycle`, not returned as the unstable gait."""
    m = vj.CompassGait(psi=math.radians(2.0))
    s = G.find_gait(m, "unstable", "shooting", guess=SEED, throw=False)
    assert vj.result_names(s.result) == "other_cycle"


@pytest.mark.parametrize("deg", SLOPES_DEG)
@pytest.mark.parametrize("fam", ["stable", "unstable"])
def test_vhc_equals_shooting(gaits, deg, fam):
    v, s = gaits[deg, fam, "vhc"], gaits[deg, fam, "shooting"]
    assert vj.result_names(v.result) == "successful"
    assert vj.result_names(s.result) == "successful"
    assert float(v.residual) < 1e-10 and float(s.residual) < 1e-10
    np.testing.assert_allclose(np.asarray(v.x_plus), np.asarray(s.x_plus), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(v.x_minus), np.asarray(s.x_minus), rtol=0, atol=1e-9)
    np.testing.assert_allclose(float(v.T), float(s.T), rtol=0, atol=1e-9)


@pytest.mark.parametrize("deg", SLOPES_DEG)
@pytest.mark.parametrize("fam", ["stable", "unstable"])
def test_vhc_gait_is_a_fixed_point_of_the_hybrid_simulation(gaits, deg, fam):
    """One step of the hybrid simulator (diffrax event, time domain) from the VHC gait's
    post-impact state returns to it; pre-impact state and period match too."""
    g = gaits[deg, fam, "vhc"]
    m = vj.CompassGait(psi=math.radians(deg))
    sim = vj.simulate(m, g.x_plus, 1)
    assert vj.result_names(sim.result) == "successful"
    np.testing.assert_allclose(np.asarray(sim.steps.x_plus[0]), np.asarray(g.x_plus), atol=1e-9)
    np.testing.assert_allclose(np.asarray(sim.steps.x_minus[0]), np.asarray(g.x_minus), atol=1e-9)
    np.testing.assert_allclose(float(sim.steps.period[0]), float(g.T), atol=1e-9)


@pytest.mark.parametrize("deg", SLOPES_DEG)
def test_energy_bookkeeping(gaits, deg):
    """Energy lost in the impact (kinetic, from the states) equals the potential energy
    released per step, m_total g (step length) sin(psi); E0 equals the model energy."""
    m = vj.CompassGait(psi=math.radians(deg))
    mt = float(m.m1 + m.m2 + m.mH)
    for fam in ("stable", "unstable"):
        g = gaits[deg, fam, "vhc"]
        drop = mt * float(m.g) * float(g.step_length) * math.sin(float(m.psi))
        np.testing.assert_allclose(float(g.energy_loss), drop, rtol=1e-9)
        # Step length from the leg geometry: 2 l sin((g - c)/2).
        np.testing.assert_allclose(
            float(g.step_length),
            2 * float(m.l) * math.sin((float(g.g) - float(g.c)) / 2),
            rtol=1e-12,
        )
        np.testing.assert_allclose(float(g.speed), float(g.step_length) / float(g.T), rtol=1e-14)


# Thesis values and how far (in units of the last printed digit) the thesis is from ours.
THESIS_7_4 = dict(
    a=(0.218669, 0),
    b=(-1.092386, 2),
    c=(-0.323389, 0),
    d=(-1.494206, 1),
    e=(-0.323389, 0),
    f=(-0.377377, 3),
    g=(0.218669, 0),
    h=(-1.805654, 25),
)
THESIS_7_9 = dict(
    a=(0.204676, 0),
    b=(-1.210571, 1),
    c=(-0.309396, 1),
    d=(-1.395725, 3),
    e=(-0.309396, 1),
    f=(-0.712484, 5),
    g=(0.204676, 0),
    h=(-0.087282, 17),
)


@pytest.mark.parametrize("fam,table", [("stable", THESIS_7_4), ("unstable", THESIS_7_9)])
def test_thesis_gaits_reproduced(gaits, fam, table):
    """Thesis (7.4)/(7.9) to the printed 6 decimals. Entries with a nonzero allowance are
    off in the last printed digit(s) by at most that many units; the VHC and shooting
    gaits agree to 1e-9 (test above), so the thesis digits are the less accurate ones
    (fminsearch, ode45 with abstol 1e-6)."""
    g = gaits[3.0, fam, "vhc"]
    for k, (want, ulps) in table.items():
        got = float(getattr(g, k))
        err = abs(round(got, 6) - want)
        assert err <= (ulps + 0.5) * 1e-6, (k, got, want)
        if ulps > 0:  # the allowance is needed: the digit really is off
            assert err >= (ulps - 0.5) * 1e-6, (k, got, want)


def test_period_matches_thesis_figure(gaits):
    """Thesis Fig. 7.4 text: T ~ 0.735 s for the stable gait at 3 degrees."""
    assert abs(float(gaits[3.0, "stable", "vhc"].T) - 0.735) < 1e-3


def test_uphill_solution_is_found_and_flagged():
    """Thesis (7.17)-(7.18): seed (0.20, +1.0), minus sign, 3 degrees: a solution of
    Problem 1 with positive velocities (the unstable gait run backwards in time)."""
    m = vj.CompassGait()
    g = G.find_gait(m, "stable", guess=(0.20, 1.0), throw=False)
    assert vj.result_names(g.result) == "infeasible_uphill"
    assert float(g.residual) < 1e-10
    assert float(g.T) < 0
    # (7.18): q1 = 0.204676, q2 = -0.309396, dq1 = 1.210571, dq2 = 0.712484
    np.testing.assert_allclose(
        np.asarray(g.x_plus), [0.204676, -0.309396, 1.210571, 0.712484], atol=6e-6
    )
    with pytest.raises(Exception):  # noqa: B017 (equinox raises its own runtime error type)
        G.find_gait(m, "stable", guess=(0.20, 1.0), throw=True).a.block_until_ready()


def test_batch_equals_unbatched_and_flags_hopeless(gaits):
    """A batch with two hopeless guesses flags them and solves the rest, to the unbatched
    gaits; each member equals a one-member call (gait to rounding, same code)."""
    m = vj.CompassGait()
    guesses = jnp.array([[0.20, -1.0], [0.20, -1.0], [2.5, 8.0], [0.2, 0.0]])
    psi = jnp.radians(jnp.array([3.0, 2.0, 3.0, 4.0]))
    b = G.find_gaits(m, guesses, "stable", psi=psi)
    names = vj.result_names(b.result)
    assert names[:2] == ["successful", "successful"]
    assert names[2] != "successful" and names[3] != "successful"
    np.testing.assert_allclose(
        np.asarray(b.x_plus[0]), np.asarray(gaits[3.0, "stable", "vhc"].x_plus), atol=1e-12
    )
    np.testing.assert_allclose(
        np.asarray(b.x_plus[1]), np.asarray(gaits[2.0, "stable", "vhc"].x_plus), atol=1e-10
    )
    assert np.all(np.isfinite(np.asarray(b.x_plus)))  # never a silent NaN
    for i in (1, 3):
        one = G.find_gaits(m, guesses[i : i + 1], "stable", psi=psi[i : i + 1])
        np.testing.assert_allclose(np.asarray(b.x_plus[i]), np.asarray(one.x_plus[0]), atol=1e-10)
        assert names[i] == vj.result_names(one.result)[0]


@pytest.mark.parametrize("method", ["vhc", "shooting"])
def test_chord_finish_gives_the_newton_gaits_and_codes(gaits, method):
    """`chord=True` (the default for batches of 64 or more per device) keeps the Jacobian
    once the residual is small and evaluates the residual alone: same gaits (to the
    solver tolerance) and the same codes as full Newton, hopeless guesses included
    (in the vectorised Newton loop)."""
    m = vj.CompassGait()
    seed = SEED if method == "vhc" else tuple(np.asarray(G.complete_guess(m, SEED, "stable")))
    hopeless = [(2.5, 8.0), (0.2, 0.0)] if method == "vhc" else [(2.5, 8.0, 1.0), (0.2, 0.0, 0.0)]
    guesses = jnp.array([seed, seed] + hopeless)
    psi = jnp.radians(jnp.array([3.0, 2.0, 3.0, 4.0]))
    full = G.find_gaits(m, guesses, "stable", method, psi=psi, chord=False)
    chord = G.find_gaits(m, guesses, "stable", method, psi=psi, chord=True)
    assert vj.result_names(chord.result) == vj.result_names(full.result)
    assert vj.result_names(chord.result)[:2] == ["successful", "successful"]
    ok = np.asarray(full.result == vj.RESULTS.successful)
    np.testing.assert_allclose(
        np.asarray(chord.x_plus)[ok], np.asarray(full.x_plus)[ok], atol=1e-10
    )
    one = gaits[3.0, "stable", method]  # unbatched, full Newton
    np.testing.assert_allclose(np.asarray(chord.x_plus[0]), np.asarray(one.x_plus), atol=1e-10)
    assert float(jnp.max(chord.residual[:2])) < 1e-10
    assert np.all(np.isfinite(np.asarray(chord.x_plus)))
    if method == "vhc":
        # A heavy hip: residuals that round above SUCCESS_TOL. Members a chord finish
        # leaves there are solved again with Newton steps: the same gaits as without.
        heavy = vj.CompassGait(mH=5000.0, m1=5.0, m2=5.0)
        start = jnp.array([(0.2674025, -1.0182185)] * 4)  # near the 2.56-degree gait
        psi = jnp.radians(jnp.full(4, 2.56))
        full = G.find_gaits(heavy, start, "stable", method, psi=psi, chord=False)
        chord = G.find_gaits(heavy, start, "stable", method, psi=psi, chord=True)
        assert vj.result_names(chord.result) == vj.result_names(full.result) == ["successful"] * 4
        np.testing.assert_allclose(np.asarray(chord.x_plus), np.asarray(full.x_plus), atol=1e-10)


def test_batched_search_under_jit_equals_the_direct_call():
    """`find_gaits` inside `jax.jit` (slopes traced) gives the gaits and codes of the
    direct call."""
    guesses = jnp.array([SEED, SEED, (2.5, 8.0), (0.2, 0.0)])
    psi = jnp.radians(jnp.array([3.0, 2.0, 3.0, 4.0]))
    direct = G.find_gaits(vj.CompassGait(), guesses, "stable", psi=psi, chord=True)
    under_jit = jax.jit(
        lambda p: G.find_gaits(vj.CompassGait(), guesses, "stable", psi=p, chord=True)
    )(psi)
    assert vj.result_names(under_jit.result) == vj.result_names(direct.result)
    np.testing.assert_allclose(
        np.asarray(under_jit.x_plus)[:2], np.asarray(direct.x_plus)[:2], atol=1e-12
    )


def test_newton_stops_a_member_that_cannot_move():
    """Where the residual is undefined (a constant, so J = 0) neither the Newton step nor
    a damped one exists: the member stops after those two trials (three evaluations with
    the guess's) instead of re-evaluating the same point `max_trials` times, which in a
    batch made every member wait. A member that can move is not affected."""
    calls = []

    def fn(x):
        jax.debug.callback(lambda: calls.append(1))
        return jnp.full_like(x, 1e3), None

    x0 = jnp.array([0.2, -1.0])
    x, r, _, k, _ = S.damped_newton(fn, x0)
    assert len(calls) == 3 and int(k) == 0
    np.testing.assert_array_equal(np.asarray(x), np.asarray(x0))
    x, r, _, k, _ = S.damped_newton(
        lambda y: (y**2 - jnp.array([2.0, 3.0]), None), jnp.array([1.4, 1.7])
    )
    np.testing.assert_allclose(np.asarray(x), np.sqrt([2.0, 3.0]), rtol=1e-12)


def test_phi_field_stops_where_the_ode_is_singular():
    """`_phi_field` returns zero rates and a flag rate of 1 where $\\dot\\theta^2 \\le 0$ (no
    NaN: the integration finishes in a few steps and the member is flagged); elsewhere
    the rates of (5.19) and no flag."""
    m = vj.CompassGait()
    ref = G.find_gait(m, "stable", guess=SEED)
    y = jnp.array([float(ref.e), float(ref.f / ref.b), 0.0, 0.0])
    args = (m, ref.E0, jnp.sign(ref.b))
    rate = _problem1._phi_field(ref.a, y, args)
    ddphi, _, dth2, _ = _vhc.phi_second_derivative(m, ref.E0, ref.a, y[0:1], y[1:2])
    np.testing.assert_allclose(
        np.asarray(rate), [y[1], ddphi[0], -1 / np.sqrt(dth2), 0.0], rtol=1e-14
    )
    low = _problem1._phi_field(
        ref.a, y, (m, ref.E0 - 100.0, jnp.sign(ref.b))
    )  # below the potential
    assert np.asarray(low).tolist() == [0.0, 0.0, 0.0, 1.0]


def test_chord_steps_keep_the_jacobian():
    """`damped_newton(chord_below=...)`: from the first point with a residual below the
    threshold the Jacobian is frozen. With an infinite threshold every step uses the
    guess's Jacobian (linear convergence: more steps than Newton) and still reaches the
    root; with a small one the steps are Newton's until the end."""
    target = jnp.array([2.0, 3.0])
    fn = lambda x: (x**2 - target, None)  # noqa: E731
    x0 = jnp.array([1.4, 1.7])  # chord contraction |1 - x*/x0| < 0.02
    root = np.sqrt(np.asarray(target))
    x_n, _, _, k_n, _ = S.damped_newton(fn, x0, rtol=1e-14, atol=1e-14)
    x_c, _, _, k_c, _ = S.damped_newton(fn, x0, rtol=1e-14, atol=1e-14, chord_below=jnp.inf)
    x_l, _, _, k_l, _ = S.damped_newton(fn, x0, rtol=1e-14, atol=1e-14, chord_below=1e-3)
    for x in (x_n, x_c, x_l):
        np.testing.assert_allclose(np.asarray(x), root, rtol=1e-13)
    assert int(k_c) > int(k_n) + 3
    assert int(k_n) <= int(k_l) <= int(k_n) + 1


@pytest.mark.parametrize("workers", ["1", "2"])
def test_large_batches_run_in_chunks_with_the_same_results(monkeypatch, workers):
    """Batches above `_MAX_CHUNK` run as host-side chunks (a 1,024 batch hung in the XLA
    CPU runtime): with the chunk size set to 2, five members run as 2 + 2 + 1, the last
    padded to 2 (one compiled program), one chunk at a time or two at once from host
    threads, and give the unchunked results and codes (the vectorised Newton loop)."""
    m = vj.CompassGait()
    guesses = jnp.array([[0.20, -1.0], [0.20, -1.0], [2.5, 8.0], [0.2, 0.0], [0.20, -1.0]])
    psi = jnp.radians(jnp.array([3.0, 2.0, 3.0, 4.0, 2.5]))
    whole = G.find_gaits(m, guesses, "stable", psi=psi)
    monkeypatch.setattr(_find, "_MAX_CHUNK", 2)
    monkeypatch.setenv("VHCJAX_HOST_WORKERS", workers)
    chunked = G.find_gaits(m, guesses, "stable", psi=psi)
    assert vj.result_names(chunked.result) == vj.result_names(whole.result)
    assert chunked.x_plus.shape == whole.x_plus.shape == (5, 4)
    np.testing.assert_allclose(
        np.asarray(chunked.x_plus), np.asarray(whole.x_plus), rtol=1e-12, atol=1e-14
    )
    np.testing.assert_allclose(np.asarray(chunked.T), np.asarray(whole.T), rtol=1e-12)


def test_chunk_size_gives_every_host_worker_a_chunk():
    """Large batches run in chunks of `_MAX_CHUNK`; with two host workers (CPU cores) a
    batch above 8 members per worker is split into one bucket-sized chunk per worker."""
    assert _find._chunk_size(1000, 1, None) == _find._chunk_size(1000, 2, None) == 128
    assert _find._chunk_size(100, 1, None) == 128 and _find._chunk_size(100, 2, None) == 64
    assert _find._chunk_size(16, 2, None) == 128  # not split: 8 per worker
    assert _find._chunk_size(17, 2, None) == 16
    assert _find._chunk_size(40, 4, None) == 16


def test_batch_over_model_parameters():
    masses = jnp.array([10.0, 12.0])
    m = vj.CompassGait(mH=masses)
    b = G.find_gaits(m, jnp.array([SEED, SEED]), "stable")
    assert vj.result_names(b.result) == ["successful", "successful"]
    one = G.find_gait(vj.CompassGait(mH=12.0), "stable", guess=SEED)
    np.testing.assert_allclose(np.asarray(b.x_plus[1]), np.asarray(one.x_plus), atol=1e-10)


def test_heavy_hip_gait_is_found_from_the_thesis_seed():
    """With a hip 1000 times as heavy as a leg the quadratic (5.13) nears a double root
    and h = (b - P11 d) / P12 divides by a small P12: in (a, b) the residual of Problem 1
    rounded to a few 1e-9. The search runs in (a, h), where it is evaluated to 1e-11,
    from the thesis seed (in (a, h) from the start: the seed lies next to a double root
    in (a, b)); shooting finds the same gait."""
    m = vj.CompassGait(mH=5000.0, m1=5.0, m2=5.0)
    vhc = G.find_gait(m, "stable", guess=SEED, throw=False)
    # Shooting from the thesis seed falls; from (a, b) of the VHC gait it solves its own
    # problem (the step map's fixed point).
    shot = G.find_gait(m, "stable", method="shooting", guess=(vhc.a, vhc.b), throw=False)
    assert vj.result_names(vhc.result) == vj.result_names(shot.result) == "successful"
    np.testing.assert_allclose(np.asarray(vhc.x_plus), np.asarray(shot.x_plus), atol=1e-10)
    np.testing.assert_allclose(np.asarray(vhc.x_minus), np.asarray(shot.x_minus), atol=1e-8)
    other = G.find_gait(vj.CompassGait(mH=4000.0, m1=5.0, m2=5.0), guess=SEED, throw=False)
    assert vj.result_names(other.result) == "successful"
    assert max(float(vhc.residual), float(other.residual)) < 1e-10
    # The acceptance itself: the residual alone, or a small error estimate with a small
    # residual; never a small error estimate alone (e.g. near a pole of the residual).
    assert bool(G.accepted(5e-10, np.inf))
    assert bool(G.accepted(3e-9, 1e-12)) and not bool(G.accepted(3e-9, 1e-9))
    assert not bool(G.accepted(5e-8, 1e-13))


def test_near_a_multiplier_of_one_the_vhc_gait_is_the_accurate_one():
    """At 1e-4 degrees the leading multiplier is 0.99874: shooting's fixed point is known
    only to its integration tolerance over 1 - lambda, the VHC search's residual rounds
    to about 1e-9. Newton's error estimate on the step map integrated at 1e-13 (an
    independent check) puts the VHC gait within 1e-9 of the fixed point, the shooting
    gait (tolerance 1e-10) within 1e-7."""
    m = vj.CompassGait(psi=math.radians(1e-4))
    guess = (0.00860135, -0.04460258)  # near the fold of (5.13): Newton needs a close guess
    vhc = G.find_gait(m, "stable", guess=guess, throw=False)
    shot = G.find_gait(m, "stable", method="shooting", guess=guess, throw=False)
    assert vj.result_names(vhc.result) == vj.result_names(shot.result) == "successful"
    tight = vj.DEFAULT_CONFIG._replace(rtol=1e-13, atol=1e-13, max_steps=16384)

    @jax.jit
    def newton_error(z):
        step = lambda z: vj.step_map(m, z, 1, tight).z_next - z  # noqa: E731
        return jnp.linalg.solve(jax.jacfwd(step)(z), step(z))

    errors = [float(jnp.max(jnp.abs(newton_error(jnp.asarray(g.z))))) for g in (vhc, shot)]
    assert errors[0] < 1e-9 and 1e-9 < errors[1] < 1e-7


# One compilation each for both families (the family sign and the model are traced).
_vhc_r = eqx.filter_jit(G.vhc_residual)
_vhc_J = eqx.filter_jit(jax.jacfwd(G.vhc_residual, argnums=1))
_shoot_r = eqx.filter_jit(lambda m, x: _shooting._shoot_eval(m, x)[0])
_shoot_J = eqx.filter_jit(jax.jacfwd(lambda m, x: _shooting._shoot_eval(m, x)[0], argnums=1))


def _central(r, x, h):
    return np.stack(
        [
            (np.asarray(r(x + h * e)) - np.asarray(r(x - h * e))) / (2 * h)
            for e in np.eye(x.shape[0])
        ],
        axis=1,
    )


@pytest.mark.parametrize("fam", ["stable", "unstable"])
def test_newton_jacobians_match_finite_differences(gaits, fam):
    m = vj.CompassGait()
    g = gaits[3.0, fam, "vhc"]
    sign = G.family_sign(fam)
    for ab in (jnp.stack([g.a, g.b]), jnp.stack([g.a, g.b]) + jnp.array([0.004, -0.01])):
        J = np.asarray(_vhc_J(m, ab, sign))
        fd = _central(lambda x: _vhc_r(m, x, sign), ab, 1e-6)
        np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-6)
    z = g.z
    J = np.asarray(_shoot_J(m, z))
    fd = _central(lambda x: _shoot_r(m, x), z, 1e-5)
    np.testing.assert_allclose(J, fd, rtol=1e-4, atol=1e-5)


def test_bad_input_and_labels():
    g = G.find_gait(vj.CompassGait(mH=-1.0), "stable", guess=SEED, throw=False)
    assert vj.result_names(g.result) == "bad_input"
    # without a guess (the homotopy from the default model) and without a numpy warning;
    # nothing was computed, so every number is the placeholder 0, not a made-up period
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        g = G.find_gait(vj.CompassGait(mH=-1.0), "stable", throw=False)
    assert vj.result_names(g.result) == "bad_input"
    assert float(g.T) == 0.0 and float(np.max(np.abs(np.asarray(g.x_plus)))) == 0.0
    with pytest.raises(ValueError, match="guess must be finite"):
        G.find_gait(vj.CompassGait(), "stable", guess=jnp.array([np.nan, -1.0]))
    g = G.find_gait(vj.CompassGait(), "stable", guess=jnp.array([np.nan, -1.0]), throw=False)
    assert vj.result_names(g.result) == "bad_input"
    with pytest.raises(ValueError):
        G.find_gait(vj.CompassGait(), "sideways", guess=SEED)
    with pytest.raises(ValueError):
        G.find_gait(vj.CompassGait(), "stable", "magic", guess=SEED)


def test_inputs_of_the_wrong_shape_or_type_are_refused_in_one_line(gaits):
    """Batches of the wrong shape get a `ValueError` naming the shapes (not an error from
    deep inside JAX); integer parameters are converted to float, so `validate` sees
    them; a numpy integer step count is a count, not an array to trace."""
    m = vj.CompassGait()
    with pytest.raises(ValueError, match="find_gait takes one model"):
        G.find_gait(vj.CompassGait(mH=jnp.array([10.0])), "stable", guess=SEED)
    with pytest.raises(ValueError, match="lengths"):
        G.find_gaits(m, jnp.zeros((0, 2)))
    with pytest.raises(ValueError, match=r"lengths \[2, 3\]"):
        G.find_gaits(m, jnp.array([SEED] * 3), psi=jnp.array([0.05, 0.06]))
    with pytest.raises(ValueError, match="family_multipliers"):
        vj.family_multipliers(m, np.array([0.05, 0.06]), np.zeros((3, 3)))
    kw = vj.KneedWalker(ms=np.int64(-1))
    assert np.asarray(kw.ms).dtype == np.float64 and not bool(kw.validate())
    assert not bool(vj.CompassGait(mH=np.array(-1)).validate())
    with pytest.raises(ValueError, match="transverse=False"):
        vj.gait_multipliers(vj.KneedWalker(), np.zeros(3))
    g = gaits[3.0, "stable", "vhc"]
    sim = vj.simulate(vj.CompassGait(psi=math.radians(3.0)), g.x_plus, np.int64(1))
    assert vj.result_names(sim.result) == "successful"


@pytest.mark.slow
def test_no_guess_other_models_and_sweep():
    """Without a guess: other masses, lengths, gravity and slope, both families; each
    gait checked by the hybrid simulator. Then a short sweep that crosses 3 degrees."""
    m = vj.CompassGait(m1=4.0, m2=4.0, mH=12.0, a=0.45, b=0.6, g=9.0, psi=math.radians(2.0))
    for fam in ("stable", "unstable"):
        g = G.find_gait(m, fam)
        sim = vj.simulate(m, g.x_plus, 1)
        np.testing.assert_allclose(np.asarray(sim.steps.x_plus[0]), np.asarray(g.x_plus), atol=1e-9)
    sw = G.sweep(vj.CompassGait(), np.radians([1.0, 2.0, 3.2, 4.0, 5.0]), "stable")
    assert np.all(np.asarray(sw.ok))
    assert sw.ends() == []
    one = G.find_gait(vj.CompassGait(psi=math.radians(5.0)), "stable", guess=SEED)
    np.testing.assert_allclose(np.asarray(sw.gaits.x_plus[-1]), np.asarray(one.x_plus), atol=1e-10)
    # d z*/d psi from the sweep's tangent vs a central difference of two solves
    dpsi = 1e-4
    gp = G.find_gait(vj.CompassGait(psi=math.radians(4.0) + dpsi), "stable", guess=SEED)
    gm = G.find_gait(vj.CompassGait(psi=math.radians(4.0) - dpsi), "stable", guess=SEED)
    fd = (np.array([float(gp.a), float(gp.b)]) - np.array([float(gm.a), float(gm.b)])) / (2 * dpsi)
    np.testing.assert_allclose(np.asarray(sw.tangent[3]), fd, rtol=1e-5)


def test_inexact_newton_ends_only_at_the_final_tolerance():
    """`damped_newton(..., tolerances=(loose, final))`: a residual whose evaluation error is
    the tolerance it is given converges to the root of the *final* problem; the last
    accepted evaluation is at `final`, the first at `loose`, and the iterates agree
    with exact Newton."""
    target = jnp.array([2.0, 3.0])

    def fn(x, tol):
        return x**2 - target + tol, tol

    x0 = jnp.array([1.0, 1.0])
    x, r, tol, k, _ = S.damped_newton(fn, x0, rtol=1e-14, atol=1e-14, tolerances=(1e-3, 1e-12))
    assert float(tol) == 1e-12
    np.testing.assert_allclose(np.asarray(x), np.sqrt(np.asarray(target) - 1e-12), rtol=1e-15)
    # The loose tolerance really is used: stopped after the first evaluation, the
    # residual carries its error.
    _, r1, tol1, _, _ = S.damped_newton(fn, x0, max_steps=0, tolerances=(1e-3, 1e-12))
    assert float(tol1) == 1e-3
    x_exact, _, _, _, _ = S.damped_newton(
        lambda y: (y**2 - target + 1e-12, None), x0, rtol=1e-14, atol=1e-14
    )
    np.testing.assert_allclose(np.asarray(x), np.asarray(x_exact), rtol=1e-15)


def test_batched_newton_equals_newton_on_each_member():
    """`damped_newton_batch` iterates every member in one loop; members stop at different
    iterations (or never converge) and keep their state: each row equals `damped_newton`
    on that member alone, with and without inexact tolerances and chord steps."""
    targets = jnp.array([[2.0, 3.0], [5.0, 0.5], [-1.0, 2.0], [2.0, 3.0]])  # row 2: no root
    X0 = jnp.array([[1.4, 1.7], [1.0, 1.0], [1.0, 1.0], [30.0, -20.0]])

    def fn(x, tol, t):
        return x**2 - t + tol, tol

    for kw in (
        {},
        {"tolerances": (1e-3, 1e-12)},
        {"tolerances": (1e-3, 1e-12), "chord_below": 1e-2},
    ):
        tol_fn = (
            (lambda X, T: fn(X, T[:, None], targets))
            if kw
            else (lambda X, T: fn(X, 0.0 * X, targets))
        )
        X, R, aux, k, err = S.damped_newton_batch(tol_fn, X0, rtol=1e-13, atol=1e-13, **kw)
        for i in range(4):
            one = (
                (lambda x, tol, i=i: fn(x, tol, targets[i]))
                if kw
                else (lambda x, i=i: fn(x, 0.0 * x, targets[i]))
            )
            x, r, _, ki, erri = S.damped_newton(one, X0[i], rtol=1e-13, atol=1e-13, **kw)
            np.testing.assert_allclose(np.asarray(X[i]), np.asarray(x), rtol=1e-15, atol=1e-15)
            np.testing.assert_allclose(np.asarray(R[i]), np.asarray(r), rtol=1e-15, atol=1e-15)
            assert int(k[i]) == int(ki)
            np.testing.assert_allclose(float(err[i]), float(erri), rtol=1e-12, atol=1e-300)
        assert len(set(np.asarray(k).tolist())) > 1  # the members did stop at different steps
        np.testing.assert_allclose(
            np.asarray(X)[[0, 1, 3]] ** 2, np.asarray(targets)[[0, 1, 3]], rtol=1e-11
        )
        assert np.all(np.isfinite(np.asarray(X)))
        # Newton's error estimate |J^{-1} r|: tiny at the roots, large where there is none
        # (row 2: x_1^2 = -1, where |J^{-1} r| = (x_1^2 + 1) / |2 x_1| >= 1); none (inf)
        # after chord steps, whose Jacobian is an old one.
        err = np.asarray(err)
        if "chord_below" in kw:
            assert np.all(np.isinf(err[[0, 1, 3]]))
        else:
            assert np.all(err[[0, 1, 3]] < 1e-12) and err[2] >= 1.0


@pytest.mark.parametrize("fam", ["stable", "unstable"])
def test_batch_jacobian_matches_finite_differences(gaits, fam):
    """The Jacobian of a batched Newton iteration (`batch_jacobian`: forward mode along
    each unknown of every member at once) against central differences, per member: the
    gait point, a point off it, and another slope."""
    g = gaits[3.0, fam, "vhc"]
    sign = G.family_sign(fam)
    psi = jnp.radians(jnp.array([3.0, 3.0, 2.5]))
    ab = jnp.stack([jnp.stack([g.a, g.b])] * 3) + jnp.array(
        [[0.0, 0.0], [0.004, -0.01], [0.0, 0.0]]
    )
    fn = lambda X: jax.vmap(lambda p, x: _problem1._vhc_eval(vj.CompassGait(psi=p), x, sign))(
        psi, X
    )  # noqa: E731
    R, J, _ = eqx.filter_jit(lambda X: S.batch_jacobian(fn, X))(ab)
    for i in range(3):
        m = vj.CompassGait(psi=psi[i])
        fd = _central(lambda x: _vhc_r(m, x, sign), ab[i], 1e-6)
        np.testing.assert_allclose(np.asarray(J[i]), fd, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(np.asarray(R[i]), np.asarray(_vhc_r(m, ab[i], sign)), atol=1e-13)


@pytest.mark.parametrize(
    "fam, deg", [("stable", 0.5 + 22 * 5.5 / 63), ("unstable", 0.5 + 59 * 5.5 / 63)]
)
def test_converged_gaits_close_well_inside_the_success_test(fam, deg):
    """The Newton-step convergence test (the step from a point, J^-1 r, below rtol) also
    needs |r| < SUCCESS_TOL / 10: with a large Jacobian a tiny step can leave a residual
    near 1e-9 (at these two slopes: 8.8e-10 and 1.05e-9 without that cap)."""
    g = G.find_gait(vj.CompassGait(psi=math.radians(deg)), fam, guess=SEED, throw=False)
    assert vj.result_names(g.result) == "successful"
    assert float(g.residual) < G.SUCCESS_TOL / 10


def test_continuation_in_calls_equals_the_searches_and_runs_only_its_points():
    """`_run_continuation` runs the compiled continuation in calls of `_CHUNK` points (here
    a full call and a short one): every point equals a search from an independent guess,
    and a short call solves only its own points (the rest of its buffer stays unset)."""
    from vhcjax.gait import _continuation as C

    sign = G.family_sign("stable")  # as the library passes it (an array)
    ref, z0 = C._seed(vj.CompassGait(), sign, "vhc")  # the reference, in its own units
    end = ref.with_slope(math.radians(3.6))
    s = np.linspace(0.0, 1.0, C._CHUNK + 4)
    g = C._run_continuation(ref, end, s, z0, sign, "vhc")
    assert np.asarray(g.result == vj.RESULTS.successful).all()
    path = C._path(ref, end)
    for i in (0, C._CHUNK - 1, C._CHUNK, len(s) - 1):
        guess = (1.02 * g.a[i], 0.98 * g.b[i])
        single = G.find_gait(path(s[i]), "stable", "vhc", guess=guess)
        np.testing.assert_allclose([single.a, single.b], [g.a[i], g.b[i]], rtol=0, atol=1e-10)
    k = 3
    s_buf = np.concatenate([s[:k], np.full(C._CHUNK - k, s[k - 1])])
    z0 = np.asarray(z0, float)  # the arguments as `_run_continuation` gives them
    out = C._continue(ref, end, s_buf, np.asarray(k), z0, sign, "vhc", np.asarray(s[0]), z0)
    np.testing.assert_allclose(np.asarray(out.a[:k]), g.a[:k], rtol=0, atol=1e-12)
    assert np.all(np.asarray(out.a[k:]) == 0.0) and np.all(np.asarray(out.iterations[k:]) == 0)


def test_batch_without_guesses_continues_each_member():
    """`find_gaits` without guesses continues every member from the reference gait (the
    continuation under `vmap`); each equals a search from the thesis seed."""
    psi = np.radians([2.5, 3.5])
    gs = G.find_gaits(vj.CompassGait(), psi=psi)
    for i, p in enumerate(psi):
        g = G.find_gait(vj.CompassGait(psi=float(p)), guess=SEED)
        np.testing.assert_allclose([gs.a[i], gs.b[i]], [g.a, g.b], rtol=0, atol=1e-10)
