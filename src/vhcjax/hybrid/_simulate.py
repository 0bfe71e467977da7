"""Exact hybrid simulation: swing phase to heel strike (diffrax event) + reset map.

One step is an adaptive solve stopped by an event whose root finder locates the heel strike
exactly (`_event_solve.solve_to_event`: differentiable in forward mode, event-time
sensitivity included, without host callbacks), followed by the impact map and leg relabelling
(thesis 3.35). Many steps are a `lax.scan`. Falls, missed strikes, unphysical impacts and
non-finite states are result codes per member, never silent NaNs, and never a Python `if`
on a traced value.
"""

import math
import operator
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._batching import bucket_size, host_workers, padded_map
from .._programs import stored_jit
from .._results import RESULTS
from ..solvers import diffeqsolve
from ..solvers._implicit import linearised
from ._event_solve import solve_to_event


class SolverConfig(NamedTuple):
    """Numerical settings of the swing-phase integration (hashable, static).

    - `rtol`, `atol`: tolerances of the adaptive step-size controller. They, not the
      root finder, set the accuracy of the heel-strike time (~1e-11 s at 1e-10 for the
      thesis walker). `atol` is in the walker's own units (angles, and rates times
      `model.time_scale`).
    - `max_steps`: ODE steps per walker step.
    - `t_max_factor`: time limit of one step, in units of `model.time_scale`.
    - `solver`: `"tsit5"` or `"dopri8"`.
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    max_steps: int = 2048
    t_max_factor: float = 10.0
    solver: str = "tsit5"


DEFAULT_CONFIG = SolverConfig()
FAST_CONFIG = SolverConfig(rtol=1e-8, atol=1e-8, max_steps=1024)


def ode_solver(name):
    return {"tsit5": diffrax.Tsit5, "dopri8": diffrax.Dopri8, "dopri5": diffrax.Dopri5}[name]()


class StepResult(eqx.Module):
    """One walker step.

    - `x_minus`: state just before heel strike.
    - `x_plus`: state just after impact and relabelling (start of the next step).
    - `period`: duration of the step (s).
    - `impulse`: contact impulse on the new stance foot (world frame, N s).
    - `result`: a `RESULTS` code.
    """

    x_minus: jax.Array
    x_plus: jax.Array
    period: jax.Array
    impulse: jax.Array
    result: RESULTS


def _event(model, gate=False):
    """Heel-strike event (real, root-found, downward crossing of `model.guard`), or the
    strike gate (upward crossing of `model.strike_gate`) when `gate=True`; plus a
    boolean fall event."""

    def strike(t, y, args, **kwargs):
        q = y[: model.n_dof]
        return model.strike_gate(q) if gate else model.guard(q)

    def fall(t, y, args, **kwargs):
        return model.fallen(y[: model.n_dof]) | ~jnp.all(jnp.isfinite(y))

    return diffrax.Event(
        cond_fn=(strike, fall),
        root_finder=event_root_finder(model),
        direction=(True if gate else False, None),
    )


def event_root_finder(model):
    """Newton on the event time, to 1e-13 of the walker's time unit (`model.time_scale`)."""
    atol = 1e-13 * jnp.asarray(model.time_scale, dtype=float)  # an array (traced models)
    return optx.Newton(rtol=1e-13, atol=atol)  # pyright: ignore[reportArgumentType]


def _units(model, latch=False, n=None):
    """The swing's own units: time $T$ = `model.time_scale`, angles 1, velocities $1/T$
    (and, with `latch`, the latch of `_latched`: $T$, guards and gates being
    dimensionless),
    so that the integration tolerances do not depend on the walker's size or gravity.
    `n`: the number of coordinates (default `model.n_dof`)."""
    t = jnp.asarray(model.time_scale, dtype=float)
    n = model.n_dof if n is None else n
    parts = [jnp.ones((n,)), jnp.ones((n,)) / t]
    if latch:
        parts.append(t[None])
    return t, jnp.concatenate(parts)


