"""Stability of gaits: multipliers two ways, period doubling, period-k gaits, bifurcations.

- `gait_multipliers`: Floquet multipliers of a period-1 gait by the transverse
  linearization (thesis ch. 6, `vhcjax.stability`) and, independently, as the
  eigenvalues of the Poincare-map Jacobian by forward-mode autodiff through the
  heel-strike events (`vhcjax.hybrid.jacobian`). Batched over slopes by `vmap`
  (`family_multipliers`).
- `midswing_multipliers`: the same multipliers on another Poincare section
  ($q_1 = 0$ in mid-swing), a check that they do not depend on the section.
- `period1_family`: the period-1 gaits over a range of slopes (continuation).
- `period_doubling_slope`: where a multiplier of the stable family crosses $-1$
  (secant/bisection on $\\det(I + J)$, which changes sign there).
- `period_k_orbit`: fixed points of $P^k$ (k = 2, 4) with their multipliers.
- `bifurcation_diagram`: Goswami et al. (1998) style: long batched simulations from
  the period-1 gait, step periods of the last steps against slope, falls marked.
"""

import math
import warnings

import diffrax
import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .. import hybrid as _poincare
from .._batching import MAX_DISPATCH, host_workers, padded_map
from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import (
    DEFAULT_CONFIG,
    FAST_CONFIG,
    check_map_steps,
    check_section_shape,
    flow,
    ode_solver,
    simulate,
    solve_to_event,
    step_map,
    step_unchecked,
)
from ..models import CompassGait  # the default model (thesis Table 1) where none is given
from ._transverse import TransverseLinearization, transverse_linearization

#: Stable and unstable period-1 gaits of the default compass gait at 3 degrees
#: (section coordinates $(q_1, \dot q_1, \dot q_2)$), e.g. Newton seeds for `fixed_point`.
SEEDS_3DEG = {
    "stable": (0.2186688, -1.09238359, -0.37737395),
    "unstable": (0.20467554, -1.21057184, -0.71248882),
}


def _sort(ev):
    return ev[jnp.argsort(-jnp.abs(ev))]


# ---- multipliers of one gait, two ways --------------------------------------------------
class GaitMultipliers(eqx.Module):
    """Multipliers of a period-1 gait, by two methods, with a check of each.

    - `transverse`: eigenvalues of $\\Xi$ (thesis 6.42), complex (2n-1,), by modulus.
      Trust them only where `transverse_result` is `successful`.
    - `poincare`: eigenvalues of the Poincare-map Jacobian (jacfwd through the events).
    - `max_abs`: the largest modulus of the Poincare multipliers (the method whose
      assumptions hold for every gait the hybrid simulator completes; where the
      transverse linearization holds the two agree to 1e-6).
    - `stable`: `max_abs < 1`.
    - `period`, `x_minus`: from the hybrid step.
    - `result`: `successful`, or the failure of the hybrid step, `nonfinite` where the
      Poincare Jacobian is not finite, `not_a_gait` where one step moves `z` by more
      than `GAIT_TOL` (no fixed point: no multipliers), `bad_input` for an invalid model.
    - `transverse_result`: `successful`, or why the transverse multipliers are not to be
      trusted: the failure of its integration (`no_impact`, `max_steps_reached`,
      `nonfinite`), `phase_not_monotone` ($\\dot q_1$ changes sign along the orbit:
      thesis ch. 6 needs a monotone phase), `ill_conditioned` (condition number of
      $[L; m^T]$ above `MAX_CONDITION`, or the flow nearly tangent to the impact
      surfaces), `methods_disagree` (the construction does not reproduce the orbit of the
      hybrid step, or its multipliers differ from the Poincare ones by more than
      `AGREEMENT_RTOL` relative to the spectral radius).
    - `disagreement`: that relative difference (symmetric nearest-eigenvalue distance
      over the Poincare spectral radius).
    - `condition`: the larger condition number of $[L; m^T]$ at the two ends.
    - `linearization`: the full `TransverseLinearization` (Xi, Phi(T), dF, ...).

    Computed with `transverse=False`, only the Poincare multipliers are there:
    `transverse`, `disagreement`, `condition` and `linearization` are `None` and
    `transverse_result` is `not_requested`.
    """

    transverse: jax.Array | None
    poincare: jax.Array
    max_abs: jax.Array
    stable: jax.Array
    period: jax.Array
    x_minus: jax.Array
    result: RESULTS
    transverse_result: RESULTS
    disagreement: jax.Array | None
    condition: jax.Array | None
    linearization: TransverseLinearization | None


#: Relative difference above which the two multiplier computations disagree.
AGREEMENT_RTOL = 1e-6
#: Condition number of $[L; m^T]$ (transverse coordinates) above which they are not used.
MAX_CONDITION = 1e8


