"""Does a perturbed walker return to its gait? Batched multi-step classification.

The common core of the robustness analyses (contraction, basin of attraction, terrain and
push disturbances): simulate a batch of post-impact states step by step and label each
member as *converged* to the gait (within `tol` of the fixed point, with the number of
steps it took), *fell* (with the failure code of the step that failed), *other cycle*
(settled on a different periodic motion, e.g. period 2) or *undecided*. The batch stops
as soon as every member is decided, so a chunk of quick fallers and quick recoveries
costs a few steps, not `num_steps`.
"""

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np

from .._batching import bucket_size
from .._results import RESULTS, result_codes, results_from_codes
from ..hybrid import FAST_CONFIG, step_unchecked
from ..solvers import linearised

CONVERGED, FELL, OTHER_CYCLE, UNDECIDED = 0, 1, 2, 3
LABEL_NAMES = ("converged", "fell", "other_cycle", "undecided")


class Recovery(eqx.Module):
    """Outcome of a batched recovery simulation (leading batch axis everywhere).

    - `label`: `CONVERGED` (0), `FELL` (1), `OTHER_CYCLE` (2) or `UNDECIDED` (3).
    - `steps`: steps taken to come within `tol` of the gait (0 if it started there);
      for fallers the step on which they fell (1-based); -1 otherwise.
    - `period`: for `OTHER_CYCLE`, the period (in steps) of the cycle found; else 0.
    - `result`: a `RESULTS` code per member: `successful` (converged), the failure of the
      step that failed (`fell`, `no_impact`, `bad_impact`, ...), `other_cycle` or
      `undecided`.
    - `x_final`: last post-impact state.
    - `distance`: $\\|x_k - x^*\\|_\\infty$ in the walker's own units (angles in rad,
      velocities times `model.time_scale`) after every step (shape `(batch, num_steps+1)`,
      entry 0 is the initial state; entries after the member stopped repeat its last value).
    - `step_times`: duration of every step (0 after the member stopped).
    """

    label: jax.Array
    steps: jax.Array
    period: jax.Array
    result: RESULTS
    x_final: jax.Array
    distance: jax.Array
    step_times: jax.Array


def recover(
    model,
    x0,
    x_star,
    num_steps=50,
    *,
    tol=1e-4,
    cycle_tol=1e-5,
    max_period=4,
    config=FAST_CONFIG,
    first_step=None,
    stop_when_converged=True,
):
    """Simulate a batch of post-impact states and classify their return to a gait.

    **Arguments:**

    - `model`: a `WalkerModel`.
    - `x0`: post-impact states, shape `(batch, 2n)`.
    - `x_star`: post-impact state of the gait (a fixed point of the step map).
    - `num_steps`: largest number of steps simulated (a Python integer; every budget up
      to 64 steps runs one compiled program).
    - `tol`: converged when $\\|x_k - x^*\\|_\\infty <$ `tol`, in the walker's own units
      (angles in rad, velocities times `model.time_scale`), so that a walker and its
      rescaled copy converge on the same step.
    - `cycle_tol`: a survivor with $\\|x_N - x_{N-p}\\|_\\infty <$ `cycle_tol` for some
      `p <= max_period` is labelled `OTHER_CYCLE` with period `p`.
    - `config`: `SolverConfig` of the swing integration (default `FAST_CONFIG`,
      rtol = atol = 1e-8).
    - `first_step`: optional callable `(x, alive) -> StepResult` (batched) replacing the
      first step, e.g. a step onto a raised floor or a pushed step; its initial state is
      then not compared with the gait (a disturbance is yet to come).
    - `stop_when_converged`: if False, converged members keep walking (for recovery
      curves); their label and `steps` still record the first time within `tol`.

    **Returns:** a `Recovery`; its distances and periods are differentiable in forward
    and reverse mode (`jax.grad`) in `model`, `x0` and `x_star` (a forward-mode Jacobian
    over all their entries: for derivatives, keep the batch small).
    """
    x0 = jnp.asarray(x0, dtype=float)
    x_star = jnp.asarray(x_star, dtype=float)
    if x0.ndim != 2 or x0.shape[-1:] != x_star.shape:
        raise ValueError(
            f"recover: x0 must have shape (batch, {x_star.shape[-1]}) (states of the gait's "
            f"size), got {x0.shape}"
        )
    if not isinstance(x_star, jax.core.Tracer) and not np.isfinite(np.asarray(x_star)).all():
        raise ValueError("recover: the gait state x_star must be finite")
    if int(num_steps) < 1 or int(max_period) < 1:
        raise ValueError(
            f"recover: num_steps and max_period must be at least 1, got {num_steps}, {max_period}"
        )
    rec = recover_padded(
        model,
        x0,
        x_star,
        np.int64(num_steps),
        step_capacity(num_steps),
        tol=tol,
        cycle_tol=cycle_tol,
        max_period=max_period,
        config=config,
        first_step=first_step,
        stop_when_converged=stop_when_converged,
    )
    return first_steps(rec, num_steps)


def step_capacity(num_steps):
    """Steps a recovery program holds room for: `num_steps` rounded up to a power of two,
    at least 64, so that every usual step budget runs one program. The loop stops at
    `num_steps` (or when every member is decided): the room costs no simulation."""
    return bucket_size(int(num_steps), minimum=64)


