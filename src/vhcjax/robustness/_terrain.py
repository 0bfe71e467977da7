"""Terrain disturbances met on the gait: a single step up or down of height `h`.

The walker, on its gait, meets a floor raised (h > 0) or lowered (h < 0) by `h`
(vertically) for one heel strike: the swing foot lands on the new level and later steps
continue on the slope from there. `FloorStepCompassGait` is the compass gait whose heel
strike happens on a surface offset by `floor_offset`; the recovery over the next steps,
the largest step up and down that the walker survives (batched bisection), and the gait
sensitivity norm of Hobbelen and Wisse (2007) for floor-height disturbances (step time as
the gait indicator) follow.

References: D. G. E. Hobbelen and M. Wisse, "A disturbance rejection measure for limit
cycle walkers: the gait sensitivity norm", IEEE Trans. Robotics 23(6), 2007.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import DEFAULT_CONFIG, FAST_CONFIG, step_unchecked
from ..models import CompassGait  # a floor step changes the compass gait's guard
from ..solvers import linearised
from ..stability import returns_to
from ._bisection import bisect_threshold
from ._recovery import first_steps, recover_padded, step_capacity


class FloorStepCompassGait(CompassGait):
    """Compass gait whose swing foot strikes a floor offset by `floor_offset` (m,
    vertical, positive = step up) from the slope through the stance foot.

    The guard is the foot height above that floor along the slope normal in leg
    lengths, $H(q) - h\\cos\\psi / l$ (thesis 3.31 shifted; dimensionless, like every
    guard, so the event tolerance is unit-free), crossing zero downward after the
    strike gate has opened; at `floor_offset = 0` the heel strike is the nominal one. A
    step up higher than the swing foot's clearance is never reached (the foot stubs
    the raised floor): the walker then falls, which is what the simulation reports.
    """

    floor_offset: float | jax.Array = 0.0

    def guard(self, q):
        return self.switching_surface(q) - self.floor_offset * jnp.cos(self.psi) / self.l


def floor_step_model(model, h):
    """The `FloorStepCompassGait` with the parameters of `model` and floor offset `h`."""
    fields = {
        k: getattr(model, k) for k in ("m1", "m2", "mH", "a", "b", "g", "psi", "min_strike_angle")
    }
    return FloorStepCompassGait(**fields, floor_offset=h)


def _first_step_fn(model, h, config):
    def first(x, alive):
        return jax.vmap(
            lambda hh, xx, aa: step_unchecked(floor_step_model(model, hh), xx, config, alive=aa)
        )(h, x, alive)

    return first


def terrain_recovery(
    model, x_star, h, num_steps=30, tol=1e-4, config=FAST_CONFIG, stop_when_converged=True
):
    """Walk from the gait's post-impact state `x_star` onto a floor step of height `h`
    (batch of heights), then `num_steps - 1` normal steps.

    **Returns:** a `vhcjax.Recovery` (label, steps to converge, step times, distances).
    """
    rec = _terrain_recovery(
        model,
        x_star,
        h,
        np.int64(num_steps),
        step_capacity(num_steps),
        tol,
        config,
        stop_when_converged,
    )
    return first_steps(rec, num_steps)


@stored_jit
def _terrain_recovery(model, x_star, h, count, capacity, tol, config, stop_when_converged):
    h = jnp.asarray(h, dtype=float)
    # Every member starts on the gait. Seen as one state broadcast over the batch, the
    # start-up of the first step's ODE solve (diffrax's time clipping, equinox's bitwise
    # `nextafter`) sends XLA's algebraic simplifier round a rewrite cycle (50 rounds and
    # a logged error per compile); the barrier hides the broadcast, the numbers are equal.
    x0 = jax.lax.optimization_barrier(jnp.broadcast_to(x_star, (h.shape[0], x_star.shape[0])))
    return recover_padded(
        model,
        x0,
        x_star,
        count,
        capacity,
        tol=tol,
        config=config,
        first_step=_first_step_fn(model, h, config),
        stop_when_converged=stop_when_converged,
    )


@host_only("`terrain_recovery`")
def max_floor_step(
    model,
    x_star,
    *,
    h_max=None,
    iterations=12,
    scan=50,
    num_steps=40,
    tol=1e-4,
    config=FAST_CONFIG,
    progress=None,
):
    """Largest step down and step up (m) met on the gait after which the walker returns to
    the gait within `num_steps`, by batched bisection on `[0, h_max]` (default 5 % of the
    leg length, `scales()["length"]`, so that a scaled walker's thresholds scale with
    it) after a scan of `scan` heights (1 mm apart for a 1 m leg), so that the *first*
    failing height is found:
    the surviving heights need not form an interval (at 3 degrees a step down of 14.5-16
    mm falls while 16.5-19.5 mm is survived).

    **Returns:** a `vhcjax.Threshold` with two members: step down (h < 0), step up (h > 0);
    magnitudes are positive; `hi_label` is the recovery label of the first failing step
    (`FELL`, or `UNDECIDED` where it had not come back within `num_steps`).
    """
    sign = jnp.array([-1.0, 1.0])
    if h_max is None:
        h_max = 0.05 * float(model.scales()["length"])

    def survives(mag):  # the recovery labels: CONVERGED (0) survives
        return terrain_recovery(model, x_star, sign * mag, num_steps, tol, config).label

    return bisect_threshold(
        survives,
        np.zeros(2),
        np.full(2, h_max),
        iterations=iterations,
        scan=scan,
        progress=progress,
    )


class GaitSensitivity(eqx.Module):
    """Linear response of the step times to a unit floor-height disturbance.

    - `dtimes`: $\\partial T_k/\\partial h$ for the disturbed step (k = 0) and the next
      ones (s/m).
    - `norm`: the gait sensitivity norm $\\|\\partial T/\\partial h\\|_2$ (s/m).
    - `b`: $\\partial x_1/\\partial h$, the post-impact state change from the step.
    - `A`: the step-to-step Jacobian in the full state (`2n x 2n`), `c`: the step time's
      gradient in the post-impact state.
    - `result`: `successful`, the failure of the step from `x_star`, or `not_a_gait` where
      that step does not return to `x_star` (`GAIT_TOL`): then the numbers are not those
      of a gait.
    """

    dtimes: jax.Array
    norm: jax.Array
    b: jax.Array
    A: jax.Array
    c: jax.Array
    result: RESULTS


def gait_sensitivity_norm(model, x_star, num_steps=40, config=DEFAULT_CONFIG):
    """Gait sensitivity norm (Hobbelen and Wisse 2007) for floor-height disturbances with
    step time as the gait indicator, from the linearized step-to-step map with the floor
    height as input: $\\delta x_1 = b\\,h$, $\\delta x_{k+1} = A\\,\\delta x_k$,
    $\\delta T_0 = t_h h$, $\\delta T_k = c^T \\delta x_k$. `b`, `t_h`, `A` and `c` are
    forward-mode autodiff of single steps through the heel-strike event.

    **Returns:** a `GaitSensitivity` (`num_steps` >= 1, static). Pure: check its `result`.
    Differentiable in forward and reverse mode (`jax.grad`) in `model` and `x_star`.
    """
    if isinstance(num_steps, bool) or not isinstance(num_steps, (int, np.integer)) or num_steps < 1:
        raise ValueError(
            f"gait_sensitivity_norm: num_steps must be an integer >= 1, got {num_steps!r}"
        )
    return linearised(_gait_sensitivity_norm, int(num_steps), config)(
        model, jnp.asarray(x_star, float)
    )


def _gait_sensitivity_norm(model, x_star, num_steps, config):
    def disturbed(h):
        sr = step_unchecked(floor_step_model(model, h), x_star, config)
        return sr.x_plus, sr.period

    def normal(x):
        sr = step_unchecked(model, x, config)
        return (sr.x_plus, sr.period), sr

    b, t_h = jax.jacfwd(disturbed)(jnp.asarray(0.0))
    (A, c), sr = jax.jacfwd(normal, has_aux=True)(x_star)
    periodic = returns_to(model, model.state_to_section(x_star), model.state_to_section(sr.x_plus))
    code = RESULTS.where(
        sr.result == RESULTS.successful,
        RESULTS.where(periodic, RESULTS.successful, RESULTS.not_a_gait),
        sr.result,
    )

    def body(dx, _):
        return A @ dx, c @ dx

    _, dts = jax.lax.scan(body, b, None, length=num_steps - 1)
    dtimes = jnp.concatenate([t_h[None], dts])
    return GaitSensitivity(dtimes, jnp.linalg.norm(dtimes), b, A, c, code)