def _spectral_distance(a, b):
    """Symmetric nearest-eigenvalue distance between spectra `a` and `b` over the spectral
    radius of `b` (0 where they are the same set)."""
    d = jnp.abs(a[:, None] - b[None, :])
    dist = jnp.maximum(jnp.max(jnp.min(d, axis=1)), jnp.max(jnp.min(d, axis=0)))
    return dist / jnp.maximum(jnp.max(jnp.abs(b)), jnp.finfo(b.real.dtype).tiny)


def _phase_monotone(model, x0, period, config):
    """Whether $\\dot q_1$ keeps the sign it has at the start, with a margin of 1e-6 of its
    initial modulus, at the end of every solver step over the step's period."""
    n = model.n_dof
    s = jnp.sign(x0[n])
    margin = 1e-6 * jnp.abs(x0[n])
    # A boolean event stops the integration at the end of the first solver step where the
    # sign is lost (steps are short where the motion is fast). No array of save times:
    # diffrax checks those with a host callback, which keeps a program out of JAX's
    # persistent compilation cache.
    event = diffrax.Event(lambda t, y, args, **kwargs: s * y[n] <= margin)
    sol = flow(model, x0, period, config, event=event)
    assert sol.ys is not None  # saved at the end
    reached = sol.result == diffrax.RESULTS.successful
    return reached & (s * sol.ys[-1, n] > margin) & jnp.all(jnp.isfinite(sol.ys))


def _transverse_checks(model, x0, sr, tl, pm, config):
    """`transverse_result`, `disagreement`, `condition` (see `GaitMultipliers`)."""
    condition = tl.condition
    ill = (condition > MAX_CONDITION) | (tl.transversality < 1e-8)
    scale = jnp.maximum(jnp.max(jnp.abs(sr.x_minus)), 1.0)
    orbit_off = (jnp.max(jnp.abs(tl.x_minus - sr.x_minus)) > AGREEMENT_RTOL * scale) | (
        jnp.abs(tl.period - sr.period) > AGREEMENT_RTOL * jnp.abs(sr.period)
    )
    disagreement = _spectral_distance(tl.multipliers, pm)
    disagreement = jnp.where(jnp.isfinite(disagreement), disagreement, jnp.inf)
    monotone = _phase_monotone(model, x0, sr.period, config)
    # The cause first: with a non-monotone phase the construction's own integration
    # usually fails too (phi' = dq2/dq1 blows up where dq1 = 0).
    code = RESULTS.where(monotone, tl.result, RESULTS.phase_not_monotone)
    for bad, c in (
        (ill, RESULTS.ill_conditioned),
        (orbit_off | (disagreement > AGREEMENT_RTOL), RESULTS.methods_disagree),
    ):
        code = RESULTS.where((code == RESULTS.successful) & bad, c, code)
    return code, disagreement, condition


#: How far (section coordinates, relative to max(1, |z|)) one step may move a state for
#: it to count as a period-1 gait in `gait_multipliers`: gaits found by the searches
#: close to about 1e-10.
GAIT_TOL = 1e-6


def returns_to(z, z_next):
    """Whether one step from the section point `z` came back to it: `z_next` within
    `GAIT_TOL` $\\max(1, \\|z\\|_\\infty)$ (False where not finite). Traceable."""
    moved = jnp.max(jnp.abs(jnp.asarray(z_next) - jnp.asarray(z)))
    return moved <= GAIT_TOL * jnp.maximum(1.0, jnp.max(jnp.abs(jnp.asarray(z))))


