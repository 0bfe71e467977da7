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
import jax.core
import jax.numpy as jnp
import optimistix as optx

from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS
from ..solvers import detach, eigenvalues, implicit_outputs, linearised
from ._simulate import (
    DEFAULT_CONFIG,
    check_map_steps,
    check_section_shape,
    section_units,
    step_unchecked,
)


class MapResult(eqx.Module):
    """`z_next` after `k` steps, the step periods (length k), and a result code."""

    z_next: jax.Array
    periods: jax.Array
    result: RESULTS


@stored_jit
def _step_map(model, z, k, config):
    """`step_map` for a checked `k` (an `int`)."""
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


def step_map(model, z, k=1, config=DEFAULT_CONFIG):
    """$P^k(z)$: `k` steps of the hybrid simulation from section coordinates `z`.

    One compiled program per model class, `k` and `config` (a stored program, kept
    on disk for later processes: see `enable_compilation_cache`); traced into the caller's program under `jit`, `vmap` or a
    derivative.
    """
    return _step_map(model, jnp.asarray(z, dtype=float), check_map_steps(k), config)


@stored_jit
def _jacobian(model, z, k, config):
    """`jacobian` for a checked `k`."""
    return jax.jacfwd(lambda zz: _step_map(model, zz, k, config).z_next)(z)


def _jacobian_of(z, model, k, config):
    return _jacobian(model, z, k, config)


def jacobian(model, z, k=1, config=DEFAULT_CONFIG):
    """$\\partial P^k / \\partial z$ by forward-mode autodiff through the events (a stored
    program, as `step_map`). Differentiable in forward and reverse mode (`jax.grad`):
    its own derivatives come from a forward-mode Jacobian times the tangents (linear,
    so reverse mode transposes it), never from reverse mode through the ODE solves."""
    z = jnp.asarray(z, dtype=float)
    return linearised(_jacobian_of, check_map_steps(k), config)(z, model)


def multipliers(model, z, k=1, config=DEFAULT_CONFIG):
    """Eigenvalues of the Poincare-map Jacobian at `z` (sorted by modulus, descending).

    Complex array of length 2n-1; differentiable as `jacobian` (eigenvalue perturbation
    for the derivatives). Eigenvalue computation runs on the host (CPU) as JAX only
    implements non-symmetric `eig` there.
    """
    return eigenvalues(jacobian(model, z, k, config))


class FixedPoint(eqx.Module):
    """A fixed point of $P^k$ found by Newton's method.

    - `z`: section coordinates of the fixed point.
    - `x0`: the corresponding post-impact state.
    - `periods`: the k step periods along the orbit.
    - `iterations`: Newton iterations taken.
    - `residual`: $\\|P^k(z) - z\\|_\\infty$ at the solution, in the walker's own
      units (angles, and rates times `model.time_scale`).
    - `result`: `successful`, `not_converged`, or the failure of the map at `z` (where
      Newton diverged, `z` is the start).
    """

    z: jax.Array
    x0: jax.Array
    periods: jax.Array
    iterations: jax.Array
    residual: jax.Array
    result: RESULTS


def _fixed_point_equation(z, model, k, config):
    """$P^k(z) - z$ and the step periods (for the implicit derivatives of `fixed_point`)."""
    out = _step_map(model, z, k, config)
    return out.z_next - z, out.periods


@stored_jit
def _search(model, z0, k, rtol, atol, max_steps, config):
    """The Newton search of `fixed_point` (on a model it does not differentiate). An
    invalid model (a NaN or negative parameter: `validate`) is `bad_input` at once,
    without a search."""
    z0 = jnp.asarray(z0, dtype=float)
    valid = model.validate() if hasattr(model, "validate") else jnp.asarray(True)

    def search():
        return _newton(model, z0, k, rtol, atol, max_steps, config)

    def refused():
        out = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(search))
        return FixedPoint(
            z0,
            model.section_to_state(z0),
            out.periods,
            out.iterations,
            out.residual,
            RESULTS.bad_input,
        )

    return jax.lax.cond(valid, search, refused)


