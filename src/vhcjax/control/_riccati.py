"""The hybrid periodic Riccati equation of a gait, solved two independent ways.

For the transverse linearization $\\dot\\zeta = A\\zeta + Bu$, $\\zeta^+ = J\\zeta^-$ of a
gait (`transverse_system`) and weights $Q \\succeq 0$, $R \\succ 0$ and a jump weight
$Q_J \\succeq 0$, the cost $\\sum_k[\\int(\\zeta^TQ\\zeta + u^TRu)\\,dt + \\zeta_k^{-T}Q_J
\\zeta_k^-]$ is minimised by $u = -K\\zeta$, $K = R^{-1}B^TX$, where the periodic $X(s)$
solves (Manchester 2011, hybrid case of Shiriaev et al. 2008 and Freidovich, Shiriaev
and Manchester 2008)
$$-\\frac{dX}{ds} = \\frac{dt}{ds}\\,(A^TX + XA + Q - XBR^{-1}B^TX),\\qquad
X(1^-) = J^TX(0^+)J + Q_J.$$

- `riccati_backward`: backward integration over one step (diffrax) and the jump,
  repeated until $X(1^-)$ is a fixed point.
- `riccati_hamiltonian`: the stable invariant subspace of the monodromy
  $S_J\\Psi(1)$ of the Hamiltonian system
  $dZ/ds = (dt/ds)\\begin{bmatrix}A & -BR^{-1}B^T\\\\ -Q & -A^T\\end{bmatrix}Z$ with the
  symplectic jump $S_J = \\begin{bmatrix}J & 0\\\\ -J^{-T}Q_J & J^{-T}\\end{bmatrix}$
  ($J$ invertible): $X(0^+) = U_2U_1^{-1}$, then $X(s)$ from the Hamiltonian flow.
  The eigenvalues on that subspace are the closed-loop multipliers.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .._results import RESULTS
from ._actuated import num_inputs
from ._transverse import phase_field, phase_matrices


class RiccatiSolution(eqx.Module):
    """Periodic solution of the hybrid Riccati equation on the phase grid.

    - `s`: the phase grid (that of the `TransverseSystem`).
    - `X`: $X(s)$, shape `(N+1, r, r)` (`X[-1]` is $X(1^-)$, before the jump).
    - `K`: gains $K(s) = R^{-1}B(s)^TX(s)$, shape `(N+1, m, r)`.
    - `iterations`: fixed-point sweeps (backward method) or 0 (Hamiltonian method).
    - `residual`: backward: the last change of $X(1^-)$ (max abs); Hamiltonian: the
      periodicity defect $\\|X(1^-) - J^TX(0^+)J - Q_J\\|_\\infty$.
    - `eigenvalues`: Hamiltonian method: the stable eigenvalues of the monodromy (the
      closed-loop multipliers); backward method: NaN.
    - `result`: a `RESULTS` code.
    """

    s: jax.Array
    X: jax.Array
    K: jax.Array
    iterations: jax.Array
    residual: jax.Array
    eigenvalues: jax.Array
    result: RESULTS


def _weights(system, Q, R, Q_jump):
    r, m = system.B.shape[1], system.B.shape[2]
    Q = jnp.eye(r) if Q is None else jnp.asarray(Q, float)
    R = jnp.eye(m) if R is None else jnp.asarray(R, float)
    Q = jnp.diag(Q) if Q.ndim == 1 else Q
    R = jnp.diag(R) if R.ndim == 1 else R.reshape(m, m)
    Q_jump = Q if Q_jump is None else jnp.asarray(Q_jump, float)
    Q_jump = jnp.diag(Q_jump) if Q_jump.ndim == 1 else Q_jump
    return Q, R, Q_jump


def _gains(system, X, R):
    return jax.vmap(lambda B, XX: jnp.linalg.solve(R, B.T @ XX))(system.B, X)


def _sym(X):
    return 0.5 * (X + X.T)


def riccati_backward(
    model,
    system,
    Q=None,
    R=None,
    Q_jump=None,
    *,
    tol=1e-13,
    max_iterations=200,
    rtol=1e-12,
    atol=1e-12,
    max_steps=8192,
):
    """Periodic $X(s)$ by backward integration repeated to convergence.

    **Arguments:**

    - `model`: the model of `system`.
    - `system`: a `TransverseSystem`.
    - `Q`, `R`, `Q_jump`: weights (matrices or diagonals); default identities, and
      `Q_jump = Q`.
    - `tol`: stop when $\\max|\\Delta X(1^-)| \\le$ `tol` $(1 + \\max|X(1^-)|)$.
    - `max_iterations`: sweeps at most (else `not_converged`).
    - `rtol`, `atol`, `max_steps`: settings of the backward integration (Tsit5).

    **Returns:** a `RiccatiSolution`.
    """
    Q, R, Q_jump = _weights(system, Q, R, Q_jump)
    r = Q.shape[0]
    tp, delta = system.theta_plus, system.theta_minus - system.theta_plus
    Rinv = jnp.linalg.inv(R)

    def field(s, y, args):
        w = y[:r]
        X = y[r:].reshape(r, r)
        A, B, c = phase_matrices(model, tp, delta, s, w)
        dX = -c * (A.T @ X + X @ A + Q - X @ B @ Rinv @ B.T @ X)
        # w_star is integrated along (backward) so that A, B are exact at every s.
        return jnp.concatenate([_orbit_rate(model, tp, delta, s, w), dX.reshape(-1)])

    def sweep(X1, saveat):
        y0 = jnp.concatenate([system.w[-1], X1.reshape(-1)])
        return diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            diffrax.Tsit5(),
            t0=1.0,
            t1=0.0,
            dt0=None,
            y0=y0,
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
            saveat=saveat,
            max_steps=max_steps,
            throw=False,
        )

    def jump(X0):
        return _sym(system.J.T @ X0 @ system.J + Q_jump)

    def cond(carry):
        _, change, i, ok = carry
        return (change > tol) & (i < max_iterations) & ok

    def body(carry):
        X1, _, i, _ = carry
        sol = sweep(X1, diffrax.SaveAt(t1=True))
        assert sol.ys is not None  # saved at t1
        X0 = _sym(sol.ys[-1, r:].reshape(r, r))
        X1n = jump(X0)
        change = jnp.max(jnp.abs(X1n - X1)) / (1.0 + jnp.max(jnp.abs(X1n)))
        ok = (sol.result == diffrax.RESULTS.successful) & jnp.all(jnp.isfinite(X1n))
        return X1n, change, i + 1, ok

    X1_init = Q_jump
    X1, change, iters, ok = jax.lax.while_loop(
        cond, body, (X1_init, jnp.asarray(jnp.inf), jnp.asarray(0), jnp.asarray(True))
    )
    sol = sweep(X1, diffrax.SaveAt(ts=system.s[::-1]))
    assert sol.ys is not None  # saved at `ts`
    X = jax.vmap(_sym)(sol.ys[::-1, r:].reshape(-1, r, r))
    code = RESULTS.where(
        ok & (change <= tol),
        RESULTS.successful,
        RESULTS.where(ok, RESULTS.not_converged, RESULTS.nonfinite),
    )
    code = RESULTS.where(sol.result == diffrax.RESULTS.successful, code, RESULTS.nonfinite)
    nan = jnp.full((r,), jnp.nan + 0j)
    return RiccatiSolution(system.s, X, _gains(system, X, R), iters, change, nan, code)


def _orbit_rate(model, tp, delta, s, w):
    return phase_field(model, tp, delta, s, w, jnp.zeros(num_inputs(model), w.dtype))[0]


def riccati_hamiltonian(
    model, system, Q=None, R=None, Q_jump=None, *, rtol=1e-12, atol=1e-12, max_steps=8192
):
    """Periodic $X(s)$ from the stable invariant subspace of the Hamiltonian monodromy.

    Arguments as `riccati_backward` (no iteration). The jump matrix $J$ must be
    invertible (`nonfinite` otherwise).

    **Returns:** a `RiccatiSolution` whose `eigenvalues` are the $r$ stable eigenvalues
    of the monodromy, i.e. the closed-loop multipliers under $u = -K\\zeta$.
    """
    Q, R, Q_jump = _weights(system, Q, R, Q_jump)
    r = Q.shape[0]
    tp, delta = system.theta_plus, system.theta_minus - system.theta_plus
    Rinv = jnp.linalg.inv(R)

    def field(s, y, args):
        w = y[:r]
        Z = y[r:].reshape(2 * r, 2 * r)
        A, B, c = phase_matrices(model, tp, delta, s, w)
        H = jnp.block([[A, -B @ Rinv @ B.T], [-Q, -A.T]])
        return jnp.concatenate([_orbit_rate(model, tp, delta, s, w), (c * H @ Z).reshape(-1)])

    y0 = jnp.concatenate([system.w[0], jnp.eye(2 * r).reshape(-1)])
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Tsit5(),
        t0=0.0,
        t1=1.0,
        dt0=None,
        y0=y0,
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        saveat=diffrax.SaveAt(ts=system.s),
        max_steps=max_steps,
        throw=False,
    )
    assert sol.ys is not None  # saved at `ts`
    Z = sol.ys[:, r:].reshape(-1, 2 * r, 2 * r)
    JinvT = jnp.linalg.inv(system.J).T
    zero = jnp.zeros((r, r))
    S_J = jnp.block([[system.J, zero], [-JinvT @ Q_jump, JinvT]])
    ev, V = jnp.linalg.eig(S_J @ Z[-1])
    idx = jnp.argsort(jnp.abs(ev))[:r]
    U = V[:, idx]
    X0 = jnp.real(jnp.linalg.solve(U[:r].T, U[r:].T).T)  # U2 U1^-1
    X0 = _sym(X0)

    def at(Zs):
        return _sym(
            jnp.linalg.solve((Zs[:r, :r] + Zs[:r, r:] @ X0).T, (Zs[r:, :r] + Zs[r:, r:] @ X0).T).T
        )

    X = jax.vmap(at)(Z)
    residual = jnp.max(jnp.abs(X[-1] - system.J.T @ X0 @ system.J - Q_jump))
    stable = ev[idx]
    stable = stable[jnp.argsort(-jnp.abs(stable))]
    finite = jnp.all(jnp.isfinite(X))
    code = RESULTS.where(
        (sol.result == diffrax.RESULTS.successful) & finite, RESULTS.successful, RESULTS.nonfinite
    )
    return RiccatiSolution(
        system.s, X, _gains(system, X, R), jnp.asarray(0), residual, stable, code
    )
