"""A second Poincare section, $q_1 = 0$ in mid-swing: the multipliers of a gait computed
there, a check that they do not depend on the section."""

import diffrax
import jax
import jax.numpy as jnp
import optimistix as optx

from .._programs import stored_jit
from ..hybrid import DEFAULT_CONFIG, ode_solver, solve_to_event
from ..hybrid._simulate import _units
from ..solvers import eigenvalues, linearised


def _gated_strike_event(model):
    """Heel strike (downward guard crossing) once the strike gate is open, in one stage
    (the flow may start with the gate already open)."""

    def cond(t, y, args, **kwargs):
        q = y[: model.n_dof]
        # Negative while the gate is closed: opening it is then never a downward crossing,
        # whatever the sign of the guard there (it is negative when the legs cross below
        # the slope line, as for the unstable family).
        return jnp.where(model.strike_gate(q) > 0, model.guard(q), -1.0 - jnp.abs(model.guard(q)))

    return diffrax.Event(cond, root_finder=optx.Newton(rtol=1e-13, atol=1e-13), direction=False)


def _midswing_event():
    def cond(t, y, args, **kwargs):
        return y[0]

    return diffrax.Event(cond, root_finder=optx.Newton(rtol=1e-13, atol=1e-13), direction=False)


def _flow_event(model, x0, event, config):
    sol = solve_to_event(
        model.vector_field,
        (event.cond_fn,),
        (event.direction,),
        x0,
        None,
        0.0,
        config.t_max_factor * model.time_scale,
        solver=ode_solver(config.solver),
        rtol=config.rtol,
        atol=config.atol,
        max_steps=config.max_steps,
        units=_units(model),
    )
    ok = sol.result == diffrax.RESULTS.event_occurred
    return sol.ys[-1], sol.ts[-1], ok


def midswing_map(model, w, config=DEFAULT_CONFIG):
    """Return map on the mid-swing section $\\{q_1 = 0, \\dot q_1 < 0\\}$ of a compass-gait
    walker, coordinates $w = (q_2, \\dot q_1, \\dot q_2)$: swing to heel strike, impact,
    swing to the next $q_1 = 0$. **Returns:** `(w_next, ok)`."""
    x = jnp.concatenate([jnp.zeros(1, w.dtype), w])
    xm, _, ok1 = _flow_event(model, x, _gated_strike_event(model), config)
    xp, _, _ = model.impact(xm)
    xs, _, ok2 = _flow_event(model, xp, _midswing_event(), config)
    return xs[1:], ok1 & ok2


def to_midswing(model, z, config=DEFAULT_CONFIG):
    """Section coordinates on the mid-swing section of the orbit through post-impact `z`."""
    xs, _, ok = _flow_event(model, model.section_to_state(z), _midswing_event(), config)
    return xs[1:], ok


def _midswing_jacobian(model, z, config):
    w, ok0 = to_midswing(model, z, config)
    J, ok = jax.jacfwd(lambda ww: midswing_map(model, ww, config), has_aux=True)(w)
    return J, w, ok0 & ok


@stored_jit
def midswing_multipliers(model, z, config=DEFAULT_CONFIG):
    """Multipliers of the gait through post-impact `z`, computed on the mid-swing section
    $q_1 = 0$: the forward-mode Jacobian of the return map from mid-swing to the next
    mid-swing, a check of the multipliers on the post-impact section. Differentiable in
    forward and reverse mode (`jax.grad`; eigenvalue perturbation of that Jacobian, whose
    own derivatives come from forward mode).

    **Returns:** `(multipliers, w, ok)`: the multipliers, the gait's mid-swing section
    point $w = (q_2, \\dot q_1, \\dot q_2)$ at $q_1 = 0$, and whether every swing of the
    computation reached its event."""
    J, w, ok = linearised(_midswing_jacobian, config)(model, jnp.asarray(z, float))
    return eigenvalues(J), w, ok
