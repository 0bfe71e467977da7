"""A walker and its rescaled copy (lengths x 1e-3, masses x 1e6, gravity x 1e4) recover
alike: the same contraction, and floor steps and pushes survived in proportion to their
own units (length, impulse)."""

import functools
import math

import numpy as np

import vhcjax as vj

K_LENGTH, K_MASS, K_GRAVITY = 1e-3, 1e6, 1e4
K_TIME = math.sqrt(K_LENGTH / K_GRAVITY)
K_IMPULSE = K_MASS * K_LENGTH / K_TIME


@functools.cache
def _gaits():
    ref = vj.CompassGait()
    scaled = vj.CompassGait(
        m1=5.0 * K_MASS,
        m2=5.0 * K_MASS,
        mH=10.0 * K_MASS,
        a=0.5 * K_LENGTH,
        b=0.5 * K_LENGTH,
        g=9.81 * K_GRAVITY,
    )
    return [(m, vj.find_gait(m, "stable")) for m in (ref, scaled)]


def test_a_scaled_walker_contracts_alike():
    (m0, g0), (m1, g1) = _gaits()
    c0, c1 = (
        vj.contraction(m, g.z, num_perturbations=4, num_steps=20, fit_window=(5, 20))
        for m, g in ((m0, g0), (m1, g1))
    )
    np.testing.assert_allclose(c1.spectral_radius, c0.spectral_radius, rtol=1e-9)
    # The same perturbations in own units, the same recoveries: errors from 1e-3 down to
    # 4e-8 agree to the two gaits' own agreement (~1e-11, their fixed-point accuracy).
    np.testing.assert_allclose(c1.distance, c0.distance, rtol=0, atol=3e-11)
    np.testing.assert_allclose(c1.measured_rates, c0.measured_rates, rtol=1e-4)
    assert c1.measured_steps_10x == c0.measured_steps_10x


def test_a_scaled_walker_survives_the_scaled_floor_steps():
    (m0, g0), (m1, g1) = _gaits()
    t0 = vj.max_floor_step(m0, g0.x_plus, iterations=6, scan=4, num_steps=30)
    t1 = vj.max_floor_step(m1, g1.x_plus, iterations=6, scan=4, num_steps=30)
    assert t0.bracketed.all() and t1.bracketed.all()
    np.testing.assert_allclose(t1.lo, t0.lo * K_LENGTH, rtol=1e-12)
    np.testing.assert_allclose(t1.hi, t0.hi * K_LENGTH, rtol=1e-12)


def test_a_scaled_walker_survives_the_scaled_pushes():
    (m0, g0), (m1, g1) = _gaits()
    phases, angles = np.array([0.3]), np.array([0.0, np.pi])
    assert math.isclose(vj.push_bound(m0), 20.0) and math.isclose(
        vj.push_bound(m1), 20.0 * K_IMPULSE
    )
    r0 = vj.max_push(m0, g0.x_plus, float(g0.T), phases, angles, iterations=6, scan=4)
    r1 = vj.max_push(m1, g1.x_plus, float(g1.T), phases, angles, iterations=6, scan=4)
    assert r0.threshold.bracketed.all() and r1.threshold.bracketed.all()
    np.testing.assert_allclose(r1.threshold.lo, r0.threshold.lo * K_IMPULSE, rtol=1e-12)
    np.testing.assert_allclose(r1.threshold.hi, r0.threshold.hi * K_IMPULSE, rtol=1e-12)


def _unit(m):
    return np.asarray(vj.hybrid._simulate.section_units(m))


def test_a_scaled_walker_gets_the_scaled_basin_grid():
    """`basin_slice`'s default grid (0.1 rad, 0.4 rad/s for the thesis walker) is the
    same grid in a rescaled walker's own units, and classifies alike."""
    (m0, g0), (m1, g1) = _gaits()
    b0, b1 = (vj.basin_slice(m, g.z, shape=(3, 5), num_steps=10) for m, g in ((m0, g0), (m1, g1)))
    assert b0.offsets_y[-1] == 0.4 and b0.offsets_x[-1] == 0.1
    np.testing.assert_allclose(b1.offsets_x, b0.offsets_x, rtol=1e-15)
    np.testing.assert_allclose(b1.offsets_y, b0.offsets_y / K_TIME, rtol=1e-12)
    np.testing.assert_array_equal(b1.label, b0.label)


def test_a_scaled_walker_gets_the_scaled_finite_difference_jacobians():
    """The finite-difference Jacobian steps in own units: the rescaled walker's Jacobian is
    the thesis walker's with rate rows and columns rescaled; likewise `period_k_orbit`."""
    (m0, g0), (m1, g1) = _gaits()
    u0, u1 = _unit(m0), _unit(m1)
    J0 = np.asarray(vj.stability.finite_difference_jacobian(m0, g0.z))
    J1 = np.asarray(vj.stability.finite_difference_jacobian(m1, g1.z))
    np.testing.assert_allclose(J1 * u0[:, None] / u1[:, None] * u1 / u0, J0, rtol=0, atol=1e-8)
    p0 = vj.period_k_orbit(m0, g0.z, 2, iterations=3)
    p1 = vj.period_k_orbit(m1, g1.z, 2, iterations=3)
    assert p0.minimal_period == p1.minimal_period == 1
    np.testing.assert_allclose(p1.multipliers_fd, p0.multipliers_fd, rtol=0, atol=1e-7)