def state_distance(model, x, x_ref):
    """$\\max_i |x_i - x_{\\mathrm{ref},i}| / Y_i$ and $\\max(1, \\max_i |x_{\\mathrm{ref},i}| / Y_i)$:
    the distance of two states and the size of the reference in the walker's own units
    (`_units`: angles, and velocities times `model.time_scale`). Traceable."""
    x, x_ref = jnp.asarray(x), jnp.asarray(x_ref)
    unit = _units(model, n=x_ref.shape[-1] // 2)[1]
    return jnp.max(jnp.abs(x - x_ref) / unit), jnp.maximum(1.0, jnp.max(jnp.abs(x_ref) / unit))


def section_units(model):
    """The units of the section coordinates (`model.state_to_section` of the state's
    units `_units`: section coordinates are a selection of state coordinates)."""
    return jnp.abs(model.state_to_section(_units(model)[1]))


#: The thesis walker's time unit $\sqrt{l/g}$ (1 m, 9.81 m/s^2), s: defaults given in
#: rad/s for it are scaled to another walker by `in_walker_units`.
THESIS_TIME = math.sqrt(1.0 / 9.81)


def in_walker_units(model, value, kind):
    """A default given for the thesis walker (1 m, 9.81 m/s^2), in the same proportion to
    `model`'s own units: `kind` `"angle"` (unchanged), `"rate"` (times $T_0/T$) or
    `"section"` (`value` one number per section coordinate, rates scaled). Traceable."""
    value = jnp.asarray(value, dtype=float)
    ratio = THESIS_TIME / jnp.asarray(model.time_scale, dtype=float)
    if kind == "angle":
        return value
    if kind == "rate":
        return value * ratio
    return jnp.where(section_rates(model), value * ratio, value)


def section_rates(model):
    """Which section coordinates are rates (a boolean mask; the others are angles)."""
    n = model.n_dof
    return model.state_to_section(jnp.concatenate([jnp.zeros(n), jnp.ones(n)])) > 0.5


def controller(model, config, latch=False):
    """The adaptive step-size controller of a swing solve with `config`'s tolerances in
    the walker's own units (`_units`): the absolute tolerance of each state component is
    `config.atol` times its unit, which is the same controller as integrating the scaled
    state $y/Y$ (the step-size selection in diffrax is invariant to the time unit)."""
    return diffrax.PIDController(rtol=config.rtol, atol=config.atol * _units(model, latch)[1])


def flow(
    model,
    x0,
    t1,
    config=DEFAULT_CONFIG,
    *,
    saveat=None,
    event: bool | diffrax.Event = True,
    adjoint=None,
    vector_field=None,
    gate=False,
    t0: float | jax.Array = 0.0,
):
    """Integrate the swing dynamics from `x0` over `[t0, t1]`, stopping at heel strike
    (or, with `gate=True`, where the strike gate opens; or at a `diffrax.Event` of the
    caller's given as `event`; `event=False`: at `t1`).

    Tolerances in the walker's own units (`controller`, `_units`). Low-level building
    block (also used for pushes and dense output); a `SaveAt(ts=...)` is answered from
    the solver's interpolant (`solvers.diffeqsolve`: a program holding it is storable).
    Returns the diffrax `Solution`.
    """
    vf = model.vector_field if vector_field is None else vector_field
    if event is True and saveat is None and adjoint is None:
        ev = _event(model, gate)
        return solve_to_event(
            vf,
            ev.cond_fn,
            ev.direction,
            x0,
            None,
            t0,
            t1,
            solver=ode_solver(config.solver),
            rtol=config.rtol,
            atol=config.atol,
            max_steps=config.max_steps,
            units=_units(model),
        )
    return diffeqsolve(
        diffrax.ODETerm(vf),
        ode_solver(config.solver),
        t0=t0,
        t1=t1,
        dt0=None,
        y0=x0,
        stepsize_controller=controller(model, config),
        saveat=diffrax.SaveAt(t1=True) if saveat is None else saveat,
        event=_event(model, gate) if event is True else (event or None),
        max_steps=config.max_steps,
        adjoint=diffrax.ForwardMode() if adjoint is None else adjoint,
        throw=False,
    )


def classify_solve(sol):
    strike_mask, fall_mask = sol.event_mask
    event = sol.result == diffrax.RESULTS.event_occurred
    reached_t1 = sol.result == diffrax.RESULTS.successful
    max_steps = sol.result == diffrax.RESULTS.max_steps_reached
    code = RESULTS.where(
        event & strike_mask & ~fall_mask,
        RESULTS.successful,
        RESULTS.where(
            event & fall_mask,
            RESULTS.fell,
            RESULTS.where(
                reached_t1,
                RESULTS.no_impact,
                RESULTS.where(max_steps, RESULTS.max_steps_reached, RESULTS.nonfinite),
            ),
        ),
    )
    return code


def _latched(model, vector_field):
    """Vector field and event for gated models, in ONE solve.

    The state is augmented with a latch $w$, $\\dot w = 10^{-3}\\max(g,0)^2\\max(\\gamma,0)$
    ($g$ = guard, $\\gamma$ = strike gate), so $w > 0$ exactly when the foot has been above
    the slope with the swing leg ahead. The strike condition is the guard once $w > 0$ and
    a positive constant before: it only switches between positive values, so its one
    sign change is the true heel strike (a smooth root for the root finder). Mid-swing
    scuffing, where the foot of equal legs dips through the slope, can never fire.
    """
    n = model.n_dof
    vf = model.vector_field if vector_field is None else vector_field

    def field(t, y, args):
        x = y[:-1]
        q = x[:n]
        dw = 1e-3 * jnp.maximum(model.guard(q), 0.0) ** 2 * jnp.maximum(model.strike_gate(q), 0.0)
        return jnp.concatenate([vf(t, x, args), dw[None]])

    def strike(t, y, args, **kwargs):
        g = model.guard(y[:n])
        return jnp.where(y[-1] > 0, g, 1.0 + jnp.abs(g))

    def fall(t, y, args, **kwargs):
        return model.fallen(y[:n]) | ~jnp.all(jnp.isfinite(y))

    event = diffrax.Event(
        cond_fn=(strike, fall),
        root_finder=event_root_finder(model),
        direction=(False, None),
    )
    return field, event


def _swing(model, x0, t_max, alive, config, adjoint, vector_field):
    """Swing phase to heel strike: `(x_minus, period, code)`.

    Models with a `strike_gate` (e.g. the compass gait) use the latched event of
    `_latched`; others stop at the first downward crossing of `model.guard`.
    """
    t1 = jnp.where(alive, t_max, 1e-9 * t_max)
    if model.strike_gate(x0[: model.n_dof]) is None:
        sol = flow(model, x0, t1, config, adjoint=adjoint, vector_field=vector_field)
        assert sol.ys is not None and sol.ts is not None  # saved at t1
        return sol.ys[-1], sol.ts[-1], classify_solve(sol)
    field, event = _latched(model, vector_field)
    y0 = jnp.concatenate([x0, jnp.zeros((1,), x0.dtype)])
    if adjoint is None:
        sol = solve_to_event(
            field,
            event.cond_fn,
            event.direction,
            y0,
            None,
            0.0,
            t1,
            solver=ode_solver(config.solver),
            rtol=config.rtol,
            atol=config.atol,
            max_steps=config.max_steps,
            units=_units(model, latch=True),
        )
    else:
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            ode_solver(config.solver),
            t0=0.0,
            t1=t1,
            dt0=None,
            y0=y0,
            stepsize_controller=controller(model, config, latch=True),
            saveat=diffrax.SaveAt(t1=True),
            event=event,
            max_steps=config.max_steps,
            adjoint=adjoint,
            throw=False,
        )
    assert sol.ys is not None and sol.ts is not None  # saved at t1
    return sol.ys[-1][:-1], sol.ts[-1], classify_solve(sol)