def _newton(model, z0, k, rtol, atol, max_steps, config):
    """Newton on the section coordinates in the walker's own units (`section_units`), so
    that `rtol`, `atol` and the residual do not depend on its size or gravity."""
    unit = section_units(model)

    def residual_fn(s, _):
        z = s * unit
        out = _step_map(model, z, k, config)
        r = (out.z_next - z) / unit
        # A failed map (fall, missed strike) would otherwise be a silent constant: make
        # Newton see a large residual so it does not declare convergence.
        return jnp.where(out.result == RESULTS.successful, r, 1e3 * jnp.ones_like(r))

    sol = optx.root_find(
        residual_fn,
        optx.Newton(rtol=rtol, atol=atol),
        z0 / unit,
        max_steps=max_steps,
        throw=False,
    )
    sol = eqx.tree_at(lambda s: s.value, sol, sol.value * unit)
    finite = jnp.all(jnp.isfinite(sol.value))
    # Newton diverged (a failed map has no slope, and its step is not finite): the
    # search ends at its start, coded `not_converged`, or with the code of the start's
    # own map where that fails (a seed that falls is coded `fell`, as a simulation
    # from it says), never with the code of a non-finite iterate.
    z = jnp.where(finite, sol.value, z0)
    final = _step_map(model, z, k, config)
    res = jnp.max(jnp.abs(final.z_next - z) / unit)
    ok_newton = (sol.result == optx.RESULTS.successful) & finite & jnp.isfinite(res)
    code = RESULTS.where(
        final.result != RESULTS.successful,
        final.result,
        RESULTS.where(ok_newton & (res < 1e-8), RESULTS.successful, RESULTS.not_converged),
    )
    return FixedPoint(
        z, model.section_to_state(z), final.periods, sol.stats["num_steps"], res, code
    )


def _with_derivatives(params, fp, k, config):
    """`fp` (found on the detached `params`) with implicit derivatives with respect to
    `params`; unchanged where `params` holds no tracer (nothing to differentiate)."""
    if not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(params)):
        return fp
    z, periods = implicit_outputs(
        _fixed_point_equation,
        fp.z,
        params,
        fp.periods,
        fp.result == RESULTS.successful,
        static=(k, config),
    )
    return FixedPoint(z, params.section_to_state(z), periods, fp.iterations, fp.residual, fp.result)


def fixed_point(model, z0, k=1, *, rtol=1e-12, atol=1e-12, max_steps=40, config=DEFAULT_CONFIG):
    """Solve $P^k(z) = z$ by Newton (optimistix) with forward-mode Jacobians (Problem 2).

    The search is one compiled program per model class and static arguments (a stored
    program: see `enable_compilation_cache`). A failed search raises nothing: inspect `result`
    (use under `vmap` freely); an invalid model is coded `bad_input` without a search;
    only a `k` that is not a positive integer or a `z0` of the wrong shape is a
    `ValueError`. Differentiable with respect to the model's parameters (`jax.jvp`,
    `jax.jacfwd`, `jax.grad`, `jax.jacrev`) by the implicit function theorem at the fixed
    point, never through the Newton iterations: the
    derivatives run the same compiled search (on the parameters' values) and compile only
    the implicit-derivative program. A failed search has zero derivatives.
    """
    z0 = jax.lax.stop_gradient(jnp.asarray(z0, dtype=float))
    check_section_shape(model, z0, "fixed_point: z0")
    k = check_map_steps(k)
    fp = _search(detach(model), z0, k, rtol, atol, max_steps, config)
    return _with_derivatives(model, fp, k, config)


#: Largest relative change of a parameter in one step of `continue_fixed_point` at
#: first (later steps grow to 4x that while they succeed); it gives up where a failing
#: step has been halved to `2**-_MAX_HALVINGS` of the first.
_CONTINUATION_RATIO = 0.015
_MAX_HALVINGS = 6


def _homotopy_model(start, model, s):
    """The model a fraction `s` of the way from `start` to `model`: every float parameter
    interpolated geometrically where both ends are positive, else linearly."""
    import numpy as np

    def mix(a, b):
        if not eqx.is_inexact_array(a):
            return a
        a, b = np.asarray(a, float), np.asarray(b, float)
        if np.all(a > 0) and np.all(b > 0):
            return jnp.asarray(a ** (1 - s) * b**s)
        return jnp.asarray((1 - s) * a + s * b)

    return jax.tree_util.tree_map(mix, start, model)


