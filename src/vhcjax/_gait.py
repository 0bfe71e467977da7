"""Periodic gaits: the VHC search (thesis Problem 1) and shooting (Problem 2).

**VHC search** (thesis 5.1-5.4). Unknowns $(a, b) = (q_1, \\dot q_1)$ just after impact.
The heel-strike geometry gives $c = -a - 2\\psi$, $g = a$, $e = c$ (5.5)-(5.6). The impact
map is linear in the velocities, $\\dot q^+ = P(q^-)\\dot q^-$ (5.7), so with $b$ and $d$
given the remaining velocities $f, h$ follow (5.9); here $P$ is taken from the model's
impact map by `jax.jacfwd`, not from the closed form. Energy conservation along the
constraint, $E(c, d) = E(a, b)$, is a quadratic $A d^2 + B d + C = 0$ in $d$ (5.13); its
coefficients are obtained by evaluating the energy difference at $d = -1, 0, 1$ (the
thesis closed form (5.14) is a test oracle). `family="stable"` takes the root
$(-B - \\sqrt{\\Delta})/2A$ (thesis selector 2, 7.3), `"unstable"` the root with the plus
sign (selector 1, 7.8). Then $\\phi'' = f_0$ (5.19) is integrated in $\\theta$ from $a$ to
$c$ (fixed endpoints, no event), carrying the time $dt/d\\theta = 1/\\dot\\theta$, and the
residual of (5.20), $(\\phi(c) - g, \\phi'(c) - h/d)$, is driven to zero by Newton's
method (forward-mode Jacobian) or, optionally, by an optax optimiser on its square.

**Shooting** (Problem 2): Newton on the step-to-step map of the hybrid simulation on
the post-impact section (`vhcjax._poincare.fixed_point`).

Both return the same `Gait` pytree and never raise under `jit`/`vmap`: inspect `result`.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from . import _poincare
from ._hybrid import DEFAULT_CONFIG, SolverConfig, _step
from ._results import RESULTS
from ._vhc import phi_second_derivative

FAMILIES = ("stable", "unstable")
METHODS = ("vhc", "shooting")

#: Settings of the $\phi''$ integration (smooth, no events: an 8th-order method).
VHC_CONFIG = SolverConfig(rtol=1e-12, atol=1e-12, max_steps=512, solver="dopri8")

#: A gait is accepted when the max-norm of its residual is below this.
SUCCESS_TOL = 1e-9

# Known gaits of the default model (thesis Table 1) at 3 degrees: (a, b). Seeds for
# continuation only (they need not be exact; tests check the gaits found from them).
_REFERENCE_PSI = math.radians(3.0)
_REFERENCE_AB = {
    "stable": (0.2186687938, -1.0923835909),
    "unstable": (0.2046755397, -1.2105718434),
}


class Gait(eqx.Module):
    """A periodic gait (one step, symmetric), thesis (5.2).

    - `a, b, e, f`: post-impact $q_1, \\dot q_1, q_2, \\dot q_2$.
    - `c, d, g, h`: pre-impact $q_1, \\dot q_1, q_2, \\dot q_2$.
    - `T`: step period (s); `E0`: energy along the step (J, zero with both legs vertical
      and at rest, thesis 5.10).
    - `x_plus`, `x_minus`: post- and pre-impact states $[q, \\dot q]$.
    - `step_length`: distance between the feet at heel strike (m); `speed`: step length
      over period (m/s); `energy_loss`: kinetic energy lost in the impact (J).
    - `iterations`, `residual`: of the search (max-norm of the final residual).
    - `result`: a `RESULTS` code.
    - `family`, `method`: static labels.
    """

    a: jax.Array
    b: jax.Array
    c: jax.Array
    d: jax.Array
    e: jax.Array
    f: jax.Array
    g: jax.Array
    h: jax.Array
    T: jax.Array
    E0: jax.Array
    x_plus: jax.Array
    x_minus: jax.Array
    step_length: jax.Array
    speed: jax.Array
    energy_loss: jax.Array
    iterations: jax.Array
    residual: jax.Array
    result: RESULTS
    family: str = eqx.field(static=True, default="stable")
    method: str = eqx.field(static=True, default="vhc")

    @property
    def z(self):
        """Section coordinates $(q_1, \\dot q_1, \\dot q_2)$ of the post-impact state."""
        return jnp.stack([self.a, self.b, self.f], axis=-1)

    def params(self):
        """`{"a": ..., ..., "h": ..., "T": ..., "E0": ...}` (arrays)."""
        return {k: getattr(self, k) for k in ("a", "b", "c", "d", "e", "f", "g", "h", "T", "E0")}


# ---------------------------------------------------------------------------------------
# Algebra of Problem 1
# ---------------------------------------------------------------------------------------
def _with_psi(model, psi):
    return eqx.tree_at(lambda m: m.psi, model, jnp.asarray(psi, dtype=float))


def impact_configuration(model, a):
    """Post-impact $q^+ = (a, e)$ and pre-impact $q^- = (c, g)$ configurations (5.5)-(5.6)."""
    n = model.n_dof
    x = model.section_to_state(jnp.concatenate([jnp.atleast_1d(a), jnp.zeros(n)]))
    q_plus = x[:n]
    q_minus, _ = model.relabel(q_plus, jnp.zeros(n))  # the leg swap is an involution
    return q_plus, q_minus


def impact_velocity_matrix(model, q_minus):
    """$P(q^-)$ with $\\dot q^+ = P\\dot q^-$ (relabelled, thesis 5.7), by `jax.jacfwd` of the
    model's impact map (which is linear in the velocities)."""
    n = model.n_dof

    def dq_plus(dq):
        return model.impact(jnp.concatenate([q_minus, dq]))[0][n:]

    return jax.jacfwd(dq_plus)(jnp.zeros(n, dtype=q_minus.dtype))