def step_unchecked(model, x0, config=DEFAULT_CONFIG, alive=True, adjoint=None, vector_field=None):
    """One step without error raising; `alive=False` members finish at once."""
    if hasattr(model, "hybrid_step"):  # multi-domain models (`_multidomain`) run a cycle
        return model.hybrid_step(x0, config, alive, adjoint, vector_field)
    finite0 = jnp.all(jnp.isfinite(x0))
    alive = jnp.asarray(alive) & finite0
    x_safe = jnp.where(finite0, x0, jnp.zeros_like(x0))
    t_max = config.t_max_factor * model.time_scale
    x_minus, period, code = _swing(model, x_safe, t_max, alive, config, adjoint, vector_field)
    x_plus, impulse, physical = model.impact(x_minus)
    finite = jnp.all(jnp.isfinite(x_plus)) & jnp.all(jnp.isfinite(impulse))
    code = RESULTS.where((code == RESULTS.successful) & ~physical, RESULTS.bad_impact, code)
    code = RESULTS.where((code == RESULTS.successful) & ~finite, RESULTS.nonfinite, code)
    code = RESULTS.where(finite0, code, RESULTS.nonfinite)
    ok = code == RESULTS.successful
    # Never hand back NaN: failed members keep their last finite state.
    x_plus = jnp.where(ok, x_plus, x_safe)
    x_minus = jnp.where(jnp.all(jnp.isfinite(x_minus)), x_minus, x_safe)
    impulse = jnp.where(ok, impulse, jnp.zeros_like(impulse))
    return StepResult(x_minus, x_plus, period, impulse, code)


