"""Transverse linearization (thesis ch. 6) against the Poincare-map Jacobian, finite
differences and the full dynamics; each piece of the construction checked on its own."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax
from vhcjax import CompassGait, stability as S
from vhcjax.gait._vhc import phi_second_derivative, theta_dynamics_coefficients
from vhcjax.stability import _transverse as TL

SLOPES_DEG = [0.5, 3.0, 6.0]
# Newton seeds only (rounded to 3-4 digits), one per (family, slope).
SEEDS = {
    "stable": [(0.139, -0.714, -0.583), (0.2187, -1.092, -0.377), (0.239, -1.186, 0.123)],
    "unstable": [(0.127, -0.703, -0.651), (0.2047, -1.211, -0.712), (0.216, -1.437, -0.467)],
}


@pytest.fixture(scope="module")
def gaits():
    """Both families at 0.5, 3 and 6 degrees, in one batched Newton solve."""
    psis, seeds, fams = [], [], []
    for fam, zz in SEEDS.items():
        for deg, z in zip(SLOPES_DEG, zz):
            psis.append(math.radians(deg))
            seeds.append(z)
            fams.append(fam)
    solve = jax.jit(
        jax.vmap(
            lambda p, z: vhcjax.fixed_point(
                CompassGait().with_slope(p), z, 1, config=vhcjax.DEFAULT_CONFIG
            )
        )
    )
    fps = solve(jnp.asarray(psis), jnp.asarray(seeds))
    assert vhcjax.result_names(fps.result) == ["successful"] * len(psis)
    assert float(jnp.max(fps.residual)) < 1e-10
    return np.asarray(psis), np.asarray(fps.z), fams


@pytest.fixture(scope="module")
def mults(gaits):
    psis, zs, _ = gaits
    return S.family_multipliers(CompassGait(), jnp.asarray(psis), jnp.asarray(zs))


def test_families_are_distinct_and_classified(gaits, mults):
    psis, zs, fams = gaits
    assert vhcjax.result_names(mults.result) == ["successful"] * len(psis)
    stable = np.asarray(mults.stable)
    for i, fam in enumerate(fams):
        deg = math.degrees(psis[i])
        # The "stable" family is stable below the flip (about 4.4 deg), the other never.
        assert stable[i] == (fam == "stable" and deg < 4.0)
    assert np.min(np.abs(zs[:3] - zs[3:])) > 1e-3


def test_transverse_equals_poincare_all_slopes_both_families(mults):
    """Two independent computations of the three multipliers agree to 1e-6."""
    tr = np.asarray(mults.transverse)
    pc = np.asarray(mults.poincare)
    assert tr.shape == pc.shape == (6, 3)
    for a, b in zip(tr, pc):
        # match eigenvalues as sets (sorting by modulus can swap a conjugate pair)
        for ev in a:
            assert np.min(np.abs(b - ev)) < 1e-6
    # ... and the checks of the transverse linearization hold for the default model
    # (it is flagged only where its assumptions fail)
    assert vhcjax.result_names(mults.transverse_result) == ["successful"] * 6
    assert np.all(np.asarray(mults.disagreement) < S.AGREEMENT_RTOL)
    assert np.all(np.asarray(mults.condition) < S.MAX_CONDITION)


def test_poincare_jacobian_equals_central_differences(gaits, mults):
    """Multipliers from central finite differences of the step map (no autodiff)."""
    psis, zs, _ = gaits
    model = CompassGait()
    for i in (1, 4):  # 3 degrees, both families (one compile, two evaluations)
        m = model.with_slope(psis[i])
        Jfd = S.finite_difference_jacobian(m, jnp.asarray(zs[i]), 1, 1e-5, vhcjax.DEFAULT_CONFIG)
        ev = np.linalg.eigvals(np.asarray(Jfd))
        for lam in np.asarray(mults.transverse[i]):
            assert np.min(np.abs(ev - lam)) < 1e-6


def test_orbit_rebuilt_from_vhc_matches_hybrid_simulation(mults):
    """The joint (6.10)+(5.19) integration ends where the hybrid simulator's heel strike
    is, at the same time; dF (6.23) by jacfwd equals central differences of the thesis
    closed-form impact (3.17)."""
    for i in (1, 4):
        tl = jax.tree_util.tree_map(lambda a: a[i], mults.linearization)
        assert abs(float(tl.period - mults.period[i])) < 1e-9
        np.testing.assert_allclose(tl.x_minus, mults.x_minus[i], atol=1e-8)
    m = CompassGait().with_slope(math.radians(SLOPES_DEG[1]))
    xm = np.asarray(tl.x_minus)
    h = 1e-6
    fd = np.stack(
        [
            (m.impact_momentum(xm + h * e) - m.impact_momentum(xm - h * e)) / (2 * h)
            for e in np.eye(4)
        ],
        axis=1,
    )
    np.testing.assert_allclose(tl.dF, fd, atol=1e-7)


@eqx.filter_jit
def _dense(m, x0, ts):
    import diffrax

    from vhcjax.hybrid._simulate import flow

    return flow(m, x0, ts[-1], vhcjax.DEFAULT_CONFIG, saveat=diffrax.SaveAt(ts=ts), event=False).ys


def _orbit_point(psi, z, T, frac=0.4):
    """A point on the gait (hybrid vector field, no event) and its phi data."""
    m = CompassGait().with_slope(psi)
    x0 = m.section_to_state(jnp.asarray(z))
    x = np.asarray(_dense(m, x0, jnp.asarray([0.0, frac * T]))[-1])
    theta, dtheta = x[0], x[2]
    phi, dphi = x[1:2], x[3:4] / dtheta
    return (
        m,
        m.energy(x0),
        jnp.asarray(theta),
        jnp.asarray(dtheta),
        jnp.asarray(phi),
        jnp.asarray(dphi),
        x,
    )


_system_matrix = eqx.filter_jit(TL.system_matrix)
_L = eqx.filter_jit(TL.L_matrix)
_m = eqx.filter_jit(TL.m_vector)
_gh = eqx.filter_jit(TL.g_h)
_ddphi = eqx.filter_jit(phi_second_derivative)
_coeffs = eqx.filter_jit(theta_dynamics_coefficients)


def test_pieces_on_the_orbit(gaits, mults):
    """g = h = 0 on the orbit (6.14); L m = 0; m is the vector field (6.31); thesis (6.11)
    with the corrected alpha0 equals the generic weights times det M."""
    psis, zs, _ = gaits
    m, E0, th, dth, phi, dphi, x = _orbit_point(psis[1], zs[1], float(mults.period[1]))
    ddphi = _ddphi(m, E0, th, phi, dphi)[0]
    g, h = _gh(m, th, dth, jnp.zeros(1), jnp.zeros(1), phi, dphi, ddphi)
    assert abs(float(g)) < 1e-12 and abs(float(h[0])) < 1e-9
    L = _L(m, E0, th, dth, phi, dphi)
    mv = _m(m, E0, th, dth, phi, dphi)
    np.testing.assert_allclose(L @ mv, 0.0, atol=1e-12)
    np.testing.assert_allclose(mv, m.vector_field(0.0, jnp.asarray(x)), atol=1e-8)
    # (6.11), alpha0 = p1 p3 - p2^2 cos^2(theta - phi) (the printed p2 cos^2 is a typo)
    p = m.parameters()
    c, s = jnp.cos(th - phi[0]), jnp.sin(th - phi[0])
    a0 = p["p1"] * p["p3"] - p["p2"] ** 2 * c**2
    b0 = p["p2"] * s * (p["p2"] * c - p["p3"] * dphi[0] ** 2)
    g0 = p["p2"] * p["p5"] * c * jnp.sin(phi[0]) - p["p3"] * p["p4"] * jnp.sin(th)
    one, beta0, gamma0 = _coeffs(m, th, phi, dphi)
    scale = a0  # our weights are (6.9) divided by det M = alpha0
    np.testing.assert_allclose([beta0 * scale, gamma0 * scale], [b0, g0], rtol=1e-12)


@eqx.filter_jit
def _transverse_rates(m, E0, th, dth, phi, dphi, zeta):
    """d/dt (I, y, ydot) of the FULL dynamics at the state with transverse coordinates
    `zeta` and phase `th` (no g, h, no jacfwd: plain accelerations)."""
    dI, y, dy = zeta
    a0, b0, c0 = theta_dynamics_coefficients(m, th, phi, dphi)
    ddth_star = -(b0 * dth**2 + c0) / a0
    ddphi = phi_second_derivative(m, E0, th, phi, dphi)[0]
    dth_p = -jnp.sqrt(dth**2 + dI)  # I = dtheta^2 - dtheta_star^2(theta)
    q = jnp.stack([th, phi[0] + y])
    dq = jnp.stack([dth_p, dphi[0] * dth_p + dy])
    ddq = m.acceleration(q, dq)
    # dI/dt = 2 dtheta ddtheta - (d/dtheta dtheta_star^2) dtheta, the latter 2 ddth_star
    rate_I = 2 * dth_p * (ddq[0] - ddth_star)
    rate_dy = ddq[1] - ddphi[0] * dth_p**2 - dphi[0] * ddq[0]
    return jnp.stack([rate_I, dy, rate_dy])


@pytest.mark.parametrize("index", [1, 4])
def test_A_equals_finite_differences_of_full_dynamics(gaits, mults, index):
    psis, zs, _ = gaits
    for frac in (0.1, 0.5, 0.9):
        m, E0, th, dth, phi, dphi, _ = _orbit_point(
            psis[index], zs[index], float(mults.period[index]), frac
        )
        A, parts = _system_matrix(m, E0, th, dth, phi, dphi)
        h = 1e-6
        cols = []
        for e in np.eye(3):
            e = jnp.asarray(e)
            cols.append(
                (
                    _transverse_rates(m, E0, th, dth, phi, dphi, h * e)
                    - _transverse_rates(m, E0, th, dth, phi, dphi, -h * e)
                )
                / (2 * h)
            )
        A_fd = np.stack(cols, axis=1)
        np.testing.assert_allclose(A, A_fd, atol=2e-6 * max(1.0, float(np.abs(A_fd).max())))
        # the directional derivative (6.18) equals d/d(dtheta) over 2 dtheta
        rates0 = _transverse_rates(m, E0, th, dth, phi, dphi, jnp.zeros(3))
        np.testing.assert_allclose(rates0, 0.0, atol=1e-9)


def test_poincare_only_gives_the_same_verdict(gaits, mults):
    """`transverse=False` computes the Poincare multipliers and the verdict only (the
    transverse fields are `None`, the code says they were not asked for)."""
    psis, zs, _ = gaits
    quick = S.family_multipliers(
        CompassGait(), jnp.asarray(psis), jnp.asarray(zs), transverse=False
    )
    assert quick.transverse is None and quick.linearization is None
    assert vhcjax.result_names(quick.transverse_result) == ["not_requested"] * 6
    assert vhcjax.result_names(quick.result) == ["successful"] * 6
    np.testing.assert_allclose(np.asarray(quick.poincare), np.asarray(mults.poincare), rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(quick.stable), np.asarray(mults.stable))
