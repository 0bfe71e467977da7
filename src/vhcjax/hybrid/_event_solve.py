"""Integration to a root-found event, forward-differentiable by variational equations.

The heel strike ends each swing at the root $\\tau$ of a switching function
$c(t, y(t), p)$ (the switching surface of thesis 3.31 in the hybrid system 3.35).
diffrax differentiates its event time through optimistix's implicit-function rule,
whose lineax linear solve carries an error check: a host callback, and a program that
holds one stays out of JAX's persistent compilation cache. `solve_to_event` is the same
integration with a forward-mode rule of its own:

- the tangent $\\delta y$ rides along in the same solve, as the variational equation
  $\\dot{\\delta y} = \\partial_y f\\,\\delta y + \\partial_p f\\,\\delta p$ (a `jvp` of the
  field), with step-size control on $y$ alone, so the steps and the event are those of
  the plain solve;
- the event-time tangent follows from $c(\\tau, y(\\tau), p) = 0$:
  $\\delta\\tau = -(\\partial_y c\\,\\delta y + \\partial_p c\\,\\delta p)
  / (\\partial_t c + \\partial_y c\\, f)$, and $\\delta y(\\tau) = \\delta y + f\\,\\delta\\tau$
  (the saltation term of the event time).

Under `jax.jacfwd` (a `vmap` over tangent directions) the state and the steps stay
unbatched: one solve carries every direction. Boolean events (falls) stop at the end of
a step and get no time tangent. Reverse mode is not supported (nor is it by diffrax's
`ForwardMode`, which this replaces).
"""

from collections.abc import Callable

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import optimistix as optx


class EventSolution(eqx.Module):
    """The end of an integration stopped by an event (the fields of `diffrax.Solution`
    that the hybrid code reads): `ts` (shape `(1,)`), `ys` (`(1, ...)`), `result` (a
    `diffrax.RESULTS`), `event_mask` (a tuple of booleans, one per condition)."""

    ts: jax.Array
    ys: jax.Array
    result: diffrax.RESULTS
    event_mask: tuple


def solve_to_event(
    field,
    conds,
    directions,
    y0,
    args,
    t0,
    t1,
    *,
    solver,
    rtol,
    atol,
    max_steps,
    norm=optx.rms_norm,
    units=None,
):
    """Integrate `field(t, y, args)` from `(t0, y0)` until the first of `conds` fires, or
    `t1`. **Returns:** an `EventSolution`.

    `units`: `None`, or `(time_unit, state_unit)` (`state_unit` a pytree like `y0`, or
    arrays that broadcast against it): the solve then runs in $t/T$ and $y/Y$, so that
    `rtol`, `atol` and the event tolerance are relative to the system's own scales and
    a rescaled system takes the same steps. The answer is in the caller's units.

    `conds`: a tuple of functions `cond(t, y, args)`; a real-valued one is root-found (its
    sign change in `directions`: True up, False down, None either), a boolean one stops at
    the end of the step where it turns True. `y0`: an array or a pytree of arrays.
    Adaptive steps (`diffrax.PIDController(rtol, atol, norm=norm)`), Newton on the dense
    output for the event time. Differentiable in forward mode, to any order, in `y0`,
    `args` (a pytree, e.g. a model), `t0`, `t1` and whatever `field` and `conds` close
    over. Never raises: read `result`.
    """
    y0 = jtu.tree_map(jnp.asarray, y0)
    if units is not None:
        return _solve_in_units(
            field,
            conds,
            directions,
            y0,
            args,
            t0,
            t1,
            units,
            solver=solver,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            norm=norm,
        )
    t = jnp.asarray(t0, jtu.tree_leaves(y0)[0].dtype)
    # Closed-over arrays (a model, push parameters) become explicit inputs, so that their
    # tangents reach the rule below instead of being lost in a closure.
    fns = (
        _Jitted(eqx.filter_closure_convert(field, t, y0, args)),
        tuple(eqx.filter_closure_convert(c, t, y0, args) for c in conds),
    )
    return _solve(
        (fns, args),
        y0,
        t0,
        t1,
        directions=tuple(directions),
        solver=solver,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        norm=norm,
    )


def _solve_in_units(field, conds, directions, y0, args, t0, t1, units, **kwargs):
    """`solve_to_event` in the time unit `T` and state unit `Y`: the field
    $T f(Ts, Yx) / Y$, the conditions $c(Ts, Yx)$."""
    dtype = jtu.tree_leaves(y0)[0].dtype
    tu = jnp.asarray(units[0], dtype)
    yu = jtu.tree_map(lambda u, y: jnp.broadcast_to(jnp.asarray(u, dtype), y.shape), units[1], y0)
    up = lambda x: jtu.tree_map(jnp.multiply, x, yu)  # noqa: E731
    down = lambda x: jtu.tree_map(jnp.divide, x, yu)  # noqa: E731

    def scaled_field(s, x, a):
        return jtu.tree_map(lambda d, u: d * tu / u, field(s * tu, up(x), a), yu)

    def scaled(cond):
        return lambda s, x, a: cond(s * tu, up(x), a)

    sol = solve_to_event(
        scaled_field,
        tuple(scaled(c) for c in conds),
        directions,
        down(y0),
        args,
        t0 / tu,
        t1 / tu,
        **kwargs,
    )
    ys = jtu.tree_map(lambda v, u: v * u, sol.ys, yu)
    return EventSolution(sol.ts * tu, ys, sol.result, sol.event_mask)


class _Jitted(eqx.Module):
    """A closure-converted field, called through `jax.jit`: diffrax traces the field
    several times (initial step size, solver state, step, event), and every call after
    the first reuses the first one's jaxpr."""

    fn: Callable

    def __call__(self, t, y, args):
        return _call_field(self.fn, t, y, args)