def _gait_multipliers(model, z, config=DEFAULT_CONFIG, transverse=True):
    """Both multiplier computations at the period-1 gait with section coordinates `z`,
    with the checks of the transverse one (`transverse=False`: the Poincare ones only)."""
    z = jnp.asarray(z, float)
    x0 = model.section_to_state(z)

    def step(zz):  # the step map and, as a by-product, the step itself
        sr = step_unchecked(model, model.section_to_state(zz), config)
        return model.state_to_section(sr.x_plus), sr

    # the Jacobian of the step map (as `hybrid.jacobian`) with the step in the same pass
    J, sr = jax.jacfwd(step, has_aux=True)(z)
    pm = _sort(jnp.linalg.eigvals(J))
    # multipliers are those of a fixed point of the step map only
    periodic = returns_to(z, model.state_to_section(sr.x_plus))
    code = RESULTS.where(
        sr.result == RESULTS.successful,
        RESULTS.where(
            jnp.all(jnp.isfinite(pm)),
            RESULTS.where(periodic, RESULTS.successful, RESULTS.not_a_gait),
            RESULTS.nonfinite,
        ),
        sr.result,
    )
    code = RESULTS.where(model.validate(), code, RESULTS.bad_input)
    ok = code == RESULTS.successful
    if not transverse:
        pm = jnp.where(ok, pm, 0.0)
        mx = jnp.max(jnp.abs(pm))
        tcode = RESULTS.where(ok, RESULTS.not_requested, code)
        return GaitMultipliers(
            None, pm, mx, ok & (mx < 1.0), sr.period, sr.x_minus, code, tcode, None, None, None
        )
    tl = transverse_linearization(model, x0, sr.x_minus, sr.period)
    tcode, disagreement, condition = _transverse_checks(model, x0, sr, tl, pm, config)
    tcode = RESULTS.where(ok, tcode, code)
    pm = jnp.where(ok, pm, 0.0)
    mx = jnp.max(jnp.abs(pm))
    # No NaN or inf in a result: where the construction broke down its matrices are
    # placeholders (0 where not finite); `transverse_result` says why.
    broke = tcode != RESULTS.successful
    tl = jax.tree_util.tree_map(
        lambda x: jnp.where(broke & ~jnp.isfinite(x), 0.0, x) if eqx.is_inexact_array(x) else x, tl
    )
    tr = jnp.where(ok, tl.multipliers, 0.0)  # no multipliers where there is no gait
    return GaitMultipliers(
        tr, pm, mx, ok & (mx < 1.0), sr.period, sr.x_minus, code, tcode, disagreement, condition, tl
    )


@stored_jit
def _family_multipliers_padded(model, psis, zs, config, transverse):
    return jax.vmap(lambda p, z: _gait_multipliers(model.with_slope(p), z, config, transverse))(
        psis, zs
    )


def family_multipliers(model, psis, zs, config=DEFAULT_CONFIG, *, transverse=True, mesh=None):
    """`gait_multipliers` for many slopes in one batched (`vmap`) call.

    `psis` (B,) in rad, `zs` (B, 2n-1) the gaits there. Returns a batched
    `GaitMultipliers`. The batch runs in padded chunks (`_batching.padded_map`: a power of
    two up to 256 members, so that nearby sizes share one compilation; one chunk per CPU
    core at a time), split over the devices of `mesh` (default: all local devices). A
    host-side function (concrete inputs; the result's leaves are numpy arrays); under
    `jit` or a derivative, `vmap` `gait_multipliers` instead.
    """
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((model, psis, zs))):
        raise TypeError(
            "family_multipliers runs on the host (concrete inputs); under jit, vmap or a "
            "derivative, vmap gait_multipliers instead"
        )
    psis = np.atleast_1d(np.asarray(psis, float))
    zs = np.asarray(zs, float)
    x = jax.ShapeDtypeStruct((2 * model.n_dof,), jnp.float64)
    n = jax.eval_shape(model.state_to_section, x).shape[0]
    B = psis.shape[0]
    one = B == 1 and zs.shape == (n,)  # one gait, without its batch axis
    if psis.ndim != 1 or B == 0 or not (zs.shape == (B, n) or one):
        raise ValueError(
            f"family_multipliers: psis must have shape (B,) with B >= 1 and zs shape (B, {n}), "
            f"got {psis.shape} and {zs.shape}"
        )
    _check_single_domain(model, transverse, "family_multipliers")
    zs = zs.reshape(B, n)
    out = padded_map(
        lambda p, z: _family_multipliers_padded(model, p, z, config, transverse),
        psis,
        zs,
        mesh=mesh,
        stage="multipliers",
        to_host=True,
    )
    return jax.device_get(out)


def gait_multipliers(model, z, config=DEFAULT_CONFIG, *, transverse=True):
    """Both multiplier computations at the period-1 gait with section coordinates `z`
    (or at a `Gait`, as `find_gait` returns it; a point that is not a gait, such as a
    failed search's, is coded `not_a_gait`):
    `transverse` (eigenvalues of Xi, thesis 6.42) and `poincare` (eigenvalues of the
    autodiff Jacobian of the step map), sorted by modulus. `transverse=False` computes
    the Poincare multipliers (and the verdict) only, several times faster.

    One compiled program, unbatched, serves every gait of a model class (its parameters
    are array leaves); `family_multipliers` batches many gaits. Concrete inputs give
    numpy leaves; under a JAX transformation, traced ones.
    """
    z = getattr(z, "z", z)  # a Gait: its section coordinates
    x = jax.ShapeDtypeStruct((2 * model.n_dof,), jnp.float64)
    n = jax.eval_shape(model.state_to_section, x).shape[0]  # 2n - 1 for a compass gait
    if np.shape(z) != (n,):
        raise ValueError(
            f"gait_multipliers: z must be a Gait or the {n} section coordinates "
            f"(model.state_to_section of the post-impact state), got shape {np.shape(z)}"
        )
    _check_single_domain(model, transverse, "gait_multipliers")
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((model, z)))
    if hasattr(model, "psi"):  # an array leaf, also when set by hand (no compile per slope)
        model = model.with_slope(model.psi)
    out = _gait_multipliers_jit(model, jnp.asarray(z, float), config, transverse)
    return out if traced else jax.device_get(out)


