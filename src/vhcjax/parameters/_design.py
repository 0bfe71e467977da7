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
after each update $u$ is projected back onto the box (projected Adam). Where Adam's step
fails (a kink of the objective: for the spectral radius, where a complex pair of
multipliers meets the real axis), the design goes on by gradient sampling (Burke, Lewis
and Overton 2005): the shortest vector in the convex hull of gradients sampled near the
iterate is a descent direction along the kink.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._results import RESULTS, result_names
from ..gait import find_gait
from ..models import CompassGait  # design varies the compass gait's parameters (PARAMETERS)
from ..stability import gait_spectrum
from ._flip import flip_slope, flip_slopes

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
#: Default bounds of the parameters for the thesis's walker (20 kg, 1 m, 9.81 m/s^2);
#: `default_bounds` scales them to another walker's own units.
DEFAULT_BOUNDS = {
    "mass-hip": (1.0, 40.0),
    "mass-leg": (1.0, 20.0),
    "a": (0.1, 0.9),
    "b": (0.1, 0.9),
    "gravity": (1.0, 20.0),
}
_KINDS = {
    "mass-hip": "mass",
    "mass-leg": "mass",
    "a": "length",
    "b": "length",
    "gravity": "acceleration",
}
_THESIS_SCALES = {"mass": 20.0, "length": 1.0, "acceleration": 9.81}


def default_bounds(model):
    """`DEFAULT_BOUNDS` in the same proportion to `model`'s own units (`scales`: its total
    mass, leg length and gravity) as to the thesis's walker's."""
    sc = model.scales()
    out = {}
    for name, (lo, hi) in DEFAULT_BOUNDS.items():
        kind = _KINDS[name]
        f = float(sc[kind]) / _THESIS_SCALES[kind]
        out[name] = (float(f"{lo * f:.12g}"), float(f"{hi * f:.12g}"))
    return out


