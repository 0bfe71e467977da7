"""The passive kneed walker: a two-domain model run by the unchanged simulator, step map,
Newton shooting and Poincare multipliers."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _text import assert_plain_text

import vhcjax
from vhcjax._results import RESULTS
from vhcjax.cli import main
from vhcjax.hybrid import _poincare as P
from vhcjax.hybrid._multidomain import multidomain_trajectory
from vhcjax.models._kneed_walker import KneedWalker

trajectory_jit = eqx.filter_jit(multidomain_trajectory)
GUESS = jnp.array([0.19, -1.10, -0.04])  # near the Hsu Chen (2007) initial condition


@pytest.fixture(scope="module")
def kw():
    return KneedWalker()  # psi = 0.0504 rad, as `vhcjax ... --model kneed` builds it


@pytest.fixture(scope="module")
def gait(kw):
    sol = vhcjax.fixed_point(kw, GUESS)
    assert sol.result == RESULTS.successful
    assert float(sol.residual) < 1e-10
    return sol


def test_gait_confirmed_by_100_step_simulation(kw, gait):
    sim = vhcjax.simulate(kw, gait.x0, 100)
    assert sim.result == RESULTS.successful and int(sim.num_successful) == 100
    z = jax.vmap(kw.state_to_section)(sim.steps.x_plus)
    assert np.max(np.abs(z - gait.z)) < 1e-8
    np.testing.assert_allclose(sim.steps.period, gait.periods[0], rtol=1e-9)
    # a genuine walk: the knee bends (domain 0 lasts) and the feet move forward
    assert 0.2 < float(gait.periods[0]) < 1.5
    assert float(gait.z[0]) > 0 and float(gait.z[1]) < 0


def test_converges_from_perturbed_start(kw, gait):
    x0 = kw.section_to_state(gait.z + jnp.array([0.01, 0.05, -0.1]))
    sim = vhcjax.simulate(kw, x0, 100)
    assert sim.result == RESULTS.successful
    z_end = kw.state_to_section(sim.steps.x_plus[-1])
    z_first = kw.state_to_section(sim.steps.x_plus[0])
    assert np.max(np.abs(z_first - gait.z)) > 1e-3
    assert np.max(np.abs(z_end - gait.z)) < 1e-9


def test_a_hyperextended_knee_is_not_a_start(kw, gait):
    """A start with the swing knee bent backward (flexion q2 - q3 < 0, past the knee
    stop) is out of the leg's range: `fell`, with no step taken."""
    x0 = kw.section_to_state(gait.z).at[2].add(0.2)  # q3 = q2 + 0.2: flexion -0.2 rad
    sim = vhcjax.simulate(kw, x0, 100)
    assert sim.result == RESULTS.fell and int(sim.num_successful) == 0
    straight = vhcjax.simulate(kw, kw.section_to_state(gait.z).at[2].add(1e-12), 100)
    assert straight.result == RESULTS.successful  # rounding below the stop is no fault


def test_energy_conserved_within_each_phase_and_lost_at_impacts(kw, gait):
    ts, xs, info = trajectory_jit(kw, gait.x0, 40)
    assert np.all(np.asarray(info.result == RESULTS.successful))
    energy = jax.vmap(jax.vmap(kw.energy))(xs)
    for i in range(2):
        assert np.ptp(np.asarray(energy[i])) < 1e-8, i
    # the knee stays locked in domain 1 (constraint drift)
    np.testing.assert_allclose(xs[1, :, 1], xs[1, :, 2], atol=1e-9)
    np.testing.assert_allclose(xs[1, :, 4], xs[1, :, 5], atol=1e-9)

    # both impacts dissipate kinetic energy (the heel-strike post-impact state is in the
    # new labelling, whose pinned stance foot is at rest, so its kinetic energy is the true one)
    def kinetic(x):
        return float(kw.kinetic_energy(x[:3], x[3:]))

    assert kinetic(info.x_start[1]) < kinetic(info.x_end[0])  # knee strike
    assert kinetic(gait.x0) < kinetic(info.x_end[1])  # heel strike
    assert float(info.duration[0]) > 0.05 and float(info.duration[1]) > 0.05
    # knee strike happens with the swing leg ahead of the stance leg
    assert float(info.x_end[0][1]) > float(info.x_end[0][0])


