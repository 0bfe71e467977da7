"""Transverse linearization of a passive gait (thesis chapter 6), without symbolic algebra.

Along a gait $q_\\star = (\\theta_\\star, \\phi(\\theta_\\star))$ ($\\theta = q_1$, $\\phi$ the
virtual holonomic constraint, $n - 1$ components) the transverse coordinates are (6.15)
$$x_\\perp = (I, y, \\dot y), \\qquad y = q_{2..n} - \\phi(\\theta),\\;
\\dot y = \\dot q_{2..n} - \\phi'(\\theta)\\dot\\theta,$$
$2n - 1$ of them, with $I = \\dot\\theta^2 - \\dot\\theta_\\star^2(\\theta)$ the integral
function (2.52) of the scalar reduced dynamics (6.10)
$\\alpha_0\\ddot\\theta + \\beta_0\\dot\\theta^2 + \\gamma_0 = 0$. Its weights eliminate
$\\phi''$ (`theta_dynamics_coefficients`; for n = 2 they are (6.9) divided by $\\det M$, so
that $\\alpha_0 = 1$). In these coordinates the equations of motion read (6.12)-(6.13)
$\\alpha_0\\ddot\\theta + \\beta_0\\dot\\theta^2 + \\gamma_0 = g$, $\\ddot y = h$, with $g$, $h$
zero on the orbit; $\\dot I = 2\\dot\\theta(g - \\beta_0 I)/\\alpha_0$ (2.55). Everything the
thesis derives in Maple (appendix B.5, B.6) comes from `jax.jacfwd` here:

- $g_y, g_{\\dot y}, h_y, h_{\\dot y}$ (6.17) and the directional derivatives
  $g_I, h_I$ (6.18) with the normal $n = (-\\ddot\\theta_\\star, \\dot\\theta_\\star)$;
- $A(t)$ (6.21) and $\\Phi(T)$ from $\\dot\\Phi = A\\Phi$, integrated with diffrax together
  with $\\theta_\\star(t)$ from (6.10) and $\\phi, \\phi'$ from the $\\phi''$ ODE (5.19) (one
  joint ODE in $t$, stopped by an event at $\\theta = \\theta_\\star^-$);
- $dF$ (6.23) = jacfwd of the impact map; the normals $n^\\mp$ (6.25), (6.27) =
  gradients of the guard; $L(t)$ (6.30), $m(t)$ (6.31);
- the projections (6.35) and (6.36) - the latter in the direction of appendix B.6,
  $\\zeta^+ = L(T^+)(I - m n^{+T}/m^T n^+)\\,\\delta x^+$ (as printed, (6.36) maps
  $\\zeta^+$ to $\\delta x^+$, which is the wrong way round);
- $\\Xi = P^+\\, dF\\, P^-\\, \\Phi(T)$ (6.42), whose eigenvalues are the multipliers of the
  gait.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .._programs import stored_jit
from .._results import RESULTS
from ..gait import phi_second_derivative, theta_dynamics_coefficients
from ..hybrid._simulate import _units, event_root_finder


# ---- transverse dynamics (6.6)-(6.13) ---------------------------------------------------
def g_h(model, theta, dtheta, y, dy, phi, dphi, ddphi):
    """$g$ and $h$ of thesis (6.12)-(6.13) at $(\\theta, \\dot\\theta, y, \\dot y)$.

    `phi`, `dphi`, `ddphi` are $\\phi, \\phi', \\phi''$ at `theta` (arrays of n-1). The
    full accelerations come from the equations of motion (3.7) at
    $q = (\\theta, \\phi + y)$, $\\dot q = (\\dot\\theta, \\phi'\\dot\\theta + \\dot y)$; then
    $\\ddot y = \\ddot q_{2..n} - \\phi''\\dot\\theta^2 - \\phi'\\ddot\\theta$ (6.5) and
    $g = \\alpha_0\\ddot\\theta + \\beta_0\\dot\\theta^2 + \\gamma_0$ with the orbit's
    coefficients at `theta`.
    """
    theta = jnp.asarray(theta)
    q = jnp.concatenate([theta[None], phi + y])
    dq = jnp.concatenate([jnp.asarray(dtheta)[None], dphi * dtheta + dy])
    ddq = model.acceleration(q, dq)
    ddtheta = ddq[0]
    h = ddq[1:] - ddphi * dtheta**2 - dphi * ddtheta
    a0, b0, c0 = theta_dynamics_coefficients(model, theta, phi, dphi)
    g = a0 * ddtheta + b0 * dtheta**2 + c0
    return g, h


def _local_constraint(model, E0, theta, phi, dphi):
    """$s \\mapsto (\\phi, \\phi', \\phi'')(\\theta + s)$, exact to first order in $s$ (enough
    for first derivatives at $s = 0$): $\\phi'' $ from the ODE (5.19) along the line."""
    ddphi0 = phi_second_derivative(model, E0, theta, phi, dphi)[0]

    def at(s):
        p = phi + dphi * s
        dp = dphi + ddphi0 * s
        ddp = phi_second_derivative(model, E0, theta + s, p, dp)[0]
        return p, dp, ddp

    return at


def system_matrix(model, E0, theta, dtheta, phi, dphi):
    """$A(t)$ of thesis (6.21) at the orbit point $(\\theta_\\star, \\dot\\theta_\\star)$.

    Shape (2n-1, 2n-1), coordinates $\\zeta = (\\Delta I, \\Delta y, \\Delta\\dot y)$.
    **Returns:** `(A, parts)` where `parts` holds $g_I, g_y, g_{\\dot y}, h_I, h_y,
    h_{\\dot y}$, $\\alpha_0, \\beta_0$ and $\\ddot\\theta_\\star$.
    """
    k = phi.shape[0]
    at = _local_constraint(model, E0, theta, phi, dphi)
    _, _, ddphi = at(0.0)
    a0, b0, c0 = theta_dynamics_coefficients(model, theta, phi, dphi)
    ddtheta = -(b0 * dtheta**2 + c0) / a0  # (6.10) on the orbit

    def gh_flat(s, dth, y, dy):
        p, dp, ddp = at(s)
        g, h = g_h(model, theta + s, dth, y, dy, p, dp, ddp)
        return jnp.concatenate([g[None], h])

    zeros = jnp.zeros(k, phi.dtype)
    d_s, d_dth, d_y, d_dy = jax.jacfwd(gh_flat, argnums=(0, 1, 2, 3))(
        jnp.zeros((), phi.dtype), dtheta, zeros, zeros
    )
    # (6.18): derivative along n = (-ddtheta, dtheta) in the (theta, dtheta) plane over
    # that of I, whose gradient on the orbit is (-2 ddtheta, 2 dtheta) (6.19); the normal
    # taken in the walker's own units (theta, T dtheta), which balances the two terms
    # (any direction across the orbit gives the same derivative: g, h vanish along it).
    T = jnp.asarray(model.time_scale, dtype=phi.dtype)
    a, b = ddtheta * T**2, dtheta * T
    d_I = (-d_s * a * T**2 + d_dth * b * T) / (2.0 * (a**2 + b**2))
    gI, hI = d_I[0], d_I[1:]
    gy, hy = d_y[0], d_y[1:]
    gdy, hdy = d_dy[0], d_dy[1:]
    c = 2.0 * dtheta / a0
    row_I = jnp.concatenate([(c * (gI - b0))[None], c * gy, c * gdy])
    row_y = jnp.concatenate([jnp.zeros((k, 1 + k), phi.dtype), jnp.eye(k, dtype=phi.dtype)], 1)
    row_dy = jnp.concatenate([hI[:, None], hy, hdy], axis=1)
    A = jnp.concatenate([row_I[None], row_y, row_dy], axis=0)
    parts = dict(gI=gI, gy=gy, gdy=gdy, hI=hI, hy=hy, hdy=hdy, alpha0=a0, beta0=b0, ddtheta=ddtheta)
    return A, parts


# ---- maps between transverse and full coordinates (6.29)-(6.31) -------------------------
def L_matrix(model, E0, theta, dtheta, phi, dphi):
    """$L(t) = \\partial x_\\perp / \\partial x$ on the orbit (thesis 6.30), shape (2n-1, 2n)."""
    k = phi.shape[0]
    ddphi = phi_second_derivative(model, E0, theta, phi, dphi)[0]
    a0, b0, c0 = theta_dynamics_coefficients(model, theta, phi, dphi)
    ddtheta = -(b0 * dtheta**2 + c0) / a0
    dt = phi.dtype
    e1 = jnp.zeros(k + 1, dt).at[0].set(1.0)
    row_I = jnp.concatenate([-2.0 * ddtheta * e1, 2.0 * dtheta * e1])
    eye = jnp.eye(k, dtype=dt)
    zk = jnp.zeros((k, k + 1), dt)
    row_y = jnp.concatenate([-dphi[:, None], eye, zk], axis=1)
    row_dy = jnp.concatenate(
        [-(ddphi * dtheta)[:, None], jnp.zeros((k, k), dt), -dphi[:, None], eye], axis=1
    )
    return jnp.concatenate([row_I[None], row_y, row_dy], axis=0)


def m_vector(model, E0, theta, dtheta, phi, dphi):
    """$m(t) = \\dot x_\\star(t)$, the flow direction on the orbit (thesis 6.31)."""
    ddphi = phi_second_derivative(model, E0, theta, phi, dphi)[0]
    a0, b0, c0 = theta_dynamics_coefficients(model, theta, phi, dphi)
    ddtheta = -(b0 * dtheta**2 + c0) / a0
    return jnp.concatenate(
        [
            jnp.asarray(dtheta)[None],
            dphi * dtheta,
            ddtheta[None],
            ddphi * dtheta**2 + dphi * ddtheta,
        ]
    )


def orbit_state(theta, dtheta, phi, dphi):
    """$x_\\star = (\\theta, \\phi, \\dot\\theta, \\phi'\\dot\\theta)$ (thesis 6.2)."""
    theta = jnp.asarray(theta)
    return jnp.concatenate([theta[None], phi, jnp.asarray(dtheta)[None], dphi * dtheta])


def guard_normal(model, x):
    """Gradient of the heel-strike guard in state space, $n^-$ (thesis 6.25)."""
    n = model.n_dof
    gq = jax.grad(model.guard)(x[:n])
    return jnp.concatenate([gq, jnp.zeros(n, x.dtype)])


def post_impact_normal(model, x_plus):
    """Normal of the post-impact surface $\\Gamma^+ = \\{q : \\text{guard}(\\text{relabel}(q))
    = 0\\}$ (thesis 6.27; relabelling is an involution for leg swaps)."""
    n = model.n_dof

    def surf(q):
        return model.guard(model.relabel(q, jnp.zeros_like(q))[0])

    gq = jax.grad(surf)(x_plus[:n])
    return jnp.concatenate([gq, jnp.zeros(n, x_plus.dtype)])


def flow_projection(m, normal):
    """$I - m n^T / (m^T n)$: projection along the flow $m$ onto $\\{n^T\\delta x = 0\\}$."""
    return jnp.eye(m.shape[0], dtype=m.dtype) - jnp.outer(m, normal) / jnp.dot(m, normal)


# ---- the whole construction (6.40)-(6.42) -----------------------------------------------
class TransverseLinearization(eqx.Module):
    """Transverse linearization of one gait.

    - `Xi`: $\\Xi$ of (6.42), shape (2n-1, 2n-1): the linearized return map in the
      transverse coordinates just after impact.
    - `multipliers`: eigenvalues of `Xi`, sorted by modulus (descending), complex.
    - `Phi_T`: $\\Phi(T)$, the state transition matrix of (6.21).
    - `dF`: Jacobian of the impact map at $x_\\star^-$ (6.23), (2n, 2n).
    - `dF_TS`: $P^+ dF P^-$ (6.38).
    - `P_minus`, `P_plus`: the projections (6.35) and (6.36) (the latter in the direction
      $\\delta x^+ \\mapsto \\zeta^+$).
    - `x_minus`: $x_\\star^-$ at the end of the integrated orbit; `period`: the time
      $T$ at which $\\theta_\\star$ reaches $\\theta^-$.
    - `condition`: the larger condition number of $[L; m^T]$ at $x^-$ and $x^+$ in the
      walker's own units (the change to transverse coordinates; large where they
      degenerate; 1/eps where singular).
    - `transversality`: the smaller $|m^T n| / (|m| |n|)$ (own units) at the two impact surfaces
      (near 0 where the flow is tangent to them and the projections (6.35), (6.36) blow
      up).
    - `result`: `successful` or a failure code (`max_steps_reached`, `no_impact`,
      `nonfinite`).
    """

    Xi: jax.Array
    multipliers: jax.Array
    Phi_T: jax.Array
    dF: jax.Array
    dF_TS: jax.Array
    P_minus: jax.Array
    P_plus: jax.Array
    x_minus: jax.Array
    period: jax.Array
    condition: jax.Array
    transversality: jax.Array
    result: RESULTS


def _cosine(m, normal):
    return jnp.abs(jnp.dot(m, normal)) / (jnp.linalg.norm(m) * jnp.linalg.norm(normal))


def _own_units(model):
    """$T$ (`model.time_scale`), the units of the state (angles 1, rates $1/T$) and of
    the transverse coordinates ($I$: $1/T^2$, $y$: 1, $\\dot y$: $1/T$), so that the
    conditioning, transversality and ODE tolerances do not depend on the walker's size
    or gravity."""
    n = model.n_dof
    T, state = _units(model)
    perp = jnp.concatenate([(1 / T**2)[None], jnp.ones(n - 1), jnp.ones(n - 1) / T])
    return T, state, perp


def joint_state_units(model):
    """The units of the state of `joint_vector_field`, $(\\theta, \\dot\\theta, \\phi,
    \\phi', \\Phi)$: angles 1, $\\dot\\theta$ $1/T$, $\\phi'$ 1, and $\\Phi_{ij}$ the
    ratio of the units of transverse coordinates $i$ and $j$ (the absolute tolerance of
    its integration, times `atol`)."""
    T, _, perp = _own_units(model)
    k = model.n_dof - 1
    head = jnp.concatenate([jnp.stack([1.0, 1 / T]), jnp.ones(2 * k)])
    return jnp.concatenate([head, (perp[:, None] / perp).reshape(-1)])


def split_orbit_state(model, u):
    k = model.n_dof - 1
    theta, dtheta = u[0], u[1]
    phi, dphi = u[2 : 2 + k], u[2 + k : 2 + 2 * k]
    return theta, dtheta, phi, dphi


# diffrax traces the field five times (initial step, solver state, step); jitted, the
# later traces reuse the first one's jaxpr.
@stored_jit
def joint_vector_field(t, u, args):
    """$\\theta, \\dot\\theta$ by (6.10); $\\phi, \\phi'$ by (5.19) in $t$; $\\dot\\Phi = A\\Phi$."""
    model, E0 = args
    k = model.n_dof - 1
    r = 2 * k + 1
    theta, dtheta, phi, dphi = split_orbit_state(model, u)
    Phi = u[2 + 2 * k :].reshape(r, r)
    ddphi = phi_second_derivative(model, E0, theta, phi, dphi)[0]
    a0, b0, c0 = theta_dynamics_coefficients(model, theta, phi, dphi)
    ddtheta = -(b0 * dtheta**2 + c0) / a0
    A, _ = system_matrix(model, E0, theta, dtheta, phi, dphi)
    return jnp.concatenate(
        [jnp.stack([dtheta, ddtheta]), dphi * dtheta, ddphi * dtheta, (A @ Phi).reshape(-1)]
    )


@stored_jit(arrays=("period",))
def transverse_linearization(
    model, x_plus, x_minus, period, *, rtol=1e-11, atol=1e-11, max_steps=4096
):
    """Multipliers of a gait by transverse linearization (thesis 6.40-6.42, Steps 1-6).

    **Arguments:**

    - `model`: a `WalkerModel` with n DOF ($\\theta = q_1$ must be monotone on the gait).
    - `x_plus`: post-impact state of the gait ($(a, e, b, f)$ for the compass gait).
    - `x_minus`: pre-impact state; only $\\theta^- = $ `x_minus[0]` is used (the end of
      the orbit); the rest is recomputed from the integration.
    - `period`: the step period, used only to bound the integration (to 2x).
    - `rtol`, `atol`, `max_steps`: settings of the joint ODE (Tsit5); `atol` in the
      walker's own units (angles, and rates times `model.time_scale`).

    The condition number, the transversality and the lift off the transverse coordinates
    are computed in the walker's own units too.

    **Returns:** a `TransverseLinearization`.

    The orbit is rebuilt from `x_plus` alone: $E_0$ = energy of `x_plus`, $\\phi$, $\\phi'$
    from (5.19) with initial values $(q_{2..n}, \\dot q_{2..n}/\\dot q_1)$ (Step 2), and
    $\\theta_\\star(t)$ from (6.10) with initial values $(q_1, \\dot q_1)$ (Step 3). It does
    not use the hybrid simulator.
    """
    n = model.n_dof
    k = n - 1
    r = 2 * k + 1
    x_plus = jnp.asarray(x_plus, float)
    E0 = model.energy(x_plus)
    theta0, dtheta0 = x_plus[0], x_plus[n]
    phi0 = x_plus[1:n]
    dphi0 = x_plus[n + 1 :] / dtheta0
    theta_end = jnp.asarray(x_minus)[0]
    u0 = jnp.concatenate(
        [jnp.stack([theta0, dtheta0]), phi0, dphi0, jnp.eye(r, dtype=x_plus.dtype).reshape(-1)]
    )

    T_unit, x_unit, perp_unit = _own_units(model)

    def cond(t, y, args, **kwargs):  # in time units, as the root finder's `atol` (angle x T)
        return (y[0] - theta_end) * T_unit

    event = diffrax.Event(cond, root_finder=event_root_finder(model), direction=False)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(joint_vector_field),
        diffrax.Tsit5(),
        t0=0.0,
        t1=2.0 * period,
        dt0=None,
        y0=u0,
        args=(model, E0),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol * joint_state_units(model)),
        event=event,
        max_steps=max_steps,
        throw=False,
    )
    assert sol.ys is not None and sol.ts is not None  # saved at t1
    uT = sol.ys[-1]
    T = sol.ts[-1]
    code = RESULTS.where(
        sol.result == diffrax.RESULTS.event_occurred,
        RESULTS.successful,
        RESULTS.where(
            sol.result == diffrax.RESULTS.successful,
            RESULTS.no_impact,
            RESULTS.where(
                sol.result == diffrax.RESULTS.max_steps_reached,
                RESULTS.max_steps_reached,
                RESULTS.nonfinite,
            ),
        ),
    )
    Phi_T = uT[2 + 2 * k :].reshape(r, r)
    thT, dthT, phT, dphT = split_orbit_state(model, uT)
    xm = orbit_state(thT, dthT, phT, dphT)

    # Discrete part: (6.23), (6.25), (6.27), (6.30), (6.31), (6.35), (6.36).
    dF = jax.jacfwd(lambda x: model.impact(x)[0])(xm)
    n_minus = guard_normal(model, xm)
    n_plus = post_impact_normal(model, x_plus)
    L_minus = L_matrix(model, E0, thT, dthT, phT, dphT)
    m_minus = m_vector(model, E0, thT, dthT, phT, dphT)
    L_plus = L_matrix(model, E0, theta0, dtheta0, phi0, dphi0)
    m_plus = m_vector(model, E0, theta0, dtheta0, phi0, dphi0)

    def own(L, m):  # [L; m^T] in own units: x = D_x x', x_perp = D_perp x_perp'
        return jnp.concatenate([L * x_unit / perp_unit[:, None], (T_unit * m / x_unit)[None]])

    Lm = own(L_minus, m_minus)
    # [L; m^T]^-1 [I; 0] (any complement of m: the projection below removes it)
    lift = x_unit[:, None] * jnp.linalg.solve(Lm, jnp.eye(2 * n, r, dtype=Lm.dtype)) / perp_unit
    P_minus = flow_projection(m_minus, n_minus) @ lift
    P_plus = L_plus @ flow_projection(m_plus, n_plus)
    dF_TS = P_plus @ dF @ P_minus
    Xi = dF_TS @ Phi_T
    ev = jnp.linalg.eigvals(Xi)
    ev = ev[jnp.argsort(-jnp.abs(ev))]
    finite = jnp.all(jnp.isfinite(Xi))
    code = RESULTS.where((code == RESULTS.successful) & ~finite, RESULTS.nonfinite, code)
    Lp = own(L_plus, m_plus)
    condition = jnp.maximum(jnp.linalg.cond(Lm), jnp.linalg.cond(Lp))
    # numerically singular: 1/eps (finite, so that no result holds inf)
    condition = jnp.where(jnp.isfinite(condition), condition, 1 / jnp.finfo(Lm.dtype).eps)
    transversality = jnp.minimum(
        _cosine(T_unit * m_minus / x_unit, n_minus * x_unit),
        _cosine(T_unit * m_plus / x_unit, n_plus * x_unit),
    )
    transversality = jnp.where(jnp.isfinite(transversality), transversality, 0.0)
    return TransverseLinearization(
        Xi, ev, Phi_T, dF, dF_TS, P_minus, P_plus, xm, T, condition, transversality, code
    )
