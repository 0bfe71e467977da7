"""Root finders: damped (Levenberg-Marquardt globalised) Newton for one member or a batch
in one loop, optimistix's Levenberg-Marquardt, and an optax minimiser of the squared
residual."""

import jax
import jax.numpy as jnp
import optimistix as optx

#: Trial tolerance of the inexact Newton iterations: this times the squared residual.
_TOL_FACTOR = 1e-4
#: Bound on the global error of a residual integrated at tolerance `tol`: this times `tol`.
_ERROR_FACTOR = 100.0


def damped_newton(
    fn,
    x0,
    *,
    rtol=1e-11,
    atol=1e-11,
    max_steps=50,
    max_trials=10,
    tolerances=None,
    chord_below=None,
    residual_cap=jnp.inf,
    chart=None,
):
    r"""Newton's method with a forward-mode Jacobian, globalised by Levenberg-Marquardt
    damping, optionally inexact (loose integrations while far from the solution) and
    finishing with chord steps.

    `fn(x) -> (r, aux)`, or `fn(x, tol) -> (r, aux)` with `tolerances`. Every evaluation
    is one forward-mode pass (`jax.jvp` along each unknown) that returns $r$, $J$ and
    `aux` together, so the evaluation that tests a step is also the next iteration's
    linearisation. From the last accepted point the full Newton step ($\lambda = 0$) is
    tried first; a step that does not decrease $\|r\|_2$ is retried from the same point
    with $(J^TJ + \lambda I)\Delta x = J^Tr$ and growing $\lambda$ (no new Jacobian), up
    to `max_trials` times (at once, where the damped step is zero or not finite: then
    no step exists). Near a solution this is plain Newton (quadratic convergence);
    far from it the damped steps turn toward steepest descent (plain Newton fails from the
    thesis seed (7.2) for the unstable family).

    `tolerances = (loose, final)`: the integration tolerance `tol` handed to `fn` for a
    trial from a point with residual $r$ is $10^{-4}\|r\|_\infty^2$ clipped to
    `[final, loose]`: $10^{-4}$ of the residual that a quadratically converging step
    leaves, so the step computed from the trial is nearly an exact Newton step, while
    the early iterations integrate with far fewer steps (inexact Newton). Only an
    evaluation at `final` can end the iteration.

    `chord_below`: once an accepted point has $\|r\|_\infty <$ `chord_below`, its
    Jacobian is kept and the remaining iterations evaluate $r$ alone (chord, or
    simplified, Newton: a second loop with the same steps and damping). From there the
    first step is an exact Newton step and the later ones contract by about
    $\|J^{-1}\|\,\|J(x) - J(x_c)\|$, tiny this close to the root; an evaluation
    without tangents costs a fraction of one with them.

    Stops at an accepted point $x$ (evaluated at `final`) when the step that led there
    or the Newton step from it, $J^{-1}r$, is below $\mathrm{atol} +
    \mathrm{rtol}\|x\|_\infty$ (the second is an estimate of the error of $x$, so a
    converged point needs no further evaluation; it also needs $\|r\|_\infty <$
    `residual_cap`), when $\|r\|_\infty < \mathrm{atol}$, when no trial decreases
    the residual, or after `max_steps` accepted steps.

    `chart = (to_y, from_y, use_y)`: other coordinates $y$ = `to_y(x)` of the
    unknowns, and back, `from_y(y, x)` (the $x$ of $y$ reached by a step from $x$; NaN
    where $y$ has no $x$); from a point where `use_y(y, r)` holds the steps (Newton and
    damped) are computed and taken along straight lines in $y$, with the Jacobian
    $J\,(\partial y/\partial x)^{-1}$.
    Newton's iterates depend on the coordinates; far from a solution the ones in which
    the residual is closer to linear there lead it in, near one those in which it is
    better conditioned finish.

    **Returns:** `(x, r, aux, iterations, error)` at the last accepted point;
    `iterations` counts accepted steps, `error` is $\|J^{-1}r\|_\infty$ there (the
    Newton estimate of the error of $x$; `inf` where it is not finite, after chord
    steps (their Jacobian is an old one) and where $r$ was not evaluated at the final
    tolerance).
    """
    call = (lambda y, tol: fn(y)) if tolerances is None else fn

    def one(X, tol):  # the batch of one member that `damped_newton_batch` iterates
        return jax.tree_util.tree_map(lambda a: jnp.asarray(a)[None], call(X[0], tol[0]))

    if chart is not None:
        to_y, from_y, use_y = chart
        chart = (
            lambda X: to_y(X[0])[None],
            lambda Y, X: from_y(Y[0], X[0])[None],
            lambda Y, R: use_y(Y[0], R[0])[None],
        )

    out = damped_newton_batch(
        one,
        x0[None],
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        max_trials=max_trials,
        tolerances=tolerances,
        chord_below=chord_below,
        residual_cap=residual_cap,
        chart=chart,
    )
    return jax.tree_util.tree_map(lambda a: a[0], out)


