"""Orbital stabilization (control layer): every figure checked two independent ways.

- The input: $M\\ddot q + C\\dot q + G = Bu$ against the mechanics functions.
- Open-loop multipliers of the transverse linearization with input against the
  autodiff Poincare map (the thesis linearization is checked elsewhere against both).
- The periodic Riccati solution by backward iteration against the Hamiltonian monodromy.
- Closed-loop multipliers: transverse monodromy against the autodiff Poincare map, and
  that against central differences of the closed-loop step map.
- Simulation: recovery from perturbations, zero torque on the orbit, saturation, basins.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj

# Gaits (post-impact section coordinates z = (q1, dq1, dq2)) as Newton seeds: the
# unstable family at three slopes and the symmetric period-1 gait at 5 degrees (past its
# period doubling, unstable through a flip).
CASES = {
    "unstable-2.5": (2.5, (0.19816763, -1.15329139, -0.74075966)),
    "unstable-3": (3.0, (0.20467554, -1.21057184, -0.71248882)),
    "unstable-3.5": (3.5, (0.20937783, -1.25976171, -0.67825628)),
    "symmetric-5": (5.0, (0.23535538, -1.16893398, -0.04794253)),
}


@pytest.fixture(scope="module")
def gaits():
    out = {}
    for name, (deg, seed) in CASES.items():
        m = vj.CompassGait(psi=math.radians(deg))
        fp = vj.fixed_point(m, jnp.asarray(seed))
        assert fp.result == vj.RESULTS.successful
        out[name] = (m, fp.z)
    return out


@pytest.fixture(scope="module")
def stabilized(gaits):
    return {name: vj.stabilize(m, z) for name, (m, z) in gaits.items()}


def test_stabilize_needs_a_gait_and_a_valid_model(gaits, stabilized):
    """A point that is not on a gait is `orbit_not_closed` (its orbit does not close), an
    invalid model `bad_input`; the real gait `successful` (closure ~1e-13)."""
    m, z = gaits["unstable-3"]
    assert stabilized["unstable-3"].result == vj.RESULTS.successful
    assert float(stabilized["unstable-3"].system.closure) < 1e-9
    assert vj.stabilize(m, z + 0.05).result == vj.RESULTS.orbit_not_closed
    bad = vj.CompassGait(mH=-10.0, psi=math.radians(3.0))
    assert vj.stabilize(bad, z).result == vj.RESULTS.bad_input
    with pytest.raises(ValueError, match="nonnegative definite"):
        vj.stabilize(m, z, Q=jnp.array([-1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="positive definite"):
        vj.stabilize(m, z, R=jnp.array([0.0]))
    with pytest.raises(ValueError, match=r"\(3, 3\) matrix"):
        vj.stabilize(m, z, Q=jnp.ones(2))


def test_stabilization_is_a_stored_program(gaits, stabilized, monkeypatch):
    """`stabilize` holds no host callback: a later process loads its program (here: the
    stored file, read again) and gets the same feedback."""
    from vhcjax import _programs

    if _programs.program_directory() is None:
        pytest.skip("stored programs are off")
    counts = {"exported": 0, "loaded": 0, "unexportable": 0}
    monkeypatch.setattr(_programs, "stats", counts)
    monkeypatch.setattr(_programs, "_memo", {})
    m, z = gaits["unstable-3"]
    again = vj.stabilize(m, z)
    assert counts["unexportable"] == 0 and counts["loaded"] + counts["exported"] == 1
    np.testing.assert_array_equal(
        np.asarray(again.riccati.K), np.asarray(stabilized["unstable-3"].riccati.K)
    )


def test_input_enters_the_equations_of_motion(model):
    q = jnp.array([0.2, -0.3])
    dq = jnp.array([-1.1, 0.4])
    u = jnp.array([2.5])
    B = vj.input_matrix(model, q)
    np.testing.assert_array_equal(np.asarray(B), [[-1.0], [1.0]])

    @jax.jit
    def residual(model, q, dq, u):
        ddq = vj.actuated_vector_field(model, jnp.concatenate([q, dq]), u)[2:]
        return (
            vj.mass_matrix(model, q) @ ddq
            + vj.coriolis_matrix(model, q, dq) @ dq
            + vj.gravity_vector(model, q)
        )

    lhs = residual(model, q, dq, u)
    np.testing.assert_allclose(np.asarray(lhs), np.asarray(B @ u), atol=1e-12)
    # The hip torque does power u (dq2 - dq1): equal and opposite on the two legs.
    assert float(dq @ (B @ u)) == pytest.approx(2.5 * (0.4 + 1.1))


def test_multidomain_push_is_refused():
    with pytest.raises(NotImplementedError):
        vj.closed_loop_push_step(
            vj.KneedWalker(), jnp.zeros(6), vj.ZeroFeedback(2), 0.1, jnp.zeros(2)
        )


@pytest.mark.parametrize("name", list(CASES))
def test_open_loop_is_unstable_and_matches_the_poincare_map(gaits, stabilized, name):
    m, z = gaits[name]
    st = stabilized[name]
    assert st.result == vj.RESULTS.successful
    assert float(st.system.closure) < 1e-9  # the tabulated orbit closes through the impact
    poincare = np.asarray(vj.closed_loop_multipliers(m, vj.ZeroFeedback(), z))
    np.testing.assert_allclose(np.asarray(st.open_loop_multipliers), poincare, atol=1e-6)
    assert np.max(np.abs(poincare)) > 1.0
    if name == "symmetric-5":  # unstable through a flip
        assert np.real(poincare[0]) < -1.0 and abs(np.imag(poincare[0])) < 1e-12


@pytest.mark.parametrize("name", list(CASES))
def test_riccati_two_ways(stabilized, name):
    st = stabilized[name]
    X1, X2 = np.asarray(st.riccati.X), np.asarray(st.riccati_check.X)
    assert st.riccati.result == vj.RESULTS.successful
    assert st.riccati_check.result == vj.RESULTS.successful
    assert float(st.riccati.residual) < 1e-12
    assert np.max(np.abs(X1 - X2)) / np.max(np.abs(X1)) < 1e-8
    assert float(st.riccati_agreement) < 1e-8
    # Periodicity with the jump, and positive definiteness along the whole step.
    J, Q = np.asarray(st.system.J), np.eye(3)
    np.testing.assert_allclose(X1[-1], J.T @ X1[0] @ J + Q, rtol=1e-10, atol=1e-8)
    assert np.min(np.linalg.eigvalsh(X1)) > 0
    np.testing.assert_allclose(
        np.asarray(st.riccati.K),
        np.asarray(st.riccati_check.K),
        rtol=0,
        atol=1e-8 * np.max(np.abs(np.asarray(st.riccati.K))),
    )


@pytest.mark.parametrize("name", list(CASES))
def test_closed_loop_multipliers_two_ways(stabilized, name):
    st = stabilized[name]
    a = np.asarray(st.closed_loop_multipliers)
    b = np.asarray(st.closed_loop_multipliers_transverse)
    np.testing.assert_allclose(a, b, atol=1e-6)
    # The stable eigenvalues of the Hamiltonian monodromy are the same multipliers.
    np.testing.assert_allclose(np.asarray(st.riccati_check.eigenvalues), b, atol=1e-6)
    assert np.max(np.abs(a)) < 1.0 < np.max(np.abs(np.asarray(st.open_loop_multipliers)))


def test_closed_loop_jacobian_against_central_differences(gaits, stabilized):
    m, z = gaits["unstable-3"]
    fb = stabilized["unstable-3"].feedback
    J = np.asarray(stabilized["unstable-3"].closed_loop_jacobian)
    h = 1e-5
    dz = jnp.concatenate([h * jnp.eye(3), -h * jnp.eye(3)])
    zs = jax.jit(jax.vmap(lambda d: vj.closed_loop_step_map(m, fb, z + d, vj.TIGHT_CONFIG)[0]))(dz)
    fd = np.asarray((zs[:3] - zs[3:]) / (2 * h)).T
    np.testing.assert_allclose(J, fd, atol=1e-6 * max(1.0, np.max(np.abs(J))))


def _errors(m, z, sim):
    zs = np.asarray(jax.vmap(m.state_to_section)(sim.steps.x_plus))
    return np.max(np.abs(zs - np.asarray(z)), axis=1)


@pytest.mark.parametrize("d", [1e-3, 1e-2])
def test_recovery_closed_loop_but_not_passive(gaits, stabilized, d):
    m, z = gaits["unstable-3"]
    x0 = m.section_to_state(z + d)
    closed = vj.simulate_closed_loop(m, x0, stabilized["unstable-3"].feedback, 30)
    assert closed.result == vj.RESULTS.successful
    err = _errors(m, z, closed)
    assert err[-1] < 1e-8 and err[-5:].max() < 1e-8
    passive = vj.simulate_closed_loop(m, x0, vj.ZeroFeedback(), 30)
    assert _errors(m, z, passive).max() > 1e-2  # the passive walker leaves the gait
    assert np.all(np.asarray(passive.max_abs_torque) == 0.0)
    # Torque: largest on the first step, decaying with the error.
    tmax = np.asarray(closed.max_abs_torque)
    assert 0 < tmax[0] and tmax[-1] < 1e-6 * tmax[0]


def test_torque_is_zero_on_the_orbit(gaits, stabilized):
    m, z = gaits["unstable-3"]
    fb = stabilized["unstable-3"].feedback
    sysm = stabilized["unstable-3"].system
    nodes = jnp.concatenate(
        [(sysm.theta_plus + sysm.s * (sysm.theta_minus - sysm.theta_plus))[:, None], sysm.w], axis=1
    )
    u_nodes = np.asarray(jax.vmap(lambda x: fb(x, m))(nodes))
    assert np.max(np.abs(u_nodes)) < 1e-12  # rounding
    # Along the orbit of the passive hybrid simulator (its own integration, 1e-12).
    _, u = vj.step_torque(m, m.section_to_state(z), sysm.period, fb, 64, vj.TIGHT_CONFIG)
    assert np.max(np.abs(np.asarray(u))) < 1e-6


def test_saturated_feedback_converges_and_respects_the_limit(gaits, stabilized):
    m, z = gaits["unstable-3"]
    x0 = m.section_to_state(z + 1e-2)  # unsaturated, the first step needs 0.87 N m
    fb = vj.with_torque_limit(stabilized["unstable-3"].feedback, 0.5)
    sim = vj.simulate_closed_loop(m, x0, fb, 30)
    assert sim.result == vj.RESULTS.successful
    assert _errors(m, z, sim)[-1] < 1e-8
    tmax = np.asarray(sim.max_abs_torque)
    assert tmax[0] == pytest.approx(0.5)  # saturated at first
    assert np.all(tmax <= 0.5 + 1e-12)
    # Below some limit the same perturbation is lost (the walker settles elsewhere).
    low = vj.simulate_closed_loop(m, x0, vj.with_torque_limit(fb, 0.3), 30)
    assert _errors(m, z, low)[-1] > 1e-3


def test_basin_grows_with_the_torque_limit(gaits, stabilized):
    m, z = gaits["unstable-3"]
    fb = stabilized["unstable-3"].feedback
    kw = {
        "half_widths": (0.05, 0.3),
        "shape": (9, 9),
        "num_steps": 25,
        "torque_points": 8,
        "config": vj.FAST_CONFIG,
    }
    fractions = []
    for lim in (0.0, 0.5, 2.0, 8.0):
        b = vj.closed_loop_basin(m, vj.with_torque_limit(fb, lim), z, **kw)
        fractions.append(float(b.fraction))
        assert np.all(np.where(b.converged, np.asarray(b.max_abs_torque), 0) <= lim + 1e-12)
    passive = vj.closed_loop_basin(m, vj.ZeroFeedback(), z, **kw)
    assert float(passive.fraction) == fractions[0] == 0.0  # an unstable gait attracts nothing
    assert fractions == sorted(fractions) and fractions[-1] > 0.5


def test_push_step_without_feedback_is_the_passive_impulse_step(gaits, stabilized):
    m, z = gaits["unstable-3"]
    x0 = m.section_to_state(z)
    t = 0.3 * float(stabilized["unstable-3"].system.period)
    imp = jnp.array([1.0, 0.5])
    # A zero torque limit makes the law passive while keeping its pytree (one compile).
    off = vj.with_torque_limit(stabilized["unstable-3"].feedback, 0.0)
    a = vj.closed_loop_push_step(m, off, x0, t, imp)
    b = vj.impulse_step(m, x0, t, imp)
    assert a.result == b.result == vj.RESULTS.successful
    np.testing.assert_allclose(np.asarray(a.x_plus), np.asarray(b.x_plus), atol=1e-9)


@pytest.mark.slow
def test_pushes_survived_with_and_without_feedback(gaits, stabilized):
    m, z = gaits["unstable-3"]
    st = stabilized["unstable-3"]
    x0, T = m.section_to_state(z), float(st.system.period)
    kw = {"p_max": 10.0, "iterations": 6, "num_steps": 25}
    grid = ([0.2, 0.6], [0.0, math.pi])
    closed = np.asarray(vj.closed_loop_max_push(m, st.feedback, x0, T, *grid, **kw))
    off = vj.with_torque_limit(st.feedback, 0.0)  # passive, same compiled program
    passive = np.asarray(vj.closed_loop_max_push(m, off, x0, T, *grid, **kw))
    assert np.all(passive == 0.0)  # the passive walker never returns to an unstable gait
    assert np.all(closed > 1.0)
    # The bisection's answer against a direct run: just below survives.
    p = 0.9 * closed[0, 0]
    sr = vj.closed_loop_push_step(m, st.feedback, x0, 0.2 * T, jnp.array([p, 0.0]))
    sim = vj.simulate_closed_loop(m, sr.x_plus, st.feedback, 30)
    assert _errors(m, z, sim)[-1] < 1e-4


def test_control_layer_under_jit_vmap_and_jacfwd(gaits, stabilized):
    """The control layer's numeric functions compose like JAX's: `jit` gives the plain
    call's numbers, `vmap` each member's, `jacfwd` the central differences."""
    m, z = gaits["unstable-3"]
    st = stabilized["unstable-3"]
    x_minus = st.system.x_minus
    J, x_plus = vj.jump_matrix(m, x_minus)
    np.testing.assert_allclose(jax.jit(vj.jump_matrix)(m, x_minus)[0], J, rtol=0, atol=1e-13)

    def jump(psi):  # the jump matrix at a fixed pre-impact state, against the slope
        return vj.jump_matrix(vj.CompassGait(psi=psi), x_minus)[0]

    psi, h = m.psi, 1e-6
    fd = (jump(psi + h) - jump(psi - h)) / (2 * h)
    np.testing.assert_allclose(jax.jacfwd(jump)(psi), fd, rtol=0, atol=1e-7)

    qs = jnp.stack([x_plus[:2], x_minus[:2]])
    B = jax.vmap(lambda q: vj.input_matrix(m, q))(qs)
    np.testing.assert_array_equal(B[1], vj.input_matrix(m, qs[1]))
    for a, b in zip(jax.jit(vj.default_weights)(m), vj.default_weights(m), strict=True):
        np.testing.assert_array_equal(a, b)

    # The feedback law off the orbit: its state derivative, and the torque limit as a
    # leaf that vmap batches (one program for every limit).
    fb = st.feedback
    x = m.section_to_state(z + 1e-2)
    dx = jnp.eye(4) * 1e-6
    fd = jnp.stack([(fb(x + d, m) - fb(x - d, m)) / 2e-6 for d in dx], axis=-1)
    np.testing.assert_allclose(jax.jacfwd(lambda x: fb(x, m))(x), fd, rtol=0, atol=1e-6)
    limits = jnp.array([0.3, 0.5, jnp.inf])
    u = jax.vmap(lambda lim: vj.with_torque_limit(fb, lim)(x, m))(limits)
    for lim, ui in zip(limits, u, strict=True):
        np.testing.assert_array_equal(ui, vj.with_torque_limit(fb, lim)(x, m))
    assert abs(float(u[0, 0])) == pytest.approx(0.3) and abs(float(u[2, 0])) > 0.5


def test_closed_loop_simulation_and_multipliers_under_grad(gaits, stabilized):
    """Reverse mode through the closed-loop heel strikes (a forward-mode Jacobian,
    transposed): `jax.grad` equals central differences in the slope, the feedback law
    and the gait held fixed."""
    m, z = gaits["unstable-3"]
    fb = stabilized["unstable-3"].feedback
    x0 = m.section_to_state(z + 1e-2)

    def walked(psi):
        return vj.simulate_closed_loop(vj.CompassGait(psi=psi), x0, fb, 2).steps.x_plus[-1, 2]

    def radius(psi):
        return jnp.abs(vj.closed_loop_multipliers(vj.CompassGait(psi=psi), fb, z)[0])

    h = 1e-4  # measured: central differences agree to 5e-6 (at 1e-6 the solver's noise, 2e-4)
    for f in (walked, radius):
        reverse = float(jax.grad(f)(m.psi))
        fd = (float(f(m.psi + h)) - float(f(m.psi - h))) / (2 * h)
        np.testing.assert_allclose(reverse, fd, rtol=2e-5)


def test_riccati_solutions_under_grad_two_ways(gaits):
    """Reverse mode through the gait, the transverse linearization and both Riccati
    methods, in the hip mass: the periodic solution of the iteration and the stable
    subspace of the Hamiltonian monodromy get their derivatives from the implicit
    function theorem; the two methods' derivatives agree, and equal central
    differences, as does that of the closed-loop multiplier."""
    m, z = gaits["unstable-3"]
    n = 101

    def solved(mH):
        mm = vj.CompassGait(psi=m.psi, mH=mH)
        x = mm.section_to_state(vj.fixed_point(mm, z).z)
        system = vj.transverse_system(mm, x, num_points=n)
        ham = vj.riccati_hamiltonian(mm, system)
        out = [
            r.X[0, 0, 0] + r.X[n // 2, 1, 2] + r.K[10, 0, 1]
            for r in (vj.riccati_backward(mm, system), ham)
        ]
        return jnp.stack([*out, jnp.abs(ham.eigenvalues[0])])

    J = jax.jacrev(solved)(m.mH)
    h = 1e-4 * m.mH
    fd = (solved(m.mH + h) - solved(m.mH - h)) / (2 * h)
    np.testing.assert_allclose(J[0], J[1], rtol=1e-9)
    np.testing.assert_allclose(J, fd, rtol=1e-6)


def test_stabilize_under_grad_equals_central_differences(gaits):
    """Reverse mode through all of `stabilize` in the control weight R: the transverse
    linearization, the periodic Riccati solution (implicit function theorem), the gains
    and the closed-loop step map. The Riccati solution and both closed-loop spectral
    radii (Poincare-map Jacobian, transverse monodromy) against central differences."""
    m, z = gaits["unstable-3"]

    def outputs(r):
        st = vj.stabilize(m, z, R=jnp.array([r]))
        return jnp.stack(
            [
                st.riccati.X[0, 0, 0],
                jnp.max(jnp.abs(st.closed_loop_multipliers)),
                jnp.max(jnp.abs(st.closed_loop_multipliers_transverse)),
            ]
        )

    J = np.asarray(jax.jacrev(outputs)(1.0))
    h = 1e-3
    fd = (np.asarray(outputs(1.0 + h)) - np.asarray(outputs(1.0 - h))) / (2 * h)
    # measured: 4e-5 for the Poincare radius and 5e-6 for the transverse one, whose values
    # carry the solvers' noise (about 1e-9 and 3e-10, divided by h here); 4e-9 for X
    for j, f, rtol in zip(J, fd, (1e-7, 1e-4, 3e-5), strict=True):
        np.testing.assert_allclose(j, f, rtol=rtol)
    assert np.all(np.abs(J) > 1e-3)  # each derivative is there to compare
