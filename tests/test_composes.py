"""vhcjax composes like a JAX library, for a user's own model (`_user_model.RodWalker`):
a second call with the same shapes traces nothing (`CALLS`); the gait search, its
multipliers and spectral radius work under `jax.jit`, `jax.vmap`, `jax.jacfwd` and
`jax.grad`, with derivatives equal to central differences; the host-side studies refuse
a trace in one line that names the traceable function to use."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _user_model import TRACES, RodWalker

import vhcjax as vj

Z0 = jnp.array([0.2, -1.0, -0.2])  # a Newton guess for the rod walker's gait at 0.03 rad


def _gait_z(psi=0.03):
    fp = vj.fixed_point(RodWalker(psi=jnp.asarray(psi)), Z0)
    assert vj.result_names(fp.result) == "successful"
    return fp.z


CALLS = {
    "step": lambda m, z: vj.step(m, m.section_to_state(z), throw=False).x_plus,
    "simulate": lambda m, z: vj.simulate(m, m.section_to_state(z), 3).steps.x_plus,
    "step_map": lambda m, z: vj.step_map(m, z).z_next,
    "fixed_point": lambda m, z: vj.fixed_point(m, z).z,
    "poincare_jacobian": lambda m, z: vj.poincare_jacobian(m, z),
    "poincare_multipliers": lambda m, z: vj.poincare_multipliers(m, z),
    "gait_multipliers": lambda m, z: vj.gait_multipliers(m, z).poincare,
    "gait_spectrum": lambda m, z: vj.gait_spectrum(m, vj.find_gait(m, guess=z)).spectral_radius,
    "simulate_dense": lambda m, z: vj.simulate(m, m.section_to_state(z), 2, dense_points=9).dense_x,
    "transverse_linearization": lambda m, z: _transverse(m, z),
    "vhc_orbit": lambda m, z: vj.vhc_orbit(m, z).z_next,
    "vhc_gait_search": lambda m, z: vj.vhc_gait_search(m, z).z,
}


def _transverse(m, z):
    sr = vj.step(m, m.section_to_state(z))
    period = float(sr.period)  # a Python number: another value runs the same program
    return vj.transverse_linearization(m, sr.x_plus, sr.x_minus, period).multipliers


@pytest.mark.parametrize("name", sorted(CALLS))
def test_a_second_call_traces_nothing(name):
    """A second call with the same shapes, other values (slope, state), runs the
    program of the first: the model's Python code does not run again. The first slope
    is a weakly typed array (`jnp.asarray(0.03)`), the second a Python float."""
    z = _gait_z()
    CALLS[name](RodWalker(psi=jnp.asarray(0.03)), z)
    before = TRACES[0]
    CALLS[name](RodWalker(psi=0.031), z + 1e-4)
    assert TRACES[0] == before


class _ActuatedRod(RodWalker):
    """The rod walker with a hip torque (as `CompassGait.input_matrix`)."""

    def input_matrix(self, q):
        return jnp.array([[-1.0], [1.0]])


def test_the_control_layer_traces_once():
    """Stabilizing a user's gait: a second call of the transverse linearization, both
    Riccati methods, the closed-loop multipliers, the torque along a step and the jump
    matrix traces nothing; the closed-loop multipliers of the transverse monodromy are
    those of the Hamiltonian's subspace."""

    def stabilized(psi, z):
        m = _ActuatedRod(psi=psi)
        system = vj.transverse_system(m, m.section_to_state(z), num_points=101)
        ric = vj.riccati_backward(m, system)
        ham = vj.riccati_hamiltonian(m, system)
        fb = vj.transverse_feedback(system, ric)
        ts, u = vj.step_torque(m, m.section_to_state(z) + 1e-3, 0.5, fb)
        assert np.all(np.isfinite(np.asarray(u)))
        J, _ = vj.jump_matrix(m, vj.step(m, m.section_to_state(z)).x_minus)
        assert J.shape == (3, 3) and np.all(np.isfinite(np.asarray(J)))
        return vj.closed_loop_multipliers_transverse(m, system, fb), ham.eigenvalues

    a, b = stabilized(jnp.asarray(0.03), _gait_z())
    np.testing.assert_allclose(a, b, atol=1e-5)  # measured 1.2e-6: the gains on 101 points
    assert np.max(np.abs(np.asarray(a))) < 1.0
    before = TRACES[0]
    stabilized(0.031, _gait_z(0.031))
    assert TRACES[0] == before


