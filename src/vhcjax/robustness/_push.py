"""Impulse-like pushes at the hip along the gait: linear sensitivity and largest push
survived, as functions of the phase of the step and of the push direction.

A push acts on the hip at the phase $s \\in [0, 1)$ of a step of the gait (time
$t_s = sT$ after the heel strike), horizontally, vertically or in any direction
$(\\cos\\beta, \\sin\\beta)$ (world frame, $\\beta = 0$ pushes forward, in the direction of
walking; $90°$ pushes up). Two kinds:

- an instantaneous impulse $P$ (N s): $\\Delta\\dot q = M^{-1} J_{hip}^T P$ (the hip's
  velocity Jacobian $J_{hip}$; the generalized impulse of a point impulse);
- a pulse of force $F$ (N) during $[t_s, t_s + \\tau]$: generalized force $J_{hip}^T F$ in
  the equations of motion (the impulse is the limit $\\tau \\to 0$ with $F\\tau = P$).

The linear sensitivity of the next post-impact state to the impulse is computed two
independent ways that the tests compare:

1. forward-mode autodiff through the pushed step (heel-strike event included);
2. the transverse linearization of thesis ch. 6 plus an input term: the impulse changes
   the state by $B(t_s) P$, $B = (0, M^{-1}J_{hip}^T)$, enters the transverse coordinates
   through $L(t_s)$ (6.30), is propagated by $\\Phi(T)\\Phi(t_s)^{-1}$ of (6.21) and
   crosses the impact by $P^+ dF P^-$ (6.38): $\\zeta^+ = P^+ dF P^- \\Phi(T)
   \\Phi(t_s)^{-1} L(t_s) B(t_s) P$.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import padded_map
from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import DEFAULT_CONFIG, FAST_CONFIG, StepResult, classify_solve, flow
from ..solvers import diffeqsolve
from ._bisection import Threshold, bisect_threshold
from ._recovery import first_steps, recover_padded, step_capacity


def hip_jacobian(model, q):
    """$J_{hip} = \\partial p_{hip}/\\partial q$ (2 x n, world frame)."""
    return jax.jacfwd(lambda qq: model.points(qq)["hip"])(q)


def impulse_velocity_jump(model, q, impulse):
    """$\\Delta\\dot q = M(q)^{-1} J_{hip}(q)^T P$ for a hip impulse `impulse` (N s)."""
    return jnp.linalg.solve(model.mass_matrix(q), hip_jacobian(model, q).T @ impulse)


def direction(angle):
    """Unit push direction at `angle` (rad) from the direction of walking (+x), counter-
    clockwise: 0 forward, pi/2 up, pi backward, -pi/2 down."""
    return jnp.stack([jnp.cos(angle), jnp.sin(angle)])


def swing_from(model, x, t0, t_max, config, vector_field=None):
    """Rest of a swing from state `x` at time `t0` to heel strike (strike gate respected:
    if it is already open at `x`, look for the strike at once)."""
    n = model.n_dof
    tiny = 1e-9 * model.time_scale  # the end of a solve whose answer is not used
    open0 = model.strike_gate(x[:n]) > 0
    sol1 = flow(
        model,
        x,
        jnp.where(open0, t0 + tiny, t_max),
        config,
        gate=True,
        t0=t0,
        vector_field=vector_field,
    )
    code1 = classify_solve(sol1)
    opened = open0 | (code1 == RESULTS.successful)
    assert sol1.ys is not None and sol1.ts is not None  # flow saves at t1
    x_mid = jnp.where(open0, x, sol1.ys[-1])
    t_mid = jnp.where(open0, t0, sol1.ts[-1])
    sol2 = flow(
        model,
        x_mid,
        jnp.where(opened, t_max, t_mid + tiny),
        config,
        t0=t_mid,
        vector_field=vector_field,
    )
    code = RESULTS.where(opened, classify_solve(sol2), code1)
    assert sol2.ys is not None and sol2.ts is not None  # flow saves at t1
    x_minus = jnp.where(opened, sol2.ys[-1], sol1.ys[-1])
    t_end = jnp.where(opened, sol2.ts[-1], t_mid)
    return x_minus, t_end, code


def finish_step(model, x_minus, period, code, x_fallback):
    x_plus, impulse, physical = model.impact(x_minus)
    finite = jnp.all(jnp.isfinite(x_plus)) & jnp.all(jnp.isfinite(impulse))
    code = RESULTS.where((code == RESULTS.successful) & ~physical, RESULTS.bad_impact, code)
    code = RESULTS.where((code == RESULTS.successful) & ~finite, RESULTS.nonfinite, code)
    ok = code == RESULTS.successful
    x_plus = jnp.where(ok, x_plus, x_fallback)
    return StepResult(x_minus, x_plus, period, jnp.where(ok, impulse, 0.0), code)


def _pushed_step(model, x0, t_push, kick, config, alive):
    """Nominal flow to `t_push`, then `kick(x) -> (x_after, t_after)`, then the rest of the
    swing to heel strike, impact. The kick must end before the heel strike."""
    n = model.n_dof
    t_max = config.t_max_factor * model.time_scale
    tiny = 1e-12 * model.time_scale  # a solve of (almost) zero length
    t_s = jnp.maximum(t_push, tiny)
    alive = jnp.asarray(alive)
    sol0 = flow(model, x0, jnp.where(alive, t_s, tiny), config, event=False)
    assert sol0.ys is not None  # flow saves at t1
    xs = sol0.ys[-1]
    x_k, t_k = kick(xs, t_s)
    bad = model.fallen(xs[:n]) | model.fallen(x_k[:n]) | ~jnp.all(jnp.isfinite(x_k))
    x_minus, t_end, code = swing_from(
        model, x_k, jnp.where(alive, t_k, tiny), jnp.where(alive, t_max, 2 * tiny), config
    )
    code = RESULTS.where(bad, RESULTS.fell, code)
    return finish_step(model, x_minus, t_end, code, x0)


@stored_jit(arrays=("t_push",))
def impulse_step(model, x0, t_push, impulse, config=DEFAULT_CONFIG, alive=True):
    """One step from the post-impact state `x0` with a hip impulse `impulse` (N s, world
    frame) at time `t_push` after the step began (before the nominal heel strike).

    **Returns:** a `StepResult` (period measured from the start of the step).
    """
    n = model.n_dof

    def kick(x, t):
        return x.at[n:].add(impulse_velocity_jump(model, x[:n], impulse)), t

    return _pushed_step(model, x0, t_push, kick, config, alive)


@stored_jit(arrays=("t_push", "duration"))
def pulse_step(model, x0, t_push, force, duration, config=DEFAULT_CONFIG, alive=True):
    """One step from `x0` with a hip force `force` (N, world frame) acting during
    `[t_push, t_push + duration]` (integrated as its own segment, so that the adaptive
    solver cannot step over a short pulse; the pulse must end before the heel strike).

    **Returns:** a `StepResult`.
    """
    n = model.n_dof

    def vf(t, x, args):
        q, dq = x[:n], x[n:]
        tau = hip_jacobian(model, q).T @ force
        return jnp.concatenate([dq, model.acceleration(q, dq, tau)])

    def kick(x, t):
        sol = flow(model, x, t + duration, config, event=False, vector_field=vf, t0=t)
        assert sol.ys is not None  # flow saves at t1
        return sol.ys[-1], t + duration

    return _pushed_step(model, x0, t_push, kick, config, alive)


# ---- linear sensitivity, way 1: autodiff through the pushed step -------------------------
@stored_jit(arrays=("period",))
def push_sensitivity_autodiff(model, x_star, period, phases, config=DEFAULT_CONFIG):
    """$\\partial x^+/\\partial P$ (shape `(len(phases), 2n, 2)`) of the post-impact state
    after a pushed step, per phase, by forward-mode autodiff at $P = 0$."""

    def one(s):
        return jax.jacfwd(lambda P: impulse_step(model, x_star, s * period, P, config).x_plus)(
            jnp.zeros(2)
        )

    return jax.vmap(one)(jnp.asarray(phases, dtype=float))


# ---- linear sensitivity, way 2: transverse linearization + input term -------------------
@stored_jit(arrays=("period",))
def push_sensitivity_transverse(model, x_star, x_minus, period, phases, rtol=1e-11, atol=1e-11):
    """$\\partial\\zeta^+/\\partial P$ (shape `(len(phases), 2n-1, 2)`): the transverse
    coordinates after the next impact per unit hip impulse at each phase, from the
    transverse linearization (thesis 6.21, 6.30, 6.38) plus the input term
    $L(t_s) B(t_s)$. `atol` in the walker's own units.
    """
    from .. import stability as tr

    n = model.n_dof
    k = n - 1
    r = 2 * k + 1
    lin = tr.transverse_linearization(model, x_star, x_minus, period, rtol=rtol, atol=atol)
    E0 = model.energy(x_star)
    phi0 = x_star[1:n]
    u0 = jnp.concatenate(
        [
            jnp.stack([x_star[0], x_star[n]]),
            phi0,
            x_star[n + 1 :] / x_star[n],
            jnp.eye(r, dtype=x_star.dtype).reshape(-1),
        ]
    )
    ts = jnp.asarray(phases, dtype=float) * lin.period
    ys = diffeqsolve(
        diffrax.ODETerm(tr.joint_vector_field),
        diffrax.Tsit5(),
        t0=0.0,
        t1=lin.period,
        dt0=None,
        y0=u0,
        args=(model, E0),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(
            rtol=rtol, atol=atol * tr.joint_state_units(model)
        ),
        max_steps=4096,
        throw=False,
    ).ys

    def one(u):
        theta, dtheta, phi, dphi = tr.split_orbit_state(model, u)
        Phi_s = u[2 + 2 * k :].reshape(r, r)
        x = tr.orbit_state(theta, dtheta, phi, dphi)
        q = x[:n]
        Bq = jnp.linalg.solve(model.mass_matrix(q), hip_jacobian(model, q).T)  # (n, 2)
        B = jnp.concatenate([jnp.zeros((n, 2), x.dtype), Bq], axis=0)
        L = tr.L_matrix(model, E0, theta, dtheta, phi, dphi)
        return lin.dF_TS @ lin.Phi_T @ jnp.linalg.solve(Phi_s, L @ B)

    return jax.vmap(one)(ys), lin


# ---- largest push survived -----------------------------------------------------------------
def push_recovery(
    model,
    x_star,
    period,
    phases,
    angles,
    magnitudes,
    num_steps=30,
    tol=1e-4,
    duration=0.0,
    config=FAST_CONFIG,
):
    """Recovery after a push of magnitude `magnitudes` (impulse in N s, or force in N when
    `duration > 0`) at phases `phases` in directions `angles` (rad), all of one batch shape.

    **Returns:** a `vhcjax.Recovery`.
    """
    rec = _push_recovery(
        model,
        x_star,
        period,
        phases,
        angles,
        magnitudes,
        np.int64(num_steps),
        step_capacity(num_steps),
        tol,
        duration,
        config,
    )
    return first_steps(rec, num_steps)


@stored_jit(arrays=("period",))
def _push_recovery(
    model, x_star, period, phases, angles, magnitudes, count, capacity, tol, duration, config
):
    s = jnp.asarray(phases, dtype=float)
    P = jnp.asarray(magnitudes, dtype=float)[:, None] * jax.vmap(direction)(jnp.asarray(angles))
    x0 = jnp.broadcast_to(x_star, (s.shape[0], x_star.shape[0]))

    def first(x, alive):
        if duration > 0:
            return jax.vmap(
                lambda xx, ss, pp, aa: pulse_step(model, xx, ss * period, pp, duration, config, aa)
            )(x, s, P, alive)
        return jax.vmap(
            lambda xx, ss, pp, aa: impulse_step(model, xx, ss * period, pp, config, aa)
        )(x, s, P, alive)

    return recover_padded(
        model, x0, x_star, count, capacity, tol=tol, config=config, first_step=first
    )


def pulse_past_strike(phases, period, duration):
    """Why a pulse of `duration` (s) from some phase of a step of `period` (s) cannot be
    simulated (it would still act at the heel strike: `pulse_step` integrates the pulse
    as its own segment, without the impact), or `""` where every pulse ends within the
    step. Checked against the unpushed gait's strike: a push that brings the strike
    earlier is not caught here."""
    phases = np.asarray(phases, dtype=float).reshape(-1)
    period = float(period)
    if duration <= 0 or phases.size == 0:
        return ""
    last = float(phases.max())
    if last * period + duration < period:
        return ""
    return (
        f"a pulse of {duration:g} s from phase {last:g} ends at "
        f"{last * period + duration:.4g} s, after the heel strike of the gait "
        f"(step period {period:.4g} s): each pulse must end within its step, here "
        f"shorter than {(1.0 - last) * period:.4g} s"
    )


class PushThresholds(eqx.Module):
    """Largest push survived (returns to the gait), per phase and direction.

    - `phases`, `angles`: the grid (rad for angles).
    - `threshold`: a `vhcjax.Threshold`, arrays of shape `(len(phases), len(angles))`
      flattened row-major: `lo` survives, `hi` does not.
    - `largest`: `lo` reshaped to `(len(phases), len(angles))`.
    - `most_fragile_phase`: per direction, the phase with the smallest `largest` (NaN
      where no push survived at any phase, or where every phase survived `p_max`).
    - `duration`: 0 for impulses (N s), else the pulse duration (s) (forces in N).
    """

    phases: np.ndarray
    angles: np.ndarray
    threshold: Threshold
    largest: np.ndarray
    most_fragile_phase: np.ndarray
    duration: float


def push_bound(model, duration=0.0):
    """The default upper bound of `max_push`: 20 N s (an impulse, `duration = 0`) or
    196.2 N (a pulse force) for the thesis's walker (20 kg, 1 m, 9.81 m/s^2), in the same
    proportion to `model`'s own impulse unit $M\\sqrt{gL}$ or force unit $Mg$ (`scales`),
    so that a rescaled walker is searched over the rescaled range. Traceable."""
    s = model.scales()
    if duration == 0:
        return s["mass"] * jnp.sqrt(s["acceleration"] * s["length"] / 9.81)
    return s["mass"] * s["acceleration"]


@host_only("`push_sensitivity_autodiff` or vmap `impulse_step`")
def max_push(
    model,
    x_star,
    period,
    phases,
    angles,
    *,
    p_max=None,
    duration=0.0,
    iterations=14,
    scan=8,
    num_steps=30,
    tol=1e-4,
    config=FAST_CONFIG,
    progress=None,
):
    """Largest impulse (or pulse force) at each phase and direction after which the walker
        returns to the gait within `num_steps`, by batched bisection on `[0, p_max]`
    (default `push_bound(model, duration)`, in proportion to the walker's own units).
        A `ValueError` where a pulse (`duration > 0`) would still act at the gait's heel
        strike (`pulse_past_strike`).

        **Returns:** `PushThresholds`.
    """
    phases = np.asarray(phases, dtype=float)
    angles = np.asarray(angles, dtype=float)
    p_max = push_bound(model, duration) if p_max is None else p_max
    if phases.size == 0 or angles.size == 0:
        raise ValueError("max_push: give at least one phase and one angle")
    if not (np.isfinite(phases).all() and np.isfinite(angles).all()):
        raise ValueError("max_push: phases and angles must be finite")
    late = pulse_past_strike(phases, period, duration)
    if late:
        raise ValueError(f"max_push: {late}")
    S, A = np.meshgrid(phases, angles, indexing="ij")
    s_flat, a_flat = jnp.asarray(S.ravel()), jnp.asarray(A.ravel())

    def labels(s, a, mag):
        return push_recovery(
            model, x_star, period, s, a, mag, num_steps, tol, duration, config
        ).label

    def survives(mag):  # the recovery labels: CONVERGED (0) survives; in padded batches
        return padded_map(labels, s_flat, a_flat, jnp.asarray(mag, float), stage="pushes")

    th = bisect_threshold(
        survives,
        np.zeros(S.size),
        np.full(S.size, p_max),
        iterations=iterations,
        scan=scan,
        progress=progress,
    )
    largest = th.lo.reshape(S.shape)
    # per direction, among the pairs with a threshold found: NaN where none survived a
    # push, or all survived `p_max` (then no phase is known to be more fragile)
    top = (np.asarray(th.survives_max) & ~np.asarray(th.fails_min)).reshape(S.shape)
    known = np.isfinite(largest) & ~top
    fragile = np.where(
        known.any(axis=0),
        phases[np.argmin(np.where(known, largest, np.inf), axis=0)],
        np.nan,
    )
    return PushThresholds(phases, angles, th, largest, fragile, float(duration))
