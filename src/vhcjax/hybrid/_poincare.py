"""The step-to-step (Poincare) map on the post-impact section, its Jacobian, its fixed points.

The section is the set of post-impact states (the relabelled switching surface); its
coordinates come from `model.state_to_section` / `model.section_to_state` (for the
compass gait $z = (q_1, \\dot q_1, \\dot q_2)$, $q_2 = -q_1 - 2\\psi$). The map is
differentiable by forward-mode autodiff through the heel-strike event (`_event_solve`:
variational equations and the event-time tangent); its Jacobian gives the Floquet
multipliers of a gait, independently of the transverse linearization (thesis ch. 6).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._programs import stored_jit
from .._results import RESULTS
from ._simulate import DEFAULT_CONFIG, step_unchecked


class MapResult(eqx.Module):
    """`z_next` after `k` steps, the step periods (length k), and a result code."""

    z_next: jax.Array
    periods: jax.Array
    result: RESULTS


def step_map(model, z, k=1, config=DEFAULT_CONFIG):
    """$P^k(z)$: `k` steps of the hybrid simulation from section coordinates `z`."""
    x = model.section_to_state(z)
    if k == 1:
        sr = step_unchecked(model, x, config)
        return MapResult(model.state_to_section(sr.x_plus), sr.period[None], sr.result)

    # k > 1: a scan traces the step once (an unrolled loop compiled k copies of it)
    def body(carry, _):
        x, result = carry
        sr = step_unchecked(model, x, config)
        result = RESULTS.where(result == RESULTS.successful, sr.result, result)
        return (sr.x_plus, result), sr.period

    (x, result), periods = jax.lax.scan(body, (x, RESULTS.successful), None, length=k)
    return MapResult(model.state_to_section(x), periods, result)


def jacobian(model, z, k=1, config=DEFAULT_CONFIG):
    """$\\partial P^k / \\partial z$ by forward-mode autodiff through the events."""
    return jax.jacfwd(lambda zz: step_map(model, zz, k, config).z_next)(z)


def multipliers(model, z, k=1, config=DEFAULT_CONFIG):
    """Eigenvalues of the Poincare-map Jacobian at `z` (sorted by modulus, descending).

    Complex array of length 2n-1. Eigenvalue computation runs on the host (CPU) as JAX
    only implements non-symmetric `eig` there.
    """
    J = jacobian(model, z, k, config)
    ev = jnp.linalg.eigvals(J)
    return ev[jnp.argsort(-jnp.abs(ev))]


class FixedPoint(eqx.Module):
    """A fixed point of $P^k$ found by Newton's method.

    - `z`: section coordinates of the fixed point.
    - `x0`: the corresponding post-impact state.
    - `periods`: the k step periods along the orbit.
    - `iterations`: Newton iterations taken.
    - `residual`: $\\|P^k(z) - z\\|_\\infty$ at the solution.
    - `result`: `successful`, `not_converged`, or the failure of the last map evaluation.
    """

    z: jax.Array
    x0: jax.Array
    periods: jax.Array
    iterations: jax.Array
    residual: jax.Array
    result: RESULTS


def fixed_point(model, z0, k=1, *, rtol=1e-12, atol=1e-12, max_steps=40, config=DEFAULT_CONFIG):
    """Solve $P^k(z) = z$ by Newton (optimistix) with forward-mode Jacobians (Problem 2).

    Never raises: inspect `result` (use under `vmap` freely).
    """
    z0 = jnp.asarray(z0, dtype=float)

    def residual_fn(z, _):
        out = step_map(model, z, k, config)
        r = out.z_next - z
        # A failed map (fall, missed strike) would otherwise be a silent constant: make
        # Newton see a large residual so it does not declare convergence.
        return jnp.where(out.result == RESULTS.successful, r, 1e3 * jnp.ones_like(r))

    sol = optx.root_find(
        residual_fn,
        optx.Newton(rtol=rtol, atol=atol),
        z0,
        max_steps=max_steps,
        throw=False,
    )
    z = sol.value
    final = step_map(model, z, k, config)
    res = jnp.max(jnp.abs(final.z_next - z))
    ok_newton = sol.result == optx.RESULTS.successful
    finite = jnp.all(jnp.isfinite(z)) & jnp.isfinite(res)
    code = RESULTS.where(
        final.result != RESULTS.successful,
        final.result,
        RESULTS.where(ok_newton & finite & (res < 1e-8), RESULTS.successful, RESULTS.not_converged),
    )
    z = jnp.where(finite, z, z0)
    return FixedPoint(
        z, model.section_to_state(z), final.periods, sol.stats["num_steps"], res, code
    )


# Shared jitted entry points (stored, see `vhcjax._programs`): one compile cache per
# function for the whole library.
step_map_jit = stored_jit(step_map)
jacobian_jit = stored_jit(jacobian)
multipliers_jit = stored_jit(multipliers)
fixed_point_jit = stored_jit(fixed_point)
