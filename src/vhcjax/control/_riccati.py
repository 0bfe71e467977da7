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

A multi-domain gait (`HybridTransverseSystem`, e.g. the kneed walker) has one such
equation per domain on the coordinates its locked joints leave free, and a reset per
domain, $X_i(1^-) = J_i^TX_{i+1}(0^+)J_i$ (plus $Q_J$ at the heel strike), with $J_i$ not
square where a joint locks or unlocks. The backward iteration runs through all of them;
the Hamiltonian method cannot form $S_J$ there (the costate jump is a relation, not a
map), so it solves for the costates after every reset in one linear system around the
cycle and takes the monodromy at the start of the domain with the fewest coordinates.
"""

import diffrax
import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np

from .._programs import stored_jit
from .._results import RESULTS
from ..solvers._implicit import detach, eigenvalues
from ._actuated import num_inputs
from ._transverse import (
    HybridTransverseSystem,
    cycle_order,
    free_units,
    phase_field,
    phase_matrices,
    phase_units,
    reduce,
    reduced_jump,
    solve_in_phase,
)


class RiccatiSolution(eqx.Module):
    """Periodic solution of the hybrid Riccati equation on the phase grid.

    - `s`: the phase grid (that of the `TransverseSystem`).
    - `X`: $X(s)$, shape `(N+1, r, r)` (`X[-1]` is $X(1^-)$, before the jump); for a
      `HybridTransverseSystem`, `(num_domains, N+1, r, r)`, each domain's $PX_iP^T$
      from its free coordinates.
    - `K`: gains $K(s) = R^{-1}B(s)^TX(s)$, shape `(N+1, m, r)` (hybrid: a leading
      domain axis).
    - `iterations`: fixed-point sweeps (backward method) or 0 (Hamiltonian method).
    - `residual`: backward: the last change of $X(1^-)$ (max abs); Hamiltonian: the
      periodicity defect $\\|X(1^-) - J^TX(0^+)J - Q_J\\|_\\infty$ (hybrid: at the end of
      the section domain).
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


def weight_matrix(name, W, k, default):
    """`W` as a `(k, k)` matrix (given as one, as its diagonal, or as a scalar when
    `k = 1`); a one-line `ValueError` for another shape, and, for concrete values, for a
    weight that is not finite, not symmetric, or negative (`name` "R": not positive)."""
    W = default if W is None else jnp.asarray(W, float)
    if W.ndim == 0 and k == 1:
        W = W.reshape(1, 1)
    elif W.ndim == 1 and W.shape == (k,):
        W = jnp.diag(W)
    if W.shape != (k, k):
        raise ValueError(
            f"{name} must be a ({k}, {k}) matrix or its diagonal of shape ({k},), got shape "
            f"{W.shape}"
        )
    if not isinstance(W, jax.core.Tracer):
        w = np.asarray(W)
        finite = bool(np.isfinite(w).all())
        scale = float(np.abs(w).max()) if finite and w.size else 0.0
        low = np.linalg.eigvalsh(0.5 * (w + w.T)).min() if finite else np.nan
        tol = 1e-12 * max(scale, 1e-300)  # rounding of a semidefinite matrix (v v^T)
        symmetric = finite and np.allclose(w, w.T, rtol=1e-10, atol=tol)
        if not (symmetric and low >= -tol):
            raise ValueError(f"{name} must be finite, symmetric and nonnegative definite")
        if name == "R" and low <= 0:
            raise ValueError("R must be positive definite (every input costs something)")
    return W