def test_impacts_at_the_gait_conserve_angular_momentum(kw, gait):
    _, info = eqx.filter_jit(vhcjax.multidomain_step)(kw, gait.x0)
    # knee strike
    x = info.x_end[0]
    q, dq = x[:3], x[3:]
    dqp = info.x_start[1][3:]
    np.testing.assert_allclose(
        kw.angular_momentum(q, dqp, jnp.zeros(2)),
        kw.angular_momentum(q, dq, jnp.zeros(2)),
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        kw.swing_leg_momentum(q, dqp), kw.swing_leg_momentum(q, dq), rtol=1e-12
    )
    # heel strike: before relabelling, with the old stance foot lifting off
    from vhcjax.hybrid._multidomain import augmented_impact_locked
    from vhcjax.models._kneed_walker import _KNEE

    x = info.x_end[1]
    q, dq = x[:3], x[3:]
    dqp, dzp, impulse = augmented_impact_locked(kw, q, dq, _KNEE)
    foot = kw.contact_point(q)
    np.testing.assert_allclose(
        kw.angular_momentum(q, dqp, foot, dzp), kw.angular_momentum(q, dq, foot), rtol=1e-12
    )
    np.testing.assert_allclose(
        kw.stance_leg_momentum(q, dqp, dzp), kw.stance_leg_momentum(q, dq), rtol=1e-12
    )
    np.testing.assert_allclose(impulse, info.impulse[1], rtol=1e-12)
    assert float(impulse @ kw.slope_normal) > 0  # pushes, does not pull
    # the relabelled post-impact state is the next cycle's start
    np.testing.assert_allclose(kw.relabel(q, dqp)[1], gait.x0[3:], rtol=1e-9, atol=1e-9)


def test_multipliers_autodiff_vs_central_differences(kw, gait):
    J = np.asarray(vhcjax.poincare_jacobian(kw, gait.z))
    h = 1e-6

    @eqx.filter_jit
    def fd(model, z):
        E = jnp.eye(3) * h
        plus = jax.vmap(lambda e: P.step_map(model, z + e).z_next)(E)
        minus = jax.vmap(lambda e: P.step_map(model, z - e).z_next)(E)
        return ((plus - minus) / (2 * h)).T

    Jfd = np.asarray(fd(kw, gait.z))
    np.testing.assert_allclose(J, Jfd, atol=2e-6 * np.abs(J).max())
    ev = np.sort_complex(np.linalg.eigvals(J))
    ev_fd = np.sort_complex(np.linalg.eigvals(Jfd))
    np.testing.assert_allclose(ev, ev_fd, atol=1e-5)
    assert np.abs(ev).max() < 1.0  # the passive gait is stable


def test_gait_derivatives_forward_reverse_and_central_differences(gait):
    """`fixed_point` of a multi-domain model is differentiable in both modes (implicit
    function theorem at the gait): d z / d (mh, psi) by `jax.jacfwd` and `jax.jacrev`
    against central differences of re-solved gaits."""

    def z_of(p):  # the compiled search runs on the values; only the derivative compiles
        return vhcjax.fixed_point(KneedWalker(mh=p[0], psi=p[1]), gait.z).z

    p = jnp.array([0.5, 0.0504])
    Jf = np.asarray(jax.jacfwd(z_of)(p))
    Jr = np.asarray(jax.jacrev(z_of)(p))
    np.testing.assert_allclose(Jr, Jf, rtol=1e-10, atol=1e-12 * np.abs(Jf).max())
    h = 1e-5
    E = h * np.eye(2)
    Jfd = np.stack([(z_of(p + e) - z_of(p - e)) / (2 * h) for e in E], axis=1)
    np.testing.assert_allclose(Jf, Jfd, atol=1e-6 * np.abs(Jfd).max())
    assert np.abs(Jf).min() > 1e-3  # every entry is a real dependence