def _check_single_domain(model, transverse, name):
    if transverse and getattr(model, "num_domains", 1) > 1:
        raise ValueError(
            f"{name}: the transverse linearization here is for single-domain models; "
            f"{type(model).__name__} has {model.num_domains} domains: use transverse=False "
            f"(Poincare multipliers), or vhcjax.control's per-domain one"
        )


_gait_multipliers_jit = stored_jit(_gait_multipliers)
gait_multipliers_jit = gait_multipliers


def finite_difference_jacobian(model, z, k=1, h=1e-6, config=DEFAULT_CONFIG):
    """Central finite differences of $P^k$: an autodiff-free check of `jacobian`."""
    z = jnp.asarray(z, float)
    eye = jnp.eye(z.shape[0], dtype=z.dtype)

    def col(e):
        return (
            step_map(model, z + h * e, k, config).z_next
            - step_map(model, z - h * e, k, config).z_next
        ) / (2 * h)

    return jax.vmap(col, out_axes=1)(eye)


finite_difference_jacobian_jit = stored_jit(finite_difference_jacobian)


# ---- a second Poincare section: q1 = 0 in mid-swing -------------------------------------
def _gated_strike_event(model):
    """Heel strike (downward guard crossing) once the strike gate is open, in one stage
    (the flow may start with the gate already open)."""

    def cond(t, y, args, **kwargs):
        q = y[: model.n_dof]
        # Negative while the gate is closed: opening it is then never a downward crossing,
        # whatever the sign of the guard there (it is negative when the legs cross below
        # the slope line, as for the unstable family).
        return jnp.where(model.strike_gate(q) > 0, model.guard(q), -1.0 - jnp.abs(model.guard(q)))

    return diffrax.Event(cond, root_finder=optx.Newton(rtol=1e-13, atol=1e-13), direction=False)


def _midswing_event():
    def cond(t, y, args, **kwargs):
        return y[0]

    return diffrax.Event(cond, root_finder=optx.Newton(rtol=1e-13, atol=1e-13), direction=False)


def _flow_event(model, x0, event, config):
    sol = solve_to_event(
        model.vector_field,
        (event.cond_fn,),
        (event.direction,),
        x0,
        None,
        0.0,
        config.t_max_factor * model.time_scale,
        solver=ode_solver(config.solver),
        rtol=config.rtol,
        atol=config.atol,
        max_steps=config.max_steps,
    )
    ok = sol.result == diffrax.RESULTS.event_occurred
    return sol.ys[-1], sol.ts[-1], ok


def midswing_map(model, w, config=DEFAULT_CONFIG):
    """Return map on the mid-swing section $\\{q_1 = 0, \\dot q_1 < 0\\}$ of a compass-gait
    walker, coordinates $w = (q_2, \\dot q_1, \\dot q_2)$: swing to heel strike, impact,
    swing to the next $q_1 = 0$. **Returns:** `(w_next, ok)`."""
    x = jnp.concatenate([jnp.zeros(1, w.dtype), w])
    xm, _, ok1 = _flow_event(model, x, _gated_strike_event(model), config)
    xp, _, _ = model.impact(xm)
    xs, _, ok2 = _flow_event(model, xp, _midswing_event(), config)
    return xs[1:], ok1 & ok2


def to_midswing(model, z, config=DEFAULT_CONFIG):
    """Section coordinates on the mid-swing section of the orbit through post-impact `z`."""
    xs, _, ok = _flow_event(model, model.section_to_state(z), _midswing_event(), config)
    return xs[1:], ok


@stored_jit
def midswing_multipliers(model, z, config=DEFAULT_CONFIG):
    """Multipliers of the gait through post-impact `z`, computed on the mid-swing section
    $q_1 = 0$ (jacfwd of `midswing_map`). **Returns:** `(multipliers, w, ok)`."""
    w, ok0 = to_midswing(model, z, config)
    J = jax.jacfwd(lambda ww: midswing_map(model, ww, config)[0])(w)
    _, ok = midswing_map(model, w, config)
    return _sort(jnp.linalg.eigvals(J)), w, ok0 & ok


# ---- the period-1 family over slopes ----------------------------------------------------
_fixed_point_jit = _poincare.fixed_point_jit


class Family(eqx.Module):
    """Period-1 gaits along a slope range: `psi` (rad), `z` (B, 2n-1), `periods` (B,),
    `result` (per slope)."""

    psi: jax.Array
    z: jax.Array
    periods: jax.Array
    result: RESULTS