OBJECTIVES = ("spectral-radius", "flip-slope", "speed")
#: Halvings of a step that finds no gait or makes the objective worse.
_HALVINGS = 7
#: Halvings of a gradient-sampling step (Armijo backtracking).
_SAMPLED_HALVINGS = 12
#: Sufficient decrease of a gradient-sampling step: `_ARMIJO * t * |d|^2`.
_ARMIJO = 1e-4
#: Gradient sampling stops when its radius (scaled coordinates) falls below this.
_MIN_RADIUS = 1e-5
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
    - `result`: `"successful"` (a stationary point: the projected gradient, or at a kink
      the shortest sampled gradient, below tolerance), `"max_iterations"`,
      `"no_descent"` (gradient sampling found no step that improves the objective, down
      to its smallest radius) or `"no_gait"` (no gait found along the last step).
    - `initial`, `optimum`: dicts with `params` (all five parameters), `value`,
      `gradient` (per varied parameter, of the objective in its own units), and for the
      optimum `x0` (post-impact state), `multipliers` (complex), `spectral_radius` and
      `stable` (whether the optimal gait is stable: a speed design may leave the stable
      walkers).
    - `projected_gradient`: max-norm of the projected gradient at the optimum, in the
      scaled coordinates $u \\in [0, 1]$.
    - `history`: one dict per iterate: `iteration`, `params`, `value`, `step` (how it
      was reached: `"start"`, `"adam"` or `"gradient sampling"`).
    - `model`: the optimal model.
    - `stationarity`, `sampling_radius`: where the design went on by gradient sampling,
      the max-norm of the shortest vector in the convex hull of the projected gradients
      sampled within `sampling_radius` (scaled coordinates) of the optimum (the smallest
      radius where it fell below tolerance, else the last measured): Clarke
      stationarity at a kink, where `projected_gradient` need not vanish; `None` where
      nothing was sampled at the optimum (Adam's steps, or a last accepted step).
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
    stationarity: float | None = eqx.field(static=True, default=None)
    sampling_radius: float | None = eqx.field(static=True, default=None)


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


def min_norm_element(G):
    """The shortest vector in the convex hull of the rows of `G`: Wolfe's (1976) finite
    active-set method (the affine minimum-norm point of a growing corral of rows)."""
    P = np.asarray(G, float)
    norms = np.einsum("ij,ij->i", P, P)
    S = [int(np.argmin(norms))]
    lam = np.ones(1)
    x = P[S[0]]
    for _ in range(50 * len(P)):  # major cycles: add the row most opposed to x
        j = int(np.argmin(P @ x))
        # the duality gap relative to |x|^2 (not to the largest row: next to a
        # square-root kink one gradient can be orders of magnitude larger than x)
        if x @ x - P[j] @ x <= 1e-12 * (x @ x) or j in S:
            break
        S.append(j)
        lam = np.append(lam, 0.0)
        while True:  # minor cycles: move to the corral's affine minimum, dropping rows
            # the affine minimum P_0 + sum_i w_i (P_i - P_0) by least squares on the
            # differences (conditioned like the rows, not like their Gram matrix)
            D = (P[S[1:]] - P[S[0]]).T
            w = np.linalg.lstsq(D, -P[S[0]], rcond=None)[0]
            y = np.r_[1.0 - w.sum(), w]
            if (y > 1e-14).all():
                lam = y
                break
            neg = y <= 1e-14
            theta = min(1.0, float(np.min(lam[neg] / (lam[neg] - y[neg]))))
            lam = theta * y + (1.0 - theta) * lam
            keep = lam > 1e-14
            keep[np.argmax(lam)] = True
            S = [i for i, k in zip(S, keep) if k]
            lam = lam[keep] / lam[keep].sum()
        x = lam @ P[S]
    return x


@host_only("`jax.grad` of your objective through `find_gait`")
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
    method="auto",
):
    """Optimise a compass-gait walker for `objective` over the parameters `vary`.

    **Arguments:**

    - `objective`: `"spectral-radius"` (minimised), `"flip-slope"` or `"speed"`
      (maximised).
    - `vary`: names from `PARAMETERS` (`"mass-hip"`, `"mass-leg"`, `"a"`, `"b"`,
      `"gravity"`).
    - `model`: the starting `CompassGait` (its `psi` is the design slope); default
      thesis Table 1 at 3 degrees. It must have a stable gait.
    - `bounds`: `{name: (lo, hi)}` for some of `vary` (others: the thesis walker's
      default bounds, in the same proportion to `model`'s mass, length and gravity).
    - `steps`: iterations at most (accepted steps); `learning_rate`: Adam's, in the
      scaled coordinates (Adam sees the gradient divided by its size at the start, so
      that its `eps` does not depend on the objective's unit).
    - `method`: the search of the starting gait (`find_gait`, continued from the
      reference gait; default `"auto"`); later gaits are searched by shooting from the
      last one.
    - `gtol`: stop when the projected gradient (scaled coordinates, relative to the
      objective's scale at the start) is below it.
    - `callback`: called with each history entry (progress).

    Every iterate is a gait found by Newton from the previous iterate's gait
    (continuation), and no worse than the last: an Adam update whose gait is not found,
    or that makes the objective worse, is halved (back toward the last iterate) up to 7
    times. If no halving helps (typically a kink of the spectral radius, where a complex
    pair of multipliers meets the real axis and the gradient jumps), the design goes on
    by gradient sampling: `2 len(vary)` gradients at random points within a radius
    (first `learning_rate`, scaled coordinates) of the iterate, projected onto the box;
    the shortest vector `d` in the convex hull of the iterate's gradient and those of
    every point evaluated within the radius since the last accepted step (samples and
    failed trial steps); a step along `-d` by Armijo backtracking, first no longer than
    `learning_rate` and halved until a trial lies within the radius (where none
    descends, once more with the failed trials' gradients). Where `d` is below
    tolerance, or no step along it descends, the radius shrinks tenfold; below 1e-5 the
    design stops, with `"successful"` (Clarke-stationary: `d` below tolerance within
    some radius), `"no_descent"` or `"no_gait"`. The samples come from a fixed seed: a
    design is reproducible.

    **Returns:** a `DesignResult`.
    """
    import optax

    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    if not (math.isfinite(learning_rate) and learning_rate > 0):
        raise ValueError(f"learning_rate must be finite and positive, got {learning_rate!r}")
    if not (math.isfinite(gtol) and gtol > 0):
        raise ValueError(f"gtol must be finite and positive, got {gtol!r}")
    if model is not None and not isinstance(model, CompassGait):
        raise ValueError(f"design works on a CompassGait, got {type(model).__name__}")
    vary = tuple(vary)
    if not vary or any(v not in PARAMETERS for v in vary) or len(set(vary)) != len(vary):
        raise ValueError(f"vary must be distinct names from {tuple(PARAMETERS)}, got {vary}")
    base = CompassGait() if model is None else model
    extra = sorted(set(bounds or {}) - set(vary))
    if extra:
        raise ValueError(f"bounds given for parameters that are not varied: {extra}")
    defaults = default_bounds(base)
    bounds = {k: tuple(map(float, (bounds or {}).get(k, defaults[k]))) for k in vary}
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
    g0 = find_gait(with_parameters(base, vary, x), "stable", method, throw=False)
    if g0.result != RESULTS.successful:
        raise ValueError(f"no stable gait at the starting parameters: {result_names(g0.result)}")
    guess = np.asarray(g0.z)
    v, grad, gait = _evaluate(base, vary, x, objective, guess)
    if not np.isfinite(v):
        why = ""
        if objective == "flip-slope":  # the scan says why it found no flip
            m = with_parameters(base, vary, x)
            scan = flip_slopes(m, np.asarray(gait.z)[None], float(m.psi))
            why = f": {scan.reason[0]}" if scan.reason[0] else ""
        raise ValueError("the objective is not defined at the starting parameters" + why)
    guess = np.asarray(gait.z)
    # the gradient's size at the start, in the objective's unit: the tolerance `gtol` and
    # Adam's `eps` are relative to it (a gradient of exactly zero: stationary at once)
    scale = float(np.abs(grad * (hi - lo)).max()) or 1.0

    def entry(k, x, v, step):
        params = parameters_of(with_parameters(base, vary, x))
        return {"iteration": k, "params": params, "value": v, "step": step}

    initial = {
        "params": parameters_of(with_parameters(base, vary, x)),
        "value": v,
        "gradient": dict(zip(vary, map(float, grad))),
    }
    history = [entry(0, x, v, "start")]
    if callback is not None:
        callback(history[-1])
    found = [True]  # whether the last failed line search found any gait
    bundle = []  # (u, gradient) of every point evaluated since the last accepted step

    def evaluate(u_new):
        """`(u, x, value, gradient, gait)` at scaled parameters `u_new`; `None` without
        a gait (Newton from the last iterate's gait: continuation)."""
        x_new = lo + u_new * (hi - lo)
        v_new, grad_new, gait_new = _evaluate(base, vary, x_new, objective, guess)
        finite = np.isfinite(v_new) and np.isfinite(grad_new).all()
        if not (bool(gait_new.result == RESULTS.successful) and finite):
            return None
        bundle.append((u_new, grad_new))
        return u_new, x_new, v_new, grad_new, gait_new

    def line_search(path, decrease, halvings, t=1.0):
        """The first of `path(t), path(t/2), ...` with a gait and `sense * value` at most
        `sense * v - decrease(u_trial)` (Armijo; `None`: no worse than the last)."""
        found[0] = False
        for _ in range(halvings + 1):
            trial = evaluate(path(t))
            if trial is not None:
                found[0] = True
                need = 0.0 if decrease is None else decrease(trial[0])
                if sense * trial[2] <= sense * v - need:
                    return trial
            t *= 0.5
        return None

    # A decaying rate: Adam steps have the size of the rate whatever the gradient, so the
    # iterates settle only as it shrinks.
    opt = optax.adam(optax.exponential_decay(learning_rate, 1, 0.92))
    u = (x - lo) / (hi - lo)
    state = opt.init(jnp.asarray(u))
    result, k, sampling = "max_iterations", 0, False
    radius, measured, certified, retried = learning_rate, None, None, False
    rng = np.random.default_rng(0)
    pg = projected_gradient(u, grad * (hi - lo), sense)
    while k < steps:
        if not sampling and np.abs(pg).max() < gtol * scale:
            result = "successful"
            break
        if not sampling:
            # 1. Adam (optax): its step, halved back toward the last iterate until it
            # finds a gait no worse than the last
            upd, state = opt.update(jnp.asarray(sense * grad * (hi - lo) / scale), state)
            u_new = np.clip(u + np.asarray(upd), 0.0, 1.0)
            step = line_search(lambda t: u + t * (u_new - u), None, _HALVINGS)
            if step is None:  # a kink (or momentum uphill): gradient sampling from here on
                sampling = True
                continue
        else:
            # 2. gradient sampling: the shortest vector in the convex hull of gradients
            # sampled within `radius` is a descent direction at a kink (components held
            # at a bound by the iterate's own gradient are left out)
            for _ in range(2 * len(vary)):
                du = rng.normal(size=u.size)
                du *= radius * rng.uniform() ** (1.0 / u.size) / np.linalg.norm(du)
                evaluate(np.clip(u + du, 0.0, 1.0))
            # with the points of failed line searches within the radius: across a kink,
            # they hold the gradients of its other side
            grads = [grad] + [g for w, g in bundle if np.linalg.norm(w - u) <= radius]
            held = projected_gradient(u, grad * (hi - lo), sense) != sense * grad * (hi - lo)
            d = min_norm_element(np.where(held, 0.0, sense * np.array(grads) * (hi - lo)))
            measured = (radius, float(np.abs(d).max()))
            step = None
            if measured[1] < gtol * scale:  # stationary within this radius
                certified = measured
            else:
                # first a step no longer than Adam's rate (Newton from the last gait must
                # stay on its branch), halved until a trial lies within the radius: a
                # failed search leaves gradients there for the next round; the decrease
                # asked for is the one of the clipped (actual) step
                dn = d / scale  # unit-free, as Adam's steps
                t0 = min(1.0, learning_rate / float(np.linalg.norm(dn)))
                n = max(
                    _SAMPLED_HALVINGS,
                    math.ceil(math.log2(t0 * float(np.linalg.norm(dn)) / radius)) + 1,
                )
                step = line_search(
                    lambda t: np.clip(u - t * dn, 0.0, 1.0),
                    lambda w: _ARMIJO * float(dn @ (u - w)) * scale,
                    n,
                    t0,
                )
                if step is None and not retried:  # again, with the failed trials' gradients
                    retried = True
                    continue
            if step is None:  # stationary, or no descent at this radius: look closer
                retried = False
                radius *= 0.1
                if radius < _MIN_RADIUS:
                    result = "successful" if certified else "no_descent"
                    break
                continue
            certified, measured, retried = None, None, False
        k += 1
        u, x, v, grad, gait = step
        bundle.clear()
        guess = np.asarray(gait.z)
        pg = projected_gradient(u, grad * (hi - lo), sense)
        history.append(entry(k, x, v, "gradient sampling" if sampling else "adam"))
        if callback is not None:
            callback(history[-1])
    if result == "max_iterations" and not sampling and np.abs(pg).max() < gtol * scale:
        result = "successful"
    if result == "no_descent" and not found[0]:
        result = "no_gait"
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
        objective,
        vary,
        bounds,
        result,
        k,
        initial,
        optimum,
        float(np.abs(pg).max()),
        history,
        best,
        (certified or measured or (None, None))[1],
        (certified or measured or (None, None))[0],
    )


def slope_deg(model):
    return math.degrees(float(model.psi))