@pytest.mark.slow
def test_slope_range_by_continuation(kw, gait):
    """Stable gaits exist from 0.0354 to 0.1054 rad (continuation in 0.005 steps from the
    Chen slope, secant predictor); at 0.1104 the continued gait is unstable, which a
    simulation from a 1e-6 perturbation confirms (it drifts away)."""
    z_prev, z = gait.z, gait.z
    psi = 0.0504
    found = {}
    for target in (0.1054, 0.1104, 0.0354):
        if target < psi:
            z_prev, z, psi = gait.z, gait.z, 0.0504
        while abs(psi - target) > 1e-9:
            psi_new = psi + np.sign(target - psi) * 0.005
            guess = 2 * z - z_prev if psi != 0.0504 else z
            sol = vhcjax.fixed_point(KneedWalker(psi=jnp.asarray(psi_new)), guess)
            assert sol.result == RESULTS.successful, psi_new
            z_prev, z, psi = z, sol.z, psi_new
        model = KneedWalker(psi=jnp.asarray(psi))
        ev = np.linalg.eigvals(np.asarray(vhcjax.poincare_jacobian(model, z)))
        found[target] = (model, z, np.abs(ev).max())
    assert found[0.1054][2] < 1.0 and found[0.0354][2] < 1.0
    assert found[0.1104][2] > 1.05
    model, z, _ = found[0.1104]
    x0 = model.section_to_state(z + jnp.array([1e-6, 0.0, 0.0]))
    sim = vhcjax.simulate(model, x0, 100)
    zs = jax.vmap(model.state_to_section)(sim.steps.x_plus)
    ok = np.asarray(sim.steps.result == RESULTS.successful)
    dist = np.max(np.abs(np.asarray(zs) - np.asarray(z)), axis=1)
    assert dist[0] < 1e-4  # starts next to the gait ...
    assert not ok.all() or dist.max() > 1e-3  # ... and leaves it


def test_dense_simulation_joins_the_domains(kw, gait):
    """`simulate(..., dense_points=N)` of a two-domain model: N points per domain, joined;
    each step's last point is the event solver's pre-impact state at its period, and the
    angles are continuous across the knee strike (only velocities jump)."""
    # 3 steps of 40 points per domain: the program `vhcjax simulate --plots` runs
    sim = vhcjax.simulate(kw, gait.x0, 3, dense_points=40)
    assert sim.dense_t is not None and sim.dense_x is not None
    t, x = np.asarray(sim.dense_t), np.asarray(sim.dense_x)
    assert x.shape == (3, 80, 6)
    starts = np.concatenate([np.asarray(gait.x0)[None], np.asarray(sim.steps.x_plus[:-1])])
    np.testing.assert_allclose(x[:, 0], starts, atol=1e-12)
    np.testing.assert_allclose(x[:, -1], sim.steps.x_minus, atol=1e-9)
    np.testing.assert_allclose(t[:, -1], sim.steps.period, rtol=1e-12)
    np.testing.assert_allclose(x[:, 39, :3], x[:, 40, :3], atol=1e-12)  # knee strike
    assert np.all(np.diff(t, axis=1) >= 0)
    assert np.all(np.abs(x[:, 39, 3:] - x[:, 40, 3:]).max(axis=1) > 1e-3)
    # a walker that falls in its first step: after the fall the points hold the last
    # state reached (the angles never jump back to the start)
    fall = vhcjax.simulate(kw, gait.x0 * jnp.array([1, 1, 1, 3, 3, 3]), 3, dense_points=40)
    assert fall.result != RESULTS.successful and int(fall.num_successful) == 0
    assert fall.dense_x is not None
    q = np.asarray(fall.dense_x[0, :, :3])
    assert np.abs(np.diff(q, axis=0)).max() < 0.2


# ---- the command line with --model kneed ------------------------------------------------