def period1_family(
    psis,
    family="stable",
    *,
    model=None,
    method="auto",
    coarse_step=math.radians(0.1),
    seed=None,
    seed_psi=None,
    config=None,
):
    """Period-1 gaits of a compass-gait model at the slopes `psis` (rad).

    The slope sweep of the gait search (`vhcjax.sweep`): the gait at 3 degrees by homotopy
    from the reference model, a continuation over anchor slopes at most `coarse_step`
    apart, then one batched Newton solve at every slope, missed slopes retried from
    their neighbours. `method="auto"` (default) solves thesis Problem 1 and, at the
    slopes where that fails for any reason, the fixed point of the Poincare map (thesis
    Problem 2); `"vhc"` and `"shooting"` use one of them throughout.

    `seed`, `seed_psi` and `config` are accepted for old calls and ignored (a warning):
    the sweep needs no seed and solves every gait to 1e-12. A slope that is not finite
    and positive (at least `vhcjax.gait.MIN_SLOPE`, 1e-6 rad) gets the code `bad_input`;
    another model than a compass gait raises
    `TypeError`.

    **Returns:** a `Family`; `z` holds the section coordinates $(q_1, \\dot q_1,
    \\dot q_2)$ after impact, `periods` the step periods, `result` the code per slope.
    """
    from ..gait import MIN_SLOPE, sweep

    model = CompassGait() if model is None else model
    if not isinstance(model, CompassGait):
        raise TypeError(
            "period1_family follows compass-gait families; for another model solve each "
            "slope with vhcjax.fixed_point (it works under jax.vmap)"
        )
    given = (("seed", seed), ("seed_psi", seed_psi), ("config", config))
    ignored = [k for k, v in given if v is not None]
    if ignored:
        warnings.warn(
            f"period1_family: {', '.join(ignored)} ignored (the sweep needs no seed)",
            DeprecationWarning,
            stacklevel=2,
        )
    psis = np.atleast_1d(np.asarray(psis, float))
    # a slope that is not finite and positive (downhill), or below the sweep's smallest,
    # is `bad_input`; the rest is solved
    valid = np.isfinite(psis) & (psis >= MIN_SLOPE)
    z = np.zeros((len(psis), 2 * model.n_dof - 1))
    periods = np.zeros(len(psis))
    codes = np.full(len(psis), int(RESULTS.bad_input._value), dtype=np.int32)
    if valid.any():  # `"auto"`: the VHC search, shooting where it fails
        g = sweep(model, psis[valid], family, method, anchor_step=coarse_step, tangents=False)
        z[valid] = np.asarray(g.gaits.z)
        periods[valid] = np.asarray(g.gaits.T)
        codes[valid] = np.asarray(g.gaits.result._value)
    result = eqx.tree_at(lambda r: r._value, RESULTS.successful, jnp.asarray(codes))
    return Family(jnp.asarray(psis), jnp.asarray(z), jnp.asarray(periods), result)


# ---- period doubling --------------------------------------------------------------------
def _flip_function(model, psi, z0, config, k=1):
    fp = _fixed_point_jit(model.with_slope(psi), jnp.asarray(z0), k, config=config)
    J = _jacobian_jit(model.with_slope(psi), fp.z, k, config)
    return float(jnp.linalg.det(jnp.eye(J.shape[0]) + J)), np.asarray(fp.z), fp.result


_jacobian_jit = _poincare.jacobian_jit


class PeriodDoubling(eqx.Module):
    """A flip bifurcation: `psi` (rad), `z` (the period-1 gait there), `multipliers`
    (Poincare, at `psi`; one of them is $-1$), `bracket` (rad), `iterations`."""

    psi: float
    z: np.ndarray
    multipliers: np.ndarray
    bracket: tuple
    iterations: int