def default_weights(model):
    """The default LQR weights `(Q, R, Q_jump)` (diagonals): $Q = R = Q_J = I$ for the
    model class's default walker (`type(model)()`, e.g. the thesis walker), posed as the
    same problem in `model`'s own units (`model.scales`), so that a rescaled walker gets
    the rescaled feedback. With $t = T/T_0$ and $\tau$ the ratio of the torque units
    $ML^2/T^2$: $Q = 1/t$ on angles and $t$ on rates, $Q_J = 1$ on angles and $t^2$ on
    rates, $R = 1/(\tau^2 t)$. A model class without defaults gets $I$."""
    n, m = model.n_dof, num_inputs(model)
    try:
        reference = type(model)()
    except (TypeError, ValueError):  # a class without defaults
        reference = model

    def torque_and_time(walker):
        sc = walker.scales()
        T = jnp.asarray(walker.time_scale, dtype=float)
        return sc["mass"] * sc["length"] ** 2 / T**2, T

    torque, T = torque_and_time(model)
    torque0, T0 = torque_and_time(reference)
    t, tau = T / T0, torque / torque0
    # an invalid model (NaN or negative parameters) is `bad_input` where it is solved:
    # its weights only need to be valid
    t = jnp.where(jnp.isfinite(t) & (t > 0), t, 1.0)
    tau = jnp.where(jnp.isfinite(tau) & (tau > 0), tau, 1.0)
    rate = jnp.arange(2 * n - 1) >= n - 1  # w = (q_2..q_n, dq_1..dq_n)
    Q = jnp.where(rate, t, 1.0 / t)
    Q_jump = jnp.where(rate, t**2, 1.0)
    R = jnp.full(m, 1.0 / (tau**2 * t))
    return Q, R, Q_jump


def weights(model, Q, R, Q_jump):
    """`(Q, R, Q_jump)` as matrices (`weight_matrix`), each defaulting to
    `default_weights(model)`; `Q_jump` to `Q` held over the time unit
    ($Q_{J0}/Q_0 = T/T_0$ on every entry)."""
    r, m = 2 * model.n_dof - 1, num_inputs(model)
    Q0, R0, Q_jump0 = default_weights(model)
    Q = weight_matrix("Q", Q, r, jnp.diag(Q0))
    R = weight_matrix("R", R, m, jnp.diag(R0))
    return Q, R, weight_matrix("Q_jump", Q_jump, r, Q * (Q_jump0[0] / Q0[0]))


def _gains(system, X, R):
    return jax.vmap(lambda B, XX: jnp.linalg.solve(R, B.T @ XX))(system.B, X)


def _pieces(system):
    """`(domains, bases, section_domain, domain)` of a `TransverseSystem` (one domain,
    all coordinates free) or a `HybridTransverseSystem`; `domain(i)` is the domain
    argument of the phase functions (`None` for a single-domain model)."""
    if isinstance(system, HybridTransverseSystem):
        return system.domains, system.bases, system.section_domain, lambda i: i
    return (system,), (None,), 0, lambda i: None


def _jump_weights(bases, Q_jump):
    """$Q_J$ at the heel strike (the reset of the last domain), in its free coordinates;
    zero at internal resets (a knee lock), where weighting the state just before the
    lock would ask the light joint for an arbitrarily fast correction."""
    last = len(bases) - 1
    return [reduce(P, Q_jump if i == last else jnp.zeros_like(Q_jump)) for i, P in enumerate(bases)]


def _expand(P, X):
    """Free-coordinate matrices `X` (..., r_i, r_i) back to all coordinates, $PXP^T$."""
    return X if P is None else P @ X @ P.T


def _reduced_rows(P, B):
    return B if P is None else P.T @ B


def _stack(system, X_domains, R):
    """`(X, K)` in all coordinates: stacked over domains for a hybrid system."""
    doms, bases, _, _ = _pieces(system)
    Xs = [_expand(P, X) for P, X in zip(bases, X_domains)]
    Ks = [_gains(d, X, R) for d, X in zip(doms, Xs)]
    if len(doms) == 1 and not isinstance(system, HybridTransverseSystem):
        return Xs[0], Ks[0]
    return jnp.stack(Xs), jnp.stack(Ks)


def _sym(X):
    return 0.5 * (X + X.T)