SLOPE_DEG = "2.887707287459349"  # 0.0504 rad


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_cli_gait_and_multipliers(capsys, kw, gait):
    """`vhcjax gait --model kneed --method shooting` gives the library's gait, with the
    eigenvalues of the step map's Jacobian (which central differences confirm in
    `test_multipliers_autodiff_vs_central_differences`); `vhcjax multipliers --model
    kneed` the same ones. The VHC search and the other model's flags are refused with one
    line."""
    rec = _json(
        capsys,
        ["gait", "--model", "kneed", "--method", "shooting", "--slope-deg", SLOPE_DEG, "--json"],
    )
    assert rec["result"] == "successful" and rec["stable"] is True
    assert rec["params"] is None and "compass gait" in rec["params_reason"]
    np.testing.assert_allclose(rec["z"], gait.z, atol=1e-10)
    np.testing.assert_allclose(rec["z"], [0.18818546, -1.10958733, -0.05714811], atol=1e-8)
    np.testing.assert_allclose(rec["period"], 0.56432817, atol=1e-8)
    assert rec["multipliers"] is None and "Poincare" in rec["multipliers_reason"]
    ev = np.asarray(rec["multipliers_poincare"])
    ev = np.sort(np.abs(ev[:, 0] + 1j * ev[:, 1]))
    np.testing.assert_allclose(rec["max_abs_multiplier"], ev[-1], atol=1e-12)
    J = np.linalg.eigvals(np.asarray(vhcjax.poincare_jacobian(kw, gait.z)))
    np.testing.assert_allclose(ev, np.sort(np.abs(J)), atol=1e-9)

    m = _json(
        capsys,
        ["multipliers", "--model", "kneed"]  # shooting: the kneed walker's default
        + ["--slope-deg", SLOPE_DEG, "--json"],
    )
    assert m["model"] == "kneed" and m["stable"] is True
    assert m["multipliers"] is None and "Poincare" in m["multipliers_reason"]
    pm = np.asarray(m["multipliers_poincare"])
    np.testing.assert_allclose(np.sort(np.abs(pm[:, 0] + 1j * pm[:, 1])), ev, atol=1e-10)
    np.testing.assert_allclose(m["max_abs_multiplier"], ev[-1], atol=1e-10)
    # both again as text (the same programs): words and units, no reprs
    for cmd in ("gait", "multipliers"):
        assert main([cmd, "--model", "kneed", "--slope-deg", SLOPE_DEG, "--quiet"]) == 0
        text = capsys.readouterr().out
        assert_plain_text(text)
        assert "kneed-walker gait at slope 2.88771 deg" in text
        assert "q1 0.18818546 rad" in text and "verdict: stable" in text

    # a model where the family is lost: the record has the compass gait's nulls, and says
    # why
    argv = ["gait", "--model", "kneed", "--mass-shank", "5", "--json"]
    assert main(argv) == 1
    rec = json.loads(capsys.readouterr().out)
    assert rec["result"] == "fell" and rec["x0"] is None and rec["residual"] is None
    assert rec["params"] is None
    assert "no gait found at slope" in rec["reason"] and "fell" in rec["reason"]

    for argv in (
        ["gait", "--model", "kneed", "--method", "vhc", "--slope-deg", "3"],
        ["multipliers", "--model", "kneed", "--method", "vhc"],
        ["gait", "--model", "kneed", "--method", "shooting", "--a", "0.4"],
        ["basin", "--mass-shank", "0.1"],
        ["gait", "--model", "kneed", "--method", "shooting", "--family", "stable"],
        ["multipliers", "--model", "kneed", "--method", "shooting", "--family", "unstable"],
    ):
        assert main(argv) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_cli_simulate_json_figures_and_animation(capsys, gait, tmp_path):
    """`vhcjax simulate --model kneed` starts on the gait by default and repeats it; the
    three figures and the GIF are written; a compass-gait state is refused."""
    gif = tmp_path / "walk.gif"
    rec = _json(
        capsys,
        ["simulate", "--model", "kneed", "--slope-deg", SLOPE_DEG, "--steps", "3", "--json"]
        + ["--plots", str(tmp_path), "--animate", str(gif)],
    )
    assert rec["result"] == "successful" and rec["num_successful"] == 3
    for s in rec["steps"]:
        np.testing.assert_allclose(s["x_plus"], gait.x0, atol=1e-7)
        np.testing.assert_allclose(s["period"], gait.periods[0], rtol=1e-7)
    for name in ("states.png", "phase.png", "periods.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    assert gif.stat().st_size > 10_000
    assert main(["simulate", "--model", "kneed", "--x0", "0.2", "-0.3", "-1", "0"]) == 2
    assert "6 numbers" in capsys.readouterr().err


def test_cli_basin(capsys, kw, gait):
    """`vhcjax basin --model kneed`: a small slice around the kneed gait converges, as
    plain simulations from its corners do."""
    rec = _json(
        capsys,
        ["basin", "--model", "kneed", "--slope-deg", SLOPE_DEG, "--grid", "3", "3"]
        + ["--half-widths", "0.01", "0.05", "--steps", "40", "--json", "--quiet"],
    )
    np.testing.assert_allclose(rec["gait"], gait.z, atol=1e-10)
    assert rec["counts"]["converged"] == 9 and rec["fraction"] == 1.0
    for dz in ([0.01, 0.05, 0.0], [-0.01, -0.05, 0.0]):
        sim = vhcjax.simulate(kw, kw.section_to_state(gait.z + jnp.asarray(dz)), 100)
        assert sim.result == RESULTS.successful
        z_end = kw.state_to_section(sim.steps.x_plus[-1])
        assert np.max(np.abs(z_end - gait.z)) < 1e-4


# ---- other parameters: the gait continued from the default walker --------------------


def test_continued_gait_at_a_heavy_hip_and_where_a_continuation_stops(kw, gait, monkeypatch):
    """`continue_fixed_point` follows the gait family from the default walker to a hip 100
    times heavier: its fixed point returns after 100 simulated steps, and a plain
    continuation in 12.5 % steps of the hip mass (secant predictor) lands on it too. Newton
    straight from the default gait lands elsewhere, on another (unstable) gait. Where the
    family is lost (shank mass 5 kg) the continuation stops with the failing step's code,
    `fell`, at a model it did solve, never with the code of a non-finite Newton iterate."""
    heavy = KneedWalker(mh=50.0)
    fp, reached = P.continue_fixed_point(kw, gait.z, heavy)
    assert vhcjax.result_names(fp.result) == "successful" and reached is heavy
    sim = vhcjax.simulate(heavy, fp.x0, 100)
    assert int(sim.num_successful) == 100
    zs = np.asarray(jax.vmap(heavy.state_to_section)(sim.steps.x_plus))
    assert np.abs(zs - np.asarray(fp.z)).max() < 1e-8
    z_prev = z = gait.z
    for k, mh in enumerate(np.geomspace(0.5, 50.0, 40)[1:]):
        sol = vhcjax.fixed_point(KneedWalker(mh=jnp.asarray(mh)), z if k == 0 else 2 * z - z_prev)
        assert sol.result == RESULTS.successful, mh
        z_prev, z = z, sol.z
    np.testing.assert_allclose(np.asarray(fp.z), np.asarray(z), atol=1e-10)
    direct = vhcjax.fixed_point(heavy, gait.z)
    assert direct.result == RESULTS.successful
    assert np.abs(np.asarray(direct.z) - np.asarray(fp.z)).max() > 0.05
    assert (
        np.abs(np.linalg.eigvals(np.asarray(vhcjax.poincare_jacobian(heavy, direct.z)))).max() > 1.0
    )

    fp, reached = P.continue_fixed_point(kw, gait.z, KneedWalker(ms=5.0))
    assert vhcjax.result_names(fp.result) == "fell"
    assert 0.05 < float(reached.ms) < 5.0 and np.isfinite(np.asarray(fp.z)).all()
    back, _ = P.continue_fixed_point(kw, gait.z, reached)  # the part of the path it solved
    assert back.result == RESULTS.successful
    searches = []  # no way to go: the start's gait, from one search
    real = P.fixed_point
    monkeypatch.setattr(P, "fixed_point", lambda *a, **k: searches.append(1) or real(*a, **k))
    same, at = P.continue_fixed_point(kw, gait.z, kw)
    assert same.result == RESULTS.successful and at is kw and len(searches) == 1
    np.testing.assert_allclose(np.asarray(same.z), np.asarray(gait.z), atol=1e-10)
    # Newton from the default gait on the far model diverges (its start walks): coded
    # not_converged at its start, with finite numbers, never `nonfinite`
    slope = KneedWalker(psi=jnp.asarray(0.0087))
    assert P.step_map(slope, gait.z).result == RESULTS.successful
    far = vhcjax.fixed_point(slope, gait.z)
    assert vhcjax.result_names(far.result) == "not_converged"
    np.testing.assert_array_equal(np.asarray(far.z), np.asarray(gait.z))
    assert np.isfinite(np.asarray(far.z)).all() and np.isfinite(float(far.residual))
