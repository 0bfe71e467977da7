"""Generic autodiff mechanics against the thesis closed forms and against physics.

Oracles: the closed forms (3.8)-(3.10) and the momentum impact map (3.17) typed into
`benchmarks/scipy_reference.py` (numpy, no JAX), and conservation laws computed here from
hand-written kinematics of the three point masses.
"""

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
from vhcjax.mechanics import _lagrangian as mech

RNG = np.random.default_rng(20261123)
GAIT_X0 = np.array([0.2186688, -0.32338856, -1.09238359, -0.37737395])  # stable 3 deg gait


def random_params(n):
    """Random physical parameters (positive masses/lengths, slope in (0.5, 8) deg)."""
    return [
        dict(
            m1=RNG.uniform(1, 10),
            m2=RNG.uniform(1, 10),
            mH=RNG.uniform(1, 20),
            a=RNG.uniform(0.2, 1.0),
            b=RNG.uniform(0.2, 1.0),
            g=RNG.uniform(5, 15),
            psi=math.radians(RNG.uniform(0.5, 8.0)),
        )
        for _ in range(n)
    ]


def make_model_prm(prm):
    """A `CompassGait` with array leaves (one compilation for all parameter values)."""
    return vj.CompassGait(**{k: jnp.asarray(v, float) for k, v in prm.items()})


def random_states(n):
    q = RNG.uniform(-0.8, 0.8, size=(n, 2))
    dq = RNG.uniform(-3, 3, size=(n, 2))
    return np.concatenate([q, dq], axis=1)


# Hand-written kinematics (thesis 3.3): stance foot at the origin.
def masses(prm, q):
    """World positions of stance-leg mass, hip, swing-leg mass, and the swing foot."""
    a, b = prm["a"], prm["b"]
    l = a + b
    q1, q2 = q
    hip = np.array([-l * math.sin(q1), l * math.cos(q1)])
    return (
        np.array([-b * math.sin(q1), b * math.cos(q1)]),
        hip,
        hip + a * np.array([math.sin(q2), -math.cos(q2)]),
        hip + l * np.array([math.sin(q2), -math.cos(q2)]),
    )


def mass_velocities(prm, q, dq):
    a, b = prm["a"], prm["b"]
    l = a + b
    q1, q2 = q
    d1, d2 = dq
    vhip = np.array([-l * math.cos(q1) * d1, -l * math.sin(q1) * d1])
    return (
        np.array([-b * math.cos(q1) * d1, -b * math.sin(q1) * d1]),
        vhip,
        vhip + a * np.array([math.cos(q2) * d2, math.sin(q2) * d2]),
    )


def cross(r, v):
    return r[0] * v[1] - r[1] * v[0]


mass_matrix_j = eqx.filter_jit(lambda m, q: m.mass_matrix(q))
coriolis_j = eqx.filter_jit(lambda m, q, dq: m.coriolis_matrix(q, dq))
gravity_j = eqx.filter_jit(lambda m, q: m.gravity_vector(q))
mdot_minus_2c_j = eqx.filter_jit(
    lambda m, q, dq: jax.jvp(m.mass_matrix, (q,), (dq,))[1] - 2 * m.coriolis_matrix(q, dq)
)
acceleration_j = eqx.filter_jit(lambda m, q, dq: m.acceleration(q, dq))
impact_j = eqx.filter_jit(lambda m, x: m.impact(x))
impact_momentum_j = eqx.filter_jit(lambda m, x: m.impact_momentum(x))
augmented_j = eqx.filter_jit(lambda m, q, dq: mech.augmented_impact(m, q, dq))


def on_guard(prm, x):
    """Move a random state onto the heel-strike branch q2 = -q1 - 2 psi, swing leg ahead."""
    q1 = -abs(x[0]) - 0.05
    return np.array([q1, -q1 - 2 * prm.get("psi", math.radians(3.0)), x[2], x[3]])