def batch_jacobian(fn, X):
    """`(R, J, aux)` of `fn(X) -> (R, aux)` for a batch `X` of shape `(B, n)` whose rows
    are independent: `J[i] = dR[i]/dX[i]`, by forward mode (`jax.jvp` along each of the
    `n` unknowns, for every member at once; the primal is computed once)."""

    def push(v):
        (R, aux), (dR, _) = jax.jvp(fn, (X,), (jnp.broadcast_to(v, X.shape),))
        return dR, (R, aux)

    J, (R, aux) = jax.vmap(push, out_axes=(-1, None))(jnp.eye(X.shape[-1], dtype=X.dtype))
    return R, J, aux


def damped_newton_batch(
    fn,
    X0,
    *,
    rtol=1e-11,
    atol=1e-11,
    max_steps=50,
    max_trials=10,
    tolerances=None,
    chord_below=None,
    residual_cap=jnp.inf,
    chart=None,
):
    r"""`damped_newton` on every member of a batch at once, written out along the leading
    axis (`X0`: `(B, n)`; `fn(X, tol) -> (R, aux)` with `tol`: `(B,)`, each row of `R`
    depending on its own row of `X` only, every leaf of `aux` with the batch axis first;
    `chart`'s functions map batches, row by row).

    The loop runs while any member is still iterating; members that have stopped keep
    their state. This is what `jax.vmap` makes of `damped_newton`, but the residual is
    differentiated *after* it is batched: tracing does not have to batch the (three
    times larger) forward-mode evaluation. `tolerances` as in `damped_newton` (`None`:
    `tol` is ignored).

    **Returns:** `(X, R, aux, iterations, error)`, each with the leading batch axis.
    """
    B, n = X0.shape
    eye = jnp.eye(n, dtype=X0.dtype)
    loose, final = (None, None) if tolerances is None else tolerances
    # Every array the loop starts from is a function of X0: under an enclosing `vmap`
    # the loop's carries are then all batched from the start, and the batching rule
    # traces the (large) body once.
    tie = jnp.where(X0[:, 0] == X0[:, 0], 0.0, 0.0).astype(X0.dtype)
    tol0 = (1.0 if loose is None else loose) + tie

    # `fn` is traced once, here, into a jaxpr; the forward-mode evaluation differentiates
    # the jaxpr, the loop bodies replay jaxprs, and the carry shapes come from the trace.
    residual_jaxpr, rconsts = jax.closure_convert(fn, X0, tol0)

    def evaluate_traced(X, tol):
        return batch_jacobian(lambda Y: residual_jaxpr(Y, tol, *rconsts), X)

    evaluate_jaxpr, consts = jax.closure_convert(evaluate_traced, X0, tol0)
    evaluate = lambda X, tol, J: evaluate_jaxpr(X, tol, *consts)  # noqa: E731

    def where(mask, a, b):  # per member
        return jnp.where(jnp.reshape(mask, mask.shape + (1,) * (jnp.ndim(a) - 1)), a, b)

    def pick(mask, u, v):
        return jax.tree_util.tree_map(lambda p, q: where(mask, p, q), u, v)

    def norm(A, axes=-1):
        return jnp.max(jnp.abs(A), axis=axes)

    def trial_tolerance(R, first):
        if tolerances is None:
            return tol0
        assert loose is not None  # set with `tolerances`
        return jnp.where(first, loose, jnp.clip(_TOL_FACTOR * norm(R) ** 2, final, loose))

    def solve(A, b):
        return jnp.linalg.solve(A, b[..., None])[..., 0]

    def solve_matrix(A, B):
        return jnp.linalg.solve(A, B)

    def iterating(carry):
        k, trials, done, chord = carry[4], carry[5], carry[6], carry[8]
        return (k < max_steps) & (trials < max_trials) & ~done & ~chord

    def chord_iterating(carry):
        return (carry[4] < max_steps) & (carry[5] < max_trials) & ~carry[6]

    def make_body(evaluate, active, chart=None):
        def body(carry):
            X, R, J, aux, k, trials, done, lam, chord, tol_R = carry
            first = k < 0  # the first pass only evaluates R, J at the guesses
            # The coordinates of the step: x, or y (`chart`) for members far from a root.
            base, Js = X, J
            if chart is not None:
                to_y, from_y, use_y = chart
                Y, dYdX, _ = batch_jacobian(lambda Z: (to_y(Z), None), X)
                far = use_y(Y, R) & jnp.isfinite(dYdX).all((-2, -1))
                Jy = jnp.swapaxes(
                    solve_matrix(jnp.swapaxes(dYdX, -1, -2), jnp.swapaxes(J, -1, -2)), -1, -2
                )
                base, Js = where(far, Y, X), where(far, Jy, J)
            # Trial step from the accepted point (X, R, J): Newton, or damped after a failure.
            Jt = jnp.swapaxes(Js, -1, -2)
            JtJ = Jt @ Js
            newton = trials == 0
            step = solve(
                where(newton, Js, JtJ + lam[:, None, None] * eye),
                where(newton, R, (Jt @ R[..., None])[..., 0]),
            )
            step = where(jnp.isfinite(step).all(-1) & ~first, step, jnp.zeros_like(step))
            X_t = base - step
            if chart is not None:
                X_t = where(far, from_y(X_t, X), X_t)
            dX = X - X_t
            # A damped trial with no step ($J^Tr = 0$, or no finite solution, e.g. J = 0
            # where the residual is undefined): the member cannot move, so it stops as
            # after `max_trials` failures instead of re-evaluating the same point.
            stuck = ~first & ~newton & ~(norm(step) > 0)
            tol = trial_tolerance(R, first)
            R_t, J_t, aux_t = evaluate(X_t, tol, J)
            # A residual integrated more accurately than the accepted one may exceed it by
            # the accepted one's integration error: such a trial is accepted too (else a
            # member can stop at a loose residual that an exact one cannot beat).
            tightened = tol < tol_R
            improved = first | (
                jnp.isfinite(R_t).all(-1)
                & jnp.isfinite(J_t).all((-2, -1))
                & (
                    (jnp.sum(R_t**2, -1) < jnp.sum(R**2, -1))
                    | (tightened & (norm(R_t) <= norm(R) + _ERROR_FACTOR * tol_R))
                )
            )
            X_new, R_new, J_new, aux_new = pick(improved, (X_t, R_t, J_t, aux_t), (X, R, J, aux))
            size = atol + rtol * norm(X_t)
            small = ~first & (norm(dX) < atol + rtol * norm(X))
            # The Newton step from the trial point estimates its error (to first order).
            close = (norm(solve(J_t, R_t)) < size) & (norm(R_t) < residual_cap)
            exact = True
            if tolerances is not None:
                assert final is not None  # set with `tolerances`
                exact = tol <= final
            done_new = improved & exact & (small | close | (norm(R_t) < atol))
            chord_new = chord
            if chord_below is not None:
                chord_new = chord | (improved & (norm(R_new) < chord_below))
            # After a failure: grow lambda from a scale of J^T J; after a success: Newton again.
            lam_start = 1e-3 * norm(jnp.diagonal(JtJ, axis1=-2, axis2=-1))
            lam_new = jnp.where(improved, 0.0, jnp.where(newton, lam_start, 10.0 * lam))
            trials_new = jnp.where(improved, 0, jnp.where(stuck, max_trials, trials + 1))
            tol_new = jnp.where(improved, tol * jnp.ones_like(tol_R), tol_R)
            new = (
                X_new,
                R_new,
                J_new,
                aux_new,
                k + improved,
                trials_new,
                done_new,
                lam_new,
                chord_new,
                tol_new,
            )
            return pick(active(carry), new, carry)  # stopped members keep their state

        return body

    # Shapes from the residual alone: `J[i] = dR[i]/dX[i]` (`batch_jacobian`).
    R_shape, aux_shape = jax.eval_shape(lambda X, tol: residual_jaxpr(X, tol, *rconsts), X0, tol0)
    J_shape = jax.ShapeDtypeStruct(R_shape.shape + (n,), R_shape.dtype)

    def zeros(tree):
        return jax.tree_util.tree_map(
            lambda leaf: (
                jnp.zeros(leaf.shape, leaf.dtype)
                + jnp.reshape(tie, (B,) + (1,) * (len(leaf.shape) - 1)).astype(leaf.dtype)
            ),
            tree,
        )

    init = (
        X0,
        zeros(R_shape),
        zeros(J_shape),
        zeros(aux_shape),
        tie.astype(int) - 1,
        tie.astype(int),
        tie != 0,
        tie,
        tie != 0,
        tol0,
    )
    carry = jax.lax.while_loop(
        lambda c: jnp.any(iterating(c)), make_body(evaluate, iterating, chart), init
    )
    if chord_below is not None:  # the chord loop: the same steps, the residual alone

        def residual(X, tol, J):
            R, aux = residual_jaxpr(X, tol, *rconsts)
            return R, J, aux

        carry = jax.lax.while_loop(
            lambda c: jnp.any(chord_iterating(c)), make_body(residual, chord_iterating), carry
        )
    X, R, J, aux, k = carry[:5]
    error = norm(solve(J, R))
    # No estimate from a Jacobian frozen by chord steps, nor from a loose residual.
    trusted = jnp.isfinite(error) & ~carry[8]
    if tolerances is not None:
        trusted = trusted & (carry[9] <= final)
    return X, R, aux, k, jnp.where(trusted, error, jnp.inf)