def velocity_relations(model, a, b, d):
    """$(f, h)$ from $(a, b, d)$ (thesis 5.9), derived from the impact map: solve
    $b = P_{11} d + P_{12} h$ for $h$, then $f = P_{21} d + P_{22} h$."""
    _, q_minus = impact_configuration(model, a)
    P = impact_velocity_matrix(model, q_minus)
    h = (b - P[0, 0] * d) / P[0, 1]
    f = P[1, 0] * d + P[1, 1] * h
    return f, h


def _states(model, a, b, d):
    q_plus, q_minus = impact_configuration(model, a)
    f, h = velocity_relations(model, a, b, d)
    x_plus = jnp.concatenate([q_plus, jnp.stack([b, f])])
    x_minus = jnp.concatenate([q_minus, jnp.stack([d, h])])
    return x_plus, x_minus


def energy_gap(model, a, b, d):
    """$E(c, d) - E(a, b)$ with $c, e, f, g, h$ eliminated (thesis 5.12-5.13)."""
    x_plus, x_minus = _states(model, a, b, d)
    return model.energy(x_minus) - model.energy(x_plus)


def quadratic_coefficients(model, a, b):
    """$(A, B, C)$ of $A d^2 + B d + C = E(c, d) - E(a, b)$ (thesis 5.13-5.14), from the
    energy difference at $d = -1, 0, 1$ (exact: it is a quadratic in $d$)."""
    one = jnp.ones_like(jnp.asarray(a, dtype=float))
    fm, f0, fp = (energy_gap(model, a, b, s * one) for s in (-1.0, 0.0, 1.0))
    return 0.5 * (fp + fm) - f0, 0.5 * (fp - fm), f0


def solve_for_d(model, a, b, family):
    """$d$ from (5.13): `"stable"` = thesis selector 2 ($-\\sqrt{}$, 7.3), `"unstable"` =
    selector 1 ($+\\sqrt{}$, 7.8). **Returns:** `(d, real)` where `real` is False when
    $B^2 - 4AC < 0$ (then `d` is the real part, $-B/2A$)."""
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    A, B, C = quadratic_coefficients(model, a, b)
    disc = B**2 - 4 * A * C
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    sign = -1.0 if family == "stable" else 1.0
    return (-B + sign * root) / (2 * A), disc >= 0