def period_doubling_slope(
    psi_lo,
    psi_hi,
    z_lo,
    *,
    model=None,
    k=1,
    tol=math.radians(1e-5),
    config=DEFAULT_CONFIG,
    max_iter=60,
):
    """Slope in `[psi_lo, psi_hi]` where a multiplier of the period-`k` gait crosses $-1$.

    $f(\\psi) = \\det(I + J(\\psi))$ ($J$ the Jacobian of $P^k$ at the fixed point) is
    smooth and changes sign where a real multiplier crosses $-1$; the root is found by
    bisection safeguarded regula falsi (Illinois) to `tol` (default 1e-5 degrees),
    continuing the fixed point from `z_lo` (a gait at `psi_lo`).
    """
    model = CompassGait() if model is None else model
    fa, za, ra = _flip_function(model, psi_lo, z_lo, config, k)
    fb, zb, rb = _flip_function(model, psi_hi, za, config, k)
    if ra != RESULTS.successful or rb != RESULTS.successful:
        raise ValueError("period_doubling_slope: no period-k gait at the bracket ends")
    if not fa * fb < 0:
        raise ValueError(f"no sign change of det(I+J) in [{psi_lo}, {psi_hi}]: {fa}, {fb}")
    a, b = psi_lo, psi_hi
    side = 0
    it = 0
    while b - a > tol and it < max_iter:
        c = (a * fb - b * fa) / (fb - fa)
        if not (a < c < b) or it % 3 == 2:
            c = 0.5 * (a + b)
        zc_guess = za + (zb - za) * (c - a) / (b - a)
        fc, zc, res = _flip_function(model, c, zc_guess, config, k)
        if fc * fb < 0:
            a, fa, za = b, fb, zb
            b, fb, zb = c, fc, zc
            side = 0
        else:
            b, fb, zb = c, fc, zc
            if side == 1:
                fa *= 0.5
            side = 1
        if a > b:
            a, b, fa, fb, za, zb = b, a, fb, fa, zb, za
        it += 1
    psi = 0.5 * (a + b)
    _, z, _ = _flip_function(model, psi, za, config, k)
    J = _jacobian_jit(model.with_slope(psi), jnp.asarray(z), k, config)
    ev = np.asarray(_sort(jnp.linalg.eigvals(J)))
    return PeriodDoubling(psi, z, ev, (a, b), it)


# ---- period-k orbits ---------------------------------------------------------------------
class PeriodKOrbit(eqx.Module):
    """A fixed point of $P^k$: `z` (its first point), `orbit` (k, 2n-1) the k points,
    `periods` (k,), `multipliers` of $P^k$ (Poincare, and by finite differences),
    `residual`, `result`, `minimal_period` (the smallest j with $P^j(z) = z$)."""

    z: np.ndarray
    orbit: np.ndarray
    periods: np.ndarray
    multipliers: np.ndarray
    multipliers_fd: np.ndarray
    residual: float
    result: RESULTS
    minimal_period: int


def settle(model, z0, num_steps=400, config=FAST_CONFIG):
    """Post-impact section coordinates after `num_steps` steps from `z0` (None if the
    walker fell): a seed for period-k searches on an attractor."""
    sim = _simulate_jit(
        model, model.section_to_state(jnp.asarray(z0, float)), num_steps, config=config
    )
    if sim.result != RESULTS.successful:
        return None
    return np.asarray(model.state_to_section(sim.steps.x_plus[-1]))


_simulate_jit = simulate  # already jitted


def period_k_orbit(model, z0, k, config=DEFAULT_CONFIG, *, iterations=20, h=1e-6):
    """Newton on $P^k(z) = z$ from `z0` (e.g. from `settle`), with multipliers of $P^k$
    by autodiff and by central finite differences.

    $P^k$ and its Jacobian are composed from $k$ one-step maps and one-step Jacobians
    (autodiff through each heel strike): the compiled one-step programs serve every $k$.
    Newton stops at a residual below 1e-12 (`successful`), after `iterations`
    (`not_converged`), or at a failed step (its code; `residual` is then `inf`: the
    failed map holds its state, which is no convergence). An invalid model is
    `bad_input`, with zero periods and multipliers (nothing computed); a `k` that is not
    a positive integer, or a `z0` of another shape, is a `ValueError`.
    """
    k = check_map_steps(k)
    check_section_shape(model, jnp.asarray(z0), "z0")
    if not bool(model.validate()):  # an invalid model takes no step: nothing computed
        z = np.asarray(z0, float)
        none = np.zeros(len(z), complex)
        orbit = np.tile(z, (k, 1))
        return PeriodKOrbit(z, orbit, np.zeros(k), none, none, np.inf, RESULTS.bad_input, k)

    def Pk(z, jac):
        J, orbit, periods, code = np.eye(len(z)), [], [], RESULTS.successful
        for _ in range(k):
            orbit.append(z)
            if jac:
                J = np.asarray(_jacobian_jit(model, jnp.asarray(z), 1, config)) @ J
            r = _step_map_jit(model, jnp.asarray(z), 1, config)
            periods.append(float(r.periods[0]))
            if code == RESULTS.successful:
                code = r.result
            z = np.asarray(r.z_next)
        return z, J, np.stack(orbit), np.asarray(periods), code

    z = np.asarray(z0, float)
    for _ in range(iterations):
        zk, J, orbit, periods, code = Pk(z, True)
        res = float(np.max(np.abs(zk - z)))
        if code != RESULTS.successful or not np.isfinite(res) or res < 1e-12:
            break
        z = z - np.linalg.solve(J - np.eye(len(z)), zk - z)
    else:
        zk, J, orbit, periods, code = Pk(z, True)
        res = float(np.max(np.abs(zk - z)))
    if code == RESULTS.successful and not res < 1e-12:
        code = RESULTS.not_converged
    if code != RESULTS.successful and not code == RESULTS.not_converged:
        res = float("inf")
    eye = np.eye(len(z))
    Jfd = np.stack(
        [(Pk(z + h * e, False)[0] - Pk(z - h * e, False)[0]) / (2 * h) for e in eye], axis=1
    )
    minimal = k
    for j in range(1, k):
        if k % j == 0 and np.max(np.abs(orbit[j] - orbit[0])) < 1e-7:
            minimal = j
            break
    return PeriodKOrbit(
        z,
        orbit,
        periods,
        np.asarray(_sort(jnp.linalg.eigvals(J))),
        np.asarray(_sort(jnp.linalg.eigvals(Jfd))),
        res,
        code,
        minimal,
    )


