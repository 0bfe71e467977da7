"""Transverse linearization with an input, along any period-1 gait, and its jump matrix.

The phase is $\\theta = q_1$ (monotone along a gait); the moving Poincare sections are
$\\{\\theta = \\text{const}\\}$ (thesis ch. 6; Shiriaev et al. 2005, 2008). On a section the
state is $x = (\\theta, w)$, $w = (q_{2..n}, \\dot q_{1..n})$: $2n - 1$ transverse
coordinates $\\zeta = w - w_\\star(s)$ measured from the orbit point on the same
section, with the normalised phase $s = (\\theta - \\theta^+)/(\\theta^- - \\theta^+)
\\in [0, 1]$. With $s$ as independent variable the walker obeys
$dw/ds = (\\theta^- - \\theta^+)\\, f_w(x, u)/\\dot\\theta$, whose linearization along
$w_\\star$ is the transverse linearization, written per unit of orbit time
($dt/ds = (\\theta^- - \\theta^+)/\\dot\\theta_\\star$):
$$\\dot\\zeta = A(s)\\zeta + B(s)u, \\qquad \\zeta^+ = J\\zeta^-,$$
with $A$, $B$ by `jax.jacfwd` for any model, and $J$ the jump at impact: flow to the
guard (a first-order correction along the flow, as thesis 6.35), impact Jacobian (6.23),
flow back to the section $\\theta = \\theta^+$ (6.36). The open-loop multipliers
(eigenvalues of $J\\Phi$) equal those of thesis (6.42) and of the Poincare map.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .._programs import stored_jit
from .._results import RESULTS
from ..stability import guard_normal
from ._actuated import actuated_vector_field, num_inputs


def phase_field(model, theta_plus, delta, s, w, u):
    """$dw/ds$ and $dt/ds$ at phase `s`, transverse state `w` and input `u`."""
    x = jnp.concatenate([(theta_plus + s * delta)[None], w])
    f = actuated_vector_field(model, x, u)
    dt_ds = delta / f[0]
    return f[1:] * dt_ds, dt_ds


def phase_matrices(model, theta_plus, delta, s, w):
    """$(A, B, dt/ds)$ at phase `s` on the orbit point `w` ($A$, $B$ per unit time)."""
    m = num_inputs(model)
    u0 = jnp.zeros(m, w.dtype)
    (dA, dB), c = (
        jax.jacfwd(
            lambda ww, uu: phase_field(model, theta_plus, delta, s, ww, uu)[0], argnums=(0, 1)
        )(w, u0),
        phase_field(model, theta_plus, delta, s, w, u0)[1],
    )
    return dA / c, dB / c, c


def jump_matrix(model, x_minus):
    """$J = \\partial\\zeta^+/\\partial\\zeta^-$ at the pre-impact orbit point `x_minus`.

    $J = [-f^+_w/f^+_\\theta,\\ I]\\; dF\\; (I - \\tilde f^- n^{-T}/n^{-T}\\tilde f^-)
    \\begin{bmatrix}0\\\\ I\\end{bmatrix}$ with $\\tilde f = f/f_\\theta$ the flow per unit
    of phase, $n^-$ the guard normal (6.25) and $dF$ the impact Jacobian (6.23).
    **Returns:** `(J, x_plus)`.
    """
    m = num_inputs(model)
    r = x_minus.shape[0] - 1
    u0 = jnp.zeros(m, x_minus.dtype)
    fm = actuated_vector_field(model, x_minus, u0)
    fm = fm / fm[0]
    nm = guard_normal(model, x_minus)
    E = jnp.eye(r + 1, r, k=-1, dtype=x_minus.dtype)
    P_minus = (jnp.eye(r + 1, dtype=x_minus.dtype) - jnp.outer(fm, nm) / jnp.dot(nm, fm)) @ E
    x_plus = model.impact(x_minus)[0]
    dF = jax.jacfwd(lambda x: model.impact(x)[0])(x_minus)
    fp = actuated_vector_field(model, x_plus, u0)
    S_plus = jnp.concatenate([-(fp[1:] / fp[0])[:, None], jnp.eye(r, dtype=x_minus.dtype)], 1)
    return S_plus @ dF @ P_minus, x_plus


# diffrax traces a vector field several times per solve (initial step, solver state,
# step); jitted, the later traces reuse the first one's jaxpr (as `vhcjax._transverse`).
phase_field = stored_jit(phase_field)
phase_matrices = stored_jit(phase_matrices)


class TransverseSystem(eqx.Module):
    """The transverse linearization of one gait, tabulated on a uniform phase grid.

    - `s`: phase grid on $[0, 1]$, shape `(N+1,)`.
    - `theta_plus`, `theta_minus`: $\\theta = q_1$ just after and just before impact.
    - `w`, `dw`: orbit $w_\\star(s)$ and $dw_\\star/ds$, shape `(N+1, 2n-1)`.
    - `A`, `B`: $A(s)$, $B(s)$ per unit time, shapes `(N+1, r, r)`, `(N+1, r, m)`.
    - `dt_ds`: $dt/ds$ on the grid; `period`: the step time $\\int dt$.
    - `J`: jump matrix at impact, `(r, r)`.
    - `Phi`: transition matrix of $d\\zeta/ds = (dt/ds) A\\zeta$ over $[0, 1]$.
    - `multipliers`: eigenvalues of $J\\Phi$, by modulus (descending).
    - `x_plus`, `x_minus`: post- and pre-impact orbit states.
    - `closure`: $\\|F(x_\\star^-) - x_\\star^+\\|_\\infty$, how well the tabulated orbit closes.
    - `result`: a `RESULTS` code.
    """

    s: jax.Array
    theta_plus: jax.Array
    theta_minus: jax.Array
    w: jax.Array
    dw: jax.Array
    A: jax.Array
    B: jax.Array
    dt_ds: jax.Array
    period: jax.Array
    J: jax.Array
    Phi: jax.Array
    multipliers: jax.Array
    x_plus: jax.Array
    x_minus: jax.Array
    closure: jax.Array
    result: RESULTS


def _solve_code(sol):
    return RESULTS.where(
        sol.result == diffrax.RESULTS.successful,
        RESULTS.successful,
        RESULTS.where(
            sol.result == diffrax.RESULTS.max_steps_reached,
            RESULTS.max_steps_reached,
            RESULTS.nonfinite,
        ),
    )


def transverse_system(model, x_plus, *, num_points=401):
    """Transverse linearization with input of the period-1 gait through `x_plus`.

    **Arguments:**

    - `model`: a single-domain `WalkerModel` with an `input_matrix`; $q_1$ must be
      monotone along the gait.
    - `x_plus`: post-impact state of the gait (a fixed point of the step map, e.g.
      `model.section_to_state(z)`); the orbit is passive ($u = 0$ on it).
    - `num_points`: phase-grid points (the feedback interpolates on this grid); the
      orbit and $\\Phi$ are integrated with fixed Tsit5 steps on this grid.

    **Returns:** a `TransverseSystem`.
    """
    x_plus = jnp.asarray(x_plus, float)
    n = model.n_dof
    # The impact leaves the configuration unchanged and relabelling is an involution on
    # configurations, so the pre-impact configuration is the relabelled post-impact one.
    q_minus = model.relabel(x_plus[:n], jnp.zeros(n, x_plus.dtype))[0]
    theta_plus, theta_minus = x_plus[0], q_minus[0]
    delta = theta_minus - theta_plus
    r = x_plus.shape[0] - 1
    m = num_inputs(model)
    u0 = jnp.zeros(m, x_plus.dtype)
    s = jnp.linspace(0.0, 1.0, num_points)

    def field(ss, y, args):
        w = y[:r]
        dw, c = phase_field(model, theta_plus, delta, ss, w, u0)
        A, _, _ = phase_matrices(model, theta_plus, delta, ss, w)
        Phi = y[r + 1 :].reshape(r, r)
        return jnp.concatenate([dw, c[None], (c * A @ Phi).reshape(-1)])

    y0 = jnp.concatenate([x_plus[1:], jnp.zeros(1, x_plus.dtype), jnp.eye(r).reshape(-1)])
    # Fixed steps (Tsit5, 5th order) landing on the grid: the tabulated orbit is then
    # a smooth function of s to ~1e-14 (dense output between adaptive steps is not: its
    # error, differentiated by the feedback along the orbit, would show in the closed-loop
    # Poincare map).
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Tsit5(),
        t0=0.0,
        t1=1.0,
        dt0=1.0 / (num_points - 1),
        y0=y0,
        stepsize_controller=diffrax.ConstantStepSize(),
        saveat=diffrax.SaveAt(ts=s),
        max_steps=num_points + 8,
        throw=False,
    )
    ys = sol.ys
    assert ys is not None  # saved at `ts`
    w = ys[:, :r]
    A, B, c = jax.vmap(lambda ss, ww: phase_matrices(model, theta_plus, delta, ss, ww))(s, w)
    dw = jax.vmap(lambda ss, ww: phase_field(model, theta_plus, delta, ss, ww, u0)[0])(s, w)
    Phi = ys[-1, r + 1 :].reshape(r, r)
    x_minus = jnp.concatenate([theta_minus[None], w[-1]])
    J, xp = jump_matrix(model, x_minus)
    closure = jnp.max(jnp.abs(xp - x_plus))
    ev = jnp.linalg.eigvals(J @ Phi)
    ev = ev[jnp.argsort(-jnp.abs(ev))]
    code = _solve_code(sol)
    finite = jnp.all(jnp.isfinite(J)) & jnp.all(jnp.isfinite(Phi)) & jnp.all(jnp.isfinite(A))
    code = RESULTS.where((code == RESULTS.successful) & ~finite, RESULTS.nonfinite, code)
    return TransverseSystem(
        s,
        theta_plus,
        theta_minus,
        w,
        dw,
        A,
        B,
        c,
        ys[-1, r],
        J,
        Phi,
        ev,
        x_plus,
        x_minus,
        closure,
        code,
    )
