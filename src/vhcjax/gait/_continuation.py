"""Continuation: homotopy in the model parameters from a known gait (secant predictor),
and the tangent of a gait along a parameter path (implicit differentiation of the
residual)."""

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp

from .._batching import report
from .._programs import stored_jit
from .._results import RESULTS
from ._dispatch import _check, _relabel, _search
from ._gait import family_sign, gait_in_units, section_in_units
from ._problem1 import vhc_residual
from ._shooting import _shoot_eval


# ---------------------------------------------------------------------------------------
# Continuation (homotopy in the parameters; sweeps in the slope)
# ---------------------------------------------------------------------------------------
def _unknowns(gait, method):
    return jnp.stack([gait.a, gait.b]) if method == "vhc" else jnp.stack([gait.a, gait.b, gait.f])


def _on_curve(result):
    """Gaits found, of the family sought or (past a double root of (5.13)) of the other:
    points on one curve of gaits. Traceable."""
    return (result == RESULTS.successful) | (result == RESULTS.other_cycle)


def _residual(model, z, sign, method):
    if method == "vhc":
        return vhc_residual(model, z, sign)
    return _shoot_eval(model, z)[0]


def _tangent(path, s, z, sign, method):
    r"""$dz^*/ds = -(\partial r/\partial z)^{-1}\,\partial r/\partial s$ along `path(s)` (implicit
    differentiation of the residual; one forward-mode Jacobian in $(z, s)$)."""
    k = z.shape[0]
    J = jax.jacfwd(lambda w: _residual(path(w[k]), w[:k], sign, method))(
        jnp.concatenate([z, jnp.asarray(s, z.dtype)[None]])
    )
    t = -jnp.linalg.solve(J[:, :k], J[:, k])
    return jnp.where(jnp.isfinite(t).all(), t, jnp.zeros_like(t))


def _mix(kind, p0, p1, s):
    """A parameter a fraction `s` of the way from `p0` to `p1`: lengths linearly (in the
    walker's own units they are fractions of its size, and may be zero), every other
    parameter geometrically where both ends are positive (masses over decades, slopes),
    else linearly."""
    p0, p1 = jnp.asarray(p0, dtype=float), jnp.asarray(p1, dtype=float)
    linear = p0 + (p1 - p0) * s
    if kind == "length":
        return linear
    both = (p0 > 0) & (p1 > 0)
    q0, q1 = jnp.where(both, p0, 1.0), jnp.where(both, p1, 1.0)
    return jnp.where(both, q0 * (q1 / q0) ** s, linear)


def _path(start, end):
    r"""$s \mapsto$ the model a fraction `s` of the way from `start` (s = 0) to `end`
    (s = 1), every float parameter at once (`_mix`); `s` may leave [0, 1]."""
    units = type(end).UNITS

    def path(s):
        m = end
        for f in dataclasses.fields(end):
            p0, p1 = getattr(start, f.name, None), getattr(end, f.name)
            if not eqx.is_inexact_array(p1) or p0 is None:
                continue
            value = _mix(units.get(f.name), p0, p1, s)
            m = eqx.tree_at(lambda mm: getattr(mm, f.name), m, value)
        return m

    return path


@stored_jit
def _continue(start, end, s_buf, n, z0, sign, method, s_prev=None, z_prev=None):
    """Follow the solution of the model `_path(start, end)(s)` through `s_buf[:n]`
    (a `fori_loop` with a dynamic length over a fixed-size buffer), from the seed `z0` at
    `s_buf[0]`, with a secant predictor: the line through the last two points solved,
    the first of them `(s_prev, z_prev)` if given (the first step from the seed alone
    starts at the seed). A failed point does not move the line: the next one is
    predicted from the last two gaits found (of either family).

    The search is traced once, into a jaxpr (`jax.closure_convert`): the buffer's shapes
    come from it and the loop replays it (tracing it again for the shapes alone would
    cost as much as the first time).

    **Returns:** a batched `Gait` (one per buffer entry; entries from `n` on are unset).
    """
    path = _path(start, end)
    s0 = s_buf[0]
    # every guess a prediction next to the last gait: Newton in (a, h) throughout (VHC)
    search, consts = jax.closure_convert(
        lambda s, z: _search(path(s), z, sign, method, far=math.inf), s0, z0
    )
    shape = jax.eval_shape(search, s0, z0, *consts)
    buf = jax.tree_util.tree_map(lambda l: jnp.zeros((s_buf.shape[0],) + l.shape, l.dtype), shape)

    def body(i, carry):
        s_prev, z_prev, s_good, z_good, buf = carry
        s = s_buf[i]
        slope = jnp.where(s_good != s_prev, (z_good - z_prev) / (s_good - s_prev), 0.0)
        gait = search(s, z_good + slope * (s - s_good), *consts)
        # a gait of the other family (its d the other root of 5.13) lies on the same
        # curve of gaits, past a double root: it carries the predictor too
        ok = _on_curve(gait.result)
        z_new = _unknowns(gait, method)
        buf = jax.tree_util.tree_map(lambda b, v: b.at[i].set(v), buf, gait)
        # a point equal to the last success (the seed re-solved) keeps the older one
        move = ok & (s != s_good)
        return (
            jnp.where(move, s_good, s_prev),
            jnp.where(move, z_good, z_prev),
            jnp.where(ok, s, s_good),
            jnp.where(ok, z_new, z_good),
            buf,
        )

    if s_prev is None:
        s_prev, z_prev = s0, z0
    init = (jnp.asarray(s_prev, s0.dtype), jnp.asarray(z_prev, z0.dtype), s0, z0, buf)
    return jax.lax.fori_loop(0, n, body, init)[-1]


