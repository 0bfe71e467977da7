"""`solve_to_event`: its forward-mode rule (variational equations + event-time tangent)
against closed-form derivatives, and against diffrax's implicit-function rule on a
walker step."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax.hybrid import _simulate as _hybrid
from vhcjax.hybrid._event_solve import solve_to_event

H, V0, G, C, T0 = 1.0, 0.5, 9.81, 0.3, 0.1


def _thrown(h, v0, g, c, t0):
    """A ball thrown up in a time-varying field, y'' = -g + c t, from (t0, h, v0), to its
    landing (y = 0, downwards); a boolean 'runaway' event never fires. Returns
    (landing time, landing velocity). `g` is passed as args, `c` is closed over."""

    def field(t, y, args):
        return jnp.stack([y[1], -args["g"] + c * t])

    def ground(t, y, args):
        return y[0]

    def runaway(t, y, args):
        return y[1] < -1e3

    sol = solve_to_event(
        field,
        (ground, runaway),
        (False, None),
        jnp.stack([h, v0]),
        {"g": g},
        t0,
        10.0,
        solver=diffrax.Tsit5(),
        rtol=1e-12,
        atol=1e-12,
        max_steps=4096,
    )
    assert sol.ys.shape == (1, 2) and sol.ts.shape == (1,)
    return jnp.stack([sol.ts[0], sol.ys[0, 1]]), sol


def _closed_form(h, v0, g, c, t0, tau):
    s = tau - t0
    y = h + v0 * s - g * s**2 / 2 + c * ((tau**3 - t0**3) / 6 - t0**2 * s / 2)
    v = v0 - g * s + c * (tau**2 - t0**2) / 2
    a = -g + c * tau
    dy = np.array(
        [1.0, s, -(s**2) / 2, (tau**3 - t0**3) / 6 - t0**2 * s / 2, -v0 + g * s - c * t0 * s]
    )
    dv = np.array([0.0, 1.0, -s, (tau**2 - t0**2) / 2, g - c * t0])
    dtau = -dy / v  # implicit function theorem on y(tau; p) = 0
    return y, np.stack([dtau, dv + a * dtau])


def test_event_time_and_state_tangents_match_the_closed_form():
    args = tuple(jnp.asarray(x) for x in (H, V0, G, C, T0))
    out, sol = _thrown(*args)
    assert sol.result == diffrax.RESULTS.event_occurred
    assert bool(sol.event_mask[0]) and not bool(sol.event_mask[1])
    tau = float(out[0])
    y_at_tau, jac_exact = _closed_form(H, V0, G, C, T0, tau)
    assert abs(y_at_tau) < 1e-11  # the event is the root of the closed form
    jac = np.stack(jax.jacfwd(lambda *p: _thrown(*p)[0], argnums=(0, 1, 2, 3, 4))(*args), -1)
    np.testing.assert_allclose(jac, jac_exact, rtol=1e-9, atol=1e-10)


def test_batched_tangents_equal_one_by_one():
    hs = jnp.array([0.5, 1.0, 2.0])
    f = jax.jacfwd(lambda h, g: _thrown(h, V0, g, C, T0)[0], argnums=(0, 1))
    batched = jax.vmap(f)(hs, jnp.full(3, G))
    for i, h in enumerate(hs):
        one = f(h, jnp.asarray(G))
        for b, o in zip(batched, one):
            np.testing.assert_allclose(b[i], o, rtol=1e-13, atol=1e-14)


@pytest.fixture(scope="module")
def walker_state():
    model = vj.CompassGait(psi=np.radians(3.0))
    return model, jnp.asarray(vj.find_gait(model, "stable", "vhc", guess=(0.2, -1.0)).x_plus)


def _step_out(model, x, config, adjoint=None):
    sr = _hybrid.step_unchecked(model, x, config, adjoint=adjoint)
    return jnp.concatenate([sr.x_plus, sr.period[None]])


def test_walker_step_jacobian_agrees_with_diffrax_and_a_tight_reference(walker_state):
    """A step's Jacobian (post-impact state and period over the initial state): the rule
    here against diffrax's own (implicit-function) event rule at the same tolerances,
    and against a tight Dopri8 solve (the variational equation integrated on the
    primal steps is the more accurate: 1e-9 against 2e-8 for diffrax's, measured)."""
    model, x0 = walker_state
    cfg = _hybrid.DEFAULT_CONFIG
    tight = _hybrid.SolverConfig(rtol=1e-13, atol=1e-13, max_steps=8192, solver="dopri8")
    ours = jax.jit(jax.jacfwd(lambda x: _step_out(model, x, cfg)))(x0)
    theirs = jax.jit(jax.jacfwd(lambda x: _step_out(model, x, cfg, diffrax.ForwardMode())))(x0)
    ref = jax.jit(jax.jacfwd(lambda x: _step_out(model, x, tight)))(x0)
    assert np.abs(ours - theirs).max() < 1e-7
    assert np.abs(ours - ref).max() < 5e-9


def test_second_derivatives_equal_differences_of_first_ones():
    """Second-order forward mode goes through the same rule (its augmented solve is a
    `solve_to_event` too), here in parameters only, so the inner start tangent is a
    symbolic zero; against central differences of the first derivatives (themselves
    checked against the closed form above)."""

    def first(g, c):
        return jnp.stack(
            jax.jacfwd(lambda gg, cc: _thrown(H, V0, gg, cc, T0)[0], argnums=(0, 1))(g, c), -1
        )

    g, c = jnp.asarray(G), jnp.asarray(C)
    second = np.stack(jax.jacfwd(first, argnums=(0, 1))(g, c), -1)
    eps = 1e-5
    fd = np.stack(
        [
            (first(g + eps, c) - first(g - eps, c)) / (2 * eps),
            (first(g, c + eps) - first(g, c - eps)) / (2 * eps),
        ],
        -1,
    )
    np.testing.assert_allclose(second, fd, rtol=1e-6, atol=1e-8)