class BoundaryData(eqx.Module):
    """Everything Problem 1 derives from $(a, b)$ before and after the $\\phi$ integration."""

    x_plus: jax.Array
    x_minus: jax.Array
    E0: jax.Array
    phi_c: jax.Array  # (phi(c), phi'(c))
    T: jax.Array
    residual: jax.Array  # (phi(c) - g, phi'(c) - h/d)
    result: RESULTS


def _phi_field(theta, y, args):
    model, E0, sign = args
    phi, dphi = y[0:1], y[1:2]
    ddphi, _, dth2, _ = phi_second_derivative(model, E0, theta, phi, dphi)
    return jnp.concatenate([dphi, ddphi, (sign / jnp.sqrt(dth2))[None]])


def _solver(name):
    return {"tsit5": diffrax.Tsit5, "dopri8": diffrax.Dopri8, "dopri5": diffrax.Dopri5}[name]()


def vhc_boundary(model, ab, family, config=VHC_CONFIG):
    """Integrate $\\phi'' = f_0$ (5.19) over $\\theta \\in [a, c]$ for given $(a, b)$; the
    residual of Problem 1 (5.20) and the data of the candidate gait."""
    a, b = ab[0], ab[1]
    d, real = solve_for_d(model, a, b, family)
    return _boundary_abd(model, a, b, d, real, config)


def _boundary_abd(model, a, b, d, real=True, config=VHC_CONFIG):
    """`vhc_boundary` for a given $d$ (not necessarily a root of 5.13)."""
    real = jnp.asarray(real)
    d = jnp.where(real, d, -1.0)  # keep the arithmetic finite on failure
    x_plus, x_minus = _states(model, a, b, d)
    E0 = model.energy(x_plus)
    n = model.n_dof
    e, f = x_plus[1], x_plus[n + 1]
    c, g, h = x_minus[0], x_minus[1], x_minus[n + 1]
    # phi'(a) = f/b; M_theta > 0 and theta_dot^2 > 0 at both ends, else singular.
    y0 = jnp.stack([e, f / b, 0.0])
    ok0 = jnp.isfinite(y0).all()
    y0 = jnp.where(ok0, y0, jnp.array([e, 0.0, 0.0]))
    sign = jnp.sign(b)
    _, _, dth2_a, det_a = phi_second_derivative(model, E0, a, y0[0:1], y0[1:2])
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_phi_field),
        _solver(config.solver),
        t0=a,
        t1=c,
        dt0=None,
        y0=y0,
        args=(model, E0, sign),
        stepsize_controller=diffrax.PIDController(rtol=config.rtol, atol=config.atol),
        saveat=diffrax.SaveAt(t1=True),
        max_steps=config.max_steps,
        adjoint=diffrax.ForwardMode(),
        throw=False,
    )
    yc = sol.ys[-1]
    _, _, dth2_c, det_c = phi_second_derivative(model, E0, c, yc[0:1], yc[1:2])
    residual = jnp.stack([yc[0] - g, yc[1] - h / d])
    singular = (
        ~ok0
        | (sol.result != diffrax.RESULTS.successful)
        | ~jnp.isfinite(yc).all()
        | ~jnp.isfinite(residual).all()
        | (dth2_a <= 0)
        | (dth2_c <= 0)
        | (jnp.abs(det_a) < 1e-12)
        | (jnp.abs(det_c) < 1e-12)
        | (b == 0)
        | (d == 0)
    )
    code = RESULTS.where(
        ~real, RESULTS.no_real_root, RESULTS.where(singular, RESULTS.singular_phi_ode, RESULTS.successful)
    )
    ok = code == RESULTS.successful
    residual = jnp.where(ok, residual, jnp.zeros_like(residual))
    return BoundaryData(x_plus, x_minus, E0, yc[:2], yc[2], residual, code)


def vhc_residual(model, ab, family, config=VHC_CONFIG):
    """The residual vector of Problem 1, $(\\phi(c) - g, \\phi'(c) - h/d)$ (5.20); a large
    constant where it is undefined (no real root, singular ODE), so Newton cannot stop
    there."""
    bd = vhc_boundary(model, ab, family, config)
    return jnp.where(bd.result == RESULTS.successful, bd.residual, 1e3 * jnp.ones(2))