def _period(psi):
    return vj.fixed_point(RodWalker(psi=psi), Z0).periods[0]


def test_jit_vmap_and_forward_derivatives_of_the_gait():
    psis = jnp.array([0.029, 0.03, 0.031])
    plain = np.array([float(_period(jnp.asarray(p))) for p in psis])
    np.testing.assert_allclose(jax.jit(_period)(psis[1]), plain[1], rtol=1e-12)
    np.testing.assert_allclose(jax.vmap(_period)(psis), plain, rtol=1e-10)
    h = 1e-5
    fd = (float(_period(jnp.asarray(0.03 + h))) - float(_period(jnp.asarray(0.03 - h)))) / (2 * h)
    np.testing.assert_allclose(jax.jacfwd(_period)(jnp.asarray(0.03)), fd, rtol=1e-6)


def test_forward_and_reverse_derivatives_of_the_spectral_radius():
    """Through `fixed_point` (implicit function theorem) and `poincare_multipliers`
    (eigenvalue perturbation of a forward-mode Jacobian): `jax.grad` works, never
    reverse mode through an ODE solve."""

    def radius(psi):
        m = RodWalker(psi=psi)
        return jnp.max(jnp.abs(vj.poincare_multipliers(m, vj.fixed_point(m, Z0).z)))

    h = 1e-5
    fd = (float(radius(jnp.asarray(0.03 + h))) - float(radius(jnp.asarray(0.03 - h)))) / (2 * h)
    forward = jax.jacfwd(radius)(jnp.asarray(0.03))
    np.testing.assert_allclose(forward, fd, rtol=1e-5)
    np.testing.assert_allclose(jax.grad(radius)(jnp.asarray(0.03)), forward, rtol=1e-10)


def test_results_are_coded_not_made_up():
    """An invalid parameter is `bad_input` without a search; a gait of another model is
    `not_a_gait`; a section point of the wrong shape is one `ValueError` naming it."""
    z = _gait_z()
    nan_model = RodWalker(psi=jnp.asarray(0.03), mH=float("nan"))
    assert vj.result_names(vj.fixed_point(nan_model, Z0).result) == "bad_input"
    gait = vj.find_gait(RodWalker(psi=jnp.asarray(0.03)), guess=z)
    assert vj.result_names(vj.gait_spectrum(RodWalker(psi=jnp.asarray(0.03)), gait).result) == (
        "successful"
    )
    spectrum = vj.gait_spectrum(nan_model, gait)
    assert vj.result_names(spectrum.result) == "bad_input"
    other = vj.gait_spectrum(RodWalker(psi=jnp.asarray(0.04)), gait)
    assert vj.result_names(other.result) == "not_a_gait"
    with pytest.raises(ValueError, match="z0 must be one section point of shape \\(3,\\)"):
        vj.fixed_point(RodWalker(psi=jnp.asarray(0.03)), jnp.zeros(4))


def test_find_gait_without_a_guess_under_jit_vmap_and_grad():
    """`find_gait` without a guess (a continuation whose steps are chosen on the host)
    under `jit(vmap(value_and_grad))`: the periods of the plain calls, derivatives equal
    to central differences."""

    def period(psi):
        return vj.find_gait(vj.CompassGait(psi=psi), "stable").T

    psis = jnp.array([0.05, 0.052])
    values, grads = jax.jit(jax.vmap(jax.value_and_grad(period)))(psis)
    h = 1e-5
    for i, psi in enumerate(np.asarray(psis)):
        np.testing.assert_allclose(values[i], period(jnp.asarray(psi)), rtol=1e-10)
        fd = (period(jnp.asarray(psi + h)) - period(jnp.asarray(psi - h))) / (2 * h)
        np.testing.assert_allclose(grads[i], fd, rtol=1e-6)


def test_a_failing_member_does_not_sink_the_batch():
    """Under `vmap`, `find_gait` from one guess codes each member: a slope where the
    guess falls does not raise for the whole batch."""
    z = _gait_z()

    def search(psi):
        return vj.find_gait(RodWalker(psi=psi), guess=z)

    gaits = jax.vmap(search)(jnp.array([0.03, 0.6]))
    assert vj.result_names(gaits.result) == ["successful", "not_converged"]
    np.testing.assert_allclose(gaits.x_plus[0], search(jnp.asarray(0.03)).x_plus, atol=1e-12)