@pytest.mark.parametrize("prm", random_params(4) + [{}])
def test_M_C_G_equal_thesis_closed_forms(prm):
    model = make_model_prm(prm)
    par = ref.Params(**prm)
    for x in random_states(5):
        q, dq = x[:2], x[2:]
        np.testing.assert_allclose(
            mass_matrix_j(model, jnp.asarray(q)),
            ref.M(par, q),
            rtol=0,
            atol=1e-12 * np.abs(ref.M(par, q)).max(),
        )
        scale = max(np.abs(ref.C(par, q, dq)).max(), 1.0)
        np.testing.assert_allclose(
            coriolis_j(model, jnp.asarray(q), jnp.asarray(dq)),
            ref.C(par, q, dq),
            rtol=0,
            atol=1e-12 * scale,
        )
        scale = max(np.abs(ref.G(par, q)).max(), 1.0)
        np.testing.assert_allclose(
            gravity_j(model, jnp.asarray(q)), ref.G(par, q), rtol=0, atol=1e-12 * scale
        )
        # Forward dynamics (via bias forces, without forming C) vs the closed-form ODE.
        acc = acceleration_j(model, jnp.asarray(q), jnp.asarray(dq))
        np.testing.assert_allclose(acc, ref.make_rhs(par)(0.0, x)[2:], rtol=1e-12, atol=1e-12)


def test_thesis_parameters_p1_to_p11():
    for prm in random_params(3):
        got = make_model_prm(prm).parameters()
        want = ref.Params(**prm).p()
        for k in range(1, 12):
            np.testing.assert_allclose(float(got[f"p{k}"]), want[k], rtol=1e-14)


def test_mdot_minus_2c_is_skew(model):
    for x in random_states(5):
        q, dq = jnp.asarray(x[:2]), jnp.asarray(x[2:])
        S = mdot_minus_2c_j(model, q, dq)
        np.testing.assert_allclose(S + S.T, 0.0, atol=1e-12)
        assert np.abs(S).max() > 1e-3  # non-trivial