def step(model, x0, *, config=DEFAULT_CONFIG, throw=True):
    """Simulate one step from the post-impact state `x0`: swing, heel strike, impact.

    **Arguments:**

    - `model`: a `WalkerModel`, e.g. `CompassGait(psi=...)`.
    - `x0`: state `[q, dq]` at the start of the step.
    - `config`: a `SolverConfig`.
    - `throw`: raise if the step did not succeed (use `False` under `vmap`).

    **Returns:** a `StepResult`.
    """
    x0 = jnp.asarray(x0, dtype=float)
    out = linearised(step_unchecked, config)(model, x0)
    if throw:
        out = eqx.tree_at(lambda r: r.x_plus, out, _raise_if_failed(out.result, out.x_plus))
    return out


def _raise_if_failed(result, token):
    return result.error_if(token, result != RESULTS.successful)


class Simulation(eqx.Module):
    """A multi-step simulation.

    - `steps`: a `StepResult` whose arrays have a leading step axis (length `num_steps`);
      entries after a failure repeat the last good state and carry the failure code.
    - `result`: the first failure, or `successful`.
    - `num_successful`: number of completed steps before the first failure.
    - `x0`: the initial state.
    - `dense_t`, `dense_x`: with `dense_points > 0`, per step a grid of `dense_points`
      times from 0 to the step period (step-local time) and the states there
      (shapes `(num_steps, dense_points)` and `(num_steps, dense_points, 2n)`); else None.
      A multi-domain model has `dense_points` times per domain, joined in order (the
      reset at each domain's end is a jump between consecutive points).
    """

    steps: StepResult
    result: RESULTS
    num_successful: jax.Array
    x0: jax.Array
    dense_t: jax.Array | None = None
    dense_x: jax.Array | None = None

    def times(self):
        """Absolute impact times (cumulative step periods)."""
        return jnp.cumsum(self.steps.period, axis=-1)


def check_state_shape(model, x0, name="x0"):
    """A one-line `ValueError` naming the expected shape of one state of `model` (at
    trace time: shapes are static)."""
    n = model.n_dof
    if jnp.shape(x0) != (2 * n,):
        raise ValueError(
            f"{name} must be one state [q, dq] of shape ({2 * n},) for "
            f"{type(model).__name__} ({n} joint angles and their rates), got "
            f"shape {jnp.shape(x0)}; for a batch use vmap"
        )


def check_section_shape(model, z, name="z"):
    """A one-line `ValueError` naming the expected shape of one section point of
    `model` (`model.state_to_section` of a post-impact state)."""
    x = jax.ShapeDtypeStruct((2 * model.n_dof,), jnp.float64)
    k = jax.eval_shape(model.state_to_section, x).shape[0]  # 2n - 1 for a compass gait
    if jnp.shape(z) != (k,):
        raise ValueError(
            f"{name} must be one section point of shape ({k},) for {type(model).__name__} "
            f"(model.state_to_section of a post-impact state), got shape {jnp.shape(z)}"
        )