def first_steps(rec, num_steps):
    """A `Recovery` of `recover_padded` with its per-step arrays cut to `num_steps`."""
    return eqx.tree_at(
        lambda r: (r.distance, r.step_times),
        rec,
        (rec.distance[..., : num_steps + 1], rec.step_times[..., :num_steps]),
    )


def recover_padded(
    model,
    x0,
    x_star,
    count,
    capacity,
    *,
    tol=1e-4,
    cycle_tol=1e-5,
    max_period=4,
    config=FAST_CONFIG,
    first_step=None,
    stop_when_converged=True,
):
    """`recover` of at most `count` steps (an integer array) with per-step arrays of
    `capacity` steps (static; `step_capacity`): the form the stored programs of the
    robustness studies call, so that one program serves every step budget."""
    static = (capacity, tol, cycle_tol, int(max_period), config, first_step)
    return linearised(_recover, *static, stop_when_converged)(model, x0, x_star, count)


def _recover(
    model,
    x0,
    x_star,
    count,
    capacity,
    tol,
    cycle_tol,
    max_period,
    config,
    first_step,
    stop_when_converged,
):
    """`recover` for checked arguments (run by `linearised` as one stored program per
    model class and static arguments, see `vhcjax._programs`)."""
    B = x0.shape[0]
    H = max_period + 1
    n = x_star.shape[-1] // 2
    weight = jnp.concatenate([jnp.ones(n), jnp.full(n, model.time_scale)])  # own units

    def norm(dx):
        return jnp.max(jnp.abs(dx * weight), axis=-1)

    dist0 = norm(x0 - x_star)
    conv0 = (dist0 < tol) & (first_step is None)

    def batched_step(mdl, x, alive):
        return jax.vmap(lambda xx, aa: step_unchecked(mdl, xx, config, alive=aa))(x, alive)

    def update(carry, sr):
        k, x, alive, label, steps, code, hist, dist, times = carry
        ok = sr.result == RESULTS.successful
        fail = alive & ~ok
        x_new = jnp.where((alive & ok)[:, None], sr.x_plus, x)
        d = norm(x_new - x_star)
        newly_conv = alive & ok & (d < tol) & (label < 0)
        label = jnp.where(fail, FELL, jnp.where(newly_conv, CONVERGED, label))
        steps = jnp.where(newly_conv | fail, k + 1, steps)
        code = jnp.where(fail, result_codes(sr.result), code)
        times = times.at[:, k].set(jnp.where(alive, sr.period, 0.0))
        if stop_when_converged:
            alive = alive & ok & ~newly_conv
        else:
            alive = alive & ok
        hist = hist.at[:, (k + 1) % H].set(x_new)
        dist = dist.at[:, k + 1].set(d)
        return (k + 1, x_new, alive, label, steps, code, hist, dist, times)

    label0 = jnp.where(conv0, CONVERGED, -1)
    steps0 = jnp.where(conv0, 0, -1)
    alive0 = ~conv0 if stop_when_converged else jnp.ones(B, bool)
    code0 = jnp.full(B, result_codes(RESULTS.successful))
    hist0 = jnp.zeros((B, H, x0.shape[-1])).at[:, 0].set(x0)
    dist_arr0 = jnp.broadcast_to(dist0[:, None], (B, capacity + 1))
    times0 = jnp.zeros((B, capacity))
    carry = (0, x0, alive0, label0, steps0, code0, hist0, dist_arr0, times0)
    # The first step may use another model (terrain disturbance): done outside the loop.
    sr0 = batched_step(model, x0, alive0) if first_step is None else first_step(x0, alive0)
    carry = update(carry, sr0)

    def cond(c):
        return (c[0] < count) & jnp.any(c[2])

    def body(c):
        return update(c, batched_step(model, c[1], c[2]))

    k, x, alive, label, steps, code, hist, dist, times = jax.lax.while_loop(cond, body, carry)
    # Members that stopped early: fill the rest of the distance history with the last value.
    idx = jnp.arange(capacity + 1)
    last = jnp.take_along_axis(dist, jnp.full((B, 1), k), axis=1)
    dist = jnp.where(idx[None, :] > k, last, dist)

    # Survivors that never came within tol: another cycle of period p, or undecided.
    undecided = label < 0
    gaps = jnp.stack([norm(x - hist[:, (k - p) % H]) for p in range(1, H)], axis=1)
    is_cycle = gaps < cycle_tol
    period = jnp.where(jnp.any(is_cycle, axis=1), jnp.argmax(is_cycle, axis=1) + 1, 0)
    other = undecided & (period > 0) & (k >= H)
    label = jnp.where(other, OTHER_CYCLE, jnp.where(undecided, UNDECIDED, label))
    period = jnp.where(other, period, 0)
    code = jnp.where(
        other,
        result_codes(RESULTS.other_cycle),
        jnp.where(label == UNDECIDED, result_codes(RESULTS.undecided), code),
    )
    result = results_from_codes(code)
    return Recovery(label, steps, period, result, x, dist, times)


def label_names(label):
    """Names of recovery labels (outside `jit`)."""
    import numpy as np

    return np.asarray(LABEL_NAMES, dtype=object)[np.asarray(label)].tolist()