@pytest.mark.parametrize("prm", random_params(3) + [{}])
def test_impact_maps_agree(prm):
    """Augmented impact (3.27) == angular-momentum impact (3.17, -p9 fix) == numpy reference."""
    model = make_model_prm(prm)
    par = ref.Params(**prm)
    for x in random_states(5):
        xm = on_guard(prm, x)
        x_plus, impulse, _ = impact_j(model, jnp.asarray(xm))
        x_mom = impact_momentum_j(model, jnp.asarray(xm))
        scale = np.abs(xm).max()
        np.testing.assert_allclose(x_plus, x_mom, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(x_plus, ref.impact(par, xm), rtol=0, atol=1e-12 * scale)


def test_printed_3_17_without_p9_is_wrong(model):
    """The printed (3.17) (no -p9) breaks the agreement: the check above can fail."""
    p = ref.Params().p()
    xm = on_guard({"psi": float(model.psi)}, random_states(1)[0])
    c = math.cos(xm[0] - xm[1])
    Qp = np.array([[p[8] - p[7] * c, -p[7] * c + p[6]], [p[8], -p[7] * c]])
    Qm = np.array([[p[10] * c, -p[11]], [-p[9], 0.0]])
    dqp = np.linalg.solve(Qp, Qm @ xm[2:])
    x_plus, _, _ = impact_j(model, jnp.asarray(xm))
    assert np.abs(np.asarray(x_plus)[2:] - dqp[::-1]).max() > 1e-3


@pytest.mark.parametrize("prm", random_params(3) + [{}])
def test_impact_conserves_angular_momenta_and_impulse_is_momentum_change(prm):
    """About the new stance foot, the whole biped's angular momentum is unchanged (3.13);
    about the hip, the new swing leg's is unchanged (3.16); and the returned contact
    impulse equals the change of linear momentum (the old stance foot lifts off freely)."""
    model = make_model_prm(prm)
    full = {"a": 0.5, "b": 0.5, "m1": 5.0, "m2": 5.0, "mH": 10.0, **prm}
    m1, m2, mH = full["m1"], full["m2"], full["mH"]
    for x in random_states(5):
        xm = on_guard(full, x)
        x_plus, impulse, _ = impact_j(model, jnp.asarray(xm))
        x_plus, impulse = np.asarray(x_plus), np.asarray(impulse)
        # Before: old labelling, old stance foot at the origin.
        r1, rH, r2, foot = masses(full, xm[:2])
        v1, vH, v2 = mass_velocities(full, xm[:2], xm[2:])
        # After: new labelling (new stance = old swing leg), new stance foot at origin.
        s1, sH, s2, _ = masses(full, x_plus[:2])
        w1, wH, w2 = mass_velocities(full, x_plus[:2], x_plus[2:])
        # Same bodies: old swing-leg mass (m2) is the new stance-leg mass (m1 slot), ...
        np.testing.assert_allclose(s1, r2 - foot, atol=1e-12)
        np.testing.assert_allclose(sH, rH - foot, atol=1e-12)
        np.testing.assert_allclose(s2, r1 - foot, atol=1e-12)
        # The legs swap, so new leg masses are (m2 -> stance slot, m1 -> swing slot).
        L_before = m1 * cross(r1 - foot, v1) + mH * cross(rH - foot, vH) + m2 * cross(r2 - foot, v2)
        L_after = m2 * cross(s1, w1) + mH * cross(sH, wH) + m1 * cross(s2, w2)
        scale = max(abs(L_before), 1.0)
        assert abs(L_after - L_before) < 1e-12 * scale
        # Old stance leg (new swing leg) about the hip, absolute velocities: the only
        # impulse on it acts at the hip (its foot lifts off freely).
        Ls_before = m1 * cross(r1 - rH, v1)
        Ls_after = m1 * cross(s2 - sH, w2)
        assert abs(Ls_after - Ls_before) < 1e-12 * max(abs(Ls_before), 1.0)
        dP = m2 * w1 + mH * wH + m1 * w2 - (m1 * v1 + mH * vH + m2 * v2)
        np.testing.assert_allclose(impulse, dP, rtol=0, atol=1e-11 * max(np.abs(dP).max(), 1))


def test_impulse_physical_on_the_gait(model):
    """At the stable gait's heel strike the impulse pushes the foot out of the slope and
    lies inside a plausible friction cone; a reversed-velocity 'impact' pulls."""
    sim = _sim.thesis_walk("7.5")
    xm = np.asarray(sim.steps.x_minus[-1])
    x_plus, impulse, physical = impact_j(model, jnp.asarray(xm))
    n = np.asarray(model.slope_normal)
    t = np.array([n[1], -n[0]])  # downhill tangent
    assert bool(physical) and impulse @ n > 0
    assert abs(impulse @ t) < impulse @ n  # friction coefficient < 1 suffices
    # The old stance foot lifts off (positive normal velocity just after impact).
    _, dz_plus, F = augmented_j(model, jnp.asarray(xm[:2]), jnp.asarray(xm[2:]))
    assert float(dz_plus @ model.slope_normal) > 0
    np.testing.assert_allclose(F, impulse, rtol=1e-14)
    xr = xm.copy()
    xr[2:] *= -1  # swing foot moving away from the ground: impulse would pull
    _, impulse_r, physical_r = impact_j(model, jnp.asarray(xr))
    assert not bool(physical_r) and np.asarray(impulse_r) @ n < 0


def test_augmented_impact_stops_the_impacting_foot(model):
    """E x+ = 0: after impact the impacting foot has zero velocity (3.26)."""
    for x in random_states(3):
        xm = on_guard({"psi": float(model.psi)}, x)
        q, dq = jnp.asarray(xm[:2]), jnp.asarray(xm[2:])
        dq_plus, dz_plus, _ = augmented_j(model, q, dq)
        foot_vel = jax.jvp(model.contact_point, (q,), (dq_plus,))[1] + dz_plus
        np.testing.assert_allclose(foot_vel, 0.0, atol=1e-12)


def test_energy_conserved_during_a_swing(model):
    """Energy (numpy closed form) along a dense swing trajectory, relative drift < 1e-10.

    Integrated at rtol = atol = 1e-12: the drift measures the integrator tolerance (at the
    default 1e-10 it is ~1e-10), the test checks that the vector field conserves energy."""
    import diffrax

    from vhcjax.hybrid._simulate import flow

    par = ref.Params()
    x0 = jnp.asarray(GAIT_X0)
    ts = jnp.linspace(0.0, 0.73, 60)
    tight = vj.SolverConfig(rtol=1e-12, atol=1e-12, max_steps=8192)
    sol = flow(model, x0, 0.73, tight, saveat=diffrax.SaveAt(ts=ts), event=False)
    E = np.array([ref.energy(par, x) for x in np.asarray(sol.ys)])
    rel = np.abs(E - E[0]).max() / np.abs(E[0])
    assert rel < 1e-10, rel
    # The library's own energy agrees with the numpy one.
    np.testing.assert_allclose(float(model.energy(x0)), E[0], rtol=1e-13)