def levenberg_marquardt(residual, x0, rtol, atol, max_steps):
    sol = optx.least_squares(
        lambda x, _: residual(x),
        optx.LevenbergMarquardt(rtol=rtol, atol=atol),
        x0,
        max_steps=max_steps,
        throw=False,
    )
    return sol.value, sol.stats["num_steps"]


def optax_minimise(residual, x0, max_steps=1000, tol=1e-22):
    """L-BFGS (optax, zoom line search) on $\\tfrac12\\|r\\|^2$. The gradient $J^T r$ comes
    from a forward-mode Jacobian (diffrax's `ForwardMode` does not support reverse mode),
    exposed to optax through a `custom_vjp`."""
    import optax

    @jax.custom_vjp
    def value(x):
        r = residual(x)
        return 0.5 * r @ r

    def value_fwd(x):
        r, J = residual(x), jax.jacfwd(residual)(x)
        return 0.5 * r @ r, J.T @ r

    value.defvjp(value_fwd, lambda g, ct: (ct * g,))
    opt = optax.lbfgs()
    vg = optax.value_and_grad_from_state(value)

    def cond(carry):
        x, state, k, v = carry
        return (k < max_steps) & (v > tol)

    def body(carry):
        x, state, k, _ = carry
        v, g = vg(x, state=state)
        updates, state = opt.update(g, state, x, value=v, grad=g, value_fn=value)
        return optax.apply_updates(x, updates), state, k + 1, v

    init = (x0, opt.init(x0), jnp.array(0), jnp.array(jnp.inf))
    x, _, k, _ = jax.lax.while_loop(cond, body, init)
    return jnp.asarray(x), k  # an array like `x0` (optax types its updates as any pytree)
