"""Actuated walkers: inputs $B(q)u$, the actuated vector field, steps and simulations under
a feedback law.

The equations of motion with an input are
$M(q)\\ddot q + C(q,\\dot q)\\dot q + G(q) = B(q)u$ (thesis 3.7 with a generalized force);
a model declares its input matrix by a method `input_matrix(q)` (shape `(n, m)`; e.g.
the hip torque of `CompassGait`). A feedback law is any callable `k(x, model) -> u`,
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
from ..hybrid import DEFAULT_CONFIG, StepResult, flow, step_unchecked


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


def actuated_vector_field(model, x, u):
    """$\\dot x = (\\dot q, M^{-1}(Bu - C\\dot q - G))$ at state `x` and input `u`."""
    n = model.n_dof
    q, dq = x[:n], x[n:]
    return jnp.concatenate([dq, model.acceleration(q, dq, input_matrix(model, q) @ u)])


class ZeroFeedback(eqx.Module):
    """The passive walker as a feedback law: $u = 0$ (`num_inputs` zeros). Running the
    passive and the controlled walker through the same code makes comparisons fair."""

    num_inputs: int = eqx.field(static=True, default=1)

    def __call__(self, x, model):
        return jnp.zeros(self.num_inputs, x.dtype)


def closed_loop_field(model, feedback):
    """Vector field `(t, x, args) -> xdot` of the walker under `u = feedback(x, model)`."""

    def field(t, x, args):
        return actuated_vector_field(model, x, feedback(x, model))

    return field


def _single_domain(model):
    if hasattr(model, "hybrid_step"):
        raise NotImplementedError(
            f"{type(model).__name__} is a multi-domain model: closed-loop steps are "
            "implemented for single-domain walkers only"
        )


def closed_loop_step(model, x0, feedback, config=DEFAULT_CONFIG, alive=True):
    """One step (swing to heel strike, impact) of the walker under `feedback`.

    Same contract as `vhcjax.step` with `throw=False`: returns a `StepResult`, failures as
    result codes. Differentiable in forward mode through the heel-strike event.
    """
    _single_domain(model)
    x0 = jnp.asarray(x0, float)
    return step_unchecked(model, x0, config, alive, None, closed_loop_field(model, feedback))


def step_torque(model, x0, period, feedback, num_points=64, config=DEFAULT_CONFIG):
    """Input along one step: `u` at `num_points` equally spaced times in `[0, period]`.

    **Returns:** `(ts, u)` with shapes `(num_points,)` and `(num_points, m)`.
    """
    ts = jnp.linspace(0.0, 1.0, num_points) * period
    sol = flow(
        model,
        x0,
        period + 1e-12,
        config,
        saveat=diffrax.SaveAt(ts=ts),
        event=False,
        vector_field=closed_loop_field(model, feedback),
    )
    u = jax.vmap(lambda x: feedback(x, model))(sol.ys)
    return ts, u


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

    - `model`: a single-domain `WalkerModel` with an `input_matrix`.
    - `x0`: initial post-impact state `[q, dq]`.
    - `feedback`: `k(x, model) -> u`, e.g. a `TransverseFeedback` or `ZeroFeedback`.
    - `num_steps`: number of steps (static).
    - `config`: a `SolverConfig`.
    - `torque_points`: samples per step for the torque statistics (0: skip them).

    **Returns:** a `ClosedLoopSimulation`.
    """
    _single_domain(model)
    x0 = jnp.asarray(x0, float)

    def body(carry, _):
        x, alive, first_fail = carry
        sr = closed_loop_step(model, x, feedback, config, alive)
        ok = alive & (sr.result == RESULTS.successful)
        new_fail = RESULTS.where(alive & ~ok, sr.result, first_fail)
        result = RESULTS.where(alive, sr.result, first_fail)
        x_next = jnp.where(ok, sr.x_plus, x)
        if torque_points:
            _, u = step_torque(
                model, x, jnp.where(ok, sr.period, 1e-9), feedback, torque_points, config
            )
            umax = jnp.where(ok, jnp.max(jnp.abs(u)), 0.0)
            urms = jnp.where(ok, jnp.sqrt(jnp.mean(u**2)), 0.0)
        else:
            umax = urms = jnp.zeros((), x.dtype)
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
    num_ok = jnp.sum(steps.result._value == RESULTS.successful._value)
    return ClosedLoopSimulation(steps, first_fail, num_ok, x0, umax, urms)


simulate_closed_loop = stored_jit(simulate_closed_loop)
