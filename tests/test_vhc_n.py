"""Generic n-DOF virtual holonomic constraints: gait search in theta and transverse
linearization, checked against the time-domain Poincare map (3-DOF pendulum walker) and
against the two-DOF thesis Problem 1 (compass gait)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax
from vhcjax._results import RESULTS
from vhcjax.gait._vhc_n import vhc_gait_search, vhc_orbit
from vhcjax.mechanics import _lagrangian as mech
from vhcjax.models._pendulum_walker import PendulumWalker
from vhcjax.stability._transverse import transverse_linearization


def _cross(r, v):
    return r[0] * v[1] - r[1] * v[0]


@pytest.fixture(scope="module")
def pw():
    return PendulumWalker()


@pytest.fixture(scope="module")
def pw_gait(pw):
    # guess: the compass-gait gait with the pendulum hanging still
    sol = vhcjax.fixed_point(pw, jnp.array([0.2187, 0.0, -1.0924, -0.3774, 0.0]))
    assert sol.result == RESULTS.successful and float(sol.residual) < 1e-10
    return sol


def test_pendulum_walker_impact_conserves_angular_momenta(pw):
    q = jnp.array([-0.21, 0.21 - 2 * pw.psi, 0.05])
    dq = jnp.array([-1.3, -0.4, 0.8])

    @jax.jit
    def go():
        dqp, dzp, _ = mech.augmented_impact(pw, q, dq)
        pts_v = jax.jvp(pw.points, (q,), (dq,))
        pts_vp = jax.jvp(pw.points, (q,), (dqp,))
        masses = {"stance_mass": pw.m1, "hip": pw.mH, "swing_mass": pw.m2, "pendulum": pw.mp}

        def L(pv, about, names, v0):
            p, v = pv
            return sum(masses[k] * _cross(p[k] - about, v[k] + v0) for k in names)

        foot, hip = pw.contact_point(q), pw.points(q)["hip"]
        z0 = jnp.zeros(2)
        return (
            L(pts_v, foot, masses, z0),
            L(pts_vp, foot, masses, dzp),  # whole, about new foot
            L(pts_v, hip, ["pendulum"], z0),
            L(pts_vp, hip, ["pendulum"], dzp),  # pendulum
            L(pts_v, hip, ["stance_mass"], z0),
            L(pts_vp, hip, ["stance_mass"], dzp),
        )

    a, b, c, d, e, f = go()
    np.testing.assert_allclose(b, a, rtol=1e-12)
    np.testing.assert_allclose(d, c, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(f, e, rtol=1e-12, atol=1e-14)


def test_vhc_arc_confirms_the_time_domain_fixed_point(pw, pw_gait):
    """The theta-domain VHC arc (phi'' ODE + energy) from the Poincare fixed point returns
    to it through the impact map, with the same period."""
    orb = vhc_orbit(pw, pw_gait.z)
    assert orb.result == RESULTS.successful
    np.testing.assert_allclose(orb.z_next, pw_gait.z, atol=1e-8)
    np.testing.assert_allclose(orb.period, pw_gait.periods[0], rtol=1e-8)
    # the pendulum really moves: a genuinely 3-DOF orbit
    assert abs(float(pw_gait.z[4])) > 0.1


@pytest.mark.slow
def test_transverse_linearization_matches_poincare_multipliers_3dof(pw, pw_gait):
    sr = vhcjax.step(pw, pw_gait.x0, throw=False)
    tl = transverse_linearization(pw, pw_gait.x0, sr.x_minus, pw_gait.periods[0])
    assert tl.result == RESULTS.successful
    assert tl.Xi.shape == (5, 5)  # 2n - 1 transverse coordinates
    ev_p = np.asarray(jnp.linalg.eigvals(vhcjax.poincare_jacobian(pw, pw_gait.z)))
    ev_t = np.asarray(tl.multipliers)
    np.testing.assert_allclose(np.sort_complex(ev_t), np.sort_complex(ev_p), atol=1e-6)
    assert np.abs(ev_p).max() < 1.0  # a stable passive 3-DOF gait


@pytest.mark.slow
def test_pendulum_walker_walks_100_steps(pw, pw_gait):
    x0 = pw.section_to_state(pw_gait.z + jnp.array([0.0, 0.02, 0.0, 0.0, 0.0]))
    sim = vhcjax.simulate(pw, x0, 100)
    assert sim.result == RESULTS.successful
    z = jax.vmap(pw.state_to_section)(sim.steps.x_plus)
    d = np.max(np.abs(np.asarray(z) - np.asarray(pw_gait.z)), axis=1)
    assert d[-1] < 0.2 * d[0]  # slow convergence: |lambda|max is about 0.98


@pytest.mark.slow
def test_n_dof_vhc_search_reproduces_two_dof_problem_1():
    """On the compass gait the n-DOF search (unknowns z, integration in theta) and the
    thesis Problem 1 solver (`_gait.vhc_search`, unknowns (a, b)) give the same gait."""
    from vhcjax.gait import vhc_search

    cg = vhcjax.CompassGait()
    g_n = vhc_gait_search(cg, jnp.array([0.21, -1.1, -0.37]))
    g_2 = eqx.filter_jit(vhc_search)(cg, jnp.array([0.21, -1.1]))
    assert g_n.result == RESULTS.successful and g_2.result == RESULTS.successful
    np.testing.assert_allclose(g_n.z, g_2.z, atol=1e-9)
    np.testing.assert_allclose(g_n.period, g_2.T, rtol=1e-9)
    np.testing.assert_allclose(g_n.x_minus, g_2.x_minus, atol=1e-8)
    # The same search on the walker at another scale (lengths x 1e-6, masses x 1e6,
    # gravity x 1e4: time unit x 1e-5): the same angles, rates and period rescaled.
    k_time = np.sqrt(1e-6 / 1e4)
    big = vhcjax.CompassGait(m1=5e6, m2=5e6, mH=1e7, a=5e-7, b=5e-7, g=9.81e4)
    unit = np.array([1.0, 1.0 / k_time, 1.0 / k_time])
    g_big = vhc_gait_search(big, jnp.array([0.21, -1.1, -0.37]) * unit)
    assert g_big.result == RESULTS.successful
    np.testing.assert_allclose(np.asarray(g_big.z) / unit, g_n.z, rtol=0, atol=1e-10)
    np.testing.assert_allclose(g_big.period, g_n.period * k_time, rtol=1e-10)
    assert int(g_big.iterations) == int(g_n.iterations)
