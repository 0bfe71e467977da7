"""Actuated walkers: inputs $B(q)u$, the actuated vector field, steps and simulations under
a feedback law.

The equations of motion with an input are
$M(q)\\ddot q + C(q,\\dot q)\\dot q + G(q) = B(q)u$ (thesis 3.7 with a generalized force);
a model declares its input matrix by a method `input_matrix(q)` (shape `(n, m)`; e.g.
the hip torque of `CompassGait`, the hip and knee torques of `KneedWalker`; a
multi-domain model applies them through `domain_vector_field(i, x, Bu)`). A feedback law is any callable `k(x, model) -> u`,
typically an `eqx.Module` (a pytree: `jit`, `vmap` and `jacfwd` go through it). Impacts
are unchanged: the torques are bounded, so they do no work during the instantaneous
heel strike.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import (
    DEFAULT_CONFIG,
    StepResult,
    check_num_steps,
    check_state_shape,
    dense_cycle,
    flow,
    multidomain_step,
    step_unchecked,
)
from ..solvers import linearised


def input_matrix(model, q):
    """$B(q)$, shape `(n_dof, m)`, from `model.input_matrix` (a `TypeError` if the model
    declares no inputs)."""
    if not hasattr(model, "input_matrix"):
        raise TypeError(f"{type(model).__name__} declares no input_matrix(q): no actuators")
    return model.input_matrix(q)


def num_inputs(model):
    """Number of inputs $m$ of a model (static)."""
    q = jnp.zeros(model.n_dof)
    return jax.eval_shape(lambda qq: input_matrix(model, qq), q).shape[1]


def actuated_vector_field(model, x, u, domain=None):
    """$\\dot x = (\\dot q, M^{-1}(Bu - C\\dot q - G))$ at state `x` and input `u`; in
    domain `domain` (static int) of a multi-domain model, that domain's dynamics."""
    n = model.n_dof
    q, dq = x[:n], x[n:]
    if is_multidomain(model):
        return model.domain_vector_field(_domain(domain), x, input_matrix(model, q) @ u)
    return jnp.concatenate([dq, model.acceleration(q, dq, input_matrix(model, q) @ u)])


def is_multidomain(model):
    """Whether `model` is a multi-domain model (a cycle of domains, e.g. `KneedWalker`)."""
    return hasattr(model, "hybrid_step")


def _domain(domain):
    if domain is None:
        raise ValueError("a multi-domain model needs the domain index")
    return domain


def in_domain(feedback, domain):
    """The law `feedback` applies in domain `domain` of a multi-domain model: its
    `in_domain(domain)` if it has one (e.g. `HybridTransverseFeedback`), else itself."""
    if domain is not None and hasattr(feedback, "in_domain"):
        return feedback.in_domain(domain)
    return feedback


class ZeroFeedback(eqx.Module):
    """The passive walker as a feedback law: $u = 0$ (`num_inputs` zeros). Running the
    passive and the controlled walker through the same code makes comparisons fair."""

    num_inputs: int = eqx.field(static=True, default=1)

    def __call__(self, x, model):
        return jnp.zeros(self.num_inputs, x.dtype)


def closed_loop_field(model, feedback, domain=None):
    """Vector field `(t, x, args) -> xdot` of the walker under `u = feedback(x, model)`
    (in domain `domain` of a multi-domain model)."""
    law = in_domain(feedback, domain)

    def field(t, x, args):
        return actuated_vector_field(model, x, law(x, model), domain)

    return field


def _fields(model, feedback):
    return [closed_loop_field(model, feedback, i) for i in range(model.num_domains)]


@stored_jit
def closed_loop_step(model, x0, feedback, config=DEFAULT_CONFIG, alive=True):
    """One step (swing to heel strike, impact; every domain of a multi-domain model) of
    the walker under `feedback`.

    Same contract as `vhcjax.step` with `throw=False`: returns a `StepResult`, failures as
    result codes. Differentiable in forward mode through the events.
    """
    x0 = jnp.asarray(x0, float)
    check_state_shape(model, x0)
    if is_multidomain(model):
        sr = multidomain_step(model, x0, config, alive, None, _fields(model, feedback))[0]
    else:
        sr = step_unchecked(model, x0, config, alive, None, closed_loop_field(model, feedback))
    # an invalid model (negative mass, NaN slope, ...): bad_input, whatever the step did
    code = RESULTS.where(model.validate(), sr.result, RESULTS.bad_input)
    return eqx.tree_at(lambda r: r.result, sr, code)


@stored_jit(arrays=("period",))
def step_torque(model, x0, period, feedback, num_points=64, config=DEFAULT_CONFIG):
    """Input along one step: `u` at `num_points` equally spaced times in `[0, period]`.

    **Returns:** `(ts, u)` with shapes `(num_points,)` and `(num_points, m)`.
    """
    if is_multidomain(model):
        raise ValueError("step_torque: a multi-domain step has a time grid per domain")
    ts = jnp.linspace(0.0, 1.0, num_points) * period
    xs = flow(
        model,
        x0,
        period + 1e-12 * model.time_scale,
        config,
        saveat=diffrax.SaveAt(ts=ts),
        event=False,
        vector_field=closed_loop_field(model, feedback),
    ).ys
    u = jax.vmap(lambda x: feedback(x, model))(xs)
    return ts, u