def cost_unit(model, R):
    """The unit of the LQR cost: the cost per second of a torque of the walker's unit
    ($M L^2/T^2$, from `model.scales`) held over its time unit $T$, weighted by the mean
    diagonal of `R`."""
    sc = model.scales()
    T = jnp.asarray(model.time_scale, dtype=float)
    torque = sc["mass"] * sc["length"] ** 2 / T**2
    return jnp.mean(jnp.diag(R)) * torque**2 * T


def own_units(model, P, R):
    """`X -> X'`: a Riccati matrix on the free coordinates of basis `P` in the walker's
    own units, $X'_{ij} = X_{ij} u_i u_j / c$ ($u$ the coordinates' units, $c$ the cost's,
    `cost_unit`): the same numbers for a walker and its rescaled copy under weights that
    pose it the same problem."""
    zu = free_units(P, phase_units(model))
    c = cost_unit(model, R)
    return lambda X: X * jnp.outer(zu, zu) / c


def _phase_functions(model, d, P, domain):
    """`(matrices, orbit)` of domain `d`: $(A, B, dt/ds)$ in free coordinates, and the
    orbit's rate $dw_\\star/ds$, at phase `s` and orbit point `w`."""
    tp, delta = d.theta_plus, d.theta_minus - d.theta_plus

    def matrices(s, w):
        A, B, c = phase_matrices(model, tp, delta, s, w, domain)
        return reduce(P, A), _reduced_rows(P, B), c

    def orbit(s, w):
        return _orbit_rate(model, tp, delta, s, w, domain)

    return matrices, orbit


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
    - `system`: a `TransverseSystem` or `HybridTransverseSystem` (then the equation
      runs backward through every domain and reset, the jump weight at the heel
      strike only).
    - `Q`, `R`, `Q_jump`: weights (matrices or diagonals, on all $2n-1$ coordinates);
      default `vhcjax.default_weights` (identities for the model class's default
      walker), and `Q_jump` $= Q\\,T/T_0$ (equal to $Q$ for the default walker).
    - `tol`: stop when $\\max|\\Delta X(1^-)| \\le$ `tol` $(1 + \\max|X(1^-)|)$, $X$ in
      the walker's own units (entries times the units of their two coordinates over
      the cost's unit).
    - `max_iterations`: sweeps at most (else `not_converged`).
    - `rtol`, `atol`, `max_steps`: settings of the backward integration (Tsit5), `atol`
      in the walker's own units.

    **Returns:** a `RiccatiSolution`. Reverse mode (`jax.grad`) gives its derivatives in
    every input by the implicit function theorem at the periodic $X(1^-)$.
    """
    Q, R, Q_jump = weights(model, Q, R, Q_jump)
    settings = dict(rtol=rtol, atol=atol, max_steps=max_steps)
    return _riccati_backward(
        model, system, Q, R, Q_jump, tol=tol, max_iterations=max_iterations, **settings
    )


@stored_jit
def _riccati_backward(model, system, Q, R, Q_jump, *, tol, max_iterations, rtol, atol, max_steps):
    """`riccati_backward` for checked weights: one compiled program per model class,
    system shape and settings (a stored program, see `vhcjax._programs`)."""
    params = (model, system, Q, R, Q_jump)
    settings = (rtol, atol, max_steps)
    doms, bases, _, _ = _pieces(system)
    D = len(doms)
    # The iterations run on constants; the derivatives of the periodic X(1^-) come from
    # the implicit function theorem (`_periodic`), those of X(s) from the last sweep.
    const = detach(params)
    frozen = _around(const, settings)

    def cond(carry):
        _, change, i, ok = carry
        return (change > tol) & (i < max_iterations) & ok

    # X(1^-) in the walker's own units
    own = own_units(const[0], _pieces(const[1])[1][D - 1], const[3])

    def body(carry):
        X1, _, i, _ = carry
        X1n, _, ok = frozen(X1, diffrax.SaveAt(t1=True))
        change = jnp.max(jnp.abs(own(X1n - X1))) / (1.0 + jnp.max(jnp.abs(own(X1n))))
        ok = ok & jnp.all(jnp.isfinite(X1n))
        return X1n, change, i + 1, ok

    start = _jump_weights(_pieces(const[1])[1], const[4])[D - 1]
    X1, change, iters, ok = jax.lax.while_loop(
        cond, body, (start, jnp.asarray(jnp.inf), jnp.asarray(0), jnp.asarray(True))
    )
    X1 = _periodic(params, X1, settings)
    _, outs, ok_final = _around(params, settings)(X1, diffrax.SaveAt(ts=doms[0].s[::-1]))
    X_domains = [jax.vmap(_sym)(Xs[::-1]) for Xs in outs]
    code = RESULTS.where(
        ok & (change <= tol),
        RESULTS.successful,
        RESULTS.where(ok, RESULTS.not_converged, RESULTS.nonfinite),
    )
    code = RESULTS.where(ok_final, code, RESULTS.nonfinite)
    X, K = _stack(system, X_domains, R)
    r_k = reduce(bases[_pieces(system)[2]], Q).shape[0]
    nan = jnp.full((r_k,), jnp.nan + 0j)
    return RiccatiSolution(doms[0].s, X, K, iters, change, nan, code)


def _around(params, settings):
    """`around(X_last, saveat) -> (X(1^-) after one period, X(s) per domain, ok)`: the
    Riccati equation backward from the end of the last domain through every domain and
    reset to the end of the period before (`riccati_backward`'s sweep)."""
    model, system, Q, R, Q_jump = params
    rtol, atol, max_steps = settings
    doms, bases, _, dom = _pieces(system)
    D = len(doms)
    Rinv = jnp.linalg.inv(R)
    Qs = [reduce(P, Q) for P in bases]
    Qjs = _jump_weights(bases, Q_jump)
    Js = [reduced_jump(bases, d.J, i) for i, d in enumerate(doms)]
    wu, cost = phase_units(model), cost_unit(model, R)

    def sweeper(i):
        d, P = doms[i], bases[i]
        r = Qs[i].shape[0]
        matrices, orbit = _phase_functions(model, d, P, dom(i))
        Qi = Qs[i]
        zu = free_units(P, wu)
        atol_i = atol * jnp.concatenate([wu, (cost / jnp.outer(zu, zu)).reshape(-1)])

        def field(s, y, args):
            w = y[: d.w.shape[1]]
            X = y[d.w.shape[1] :].reshape(r, r)
            A, B, c = matrices(s, w)
            dX = -c * (A.T @ X + X @ A + Qi - X @ B @ Rinv @ B.T @ X)
            # w_star is integrated along (backward) so that A, B are exact at every s.
            return jnp.concatenate([orbit(s, w), dX.reshape(-1)])

        def sweep(X1, saveat):
            y0 = jnp.concatenate([d.w[-1], X1.reshape(-1)])
            sol = solve_in_phase(field, y0, 1.0, 0.0, saveat, rtol, atol_i, max_steps)
            assert sol.ys is not None
            return sol.ys[..., d.w.shape[1] :].reshape(*sol.ys.shape[:-1], r, r), sol.result

        return sweep

    sweeps = [sweeper(i) for i in range(D)]

    def jump(i, X_next):
        return _sym(Js[i].T @ X_next @ Js[i] + Qjs[i])

    def around(X_last, saveat):
        X_end, outs, ok = X_last, [jnp.zeros(0)] * D, jnp.asarray(True)
        for i in reversed(range(D)):
            Xs, res = sweeps[i](X_end, saveat)
            outs[i] = Xs
            ok = ok & (res == diffrax.RESULTS.successful)
            X_start = _sym(Xs[-1])
            if i:
                X_end = jump(i - 1, X_start)
        return jump(D - 1, X_start), outs, ok

    return around


@eqx.filter_custom_vjp
def _periodic(params, X1, settings):
    r"""The periodic $X(1^-)$ (a fixed point of one backward period, `_around`), found by
    iteration, with the derivatives of the implicit function theorem: for a cotangent
    $\bar X$, $\bar p = \lambda^T\,\partial G/\partial p$ with
    $(I - \partial G/\partial X)^T\lambda = \bar X$, $G$ the period map (reverse mode
    only: the iterations are never differentiated)."""
    return X1


@_periodic.def_fwd
def _periodic_fwd(perturbed, params, X1, settings):
    return X1, None


@_periodic.def_bwd
def _periodic_bwd(residuals, X_bar, perturbed, params, X1, settings):
    def period(p, X):
        return _around(p, settings)(X, diffrax.SaveAt(t1=True))[0]

    k = X1.size
    _, vjp_X = jax.vjp(lambda X: period(detach(params), X), X1)
    # rows e^T dG/dX: the Jacobian of the period map in X (k = r^2 cotangents)
    Gx = jax.vmap(lambda e: vjp_X(e.reshape(X1.shape))[0].reshape(-1))(jnp.eye(k))
    lam = jnp.linalg.solve((jnp.eye(k) - Gx).T, X_bar.reshape(-1))
    _, vjp_p = eqx.filter_vjp(lambda p: period(p, X1), params)
    return vjp_p(lam.reshape(X1.shape))[0]


def _orbit_rate(model, tp, delta, s, w, domain=None):
    return phase_field(model, tp, delta, s, w, jnp.zeros(num_inputs(model), w.dtype), domain)[0]


def _hamiltonian_transitions(model, d, P, Q, Rinv, domain, rtol, atol, max_steps):
    """$\\Psi(s)$ on the phase grid of domain `d`: the transition matrix of the
    Hamiltonian system in free coordinates, from $\\Psi(0) = I$."""
    matrices, orbit = _phase_functions(model, d, P, domain)
    Qi = reduce(P, Q)
    r = Qi.shape[0]
    nw = d.w.shape[1]
    # units of (zeta, lambda): zeta's, and the cost's per zeta's
    wu = phase_units(model)
    zu = free_units(P, wu)
    v = jnp.concatenate([zu, cost_unit(model, jnp.linalg.inv(Rinv)) / zu])
    atol = atol * jnp.concatenate([wu, (v[:, None] / v).reshape(-1)])

    def field(s, y, args):
        w = y[:nw]
        Z = y[nw:].reshape(2 * r, 2 * r)
        A, B, c = matrices(s, w)
        H = jnp.block([[A, -B @ Rinv @ B.T], [-Qi, -A.T]])
        return jnp.concatenate([orbit(s, w), (c * H @ Z).reshape(-1)])

    y0 = jnp.concatenate([d.w[0], jnp.eye(2 * r).reshape(-1)])
    sol = solve_in_phase(field, y0, 0.0, 1.0, diffrax.SaveAt(ts=d.s), rtol, atol, max_steps)
    assert sol.ys is not None  # saved at `ts`
    return sol.ys[:, nw:].reshape(-1, 2 * r, 2 * r), sol.result


def _hamiltonian_monodromy(Psis, Js, Qjs, start):
    """The Hamiltonian monodromy around the cycle from the start of domain `start`.

    Over a reset $\\zeta^+ = J\\zeta^-$ the costate obeys $\\lambda^- = J^T\\lambda^+ +
    Q_J\\zeta^-$, a relation rather than a map when $J$ is not square or not invertible
    (a joint locks or unlocks). Unknown costates after every reset make one square
    linear system over the whole cycle; solving it gives the monodromy as a matrix
    ($S_J\\Psi(1)$, $S_J$ the symplectic jump, for a single invertible $J$).
    """
    D = len(Psis)
    order = cycle_order(D, start)
    rs = [Psi.shape[-1] // 2 for Psi in Psis]
    n0, nu = 2 * rs[start], sum(rs)
    T = jnp.concatenate([jnp.eye(n0), jnp.zeros((n0, nu))], 1)
    rows, col = [], n0
    for i in order:
        j = (i + 1) % D
        T = Psis[i] @ T
        zeta, lam = T[: rs[i]], T[rs[i] :]
        lam_next = jnp.zeros((rs[j], n0 + nu)).at[:, col : col + rs[j]].set(jnp.eye(rs[j]))
        rows.append(Js[i].T @ lam_next - lam + Qjs[i] @ zeta)
        T = jnp.concatenate([Js[i] @ zeta, lam_next], 0)
        col += rs[j]
    E = jnp.concatenate(rows, 0)
    costates = -jnp.linalg.solve(E[:, n0:], E[:, :n0])
    return T[:, :n0] + T[:, n0:] @ costates


def _subspace_tangent(M, X0):
    r"""Zero, with the derivative of $X_0$ (the stable invariant subspace
    $\{(\zeta, X_0\zeta)\}$ of `M`) from the implicit function theorem: $X_0$ solves
    $F = M_{21} + M_{22}X_0 - X_0(M_{11} + M_{12}X_0) = 0$, so
    $(M_{22} - X_0M_{12})\,\mathrm dX - \mathrm dX\,\Lambda = -\partial_MF\,\mathrm dM$,
    $\Lambda = M_{11} + M_{12}X_0$ (a Sylvester equation: the spectra of its two
    matrices, the unstable and the stable multipliers, are disjoint). `eig`'s eigenvector
    derivatives are never taken."""
    r = X0.shape[0]
    Mc = jax.lax.stop_gradient(M)
    Lam = Mc[:r, :r] + Mc[:r, r:] @ X0
    A = Mc[r:, r:] - X0 @ Mc[:r, r:]
    L = jnp.kron(A, jnp.eye(r)) - jnp.kron(jnp.eye(r), Lam.T)  # row-major vec
    F = M[r:, :r] + M[r:, r:] @ X0 - X0 @ (M[:r, :r] + M[:r, r:] @ X0)
    Y = -jnp.linalg.solve(L, F.reshape(-1)).reshape(r, r)
    return _sym(Y - jax.lax.stop_gradient(Y))


def riccati_hamiltonian(
    model, system, Q=None, R=None, Q_jump=None, *, rtol=1e-12, atol=1e-12, max_steps=8192
):
    """Periodic $X(s)$ from the stable invariant subspace of the Hamiltonian monodromy.

    Arguments as `riccati_backward` (no iteration). The monodromy is taken at the start
    of the domain with the fewest free coordinates (`section_domain`), where it is a
    symplectic matrix even when a reset changes the number of free coordinates;
    $X(0^+)$ there is $U_2U_1^{-1}$ from its stable eigenvectors, $X(s)$ on that domain
    follows from the Hamiltonian flow, and on the other domains from the resets
    ($X(1^-) = J^TX^+J + Q_J$) and the flow backward from their ends.

    **Returns:** a `RiccatiSolution` whose `eigenvalues` are the stable eigenvalues
    of the monodromy, i.e. the closed-loop multipliers under $u = -K\\zeta$. Reverse mode
    (`jax.grad`) gives the derivatives of $X$ and of the eigenvalues in every input by
    the implicit function theorem at the invariant subspace.
    """
    Q, R, Q_jump = weights(model, Q, R, Q_jump)
    settings = dict(rtol=rtol, atol=atol, max_steps=max_steps)
    return _riccati_hamiltonian(model, system, Q, R, Q_jump, **settings)


@stored_jit
def _riccati_hamiltonian(model, system, Q, R, Q_jump, *, rtol, atol, max_steps):
    """`riccati_hamiltonian` for checked weights: one compiled program per model class,
    system shape and settings (a stored program, see `vhcjax._programs`)."""
    doms, bases, k, dom = _pieces(system)
    D = len(doms)
    Rinv = jnp.linalg.inv(R)
    Qjs = _jump_weights(bases, Q_jump)
    Js = [reduced_jump(bases, d.J, i) for i, d in enumerate(doms)]
    Psis, ok = [], jnp.asarray(True)
    for i in range(D):
        Z, res = _hamiltonian_transitions(
            model, doms[i], bases[i], Q, Rinv, dom(i), rtol, atol, max_steps
        )
        Psis.append(Z)
        ok = ok & (res == diffrax.RESULTS.successful)
    M = _hamiltonian_monodromy([Z[-1] for Z in Psis], Js, Qjs, k)
    r = M.shape[0] // 2
    ev, V = jnp.linalg.eig(jax.lax.stop_gradient(M))
    idx = jnp.argsort(jnp.abs(ev))[:r]
    U = V[:, idx]
    X0 = _sym(jnp.real(jnp.linalg.solve(U[:r].T, U[r:].T).T))  # U2 U1^-1
    X0 = X0 + _subspace_tangent(M, X0)

    def forward(Zs):
        ri = Zs.shape[0] // 2
        return _sym(
            jnp.linalg.solve(
                (Zs[:ri, :ri] + Zs[:ri, ri:] @ X0).T, (Zs[ri:, :ri] + Zs[ri:, ri:] @ X0).T
            ).T
        )

    X_domains = [jnp.zeros(0)] * D
    X_domains[k] = jax.vmap(forward)(Psis[k])
    X_start = X0
    for i in reversed(cycle_order(D, k)[1:]):  # backward from the section domain
        X_end = _sym(Js[i].T @ X_start @ Js[i] + Qjs[i])
        Psi1 = Psis[i][-1]
        ri = X_end.shape[0]
        W = jnp.linalg.solve(Psi1, jnp.concatenate([jnp.eye(ri), X_end], 0))

        def backward(Zs, W=W, ri=ri):
            Y = Zs @ W
            return _sym(jnp.linalg.solve(Y[:ri].T, Y[ri:].T).T)

        X_domains[i] = jax.vmap(backward)(Psis[i])
        X_start = X_domains[i][0]
    nxt = (k + 1) % D
    X_next = X0 if D == 1 else X_domains[nxt][0]
    residual = jnp.max(jnp.abs(X_domains[k][-1] - Js[k].T @ X_next @ Js[k] - Qjs[k]))
    stable = ev[idx]
    stable = stable[jnp.argsort(-jnp.abs(stable))]
    # their derivatives: those of the eigenvalues of M on the subspace, M11 + M12 X0
    lam = eigenvalues(M[:r, :r] + M[:r, r:] @ X0)
    dlam = lam - jax.lax.stop_gradient(lam)
    near = jnp.argmin(jnp.abs(jax.lax.stop_gradient(lam)[None, :] - stable[:, None]), axis=1)
    stable = stable + dlam[near]
    X, K = _stack(system, X_domains, R)
    # A symplectic monodromy has its eigenvalues in pairs (mu, 1/mu): exactly r inside
    # the unit circle, and the subspace they span closes the cycle. Else the monodromy
    # lost its structure to rounding (growth like exp(500) over a domain).
    own = own_units(model, bases[k], R)
    defect = own(X_domains[k][-1] - Js[k].T @ X_next @ Js[k] - Qjs[k])
    valid = (
        jnp.all(jnp.isfinite(X))
        & (jnp.sum(jnp.abs(ev) < 1.0) == r)
        & (jnp.max(jnp.abs(defect)) <= 1e-6 * (1.0 + jnp.max(jnp.abs(own(X_domains[k][-1])))))
    )
    # An integration that overflows or runs out of steps (fast modes growing like
    # exp(500)) is the same failure of the method.
    code = RESULTS.where(ok & valid, RESULTS.successful, RESULTS.riccati_ill_conditioned)
    return RiccatiSolution(doms[0].s, X, K, jnp.asarray(0), residual, stable, code)