_step_map_jit = _poincare.step_map_jit


# ---- bifurcation diagram ---------------------------------------------------------------
class BifurcationDiagram(eqx.Module):
    """Long simulations over slopes.

    - `psi` (B,): slopes (rad).
    - `periods` (B, num_record): step periods of the last `num_record` steps (NaN-free;
      zero after a fall).
    - `fell` (B,): the walker did not complete all steps.
    - `result` (B,): first failure code per slope.
    - `period_pattern` (B,): `detect_period` of the recorded step periods: 1, 2, 4, ...
      steps per repetition, 0 if aperiodic (chaotic or not settled), -1 where it fell.
    """

    psi: np.ndarray
    periods: np.ndarray
    fell: np.ndarray
    result: np.ndarray
    period_pattern: np.ndarray


@stored_jit
def _long_runs(model, psis, x0s, num_steps, num_record, config):
    def one(p, x0):
        sim = simulate(model.with_slope(p), x0, num_steps, config=config)
        return sim.steps.period[-num_record:], sim.result

    return jax.vmap(one)(psis, x0s)


def bifurcation_diagram(
    psis,
    zs,
    *,
    model=None,
    num_transient=300,
    num_record=64,
    perturbation=1e-4,
    config=FAST_CONFIG,
    chunk=None,
    mesh=None,
):
    """Simulate from the period-1 gaits `zs` at slopes `psis` (rad) for
    `num_transient + num_record` steps (batched with `vmap`) and keep the step periods
    of the last `num_record`.

    The start is the gait plus `perturbation` on $\\dot q_2$, so that unstable period-1
    gaits (past the flip) leave towards the attractor. Default tolerance: `FAST_CONFIG`
    (rtol = atol = 1e-8). `chunk`: largest batch of one call (default: 256 when the
    chunks run one per CPU core at a time, else the whole batch). The chunks are padded
    (`_batching.padded_map`) and split over the devices of `mesh` (default: all local
    devices).
    """
    model = CompassGait() if model is None else model
    psis = np.asarray(psis, float).reshape(-1)
    zs = np.asarray(zs, float)
    if zs.ndim != 2 or len(zs) != len(psis):
        raise ValueError(
            f"bifurcation_diagram: one gait per slope: zs must have shape ({len(psis)}, n), "
            f"got {zs.shape}"
        )
    if int(num_transient) < 0 or int(num_record) < 2:  # one period shows no pattern
        raise ValueError(
            "bifurcation_diagram: num_transient must be at least 0 and num_record at least 2, "
            f"got {num_transient}, {num_record}"
        )
    x0s = np.stack(
        [np.asarray(model.with_slope(p).section_to_state(jnp.asarray(z))) for p, z in zip(psis, zs)]
    )
    x0s[:, -1] += perturbation
    steps = num_transient + num_record
    p, r = padded_map(
        lambda ps, xs: _long_runs(model, ps, xs, steps, num_record, config),
        psis,
        x0s,
        # chunks of up to 256 run one per CPU core; a GPU takes the whole batch at once
        max_chunk=chunk or (MAX_DISPATCH if host_workers(mesh) > 1 else len(psis)),
        mesh=mesh,
        stage="simulation",
    )
    periods, codes = np.asarray(p), np.asarray(r._value)
    fell = codes != int(RESULTS.successful._value)
    nd = np.array([-1 if f else detect_period(pp) for pp, f in zip(periods, fell)])
    return BifurcationDiagram(psis, periods, fell, codes, nd)


#: The periods (in steps) that `detect_period` looks for.
PERIOD_CANDIDATES = (1, 2, 4, 8, 16, 32)