# ---------------------------------------------------------------------------------------
# Gait assembly
# ---------------------------------------------------------------------------------------
def _derived(model, x_plus, x_minus, T):
    n = model.n_dof
    step_length = jnp.linalg.norm(model.contact_point(x_minus[:n]))
    speed = step_length / T
    # The potential energy is continuous through the impact: the loss is kinetic.
    ke = lambda x: model.kinetic_energy(x[:n], x[n:])  # noqa: E731
    return step_length, speed, ke(x_minus) - ke(x_plus)


def _make_gait(model, x_plus, x_minus, T, E0, iterations, residual, code, family, method):
    n = model.n_dof
    step_length, speed, loss = _derived(model, x_plus, x_minus, T)
    _, _, physical = model.impact(x_minus)
    # A periodic solution walking uphill in negative time (thesis 7.17-7.18).
    uphill = (x_plus[n] > 0) | (T < 0)
    code = RESULTS.where(
        (code == RESULTS.successful) & uphill, RESULTS.infeasible_uphill, code
    )
    code = RESULTS.where((code == RESULTS.successful) & ~physical, RESULTS.bad_impact, code)
    code = RESULTS.where(model.validate(), code, RESULTS.bad_input)
    return Gait(
        a=x_plus[0], b=x_plus[n], c=x_minus[0], d=x_minus[n],
        e=x_plus[1], f=x_plus[n + 1], g=x_minus[1], h=x_minus[n + 1],
        T=T, E0=E0, x_plus=x_plus, x_minus=x_minus,
        step_length=step_length, speed=speed, energy_loss=loss,
        iterations=jnp.asarray(iterations), residual=residual, result=code,
        family=family, method=method,
    )


def _finish_vhc(model, ab, iterations, solver_ok, family, method="vhc", config=VHC_CONFIG):
    bd = vhc_boundary(model, ab, family, config)
    res = jnp.max(jnp.abs(bd.residual))
    converged = solver_ok & (res < SUCCESS_TOL) & jnp.isfinite(ab).all()
    code = RESULTS.where(
        bd.result != RESULTS.successful,
        bd.result,
        RESULTS.where(converged, RESULTS.successful, RESULTS.not_converged),
    )
    res = jnp.where(bd.result == RESULTS.successful, res, jnp.inf)
    return _make_gait(
        model, bd.x_plus, bd.x_minus, bd.T, bd.E0, iterations, res, code, family, method
    )


def vhc_search(
    model, guess, family="stable", *, solver="newton", rtol=1e-11, atol=1e-11,
    max_steps=50, config=VHC_CONFIG,
):
    """Solve thesis Problem 1 for $(a, b)$ from `guess` (pure; never raises).

    **Arguments:**

    - `model`: a two-DOF `WalkerModel` (e.g. `CompassGait`).
    - `guess`: $(a_0, b_0)$.
    - `family`: `"stable"` (thesis selector 2) or `"unstable"` (selector 1).
    - `solver`: `"newton"` (default: `damped_newton`, forward-mode Jacobian with a
      backtracking line search, rescued by Levenberg-Marquardt (optimistix) where it
      stalls), `"lm"` (Levenberg-Marquardt only), `"optimistix"` (plain `optx.Newton`, which stalls from
      the thesis seed (7.2) for the unstable family) or `"optax"` (L-BFGS on the squared
      residual; slower, offered for comparison).
    - `rtol`, `atol`, `max_steps`: of the solver.
    - `config`: `SolverConfig` of the $\\phi''$ integration.

    **Returns:** a `Gait`.
    """
    ab0 = jnp.asarray(guess, dtype=float)[:2]
    res_fn = lambda ab: vhc_residual(model, ab, family, config)  # noqa: E731
    if solver == "newton":
        ab, iters, _ = damped_newton(res_fn, ab0, rtol=rtol, atol=atol, max_steps=max_steps)
        # Rescue: Levenberg-Marquardt from the seed where Newton stalled (it does from the
        # thesis seed (7.2) for the unstable family, whose gait lies near the region where
        # (5.13) has no real root). From a converged point LM stops after one step, so
        # a batch pays little for it when every member converged.
        ok = jnp.max(jnp.abs(res_fn(ab))) < SUCCESS_TOL
        ab_lm, it_lm = _levenberg_marquardt(res_fn, jnp.where(ok, ab, ab0), rtol, atol, 4 * max_steps)
        ab = jnp.where(ok, ab, ab_lm)
        iters = iters + jnp.where(ok, 0, it_lm)
    elif solver == "lm":
        ab, iters = _levenberg_marquardt(res_fn, ab0, rtol, atol, 4 * max_steps)
    elif solver == "optimistix":
        sol = optx.root_find(
            lambda ab, _: res_fn(ab),
            optx.Newton(rtol=rtol, atol=atol), ab0, max_steps=max_steps, throw=False,
        )
        ab, iters = sol.value, sol.stats["num_steps"]
    elif solver == "optax":
        ab, iters = _optax_minimise(res_fn, ab0, max_steps=20 * max_steps)
    else:
        raise ValueError(f"solver must be 'newton', 'lm', 'optimistix' or 'optax', got {solver!r}")
    finite = jnp.isfinite(ab).all()
    ab = jnp.where(finite, ab, ab0)
    return _finish_vhc(model, ab, iters, finite, family, "vhc", config)