def _parameter_units(start, model):
    """A pytree like `model` holding each float parameter's unit: the larger of the two
    walkers' `scales()` of its dimension (`UNITS`), 1 for a dimensionless one (angles)."""
    import numpy as np

    s0, s1 = start.scales(), model.scales()
    out = jax.tree_util.tree_map(
        lambda x: np.ones(np.shape(x)) if eqx.is_inexact_array(x) else x, model
    )
    for name, kind in getattr(model, "UNITS", {}).items():
        unit = max(float(s0[kind]), float(s1[kind]))
        value = np.full(np.shape(getattr(model, name)), unit)
        out = eqx.tree_at(lambda m, name=name: getattr(m, name), out, value)
    return out


@host_only("`fixed_point` from a nearby guess, or `find_gait`")
def continue_fixed_point(start, z_start, model, k=1, *, config=DEFAULT_CONFIG):
    """The fixed point of $P^k$ on `model` that continues the one of `start` near
    `z_start`: a homotopy in the parameters (every float parameter at once, geometrically
    where both ends are positive), each step solved by `fixed_point` from a secant
    prediction (a parameter that is zero at either end moves by its change over its unit,
    the walkers' `scales`). A step moves no parameter by more than 1.5 % at first, up to 6 % while
    steps succeed, and is halved where one fails, until it is 1/64 of the first (then
    the continuation stops there). So a gait family is
    followed to other parameters rather than Newton from a distant seed landing on
    whichever fixed point is nearest, or on none.

    Host-side (concrete inputs; a Python loop of compiled searches).

    **Returns:** `(fixed_point, reached)`: the `FixedPoint` at `model` (`successful`), or
    the failed search of the step where the continuation stopped (its code says why:
    `fell`, `not_converged`, ...); `reached` is the last model solved (`model` itself
    on success, `start` if even `z_start` does not converge there).
    """
    import math

    import numpy as np

    a, b = jax.tree_util.tree_leaves(start), jax.tree_util.tree_leaves(model)
    if jax.tree_util.tree_structure(start) != jax.tree_util.tree_structure(model) or any(
        not eqx.is_inexact_array(x) and not np.array_equal(x, y) for x, y in zip(a, b)
    ):
        raise ValueError("continue_fixed_point: start and model must be the same kind of model")
    if any(eqx.is_inexact_array(x) and not np.all(np.isfinite(x)) for x in a + b):
        raise ValueError("continue_fixed_point: every parameter must be finite")
    k = check_map_steps(k)
    check_section_shape(start, np.asarray(z_start, float), "z_start")
    spread = 0.0
    units = jax.tree_util.tree_leaves(_parameter_units(start, model))
    for x, y, u in zip(a, b, units):
        if eqx.is_inexact_array(x):
            x, y = np.asarray(x, float), np.asarray(y, float)
            positive = np.all(x > 0) and np.all(y > 0)
            change = np.abs(np.log(y / x)) if positive else np.abs(y - x) / np.maximum(u, np.abs(x))
            spread = max(spread, float(np.max(change)))
    if not math.isfinite(spread):
        raise ValueError("continue_fixed_point: every parameter must be finite")
    first = 1.0 / max(1, math.ceil(spread / _CONTINUATION_RATIO))
    fp = fixed_point(start, jnp.asarray(z_start, float), k, config=config)
    if fp.result != RESULTS.successful:
        return fp, start
    if spread == 0.0:  # `model` is `start`
        return fp, model
    s, ds, z, previous, reached = 0.0, first, fp.z, None, start
    while s < 1.0:
        t = min(1.0, s + ds)
        guess = z if previous is None else z + (z - previous[1]) * ((t - s) / (s - previous[0]))
        m = model if t == 1.0 else _homotopy_model(start, model, t)
        trial = fixed_point(m, guess, k, config=config)
        if trial.result == RESULTS.successful:
            previous, s, z, fp, reached = (s, z), t, trial.z, trial, m
            ds = min(1.5 * ds, 4 * first)
        else:
            ds /= 2
            if ds < first / 2**_MAX_HALVINGS:
                return trial, reached
    return fp, reached
