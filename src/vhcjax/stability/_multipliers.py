"""Floquet multipliers of a period-1 gait, two ways, with a check of each.

`gait_multipliers` computes them by the transverse linearization (thesis ch. 6,
`vhcjax.stability.transverse_linearization`) and, independently, as the eigenvalues of
the Poincare-map Jacobian by forward-mode autodiff through the heel-strike events
(`vhcjax.hybrid.jacobian`); `family_multipliers` batches them over slopes (`vmap`).
`finite_difference_jacobian` is an autodiff-free check of the Jacobian.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np

from .._batching import padded_map
from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS, result_codes, result_names
from ..hybrid import DEFAULT_CONFIG, flow, step_map, step_unchecked
from ..hybrid._simulate import section_units, state_distance
from ._transverse import TransverseLinearization, transverse_linearization


def _sort(ev):
    """Eigenvalues by modulus, descending."""
    return ev[jnp.argsort(-jnp.abs(ev))]


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
    moved, scale = state_distance(model, tl.x_minus, sr.x_minus)  # own units
    orbit_off = (moved > AGREEMENT_RTOL * scale) | (
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


#: How far one step may move a state for it to count as a period-1 gait in
#: `gait_multipliers` (`returns_to`: in the walker's own units, relative to max(1, |x|)):
#: gaits found by the searches close to about 1e-10.
GAIT_TOL = 1e-6


def returns_to(model, z, z_next):
    """Whether one step of `model` from the section point `z` came back to it: `z_next`
    within `GAIT_TOL` $\\max(1, \\|x\\|_\\infty)$ of it, states compared in the walker's
    own units (angles, and velocities times `model.time_scale`), so that the test is the
    same for a walker and its rescaled copy (False where not finite). Traceable."""
    moved, size = state_distance(
        model, model.section_to_state(jnp.asarray(z_next)), model.section_to_state(jnp.asarray(z))
    )
    return moved <= GAIT_TOL * size


@stored_jit
def _gait_multipliers(model, z, config=DEFAULT_CONFIG, transverse=True):
    """Both multiplier computations at the period-1 gait with section coordinates `z`,
    with the checks of the transverse one (`transverse=False`: the Poincare ones only):
    one stored program per model class (see `vhcjax._programs`)."""
    z = jnp.asarray(z, float)
    x0 = model.section_to_state(z)

    def step(zz):  # the step map and, as a by-product, the step itself
        sr = step_unchecked(model, model.section_to_state(zz), config)
        return model.state_to_section(sr.x_plus), sr

    # the Jacobian of the step map (as `hybrid.jacobian`) with the step in the same pass
    J, sr = jax.jacfwd(step, has_aux=True)(z)
    pm = _sort(jnp.linalg.eigvals(J))
    # multipliers are those of a fixed point of the step map only
    periodic = returns_to(model, z, model.state_to_section(sr.x_plus))
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


@host_only("vmap `gait_multipliers`")
def family_multipliers(model, psis, zs, config=DEFAULT_CONFIG, *, transverse=True, mesh=None):
    """`gait_multipliers` for many slopes in one batched (`vmap`) call.

    `psis` (B,) in rad, `zs` (B, 2n-1) the gaits there. Returns a batched
    `GaitMultipliers`. The batch runs in padded chunks (a power of two up to 256
    members, so that nearby sizes share one compilation; one chunk per CPU
    core at a time), split over the devices of `mesh` (default: all local devices). A
    host-side function (concrete inputs; the result's leaves are numpy arrays); under
    `jit` or a derivative, `vmap` `gait_multipliers` instead.
    """
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
    out = _gait_multipliers(model, jnp.asarray(z, float), config, transverse)
    return out if traced else jax.device_get(out)


def _check_single_domain(model, transverse, name):
    if transverse and getattr(model, "num_domains", 1) > 1:
        raise ValueError(
            f"{name}: the transverse linearization here is for single-domain models; "
            f"{type(model).__name__} has {model.num_domains} domains: use transverse=False "
            f"(Poincare multipliers), or vhcjax.control's per-domain one"
        )


@stored_jit
def finite_difference_jacobian(model, z, k=1, h=1e-6, config=DEFAULT_CONFIG):
    """Central finite differences of $P^k$: an autodiff-free check of `jacobian`. The
    step along each section coordinate is `h` times its unit (`model.time_scale` makes
    rates dimensionless), so that a rescaled walker gets the rescaled Jacobian."""
    z = jnp.asarray(z, float)
    steps = h * section_units(model) * jnp.eye(z.shape[0], dtype=z.dtype)

    def col(d):
        return (
            step_map(model, z + d, k, config).z_next - step_map(model, z - d, k, config).z_next
        ) / (2 * jnp.max(d))

    return jax.vmap(col, out_axes=1)(steps)


# ---- why the transverse multipliers are not used -------------------------------------
def _pick(x, index):
    x = np.asarray(x)
    return x if index is None else x[index]


def transverse_note(gm, index=None):
    """`None` where the transverse multipliers of a (possibly batched, then `index`)
    `GaitMultipliers` hold; else a one-line reason they are not to be trusted."""
    name = result_names(_pick(result_codes(gm.transverse_result), index))
    if name == "successful":
        return None
    assert isinstance(name, str)  # one result: a single `GaitMultipliers` or `index` given
    msg = f"transverse linearization not used ({name}): {RESULTS[getattr(RESULTS, name)]}"
    if name == "methods_disagree":
        dis = float(_pick(gm.disagreement, index))
        if math.isfinite(dis):
            msg += f" Relative difference {dis:.3g}."
    return msg