def damped_newton(residual, x0, *, rtol=1e-11, atol=1e-11, max_steps=50, max_halvings=8):
    """Newton's method with a forward-mode Jacobian (`jax.linearize` + dense solve) and a
    backtracking line search on $\|r\|_2$ (halving the step up to `max_halvings` times
    until the residual decreases); the full step is taken when it decreases the
    residual, so near a solution this is plain Newton (quadratic convergence). Stops when
    $\|\Delta x\|_\infty < \mathrm{atol} + \mathrm{rtol}\|x\|_\infty$ or $\|r\|_\infty < \mathrm{atol}$.

    **Returns:** `(x, iterations, stopped)`.
    """

    def jac(x):
        r, lin = jax.linearize(residual, x)
        return r, jax.vmap(lin, out_axes=1)(jnp.eye(x.shape[0], dtype=x.dtype))

    def cond(carry):
        _, _, k, done = carry
        return (k < max_steps) & ~done

    def body(carry):
        x, r, k, _ = carry
        _, J = jac(x)
        dx = jnp.linalg.solve(J, r)
        dx = jnp.where(jnp.isfinite(dx).all(), dx, jnp.zeros_like(dx))
        n0 = jnp.sum(r**2)

        def ls_cond(c):
            alpha, rn, j = c
            return (j < max_halvings) & ~(jnp.sum(rn**2) < n0)

        def ls_body(c):
            alpha, _, j = c
            alpha = 0.5 * alpha
            return alpha, residual(x - alpha * dx), j + 1

        alpha, r_new, _ = jax.lax.while_loop(
            ls_cond, ls_body, (jnp.asarray(1.0), residual(x - dx), jnp.array(0))
        )
        improved = jnp.sum(r_new**2) < n0
        x_new = jnp.where(improved, x - alpha * dx, x)
        r_new = jnp.where(improved, r_new, r)
        small = jnp.max(jnp.abs(alpha * dx)) < atol + rtol * jnp.max(jnp.abs(x))
        done = ~improved | small | (jnp.max(jnp.abs(r_new)) < atol)
        return x_new, r_new, k + 1, done

    r0 = residual(x0)
    x, _, k, done = jax.lax.while_loop(
        cond, body, (x0, r0, jnp.array(0), jnp.max(jnp.abs(r0)) < atol)
    )
    return x, k, done


def _levenberg_marquardt(residual, x0, rtol, atol, max_steps):
    sol = optx.least_squares(
        lambda x, _: residual(x), optx.LevenbergMarquardt(rtol=rtol, atol=atol), x0,
        max_steps=max_steps, throw=False,
    )
    return sol.value, sol.stats["num_steps"]


