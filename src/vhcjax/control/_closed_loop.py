"""Closed-loop analysis of a gait stabilized by transverse-linearization feedback.

- `stabilize`: transverse linearization, the Riccati solution both ways, the feedback
  law, and the closed-loop multipliers both ways, in one call.
- `closed_loop_multipliers_transverse`: eigenvalues of $J\\Phi_{cl}(1)$, the monodromy of
  $\\dot\\zeta = (A - BK)\\zeta$ with the jump (the interpolated gains of the law itself).
- `closed_loop_jacobian` / `closed_loop_multipliers`: the Poincare map of the walker
  under the feedback law on the post-impact section, differentiated by forward-mode
  autodiff through the heel-strike event (independent of the linearization).
- Multi-domain models (the kneed walker): one transverse system, gain table and law
  per domain (`HybridTransverseSystem`, `HybridTransverseFeedback`); the closed-loop
  step applies each domain's law in that domain.
- `closed_loop_basin`: a 2-D slice of the basin of attraction on the post-impact
  section, with the torque used per converging point.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import (
    DEFAULT_CONFIG,
    SolverConfig,
    check_section_shape,
    flow,
    in_walker_units,
    section_rates,
)
from ..hybrid._simulate import section_units
from ..robustness import direction, finish_step, impulse_velocity_jump, push_bound, swing_from
from ..solvers import eigenvalues, linearised
from ._actuated import (
    closed_loop_field,
    closed_loop_step,
    in_domain,
    is_multidomain,
    num_inputs,
    simulate_closed_loop,
)
from ._feedback import (
    HybridTransverseFeedback,
    TransverseFeedback,
    check_torque_limit,
    transverse_feedback,
)
from ._riccati import (
    RiccatiSolution,
    _pieces,
    own_units,
    riccati_backward,
    riccati_hamiltonian,
    weights,
)
from ._transverse import (
    HybridTransverseSystem,
    TransverseSystem,
    cycle_monodromy,
    free_units,
    phase_field,
    phase_matrices,
    phase_units,
    solve_in_phase,
    transverse_system,
)

#: Hybrid-step settings of the closed-loop Poincare map: at the default 1e-10 the
#: autodiff Jacobian of the step map carries the ODE error (~1e-6 in the multipliers).
TIGHT_CONFIG = SolverConfig(rtol=1e-12, atol=1e-12, max_steps=8192)


def _sort(ev):
    return ev[jnp.argsort(-jnp.abs(ev))]


@stored_jit
def closed_loop_multipliers_transverse(
    model, system, feedback, *, rtol=1e-12, atol=1e-12, max_steps=8192
):
    """Closed-loop multipliers from the transverse linearization: eigenvalues of
    $J\\,\\Phi_{cl}(1)$, $d\\Phi_{cl}/ds = (dt/ds)(A - BK(s))\\Phi_{cl}$, with $K(s)$ the
    gain interpolant of `feedback` (saturation inactive at the orbit). For a
    `HybridTransverseSystem`, the product around the cycle in free coordinates (as its
    `multipliers`). Sorted by modulus.
    """
    doms, bases, k, dom = _pieces(system)
    u0 = jnp.zeros(num_inputs(model))
    transitions = []
    for i, d in enumerate(doms):
        P, law = bases[i], in_domain(feedback, dom(i))
        r = d.w.shape[1] if P is None else P.shape[1]
        nw = d.w.shape[1]
        tp, delta = d.theta_plus, d.theta_minus - d.theta_plus

        def field(s, y, args, P=P, law=law, r=r, nw=nw, tp=tp, delta=delta, i=i):
            w = y[:nw]
            Phi = y[nw:].reshape(r, r)
            A, B, c = phase_matrices(model, tp, delta, s, w, dom(i))
            dw = phase_field(model, tp, delta, s, w, u0, dom(i))[0]
            K = law.gain(s)
            if P is not None:
                A, B, K = P.T @ A @ P, P.T @ B, K @ P
            return jnp.concatenate([dw, (c * (A - B @ K) @ Phi).reshape(-1)])

        y0 = jnp.concatenate([d.w[0], jnp.eye(r).reshape(-1)])
        wu = phase_units(model)
        zu = free_units(P, wu)
        atol_i = atol * jnp.concatenate([wu, (zu[:, None] / zu).reshape(-1)])  # own units
        sol = solve_in_phase(field, y0, 0.0, 1.0, diffrax.SaveAt(t1=True), rtol, atol_i, max_steps)
        assert sol.ys is not None  # saved at t1
        transitions.append(sol.ys[-1, nw:].reshape(r, r))
    M = cycle_monodromy(bases, k, transitions, [d.J for d in doms])
    return _sort(jnp.linalg.eigvals(M))


@stored_jit
def closed_loop_step_map(model, feedback, z, config=DEFAULT_CONFIG):
    """One step of the walker under `feedback` in post-impact section coordinates:
    `(z_next, result)`."""
    sr = closed_loop_step(model, model.section_to_state(z), feedback, config)
    return model.state_to_section(sr.x_plus), sr.result


@stored_jit
def _closed_loop_jacobian(model, feedback, z, config):
    return jax.jacfwd(lambda zz: closed_loop_step_map(model, feedback, zz, config)[0])(z)


def closed_loop_jacobian(model, feedback, z, config=TIGHT_CONFIG):
    """Jacobian of `closed_loop_step_map` by forward-mode autodiff through the event (one
    stored program). Differentiable in forward and reverse mode (`jax.grad`): its own
    derivatives come from a forward-mode Jacobian times the tangents."""
    z = jnp.asarray(z, float)
    check_section_shape(model, z, "z")
    return linearised(_closed_loop_jacobian, config)(model, feedback, z)


def closed_loop_multipliers(model, feedback, z, config=TIGHT_CONFIG):
    """Closed-loop multipliers as the eigenvalues of `closed_loop_jacobian`, by modulus
    (descending), differentiable as `closed_loop_jacobian` (eigenvalue perturbation)."""
    return eigenvalues(closed_loop_jacobian(model, feedback, z, config))


class Stabilization(eqx.Module):
    """A gait stabilized by transverse-linearization LQR feedback.

    - `system`: the `TransverseSystem` (open-loop `multipliers` included; a
      `HybridTransverseSystem` for a multi-domain model).
    - `riccati`: the `RiccatiSolution` by backward iteration (used for the gains).
    - `riccati_check`: the `RiccatiSolution` by the Hamiltonian monodromy (its `result`
      says when that method does not hold, e.g. `riccati_ill_conditioned`).
    - `riccati_agreement`: $\\max|X_1 - X_2| / \\max|X_1|$ over the phase grid ($X$ in
      the walker's own units: entries times the units of their two coordinates over
      the cost's unit); NaN when
      the check did not succeed.
    - `feedback`: the `TransverseFeedback` law (`HybridTransverseFeedback`: one per
      domain).
    - `open_loop_multipliers`: eigenvalues of $J\\Phi$ (passive gait).
    - `closed_loop_jacobian`: the autodiff Jacobian of the closed-loop step map at `z`
      (post-impact section coordinates).
    - `closed_loop_multipliers`: its eigenvalues.
    - `closed_loop_multipliers_transverse`: eigenvalues of $J\\Phi_{cl}$.
    - `max_gain`: $\\max_s \\|K(s)\\|_\\infty$ (largest entry).
    - `result`: the first failure of the transverse system or the backward Riccati
      solution, or `successful`.
    """

    system: TransverseSystem | HybridTransverseSystem
    riccati: RiccatiSolution
    riccati_check: RiccatiSolution
    riccati_agreement: jax.Array
    feedback: TransverseFeedback | HybridTransverseFeedback
    open_loop_multipliers: jax.Array
    closed_loop_jacobian: jax.Array
    closed_loop_multipliers: jax.Array
    closed_loop_multipliers_transverse: jax.Array
    max_gain: jax.Array
    result: RESULTS


def stabilize(
    model,
    z,
    Q=None,
    R=None,
    Q_jump=None,
    *,
    torque_limit: float | jax.Array = jnp.inf,
    num_points=401,
    config=TIGHT_CONFIG,
):
    """Stabilize the period-1 gait with post-impact section coordinates `z` by
    transverse-linearization feedback (Shiriaev et al. 2008; Freidovich, Shiriaev and
    Manchester 2008; Manchester 2011).

    **Arguments:**

    - `model`: a `WalkerModel` with an `input_matrix`, single- or multi-domain (e.g.
      `KneedWalker`: one transverse system, gain table and feedback law per domain).
    - `z`: section coordinates of the gait (`model.state_to_section` of its post-impact
      state), a fixed point of the passive step map.
    - `Q`, `R`, `Q_jump`: LQR weights on $\\zeta$ (per second), on $u$ (per second) and on
      $\\zeta^-$ at each heel strike; matrices or diagonals; default
      `vhcjax.default_weights`: $I$, $I$, $Q$ for the model class's default walker (the
      thesis walker), the same problem in a rescaled walker's units.
    - `torque_limit`: saturation of each input (N m), default none.
    - `num_points`: phase-grid points of the tabulated orbit and gains.
    - `config`: `SolverConfig` of the hybrid steps (default `TIGHT_CONFIG`, 1e-12).

    **Returns:** a `Stabilization`. Jittable (`eqx.filter_jit`); `throw` is not offered:
    inspect `result` (`orbit_not_closed` where `z` is not a gait, `bad_input` for an
    invalid model). Weights of another shape, not symmetric, negative ($Q$) or not
    positive ($R$), and a negative or NaN torque limit, are a `ValueError`.
    """
    z = jnp.asarray(z, float)
    check_section_shape(model, z)
    # Weights, torque limit and gait as arrays: one compiled program serves them all.
    Q, R, Q_jump = weights(model, Q, R, Q_jump)
    check_torque_limit(torque_limit)
    return _stabilize(
        model,
        z,
        Q,
        R,
        Q_jump,
        torque_limit=jnp.asarray(torque_limit, float),
        num_points=num_points,
        config=config,
    )


@stored_jit
def _stabilize(model, z, Q, R, Q_jump, *, torque_limit, num_points, config):
    """`stabilize` for checked weights and torque limit (arrays): one compiled program per
    model class, grid size and `config` (a stored program, see `vhcjax._programs`)."""
    system = transverse_system(model, model.section_to_state(z), num_points=num_points)
    ric = riccati_backward(model, system, Q, R, Q_jump)
    ric2 = riccati_hamiltonian(model, system, Q, R, Q_jump)
    own = own_units(model, None, R)  # X on all coordinates, in the walker's own units
    agree = jnp.max(jnp.abs(own(ric.X - ric2.X))) / jnp.max(jnp.abs(own(ric.X)))
    agree = jnp.where(ric2.result == RESULTS.successful, agree, jnp.nan)
    fb = transverse_feedback(system, ric, torque_limit)
    cl_t = closed_loop_multipliers_transverse(model, system, fb)
    jac = closed_loop_jacobian(model, fb, z, config)
    cl_p = _sort(jnp.linalg.eigvals(jac))
    code = RESULTS.where(system.result == RESULTS.successful, ric.result, system.result)
    code = RESULTS.where(model.validate(), code, RESULTS.bad_input)
    return Stabilization(
        system,
        ric,
        ric2,
        agree,
        fb,
        system.multipliers,
        jac,
        cl_p,
        cl_t,
        jnp.max(jnp.abs(ric.K)),
        code,
    )


class ClosedLoopBasin(eqx.Module):
    """A 2-D slice of the basin of attraction on the post-impact section.

    - `offsets_x`, `offsets_y`: grid offsets along section coordinates `axes`.
    - `converged`: boolean grid `(nx, ny)`: within `tol` of the gait after the steps.
    - `fell`: boolean grid: the walker failed (fall, missed strike, ...).
    - `fraction`: converging fraction of the grid.
    - `max_abs_torque`, `rms_torque`: per point, the largest $|u|$ over all steps and the
      RMS of $u$ over the first step (N m).
    - `axes`: the two section coordinates varied.
    """

    offsets_x: jax.Array
    offsets_y: jax.Array
    converged: jax.Array
    fell: jax.Array
    fraction: jax.Array
    max_abs_torque: jax.Array
    rms_torque: jax.Array
    axes: tuple = eqx.field(static=True)


def closed_loop_basin(
    model,
    feedback,
    z_star,
    *,
    axes=(0, 1),
    half_widths=None,
    shape=(21, 21),
    num_steps=30,
    tol=1e-4,
    torque_points=16,
    config=DEFAULT_CONFIG,
):
    """Basin slice of the gait `z_star` under `feedback` (use `ZeroFeedback` for the
    passive walker: the same code path). Jittable; all points in one `vmap`.
    `half_widths`: of the grid along `axes` (rad, rad/s; default 0.05 rad on an angle and
    0.3 rad/s on a rate for the thesis walker, in the same proportion to another
    walker's time unit, `vhcjax.in_walker_units`); `tol`: a start converged when
    the section point after `num_steps` steps is within `tol` of the gait in the walker's
    own units (angles, and rates times `model.time_scale`).

    **Returns:** a `ClosedLoopBasin`.
    """
    z_star = jnp.asarray(z_star, float)
    unit = section_units(model)
    if half_widths is None:
        default = in_walker_units(model, jnp.where(section_rates(model), 0.3, 0.05), "section")
        half_widths = (default[axes[0]], default[axes[1]])
    ox = jnp.linspace(-half_widths[0], half_widths[0], shape[0])
    oy = jnp.linspace(-half_widths[1], half_widths[1], shape[1])
    X, Y = jnp.meshgrid(ox, oy, indexing="ij")
    Z = jnp.broadcast_to(z_star, X.shape + z_star.shape)
    Z = Z.at[..., axes[0]].add(X).at[..., axes[1]].add(Y).reshape(-1, z_star.shape[0])

    def one(z):
        sim = simulate_closed_loop(
            model,
            model.section_to_state(z),
            feedback,
            num_steps,
            config=config,
            torque_points=torque_points,
        )
        zf = model.state_to_section(sim.steps.x_plus[-1])
        ok = sim.result == RESULTS.successful
        conv = ok & (jnp.max(jnp.abs(zf - z_star) / unit) < tol)
        return conv, ~ok, jnp.max(sim.max_abs_torque), sim.rms_torque[0]

    conv, fell, umax, urms = jax.vmap(one)(Z)
    conv = conv.reshape(shape)
    return ClosedLoopBasin(
        ox,
        oy,
        conv,
        fell.reshape(shape),
        jnp.mean(conv),
        umax.reshape(shape),
        urms.reshape(shape),
        tuple(axes),
    )


@stored_jit(arrays=("t_push",))
def closed_loop_push_step(model, feedback, x0, t_push, impulse, config=DEFAULT_CONFIG, alive=True):
    """One step of the walker under `feedback` from the post-impact state `x0`, with a hip
    impulse `impulse` (N s, world frame) at time `t_push` into the step (as
    `vhcjax.impulse_step`, which is the passive case; single-domain models).
    **Returns:** a `StepResult`."""
    if is_multidomain(model):
        raise NotImplementedError("closed-loop pushes: single-domain models only")
    n = model.n_dof
    field = closed_loop_field(model, feedback)
    t_max = config.t_max_factor * model.time_scale
    tiny = 1e-12 * model.time_scale  # a solve of (almost) zero length
    t_s = jnp.maximum(t_push, tiny)
    alive = jnp.asarray(alive)
    sol0 = flow(model, x0, jnp.where(alive, t_s, tiny), config, event=False, vector_field=field)
    assert sol0.ys is not None  # saved at t1
    xs = sol0.ys[-1]
    x_k = xs.at[n:].add(impulse_velocity_jump(model, xs[:n], impulse))
    bad = model.fallen(xs[:n]) | model.fallen(x_k[:n]) | ~jnp.all(jnp.isfinite(x_k))
    x_minus, t_end, code = swing_from(
        model,
        x_k,
        jnp.where(alive, t_s, tiny),
        jnp.where(alive, t_max, 2 * tiny),
        config,
        vector_field=field,
    )
    code = RESULTS.where(bad, RESULTS.fell, code)
    return finish_step(model, x_minus, t_end, code, x0)


def _push_survives(model, feedback, x_star, t_push, impulse, num_steps, tol, config):
    sr = closed_loop_push_step(model, feedback, x_star, t_push, impulse, config)
    sim = simulate_closed_loop(
        model, sr.x_plus, feedback, num_steps, config=config, torque_points=0
    )
    err = jnp.max(  # in the walker's own units
        jnp.abs(model.state_to_section(sim.steps.x_plus[-1]) - model.state_to_section(x_star))
        / section_units(model)
    )
    return (sr.result == RESULTS.successful) & (sim.result == RESULTS.successful) & (err < tol)


def closed_loop_max_push(
    model,
    feedback,
    x_star,
    period,
    phases,
    angles,
    *,
    p_max=None,
    iterations=10,
    num_steps=30,
    tol=1e-4,
    config=DEFAULT_CONFIG,
):
    """Largest hip impulse (N s) after which the walker under `feedback` returns within
    `tol` of the gait (in the walker's own units: angles, and rates times its time unit)
    in `num_steps` steps, per phase and direction (bisection on $[0, p_{max}]$ assuming
    survival is monotone in the magnitude; `vmap` over the grid). `p_max`: default
    `vhcjax.push_bound(model)` (20 N s for the thesis's walker).

    - `x_star`, `period`: post-impact state and step time of the gait.
    - `phases`: fractions of `period` at which the push acts; `angles`: directions (rad,
      0 forward, $\\pi/2$ up), as `vhcjax.max_push`.

    **Returns:** array `(len(phases), len(angles))`; 0 where even the unpushed walker does
    not return (e.g. the passive walker on an unstable gait).
    """
    x_star = jnp.asarray(x_star, float)
    P, A = jnp.meshgrid(jnp.asarray(phases, float), jnp.asarray(angles, float), indexing="ij")

    def one(ph, ang):
        t = ph * period
        e = direction(ang)

        def ok(p):
            return _push_survives(model, feedback, x_star, t, p * e, num_steps, tol, config)

        def body(_, lohi):
            lo, hi = lohi
            mid = 0.5 * (lo + hi)
            good = ok(mid)
            return jnp.where(good, mid, lo), jnp.where(good, hi, mid)

        lo, _ = jax.lax.fori_loop(
            0,
            iterations,
            body,
            (jnp.zeros(()), jnp.asarray(push_bound(model) if p_max is None else p_max, float)),
        )
        return jnp.where(ok(jnp.zeros(())), lo, 0.0)

    return jax.vmap(one)(P.reshape(-1), A.reshape(-1)).reshape(P.shape)


# Jitted entry points (models and feedback laws carry array leaves: one compilation
# serves every slope, weight and torque limit).
closed_loop_basin = stored_jit(closed_loop_basin)
closed_loop_multipliers = stored_jit(closed_loop_multipliers)
closed_loop_jacobian = stored_jit(closed_loop_jacobian)
closed_loop_max_push = stored_jit(arrays=("period", "p_max"))(closed_loop_max_push)