#: Points per call of the compiled continuation: every length of continuation runs as
#: calls of this one size, so one program serves them all.
_CHUNK = 16


def _run_continuation(start, end, s_values, z0, sign, method):
    """Host wrapper: run `_continue` over `s_values` in calls of `_CHUNK` points. Each call
    after the first starts again from the last point solved (re-solved as its first entry,
    dropped) with the secant line through it and the success before, so the result is
    that of one long loop up to rounding. **Returns:** the gaits as numpy arrays (host
    side).
    """
    import numpy as np

    s_values = np.asarray(s_values, dtype=float)
    z0 = np.asarray(z0, dtype=float)
    n = len(s_values)
    parts = []
    s_start, z_start, done = s_values[0], z0, 0
    s_prev, z_prev = s_start, z_start
    while done < n:
        first = done == 0
        new = s_values[done : done + (_CHUNK if first else _CHUNK - 1)]
        s_run = new if first else np.concatenate([[s_start], new])
        k = len(s_run)
        s_buf = np.concatenate([s_run, np.full(_CHUNK - k, s_run[-1])])
        # `k` traced: a short last call shares the program.
        out = _continue(
            start, end, s_buf, np.asarray(k), z_start, sign, method, np.asarray(s_prev), z_prev
        )
        skip = 0 if first else 1
        gaits = jax.tree_util.tree_map(lambda x: x[skip:k], jax.device_get(out))
        parts.append(gaits)
        # the last two successes so far carry the secant line into the next call
        ok = np.flatnonzero(np.asarray(_on_curve(gaits.result)))
        solved = [(s_prev, z_prev), (s_start, z_start)] + [
            (new[i], np.asarray(_unknowns(jax.tree_util.tree_map(lambda x: x[i], gaits), method)))
            for i in ok[-2:]
        ]
        (s_prev, z_prev), (s_start, z_start) = solved[-2:]
        done += len(new)
        if n > _CHUNK:
            report("continuation", len(parts), 1 + -(-(n - _CHUNK) // (_CHUNK - 1)))
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)


_HOMOTOPY_STEPS = 16


def _seed(model, sign, method):
    """The start of a continuation to `model` in its own units: `(start, z0)`, the
    `reference_gait` of the family of `sign` (traced signs choose between the two), its
    unknowns for `method` ($(a, b)$ for the VHC search, the section point for
    shooting)."""
    ref, z_stable = model.reference_gait("stable")
    _, z_unstable = model.reference_gait("unstable")
    z = jnp.where(sign < 0, z_stable, z_unstable)
    z = section_in_units(ref, z, ref.scales()["time"])
    return ref.in_own_units(), (z[:2] if method == "vhc" else z)


#: Largest relative change of a physical parameter in one homotopy step (`num=None`).
_HOMOTOPY_RATIO = 0.015


def _homotopy_steps(start, end):
    """Steps of the homotopy from `start` to `end` (`_path`): at least `_HOMOTOPY_STEPS`,
    and enough that no parameter changes by more than `_HOMOTOPY_RATIO` in one step
    (relative, or absolute for lengths in the walker's own units); one where `end` is
    `start` (the reference walker itself: its gait is solved where it starts)."""
    import numpy as np

    units = type(end).UNITS
    spread = 0.0
    with np.errstate(invalid="ignore", divide="ignore"):  # an invalid model: bad_input
        for f in dataclasses.fields(end):
            p0, p1 = getattr(start, f.name, None), getattr(end, f.name)
            if not eqx.is_inexact_array(p1) or p0 is None:
                continue
            p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
            if units.get(f.name) != "length" and np.all(p0 > 0) and np.all(p1 > 0):
                change = np.abs(np.log(p1 / p0))
            else:
                change = np.abs(p1 - p0)
            spread = max(spread, float(np.max(change)))
    if not np.isfinite(spread):  # the search codes the model bad_input
        return _HOMOTOPY_STEPS
    if spread == 0.0:
        return 1
    return max(_HOMOTOPY_STEPS, int(np.ceil(spread / np.log1p(_HOMOTOPY_RATIO))) + 1)


def continue_to_model(model, family="stable", method="vhc", num=None):
    """The `family` gait of `model` without a guess: homotopy from the model's `reference_gait` (for the compass gait the default
    walker at 3 degrees, thesis Table 1) to `model`, all parameters at once (`_path`), in
    `num` steps with a secant predictor (`None`: at least 16, and no parameter changing
    by more than 1.5 % in a step; one for the reference walker itself). `method`:
    `"vhc"` or `"shooting"`. It runs in the walker's own units (`in_own_units`): gravity
    and size drop out.

    **Returns:** a `Gait` (never raises; check `result`).
    """
    import numpy as np

    _check(family, method)
    sign = family_sign(family)
    own = model.in_own_units()
    start, z0 = _seed(own, sign, method)
    if num is None:
        num = _homotopy_steps(start, own)
    gaits = _run_continuation(start, own, np.linspace(0.0, 1.0, num), z0, sign, method)
    gait = _relabel(jax.tree_util.tree_map(lambda x: x[-1], gaits), family)
    return _finite_gait_in_units(gait, model)


@eqx.filter_jit
def _finite_gait_in_units(gait, model):
    """`gait_in_units`; a failed gait's placeholders stay finite (a period of 0 would
    make its speed NaN)."""
    out = gait_in_units(gait, model)
    bad = out.result != RESULTS.successful
    return jax.tree_util.tree_map(
        lambda x: jnp.where(bad & ~jnp.isfinite(x), 0.0, x) if eqx.is_inexact_array(x) else x,
        out,
    )
