"""Gradient-based walker design: an optax optimiser over chosen model parameters within
bounds, every iterate a converged gait continued from the last, with exact gradients of
the objective (implicit function theorem through `find_gait`, `gait_spectrum` and
`flip_slope`).

Objectives (all at the design slope, stable family, shooting on the step map):

- `"spectral-radius"`: minimise the spectral radius of the step-map Jacobian (faster
  convergence back to the gait, thesis ch. 6).
- `"flip-slope"`: maximise the slope at which the stable period-1 gait period-doubles
  (a multiplier reaches $-1$).
- `"speed"`: maximise the mean speed (step length over period, m/s).

The optimiser works on the parameters scaled to $u \\in [0, 1]$ within their bounds;
after each update $u$ is projected back onto the box (projected Adam).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._results import RESULTS, result_names
from ..gait import find_gait
from ..models import CompassGait
from ..stability import gait_spectrum
from ._flip import flip_slope

#: The parameters a design may vary, by their CLI names, and the model leaves they set.
PARAMETERS = {
    "mass-hip": ("mH",),
    "mass-leg": ("m1", "m2"),
    "a": ("a",),
    "b": ("b",),
    "gravity": ("g",),
}
#: Units of the parameters (for labels).
UNITS = {"mass-hip": "kg", "mass-leg": "kg", "a": "m", "b": "m", "gravity": "m/s^2"}
#: Default bounds of the parameters.
DEFAULT_BOUNDS = {
    "mass-hip": (1.0, 40.0),
    "mass-leg": (1.0, 20.0),
    "a": (0.1, 0.9),
    "b": (0.1, 0.9),
    "gravity": (1.0, 20.0),
}
OBJECTIVES = ("spectral-radius", "flip-slope", "speed")
#: Halvings of a step that finds no gait or makes the objective worse.
_HALVINGS = 7
#: +1: minimised as is; -1: maximised (the optimiser minimises -value).
_SENSE = {"spectral-radius": 1.0, "flip-slope": -1.0, "speed": -1.0}


def parameters_of(model):
    """`{"mass-hip", "mass-leg", "a", "b", "gravity"}` of a `CompassGait` (floats;
    `mass-leg` is `m1`, the design keeps `m2 = m1`)."""
    return {k: float(getattr(model, v[0])) for k, v in PARAMETERS.items()}


def with_parameters(model, vary, values):
    """`model` with the parameters `vary` (names of `PARAMETERS`) set to `values`."""
    for name, v in zip(vary, values):
        for leaf in PARAMETERS[name]:
            model = eqx.tree_at(lambda m: getattr(m, leaf), model, jnp.asarray(v, float))
    return model


def objective_value(model, gait, objective):
    """The objective of the gait `gait` of `model` (differentiable in the model)."""
    if objective == "spectral-radius":
        return gait_spectrum(model, gait).spectral_radius
    if objective == "speed":
        return gait.speed
    if objective == "flip-slope":
        return flip_slope(model, gait.z)
    raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")


class DesignResult(eqx.Module):
    """The outcome of `design` (host values).

    - `objective`, `vary`, `bounds`: as asked.
    - `result`: `"successful"` (projected gradient below tolerance), `"max_iterations"`,
      `"no_descent"` (no step along Adam's update or the projected gradient improves the
      objective: typically a kink, see `design`) or `"no_gait"` (no gait found along the
      step).
    - `initial`, `optimum`: dicts with `params` (all five parameters), `value`,
      `gradient` (per varied parameter, of the objective in its own units), and for the
      optimum `x0` (post-impact state), `multipliers` (complex), `spectral_radius` and
      `stable` (whether the optimal gait is stable: a speed design may leave the stable
      walkers).
    - `projected_gradient`: max-norm of the projected gradient at the optimum, in the
      scaled coordinates $u \\in [0, 1]$.
    - `history`: one dict per iterate: `iteration`, `params`, `value`.
    - `model`: the optimal model.
    """

    objective: str = eqx.field(static=True)
    vary: tuple = eqx.field(static=True)
    bounds: dict = eqx.field(static=True)
    result: str = eqx.field(static=True)
    iterations: int = eqx.field(static=True)
    initial: dict = eqx.field(static=True)
    optimum: dict = eqx.field(static=True)
    projected_gradient: float = eqx.field(static=True)
    history: list = eqx.field(static=True)
    model: CompassGait


def _evaluate(base, vary, x, objective, guess):
    """Value, gradient (per varied parameter) and gait at parameters `x`."""

    def f(xx):
        m = with_parameters(base, vary, xx)
        g = find_gait(m, method="shooting", guess=guess, throw=False)
        return objective_value(m, g, objective), g

    (v, g), grad = jax.value_and_grad(f, has_aux=True)(jnp.asarray(x, float))
    return float(v), np.asarray(grad), g


def projected_gradient(u, grad_u, sense):
    """The projected gradient of the minimised function `sense * value` on $[0, 1]^k$:
    components pushing out of the box at an active bound are zero."""
    gm = sense * np.asarray(grad_u)
    at_lo = (u <= 0.0) & (gm > 0)
    at_hi = (u >= 1.0) & (gm < 0)
    return np.where(at_lo | at_hi, 0.0, gm)


def design(
    objective,
    vary,
    *,
    model=None,
    bounds=None,
    steps=40,
    learning_rate=0.05,
    gtol=1e-4,
    callback=None,
):
    """Optimise a compass-gait walker for `objective` over the parameters `vary`.

    **Arguments:**

    - `objective`: `"spectral-radius"` (minimised), `"flip-slope"` or `"speed"`
      (maximised).
    - `vary`: names from `PARAMETERS` (`"mass-hip"`, `"mass-leg"`, `"a"`, `"b"`,
      `"gravity"`).
    - `model`: the starting `CompassGait` (its `psi` is the design slope); default
      thesis Table 1 at 3 degrees. It must have a stable gait.
    - `bounds`: `{name: (lo, hi)}` for some of `vary` (others: `DEFAULT_BOUNDS`).
    - `steps`: Adam iterations at most; `learning_rate`: in the scaled coordinates.
    - `gtol`: stop when the projected gradient (scaled coordinates, relative to the
      objective's scale at the start) is below it.
    - `callback`: called with each history entry (progress).

    Every iterate is a gait found by Newton from the previous iterate's gait
    (continuation), and no worse than the last: an update whose gait is not found, or
    that makes the objective worse, is halved (back toward the last iterate) up to 7
    times; if no halving helps, a projected steepest-descent step of the same length is
    tried the same way. If neither helps, the design stops with `"no_gait"` (no gait
    found on the way) or `"no_descent"` (gaits found, none better: down to a 128th of a
    step, neither direction improves the objective; typically a kink of the spectral
    radius, where a complex pair of multipliers meets the real axis, or a local minimum).

    **Returns:** a `DesignResult`.
    """
    import optax

    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if not (math.isfinite(learning_rate) and learning_rate > 0):
        raise ValueError(f"learning_rate must be finite and positive, got {learning_rate!r}")
    if model is not None and not isinstance(model, CompassGait):
        raise ValueError(f"design works on a CompassGait, got {type(model).__name__}")
    vary = tuple(vary)
    if not vary or any(v not in PARAMETERS for v in vary) or len(set(vary)) != len(vary):
        raise ValueError(f"vary must be distinct names from {tuple(PARAMETERS)}, got {vary}")
    base = CompassGait() if model is None else model
    extra = sorted(set(bounds or {}) - set(vary))
    if extra:
        raise ValueError(f"bounds given for parameters that are not varied: {extra}")
    bounds = {k: tuple(map(float, (bounds or {}).get(k, DEFAULT_BOUNDS[k]))) for k in vary}
    lo = np.array([bounds[k][0] for k in vary])
    hi = np.array([bounds[k][1] for k in vary])
    if not (np.isfinite(lo).all() and np.isfinite(hi).all() and (0 < lo).all() and (lo < hi).all()):
        raise ValueError(
            f"every bound needs finite 0 < lo < hi (physical parameters), got {bounds}"
        )
    sense = _SENSE[objective]
    if not bool(base.validate()):
        raise ValueError("design: the starting model has a non-positive or non-finite parameter")
    x = np.array([parameters_of(base)[k] for k in vary])
    outside = [
        f"{k} = {v:g} not in [{a:g}, {b:g}]"
        for k, v, a, b in zip(vary, x, lo, hi)
        if not a <= v <= b
    ]
    if outside:
        raise ValueError(
            "design: the starting parameters lie outside the bounds: " + "; ".join(outside)
        )
    g0 = find_gait(with_parameters(base, vary, x), method="shooting", throw=False)
    if g0.result != RESULTS.successful:
        raise ValueError(f"no stable gait at the starting parameters: {result_names(g0.result)}")
    guess = np.asarray(g0.z)
    v, grad, gait = _evaluate(base, vary, x, objective, guess)
    if not np.isfinite(v):
        raise ValueError("the objective is not defined at the starting parameters")
    guess = np.asarray(gait.z)
    scale = max(np.abs(grad * (hi - lo)).max(), 1e-12)

    def entry(k, x, v):
        return {"iteration": k, "params": parameters_of(with_parameters(base, vary, x)), "value": v}

    initial = {
        "params": parameters_of(with_parameters(base, vary, x)),
        "value": v,
        "gradient": dict(zip(vary, map(float, grad))),
    }
    history = [entry(0, x, v)]
    if callback is not None:
        callback(history[-1])
    # A decaying rate: Adam steps have the size of the rate whatever the gradient, so the
    # iterates settle only as it shrinks.
    opt = optax.adam(optax.exponential_decay(learning_rate, 1, 0.92))
    u = (x - lo) / (hi - lo)
    state = opt.init(jnp.asarray(u))
    result, k = "max_iterations", 0
    pg = projected_gradient(u, grad * (hi - lo), sense)
    for k in range(1, steps + 1):
        if np.abs(pg).max() < gtol * scale:
            result = "successful"
            k -= 1
            break
        upd, state = opt.update(jnp.asarray(sense * grad * (hi - lo)), state)
        adam = np.clip(u + np.asarray(upd), 0.0, 1.0)
        # Adam's step first; where no halving of it helps (its momentum may point uphill),
        # a projected steepest-descent step of the same length
        g_u = -sense * grad * (hi - lo)
        length = float(np.linalg.norm(adam - u))
        steepest = np.clip(u + length * g_u / max(float(np.linalg.norm(g_u)), 1e-300), 0.0, 1.0)
        found = accepted = False
        for u_new in (adam, steepest):
            for _ in range(_HALVINGS + 1):
                x_new = lo + u_new * (hi - lo)
                v_new, grad_new, gait_new = _evaluate(base, vary, x_new, objective, guess)
                ok = bool(gait_new.result == RESULTS.successful) and np.isfinite(v_new)
                found |= ok
                if ok and sense * v_new <= sense * v:  # a gait, and no worse: accepted
                    accepted = True
                    break
                u_new = 0.5 * (u + u_new)
            if accepted:
                break
        if not accepted:
            result = "no_descent" if found else "no_gait"
            k -= 1
            break
        u, x, v, grad, gait = u_new, x_new, v_new, grad_new, gait_new
        guess = np.asarray(gait.z)
        pg = projected_gradient(u, grad * (hi - lo), sense)
        history.append(entry(k, x, v))
        if callback is not None:
            callback(history[-1])
    else:
        if np.abs(pg).max() < gtol * scale:
            result = "successful"
    best = with_parameters(base, vary, x)
    spec = gait_spectrum(best, gait)
    optimum = {
        "params": parameters_of(best),
        "value": v,
        "gradient": dict(zip(vary, map(float, grad))),
        "x0": [float(t) for t in np.asarray(gait.x_plus)],
        "multipliers": [complex(t) for t in np.asarray(spec.multipliers)],
        "spectral_radius": float(spec.spectral_radius),
        "stable": bool(spec.spectral_radius < 1.0),
    }
    return DesignResult(
        objective, vary, bounds, result, k, initial, optimum, float(np.abs(pg).max()), history, best
    )


def slope_deg(model):
    return math.degrees(float(model.psi))