def detect_period(periods, tol=1e-5, candidates=PERIOD_CANDIDATES):
    """Smallest p in `candidates` with `periods[i + p] == periods[i]` (within `tol` s)
    for all recorded i; 0 if none (aperiodic, e.g. chaotic, or not settled)."""
    periods = np.asarray(periods)
    for p in candidates:
        if p < len(periods) and np.max(np.abs(periods[p:] - periods[:-p])) < tol:
            return p
    return 0


def period_doubling_slopes_from_diagram(diagram):
    """Slopes (rad) where the detected step-period pattern (`detect_period`) first reaches
    2, 4, 8, ... (midpoints between neighbouring slopes), from a `BifurcationDiagram`: a
    simulation-only estimate of the cascade, as coarse as the slope grid."""
    per = np.asarray(diagram.period_pattern)
    out = []
    target = 2
    for i in range(1, len(per)):
        if per[i] >= target and 0 < per[i - 1] < target:
            out.append(0.5 * (diagram.psi[i - 1] + diagram.psi[i]))
            target *= 2
    return out


def period2_branch(model, pd, psis, config=DEFAULT_CONFIG, amplitudes=(3e-3, 1e-2, 3e-2)):
    """Continue the period-2 gait born at the flip `pd` (a `PeriodDoubling`) over the
    slopes `psis` (rad, increasing, all past the flip).

    The first solve starts from the period-1 gait at the flip displaced along the flip
    eigenvector (several trial amplitudes; a solution that is the period-1 gait again is
    rejected), then secant continuation. Stops where Newton fails or the orbit collapses.
    **Returns:** dict with `psi` (m,), `z` (m, 3), `periods` (m, 2), `max_abs` (m,) and
    `stable` (m,) from the multipliers of $P^2$, and `flip_psi`: the slope where a
    multiplier of $P^2$ crosses $-1$ (period 2 -> 4), located to 1e-5 degrees, or None.
    """
    psis = np.asarray(psis, float)
    if len(psis) == 0:
        return None
    J = _jacobian_jit(model.with_slope(pd.psi), jnp.asarray(pd.z), 1, config)
    ev, V = np.linalg.eig(np.asarray(J))
    v = np.real(V[:, np.argmin(np.abs(ev + 1))])
    v = v / np.linalg.norm(v)
    out_psi, out_z, out_T, out_mx = [], [], [], []
    zs = []
    for i, p in enumerate(psis):
        m = model.with_slope(p)
        if i == 0:
            trials = [pd.z + s * v for s in amplitudes]
        else:
            trials = [
                zs[-1]
                if len(zs) == 1
                else zs[-1] + (zs[-1] - zs[-2]) * (p - out_psi[-1]) / (out_psi[-1] - out_psi[-2])
            ]
        found = None
        for guess in trials:
            fp = _fixed_point_jit(m, jnp.asarray(guess), 2, config=config)
            if fp.result != RESULTS.successful:
                continue
            z1 = np.asarray(_step_map_jit(m, fp.z, 1, config).z_next)
            if np.max(np.abs(z1 - np.asarray(fp.z))) > 1e-6:
                found = fp
                break
        if found is None:
            break
        zs.append(np.asarray(found.z))
        Jk = _jacobian_jit(m, found.z, 2, config)
        out_psi.append(p)
        out_z.append(zs[-1])
        out_T.append(np.asarray(found.periods))
        out_mx.append(float(np.max(np.abs(np.linalg.eigvals(np.asarray(Jk))))))
    if not out_psi:
        return None
    mx = np.asarray(out_mx)
    stable = mx < 1.0
    flip = None
    idx = np.where(stable[:-1] & ~stable[1:])[0]
    if len(idx):
        i = int(idx[0])
        try:
            flip = period_doubling_slope(
                out_psi[i], out_psi[i + 1], out_z[i], model=model, k=2, config=config
            ).psi
        except ValueError:
            flip = None
    return {
        "psi": np.asarray(out_psi),
        "z": np.stack(out_z),
        "periods": np.stack(out_T),
        "max_abs": mx,
        "stable": stable,
        "flip_psi": flip,
    }


# ---- why the transverse multipliers are not used -------------------------------------
def _pick(x, index):
    x = np.asarray(x)
    return x if index is None else x[index]


def transverse_note(gm, index=None):
    """`None` where the transverse multipliers of a (possibly batched, then `index`)
    `GaitMultipliers` hold; else a one-line reason they are not to be trusted."""
    from .._results import result_names

    name = result_names(_pick(gm.transverse_result._value, index))
    if name == "successful":
        return None
    assert isinstance(name, str)  # one result: a single `GaitMultipliers` or `index` given
    msg = f"transverse linearization not used ({name}): {RESULTS[getattr(RESULTS, name)]}"
    if name == "methods_disagree":
        dis = float(_pick(gm.disagreement, index))
        if math.isfinite(dis):
            msg += f" Relative difference {dis:.3g}."
    return msg