@eqx.filter_jit
def _call_field(fn, t, y, args):
    return fn(t, y, args)


def _cond_call(cond, a):
    return lambda t, y, args, **kwargs: cond(t, y, a)  # diffrax passes keywords


@eqx.filter_custom_jvp
def _solve(params, y0, t0, t1, *, directions, solver, rtol, atol, max_steps, norm):
    (field, conds), args = params
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(lambda t, y, _: field(t, y, args)),
        solver,
        t0=t0,
        t1=t1,
        dt0=None,
        y0=y0,
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol, norm=norm),
        saveat=diffrax.SaveAt(t1=True),
        event=diffrax.Event(
            cond_fn=tuple(_cond_call(c, args) for c in conds),
            root_finder=optx.Newton(rtol=1e-13, atol=1e-13),
            direction=directions,
        ),
        max_steps=max_steps,
        adjoint=diffrax.ForwardMode(),  # the plain while loop; never differentiated here
        throw=False,
    )
    # Saved at t1, with an event: none of these is None.
    assert sol.ts is not None and sol.ys is not None and sol.event_mask is not None
    return EventSolution(sol.ts, sol.ys, sol.result, tuple(sol.event_mask))


def _differentiated(primal, tangent):
    """`(primal, tangent)` with `None` for each symbolic-zero tangent (those leaves stay
    constants of the variational equation: no work for them) and arrays for
    differentiated Python scalars."""
    none = lambda x: x is None  # noqa: E731
    if tangent is None:
        tangent = jtu.tree_map(lambda _: None, primal)
    primal = jtu.tree_map(
        lambda t, p: p if t is None else jnp.asarray(p), tangent, primal, is_leaf=none
    )
    return primal, jtu.tree_map(lambda t: t if t is None else jnp.asarray(t), tangent, is_leaf=none)


def _axpy(a, x, y):
    """`y + a x` over pytrees `x`, `y` (scalar `a`)."""
    return jtu.tree_map(lambda xx, yy: yy + a * xx, x, y)


@_solve.def_jvp
def _solve_jvp(primals, tangents, *, directions, solver, rtol, atol, max_steps, norm):
    params, y0, t0, t1 = primals
    dparams, dy0, dt0, dt1 = tangents
    params, dparams = _differentiated(params, dparams)
    (field, conds), args = params
    dtype = jtu.tree_leaves(y0)[0].dtype
    if dy0 is None:
        dy0 = jtu.tree_map(lambda _: None, y0)
    # Symbolic zeros, also single leaves of a pytree state (the second-order rule's), as
    # arrays: they are states of the variational equation.
    dy0 = jtu.tree_map(
        lambda p, t: jnp.zeros_like(p) if t is None else t, y0, dy0, is_leaf=lambda x: x is None
    )
    t0 = jnp.asarray(t0, dtype)
    t1 = jnp.asarray(t1, dtype)
    dt1 = jnp.zeros_like(t1) if dt1 is None else dt1

    def f_of(p, t, y):
        (f, _), a = p
        return f(t, y, a)

    def c_of(i):
        def c(p, t, y):
            (_, cs), a = p
            return cs[i](t, y, a)

        return c

    if dt0 is not None:  # a later start is an earlier state: y(t0 + e) = y0, y(t0) = y0 - f e
        dy0 = _axpy(-dt0, f_of(params, t0, y0), dy0)

    def aug_field(t, yy, _):  # the field and its variational equation
        return eqx.filter_jvp(lambda p, y: f_of(p, t, y), (params, yy[0]), (dparams, yy[1]))

    # The augmented solve is an event solve itself (so a second derivative goes through
    # this rule again), with the error control of the primal state alone: the steps and
    # the event are those of the plain solve.
    sol = solve_to_event(
        aug_field,
        tuple(_lift(c) for c in conds),
        directions,
        (y0, dy0),
        args,
        t0,
        t1,
        solver=solver,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        norm=lambda e: norm(e[0]),
    )
    result, mask = sol.result, sol.event_mask
    tau = sol.ts[-1]
    y, dy = jtu.tree_map(lambda v: v[-1], sol.ys)
    f = f_of(params, tau, y)

    # Event time: c(tau, y(tau), p) = 0 to first order.
    dtau = jnp.where(result == diffrax.RESULTS.successful, dt1, jnp.zeros_like(dt1))
    hit = result == diffrax.RESULTS.event_occurred
    for i, fired in enumerate(mask):
        ci = c_of(i)
        if jnp.issubdtype(eqx.filter_eval_shape(ci, params, tau, y).dtype, jnp.bool_):
            continue  # a boolean event: no time to differentiate
        _, dc = eqx.filter_jvp(lambda p, yy: ci(p, tau, yy), (params, y), (dparams, dy))
        _, rate = jax.jvp(lambda tt, yy: ci(params, tt, yy), (tau, y), (jnp.ones_like(tau), f))
        ok = hit & fired & (rate != 0)
        dtau = jnp.where(ok, -dc / jnp.where(ok, rate, 1.0), dtau)
    dy_end = _axpy(dtau, f, dy)
    out = EventSolution(sol.ts, jtu.tree_map(lambda v: v[-1:], sol.ys[0]), result, mask)
    dout = EventSolution(
        dtau[None],
        jtu.tree_map(lambda v: v[None], dy_end),
        jtu.tree_map(lambda _: None, result),
        tuple(None for _ in mask),
    )
    return out, dout


def _lift(cond):
    return lambda t, yy, a: cond(t, yy[0], a)