def check_num_steps(num_steps):
    """A one-line `ValueError` unless `num_steps` is a nonnegative integer."""
    if isinstance(num_steps, bool) or not isinstance(num_steps, (int, np.integer)) or num_steps < 0:
        raise ValueError(f"num_steps must be a nonnegative integer, got {num_steps!r}")


def check_map_steps(k):
    """`k`, the steps of a map $P^k$, as an `int`; a one-line `ValueError` unless it is a
    positive integer (an int, a numpy integer or a 0-d integer array)."""
    try:
        n = operator.index(k)
    except TypeError:
        n = 0
    if isinstance(k, bool) or n < 1:
        raise ValueError(f"k (steps of the map) must be a positive integer, got {k!r}")
    return n


def _simulate(model, x0, count, capacity, config=DEFAULT_CONFIG, dense_points=0):
    """`capacity` (static) steps of which the first `count` (an array) are walked; the
    rest take no time and are cut off by `_first_steps`."""
    x0 = jnp.asarray(x0, dtype=float)
    check_state_shape(model, x0)
    # An invalid model (negative mass, NaN gravity, negative slope, ...) takes no step:
    # every step carries `bad_input`, whatever the dynamics would have done with it.
    valid = model.validate() if hasattr(model, "validate") else jnp.asarray(True)

    multidomain_dense = bool(dense_points) and hasattr(model, "num_domains")

    def body(carry, k):
        x, alive, first_fail = carry
        alive = alive & (k < count)
        if multidomain_dense:  # the cycle once, with what its dense output needs
            from ._multidomain import dense_cycle

            sr, ts, ys = dense_cycle(model, x, dense_points, config, alive)
            dense = (jnp.where(alive, ts, 0.0), jnp.where(alive, ys, x))
        else:
            sr = step_unchecked(model, x, config, alive=alive)
            dense = None
        ok = alive & (sr.result == RESULTS.successful)
        new_fail = RESULTS.where(alive & ~ok, sr.result, first_fail)
        result = RESULTS.where(alive, sr.result, first_fail)
        x_next = jnp.where(ok, sr.x_plus, x)
        out = StepResult(
            jnp.where(alive, sr.x_minus, x),
            x_next,
            jnp.where(alive, sr.period, 0.0),
            sr.impulse,
            result,
        )
        if dense_points and not multidomain_dense:
            ts = jnp.linspace(0.0, 1.0, dense_points) * jnp.where(alive, sr.period, 0.0)
            ys = flow(
                model,
                x,
                jnp.where(alive, sr.period, 0.0) + 1e-12 * model.time_scale,
                config,
                saveat=diffrax.SaveAt(ts=ts),
                event=False,
            ).ys
            assert ys is not None  # saved at ts
            dense = (ts, jnp.where(alive, ys, x))
        return (x_next, ok, new_fail), (out, dense)

    init = (x0, valid, RESULTS.where(valid, RESULTS.successful, RESULTS.bad_input))
    (_, _, first_fail), (steps, dense) = jax.lax.scan(body, init, jnp.arange(capacity))
    num_ok = jnp.sum((steps.result == RESULTS.successful) & (jnp.arange(capacity) < count))
    dense_t, dense_x = (None, None) if dense is None else dense
    return Simulation(steps, first_fail, num_ok, x0, dense_t, dense_x)


@stored_jit
def _simulate_stored(model, x0, count, capacity, config, dense_points, throw):
    sim = linearised(_simulate, capacity, config, dense_points)(model, x0, count)
    if throw:
        sim = eqx.tree_at(lambda s: s.x0, sim, _raise_if_failed(sim.result, sim.x0))
    return sim


def _capacity(num_steps):
    """Steps a simulation program holds: a step count rounded up to a power of two (at
    least 8), so that nearby counts share one program; the steps past the count take no
    time (a member that is not walking finishes at once)."""
    check_num_steps(num_steps)
    return bucket_size(num_steps)


