"""Generic multi-domain machinery: locked-joint dynamics and impacts (no ODE solves)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax
from vhcjax.hybrid._multidomain import augmented_impact_locked, lock_impact, locked_acceleration
from vhcjax.mechanics import _lagrangian as mech
from vhcjax.models._kneed_walker import _KNEE, KneedWalker

T = jnp.array([[1.0, 0.0], [0.0, 1.0], [0.0, 1.0]])  # locked knee: q = T (q1, q2)


@pytest.fixture(scope="module")
def kw():
    return KneedWalker()


def _random_states(seed, n=8):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-0.4, 0.4, (n, 3))
    dq = rng.uniform(-2.0, 2.0, (n, 3))
    return jnp.asarray(q), jnp.asarray(dq)


class _Reduced(vhcjax.WalkerModel):
    """The kneed walker with its knee locked, as an independent 2-DOF Lagrangian."""

    full: KneedWalker
    n_dof = 2

    def kinetic_energy(self, q, dq, base_velocity=None):
        return self.full.kinetic_energy(T @ q, T @ dq, base_velocity)

    def potential_energy(self, q):
        return self.full.potential_energy(T @ q)

    def contact_point(self, q):
        return self.full.contact_point(T @ q)

    guard = relabel = fallen = section_to_state = state_to_section = None
    slope_normal = time_scale = None


def test_locked_mass_matrix_matches_literature_closed_form(kw):
    # Two-link (knee locked) inertia matrix of the McGeer / Hsu Chen kneed walker.
    q, _ = _random_states(0)
    ms, mt, mh, a1, b1, a2, b2 = kw.ms, kw.mt, kw.mh, kw.a1, kw.b1, kw.a2, kw.b2
    ls, lt, L = kw.ls, kw.lt, kw.L

    @jax.jit
    @jax.vmap
    def both(qi):
        qr = qi[:2]
        H11 = ms * a1**2 + mt * (ls + a2) ** 2 + (mh + ms + mt) * L**2
        H12 = -(mt * b2 + ms * (lt + b1)) * L * jnp.cos(qr[1] - qr[0])
        H22 = mt * b2**2 + ms * (lt + b1) ** 2
        H = jnp.stack([jnp.stack([H11, H12]), jnp.stack([H12, H22])])
        return T.T @ mech.mass_matrix(kw, T @ qr) @ T, H

    A, B = both(q)
    np.testing.assert_allclose(A, B, rtol=1e-13, atol=1e-13)


def test_locked_acceleration_equals_reduced_lagrangian(kw):
    red = _Reduced(kw)
    q, dq = _random_states(1)

    @jax.jit
    @jax.vmap
    def both(qi, dqi):
        qr, dqr = qi[:2], dqi[:2]
        ddq, _ = locked_acceleration(kw, T @ qr, T @ dqr, _KNEE)
        return ddq, T @ mech.acceleration(red, qr, dqr)

    a, b = both(q, dq)
    np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(a[:, 1], a[:, 2], atol=1e-12)


ALL = ["stance_shank", "stance_thigh", "hip", "swing_thigh", "swing_shank"]


def test_knee_strike_conserves_angular_momenta(kw):
    q, dq = _random_states(2)

    @jax.jit
    @jax.vmap
    def one(qi, dqi):
        qi = qi.at[2].set(qi[1])  # at knee strike thigh and shank are aligned
        dqp, _ = lock_impact(kw, qi, dqi, _KNEE)
        hip = kw.points(qi)["hip"]
        out = []
        # whole walker about the stance foot; swing leg (thigh + shank) about the hip
        for about, names in [(jnp.zeros(2), ALL), (hip, ["swing_thigh", "swing_shank"])]:
            out.append(kw._momentum(qi, dqi, about, names, None))
            out.append(kw._momentum(qi, dqp, about, names, None))
        dK = kw.kinetic_energy(qi, dqp) - kw.kinetic_energy(qi, dqi)
        return jnp.stack(out), dqp[1] - dqp[2], dK

    L, lock, dK = one(q, dq)
    np.testing.assert_allclose(L[:, 1], L[:, 0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(L[:, 3], L[:, 2], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lock, 0.0, atol=1e-13)
    assert np.all(dK <= 1e-12)  # a plastic impact loses kinetic energy


def test_heel_strike_conserves_angular_momenta(kw):
    q, dq = _random_states(3)

    @jax.jit
    @jax.vmap
    def one(qi, dqi):
        q2 = -qi[0] - 2 * kw.psi
        qi = jnp.stack([qi[0], q2, q2])
        dqi = dqi.at[2].set(dqi[1])  # both knees locked at heel strike
        dqp, dzp, _ = augmented_impact_locked(kw, qi, dqi, _KNEE)
        foot = kw.contact_point(qi)
        hip = kw.points(qi)["hip"]
        out = []
        # whole walker about the impacting foot; old stance leg about the hip
        for about, names in [(foot, ALL), (hip, ["stance_shank", "stance_thigh"])]:
            out.append(kw._momentum(qi, dqi, about, names, None))
            out.append(kw._momentum(qi, dqp, about, names, dzp))
        vfoot = jax.jvp(kw.contact_point, (qi,), (dqp,))[1] + dzp
        return jnp.stack(out), dqp[1] - dqp[2], vfoot

    L, lock, vfoot = one(q, dq)
    np.testing.assert_allclose(L[:, 1], L[:, 0], rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(L[:, 3], L[:, 2], rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(lock, 0.0, atol=1e-13)
    np.testing.assert_allclose(vfoot, 0.0, atol=1e-13)  # the impacting foot stops


def test_heel_strike_without_locks_is_the_augmented_impact():
    cg = vhcjax.CompassGait()
    q = jnp.array([-0.2, 0.2 - 2 * cg.psi])
    dq = jnp.array([-1.2, 0.3])
    a = jax.jit(lambda: augmented_impact_locked(cg, q, dq, jnp.zeros((0, 2))))()
    b = jax.jit(lambda: mech.augmented_impact(cg, q, dq))()
    for u, v in zip(a, b):
        np.testing.assert_allclose(u, v, rtol=1e-13, atol=1e-14)


def test_multidomain_model_has_no_single_vector_field(kw):
    with pytest.raises(NotImplementedError):
        kw.vector_field(0.0, jnp.zeros(6))


def test_multidomain_step_refuses_a_single_vector_field(kw):
    """One field for every domain would be silently wrong: refused before any step."""
    with pytest.raises(ValueError, match="one vector field per domain"):
        kw.hybrid_step(jnp.zeros(6), vector_field=lambda t, x, args: jnp.zeros_like(x))


_TRACES = [0]


class _CountedKneed(KneedWalker):
    """The kneed walker, counting how often its Python code runs (once per trace)."""

    def potential_energy(self, q):
        _TRACES[0] += 1
        return super().potential_energy(q)


def test_multidomain_trajectory_follows_the_cycle_and_traces_once():
    """The dense trajectory of each domain runs from the state entering it to the state
    at its reset, over its duration (the cycle's events); a second call with another
    slope and state runs the same program."""
    m = _CountedKneed(psi=jnp.asarray(0.0504))
    x0 = m.section_to_state(m.reference_gait()[1])
    ts, xs, info = vhcjax.multidomain_trajectory(m, x0, 9)
    assert ts.shape == (2, 9) and xs.shape == (2, 9, 6)
    np.testing.assert_allclose(ts[:, -1], info.duration, rtol=1e-12)
    np.testing.assert_allclose(xs[:, 0], info.x_start, atol=1e-12)
    np.testing.assert_allclose(xs[:, -1], info.x_end, atol=1e-8)
    before = _TRACES[0]
    vhcjax.multidomain_trajectory(_CountedKneed(psi=0.05), x0 + 1e-4, 9)
    assert _TRACES[0] == before