def _on_gait(psi):
    """The rod walker at slope `psi` and its gait at 0.03 rad (held fixed)."""
    z = _gait_z()
    m = RodWalker(psi=psi)
    return m, z, m.section_to_state(z)


def _recovered(psi):
    m, _, x = _on_gait(psi)
    return vj.recover(m, x[None] + 1e-3, x, 3, stop_when_converged=False).x_final[0, 2]


def _sensitivity(psi):  # the floor-step model of this study is the compass gait's
    x = vj.find_gait(vj.CompassGait()).x_plus  # its gait at 3 deg (held fixed)
    return vj.gait_sensitivity_norm(vj.CompassGait(psi=psi), x, 3).norm


#: Scalar functions of the slope through the simulations and single-gait studies whose
#: event-located steps are loops reverse mode cannot enter: each gets its derivatives
#: from a forward-mode Jacobian (`linearised`).
THROUGH_STEPS = {
    "simulate": lambda psi: vj.simulate(_on_gait(psi)[0], _on_gait(psi)[2], 2).steps.x_plus[-1, 2],
    "simulate_batch": lambda psi: vj.simulate_batch(
        _on_gait(psi)[0], _on_gait(psi)[2][None] + jnp.array([[0.0], [1e-3]]), 2
    ).steps.period.sum(),
    "midswing_multipliers": lambda psi: jnp.abs(
        vj.midswing_multipliers(_on_gait(psi)[0], _on_gait(psi)[1])[0][0]
    ),
    "recover": _recovered,
    "gait_sensitivity_norm": _sensitivity,
}


@pytest.mark.parametrize("name", sorted(THROUGH_STEPS))
def test_reverse_derivatives_through_steps(name):
    """`jax.grad` equals central differences."""
    f = THROUGH_STEPS[name]
    psi, h = jnp.asarray(0.03), 1e-5
    reverse = float(jax.grad(f)(psi))
    fd = (float(f(psi + h)) - float(f(psi - h))) / (2 * h)
    np.testing.assert_allclose(reverse, fd, rtol=1e-5, atol=1e-8)


HOST_SIDE = [
    "atlas",
    "basin_slice",
    "basin_volume",
    "bifurcation_diagram",
    "bisect_threshold",
    "continue_fixed_point",
    "contraction",
    "design",
    "family_multipliers",
    "flip_slopes",
    "max_converging_perturbation",
    "max_floor_step",
    "max_push",
    "period1_family",
    "period2_branch",
    "period_k_orbit",
    "period_doubling_slope",
    "slope_sensitivity",
    "sweep",
]


@pytest.mark.parametrize("name", HOST_SIDE)
def test_host_side_functions_refuse_a_trace_in_one_line(name):
    """The functions that loop on the host (sweeps, scans, bisections, optimisers) raise
    one `TypeError` naming themselves and the traceable alternative under `jit` (even
    with only constants inside the trace), before any work."""
    fn = getattr(vj, name)
    with pytest.raises(TypeError, match=f"^{name} runs on the host .* use "):
        jax.jit(lambda psi: fn(psi))(0.03)
    with pytest.raises(TypeError, match=f"^{name} runs on the host"):
        jax.jit(lambda: fn(0.03))()


def test_host_side_functions_under_vmap_and_grad_with_real_arguments():
    """The same one line under `vmap` and `grad` of a real call, and the plain call
    still works."""
    z = _gait_z()
    with pytest.raises(TypeError, match="^sweep runs on the host .* `find_gaits`"):
        jax.vmap(lambda psi: vj.sweep(vj.CompassGait(psi=psi), [0.05]))(jnp.array([0.05]))
    with pytest.raises(TypeError, match="^family_multipliers runs on the host"):
        jax.grad(
            lambda psi: vj.family_multipliers(RodWalker(psi=psi), psi[None], z[None]).max_abs[0]
        )(jnp.asarray(0.03))
    fp, reached = vj.continue_fixed_point(
        RodWalker(psi=jnp.asarray(0.03)), z, RodWalker(psi=jnp.asarray(0.031))
    )
    assert vj.result_names(fp.result) == "successful"
    np.testing.assert_allclose(
        fp.z, vj.fixed_point(RodWalker(psi=jnp.asarray(0.031)), z).z, atol=1e-10
    )