def _torque_stats(model, x0, feedback, config, alive, num_points):
    """One closed-loop step and `(max |u|, RMS u)` on `num_points` samples of it (per
    domain for a multi-domain model); zeros where the step failed."""
    if not is_multidomain(model):
        sr = closed_loop_step(model, x0, feedback, config, alive)
        ok = sr.result == RESULTS.successful
        _, u = step_torque(
            model,
            x0,
            jnp.where(ok, sr.period, 1e-9 * model.time_scale),
            feedback,
            num_points,
            config,
        )
    else:
        sr, ts, xs = dense_cycle(model, x0, num_points, config, alive, _fields(model, feedback))
        ok = sr.result == RESULTS.successful
        D = model.num_domains
        ts, xs = ts.reshape(D, num_points), xs.reshape(D, num_points, -1)
        u = jnp.stack(
            [jax.vmap(lambda x, law=in_domain(feedback, i): law(x, model))(xs[i]) for i in range(D)]
        )
        # the mean square over time: each domain's samples weighted by its duration
        dur = ts[:, -1] - ts[:, 0]
        ms = jnp.sum(dur * jnp.mean(u**2, axis=(1, 2))) / jnp.maximum(jnp.sum(dur), 1e-300)
        umax = jnp.where(ok, jnp.max(jnp.abs(u)), 0.0)
        return sr, umax, jnp.where(ok, jnp.sqrt(ms), 0.0)
    umax = jnp.where(ok, jnp.max(jnp.abs(u)), 0.0)
    urms = jnp.where(ok, jnp.sqrt(jnp.mean(u**2)), 0.0)
    return sr, umax, urms


class ClosedLoopSimulation(eqx.Module):
    """A multi-step simulation of the walker under a feedback law.

    - `steps`: a `StepResult` with a leading step axis (after a failure, entries repeat
      the last good state and carry the failure code).
    - `result`: the first failure, or `successful`.
    - `num_successful`: completed steps.
    - `x0`: the initial state.
    - `max_abs_torque`, `rms_torque`: per step, the largest $|u_i|$ and the RMS of $u$
      (over inputs and time) on `torque_points` samples of the step (shape `(steps,)`;
      zero after a failure).
    """

    steps: StepResult
    result: RESULTS
    num_successful: jax.Array
    x0: jax.Array
    max_abs_torque: jax.Array
    rms_torque: jax.Array


def simulate_closed_loop(
    model, x0, feedback, num_steps, *, config=DEFAULT_CONFIG, torque_points=32
):
    """Simulate `num_steps` steps of the walker under `feedback` from the post-impact
    state `x0` (pure, jittable, `vmap` over `x0`).

    **Arguments:**

    - `model`: a `WalkerModel` (single- or multi-domain) with an `input_matrix`.
    - `x0`: initial post-impact state `[q, dq]`.
    - `feedback`: `k(x, model) -> u`, e.g. a `TransverseFeedback` or `ZeroFeedback`.
    - `num_steps`: number of steps (static).
    - `config`: a `SolverConfig`.
    - `torque_points`: samples per step for the torque statistics (0: skip them).

    **Returns:** a `ClosedLoopSimulation`, differentiable in forward and reverse mode
    (`jax.grad`) in `model`, `x0` and `feedback` (a forward-mode Jacobian through the
    heel strikes times the tangents).
    """
    x0 = jnp.asarray(x0, float)
    check_state_shape(model, x0)
    check_num_steps(num_steps)
    return linearised(_simulate_closed_loop, num_steps, config, torque_points)(model, x0, feedback)


def _simulate_closed_loop(model, x0, feedback, num_steps, config, torque_points):
    def body(carry, _):
        x, alive, first_fail = carry
        if torque_points:
            sr, umax, urms = _torque_stats(model, x, feedback, config, alive, torque_points)
        else:
            sr = closed_loop_step(model, x, feedback, config, alive)
            umax = urms = jnp.zeros((), x.dtype)
        # an invalid model takes no step (the torque statistics' step is not checked)
        bad = RESULTS.where(model.validate(), sr.result, RESULTS.bad_input)
        sr = eqx.tree_at(lambda r: r.result, sr, bad)
        ok = alive & (sr.result == RESULTS.successful)
        new_fail = RESULTS.where(alive & ~ok, sr.result, first_fail)
        result = RESULTS.where(alive, sr.result, first_fail)
        x_next = jnp.where(ok, sr.x_plus, x)
        umax = jnp.where(ok, umax, 0.0)
        urms = jnp.where(ok, urms, 0.0)
        out = StepResult(
            jnp.where(alive, sr.x_minus, x),
            x_next,
            jnp.where(alive, sr.period, 0.0),
            sr.impulse,
            result,
        )
        return (x_next, ok, new_fail), (out, umax, urms)

    init = (x0, jnp.asarray(True), RESULTS.successful)
    (_, _, first_fail), (steps, umax, urms) = jax.lax.scan(body, init, None, length=num_steps)
    num_ok = jnp.sum(steps.result == RESULTS.successful)
    return ClosedLoopSimulation(steps, first_fail, num_ok, x0, umax, urms)


simulate_closed_loop = stored_jit(simulate_closed_loop)