def _optax_minimise(residual, x0, max_steps=1000, tol=1e-22):
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
    return x, k


# ---------------------------------------------------------------------------------------
# Shooting (Problem 2)
# ---------------------------------------------------------------------------------------
def complete_guess(model, ab, family="stable"):
    """Section coordinates $(a, b, f)$ of a guess $(a, b)$: $d$ from the energy quadratic
    with the `family` root, then $f$ from the impact relations (5.9). A seed for shooting
    that uses no integration."""
    ab = jnp.asarray(ab, dtype=float)
    d, _ = solve_for_d(model, ab[0], ab[1], family)
    f, _ = velocity_relations(model, ab[0], ab[1], d)
    return jnp.stack([ab[0], ab[1], f])


def shooting_search(
    model, guess, family="stable", *, rtol=1e-12, atol=1e-12, max_steps=40,
    config=DEFAULT_CONFIG,
):
    """Solve Problem 2 (fixed point of the step-to-step map) from `guess` (pure).

    `guess` is $(a_0, b_0, f_0)$ on the post-impact section, or $(a_0, b_0)$ completed by
    `complete_guess` with the `family` root. The `family` label of the result is checked:
    a fixed point whose $d$ is the other root of (5.13) gets `RESULTS.other_cycle`.

    **Returns:** a `Gait` (`method="shooting"`).
    """
    guess = jnp.asarray(guess, dtype=float)
    z0 = guess if guess.shape[-1] == 3 else complete_guess(model, guess, family)
    fp = _poincare.fixed_point(
        model, z0, 1, rtol=rtol, atol=atol, max_steps=max_steps, config=config
    )
    sr = _step(model, fp.x0, config)
    x_plus, x_minus = fp.x0, sr.x_minus
    E0 = model.energy(x_plus)
    # Which root of the energy quadratic is this gait's d?
    n = model.n_dof
    a, b = x_plus[0], x_plus[n]
    d_fam, _ = solve_for_d(model, a, b, family)
    other = "unstable" if family == "stable" else "stable"
    d_oth, _ = solve_for_d(model, a, b, other)
    d = x_minus[n]
    wrong = jnp.abs(d - d_oth) < jnp.abs(d - d_fam)
    code = RESULTS.where(
        (fp.result == RESULTS.successful) & wrong, RESULTS.other_cycle, fp.result
    )
    return _make_gait(
        model, x_plus, x_minus, fp.periods[0], E0, fp.iterations, fp.residual, code,
        family, "shooting",
    )


def _search(model, guess, family, method, solver="newton"):
    if method == "vhc":
        return vhc_search(model, guess, family, solver=solver)
    if method == "shooting":
        return shooting_search(model, guess, family)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


_search_jit = eqx.filter_jit(_search)


def reference_guess(family="stable"):
    """$(a, b)$ of the `family` gait of the default model at 3 degrees (a seed)."""
    return jnp.asarray(_REFERENCE_AB[family])


def find_gait(model, family="stable", method="vhc", guess=None, *, solver="newton", throw=True):
    """Find the periodic gait of `family` on `model`.

    **Arguments:**

    - `model`: a `CompassGait` (any masses, lengths, gravity, slope).
    - `family`: `"stable"` or `"unstable"` (the root of the energy quadratic, 7.3/7.8).
    - `method`: `"vhc"` (Problem 1) or `"shooting"` (Problem 2).
    - `guess`: $(a_0, b_0)$ (or $(a_0, b_0, f_0)$ for shooting). `None`: continue the
      known default-model gait to `model` (homotopy in the parameters).
    - `solver`: `"newton"` or `"optax"` (VHC only).
    - `throw`: raise if no gait was found.

    **Returns:** a `Gait`.
    """
    if guess is None:
        from ._continuation import continue_to_model

        gait = continue_to_model(model, family, method)
    else:
        gait = _search_jit(model, jnp.asarray(guess, dtype=float), family, method, solver)
    if throw:
        gait = eqx.tree_at(
            lambda g: g.a, gait, gait.result.error_if(gait.a, gait.result != RESULTS.successful)
        )
    return gait