def _first_steps(sim, num_steps, axis=0):
    """`sim` with its step axis (`axis`, after any batch axis) cut to `num_steps`."""
    cut = (slice(None),) * axis + (slice(0, num_steps),)

    def first(x):
        return None if x is None else x[cut]

    return eqx.tree_at(
        lambda s: (s.steps, s.dense_t, s.dense_x),
        sim,
        (jax.tree_util.tree_map(first, sim.steps), first(sim.dense_t), first(sim.dense_x)),
        is_leaf=lambda x: x is None,
    )


def simulate(model, x0, num_steps, *, config=DEFAULT_CONFIG, dense_points=0, throw=False):
    """Simulate `num_steps` walker steps from `x0` (a post-impact state).

    Pure and jittable; `jax.vmap` over `x0` and over model parameters (slope included)
    works. Members that fall keep their last state and carry the result code of the
    failure; the batch goes on.

    **Arguments:**

    - `model`: a `WalkerModel`.
    - `x0`: initial state `[q, dq]`.
    - `num_steps`: number of steps (a Python or numpy integer; counts up to the same power
      of two, at least 8, run one compiled program).
    - `config`: a `SolverConfig`.
    - `dense_points`: if positive, also return the trajectory of each step on this many
      equally spaced times (for plots and animations).
    - `throw`: raise if the walker did not complete all steps.

    **Returns:** a `Simulation`. Differentiable in forward and reverse mode (`jax.grad`)
    in `model` and `x0`: its derivatives come from a forward-mode Jacobian through the
    heel strikes times the tangents, never from reverse mode through the ODE solves.
    """
    # One compiled program per model class and static arguments, shared by every caller.
    capacity = _capacity(num_steps)
    count = np.int64(num_steps)
    return _first_steps(
        _simulate_stored(model, x0, count, capacity, config, dense_points, throw), num_steps
    )


# The public entry points are jitted once here (models carry array leaves, so one
# compilation serves every parameter value); every caller shares these caches.
step = stored_jit(step)


@stored_jit
def _simulate_many(model, x0, count, capacity, config):
    member = linearised(_simulate, capacity, config, 0)
    return jax.vmap(lambda x: member(model, x, count))(x0)


def simulate_batch(model, x0, num_steps, *, config=DEFAULT_CONFIG, mesh=None):
    """Simulate a batch of walkers of one model, spread over all devices.

    The batch is padded (to a power of two: nearby sizes share one compiled program) and
    split over the `"batch"` axis of `mesh` (default: all local devices, e.g. several
    GPUs). On a CPU, where XLA runs one
    program on one core, the batch is also cut into one chunk per core, run concurrently
    from host threads (`VHCJAX_HOST_WORKERS` sets their number). Results agree with
    unbatched `simulate` calls to rounding.

    **Arguments:**

    - `model`: a `WalkerModel`.
    - `x0`: initial states, shape `(batch, 2 n_dof)`.
    - `num_steps`: number of steps (a Python or numpy integer; as in `simulate`).
    - `config`: a `SolverConfig`.
    - `mesh`: a `jax.sharding.Mesh` with a `"batch"` axis, or None.

    **Returns:** a `Simulation` whose arrays carry a leading batch axis; differentiable
    as `simulate` (a forward-mode Jacobian per member).
    """
    x0 = jnp.asarray(x0, dtype=float)
    if x0.ndim != 2 or x0.shape[1] != 2 * model.n_dof or x0.shape[0] == 0:
        raise ValueError(
            f"x0 must have shape (batch, {2 * model.n_dof}) with batch >= 1, got {x0.shape}"
        )
    capacity = _capacity(num_steps)
    count = np.int64(num_steps)
    # One chunk per CPU core: a chunk waits for its slowest walker, so a few large chunks
    # beat many of 256 (about 1.1x at 1,000 walkers on 2 cores, bench_simulate.py).
    per_worker = -(-x0.shape[0] // host_workers(mesh))
    sims = padded_map(
        lambda x: _simulate_many(model, x, count, capacity, config),
        x0,
        max_chunk=per_worker,
        mesh=mesh,
        stage="simulation",
    )
    return _first_steps(sims, int(num_steps), axis=1)
