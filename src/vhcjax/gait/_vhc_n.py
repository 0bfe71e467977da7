"""Gait search by virtual holonomic constraints for single-domain models with n DOF.

A passive gait is a trajectory along its own VHC $q = \\Phi(\\theta) = (\\theta,
\\phi(\\theta))$, $\\theta = q_1$. Given the post-impact state on the section (coordinates
$z$, $2n - 1$ of them), the constraint is fixed by the ODE for $\\phi''$ (thesis 5.19,
`_vhc.phi_second_derivative`, any n) with initial values $\\phi(\\theta^+) = q^+_{2..n}$,
$\\phi'(\\theta^+) = \\dot q^+_{2..n}/\\dot\\theta^+$ and $\\dot\\theta^2$ from the energy
(5.18). It is integrated in $\\theta$ (not in time) until the heel-strike guard
$H(\\Phi(\\theta)) = 0$, giving the pre-impact state; the boundary condition is that the
impact map returns to $z$. The period is the quadrature $T = \\int d\\theta/\\dot\\theta$.
Newton on these $2n - 1$ equations is the n-DOF counterpart of thesis Problem 1; it
shares no code with the time-domain simulator (`_hybrid`) except the impact map.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import solve_to_event
from ..hybrid._simulate import section_units
from ._vhc import constraint, phi_second_derivative


class VHCOrbit(eqx.Module):
    """The arc of a VHC from a post-impact state to heel strike.

    - `x_minus`: pre-impact state at the end of the arc.
    - `z_next`: section coordinates after the impact map.
    - `period`: $\\int d\\theta / \\dot\\theta$ along the arc (s).
    - `result`: `successful`, `no_real_root` ($\\dot\\theta^2 \\le 0$ on the arc),
      `no_impact` or `max_steps_reached`.
    """

    x_minus: jax.Array
    z_next: jax.Array
    period: jax.Array
    result: RESULTS


def _field(s, y, args):
    """In $s = -\\theta$ (increasing while walking): $y = (\\phi, \\phi', t)$."""
    model, E0, sign = args
    k = model.n_dof - 1
    theta = -s
    phi, dphi = y[:k], y[k : 2 * k]
    ddphi, _, dth2, _ = phi_second_derivative(model, E0, theta, phi, dphi)
    dtheta = sign * jnp.sqrt(jnp.maximum(dth2, 1e-300))
    return -jnp.concatenate([dphi, ddphi, (1.0 / dtheta)[None]])


@stored_jit
def vhc_orbit(model, z, *, rtol=1e-11, atol=1e-11, max_steps=4096):
    """Integrate the VHC from the post-impact section point `z` to heel strike (`atol`
    in the walker's own units: the time in units of `model.time_scale`)."""
    n = model.n_dof
    k = n - 1
    x_plus = model.section_to_state(jnp.asarray(z, float))
    E0 = model.energy(x_plus)
    theta0, dtheta0 = x_plus[0], x_plus[n]
    sign = jnp.sign(dtheta0)
    y0 = jnp.concatenate([x_plus[1:n], x_plus[n + 1 :] / dtheta0, jnp.zeros(1, x_plus.dtype)])

    def q_of(s, y):
        return constraint(-s, y[:k], y[k : 2 * k])[0]

    def strike(t, y, args, **kwargs):  # diffrax's time is s = -theta here
        q = q_of(t, y)
        gate = model.strike_gate(q)
        guard = model.guard(q)
        return guard if gate is None else jnp.where(gate > 0, guard, 1.0)

    def bad(t, y, args, **kwargs):
        q = q_of(t, y)
        dth2 = phi_second_derivative(model, E0, -t, y[:k], y[k : 2 * k])[2]
        return (dth2 <= 0) | ~jnp.all(jnp.isfinite(y)) | model.fallen(q)

    event = diffrax.Event(
        (strike, bad), root_finder=optx.Newton(rtol=1e-13, atol=1e-13), direction=(False, None)
    )
    sol = solve_to_event(
        _field,
        event.cond_fn,
        event.direction,
        y0,
        (model, E0, sign),
        -theta0,
        -theta0 + jnp.pi,
        solver=diffrax.Tsit5(),
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        # phi and phi' are angles and slopes, t is in the walker's time unit
        units=(1.0, jnp.ones_like(y0).at[-1].set(model.time_scale)),
    )
    s_end, y_end = sol.ts[-1], sol.ys[-1]
    phi, dphi = y_end[:k], y_end[k : 2 * k]
    theta = -s_end
    dth2 = phi_second_derivative(model, E0, theta, phi, dphi)[2]
    dtheta = sign * jnp.sqrt(jnp.maximum(dth2, 0.0))
    x_minus = jnp.concatenate([theta[None], phi, dtheta[None], dphi * dtheta])
    x_next, _, physical = model.impact(x_minus)
    strike_mask, bad_mask = sol.event_mask
    hit = sol.result == diffrax.RESULTS.event_occurred
    code = RESULTS.where(
        hit & strike_mask & ~bad_mask,
        RESULTS.where(physical, RESULTS.successful, RESULTS.bad_impact),
        RESULTS.where(
            hit & bad_mask,
            RESULTS.no_real_root,
            RESULTS.where(
                sol.result == diffrax.RESULTS.max_steps_reached,
                RESULTS.max_steps_reached,
                RESULTS.no_impact,
            ),
        ),
    )
    return VHCOrbit(x_minus, model.state_to_section(x_next), y_end[-1], code)


class VHCGait(eqx.Module):
    """A gait found by the n-DOF VHC search.

    - `z`: post-impact section coordinates; `x_plus`, `x_minus`: states at the ends of
      the arc; `period`; `energy` $E_0$.
    - `iterations`, `residual` ($\\|z_{next} - z\\|_\\infty$ in the walker's own
      units), `result`.
    """

    z: jax.Array
    x_plus: jax.Array
    x_minus: jax.Array
    period: jax.Array
    energy: jax.Array
    iterations: jax.Array
    residual: jax.Array
    result: RESULTS


@stored_jit
def vhc_gait_search(model, z0, *, rtol=1e-12, atol=1e-12, max_steps=40):
    """Newton (optimistix) on $z \\mapsto z_{next}(z) - z$ along the VHC arc (the n-DOF
    Problem 1). Jacobians by `jax.jacfwd` through the $\\theta$-event. Newton, its
    tolerances and `residual` are in the walker's own units (angles, and rates times
    `model.time_scale`). Never raises."""
    z0 = jnp.asarray(z0, float)
    unit = section_units(model)

    def residual(w, _):
        z = w * unit
        orb = vhc_orbit(model, z)
        r = (orb.z_next - z) / unit
        return jnp.where(orb.result == RESULTS.successful, r, 1e3 * jnp.ones_like(r))

    sol = optx.root_find(
        residual, optx.Newton(rtol=rtol, atol=atol), z0 / unit, max_steps=max_steps, throw=False
    )
    z = sol.value * unit
    orb = vhc_orbit(model, z)
    res = jnp.max(jnp.abs(orb.z_next - z) / unit)
    ok = (sol.result == optx.RESULTS.successful) & jnp.isfinite(res) & (res < 1e-8)
    code = RESULTS.where(
        orb.result != RESULTS.successful,
        orb.result,
        RESULTS.where(ok, RESULTS.successful, RESULTS.not_converged),
    )
    x_plus = model.section_to_state(z)
    return VHCGait(
        z,
        x_plus,
        orb.x_minus,
        orb.period,
        model.energy(x_plus),
        sol.stats["num_steps"],
        res,
        code,
    )
