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

The search itself runs in the unknowns $(a, h)$, $h = \\dot q_2^-$: with $a$ and $h$
fixed, $b = P_{11} d + P_{12} h$ and $f = P_{21} d + P_{22} h$ are linear in $d$, the
energy balance is again a quadratic in $d$, and the gait's $d$ is its smaller root for
both families. In $(a, b)$ the residual has a square-root branch where (5.13) has a
double root, and gaits lie close to one (a hip 1000 times as heavy as a leg: relative
discriminant $10^{-8}$; a family that passes from one root to the other), and
$h = (b - P_{11} d)/P_{12}$ divides by a small $P_{12}$ for a heavy hip; in $(a, h)$
the gaits tried lie at relative discriminants above 0.5. Guesses and results stay in
$(a, b)$; the gait found is labelled with its root of (5.13) (`other_cycle` where that
is not the `family` asked for).

**Shooting** (Problem 2): Newton on the step-to-step map of the hybrid simulation on
the post-impact section (`vhcjax.hybrid.fixed_point`).

Both return the same `Gait` pytree and never raise under `jit`/`vmap`: inspect `result`.
"""

import math
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._programs import stored_jit
from .._results import RESULTS
from ..solvers import levenberg_marquardt, optax_minimise
from ._gait import (
    _LOOSE_TOL,
    _RESIDUAL_CAP,
    VHC_CONFIG,
    _label,
    _make_gait,
    accepted,
    family_sign,
)
from ._newton_search import _each_member, _newton_search
from ._vhc import phi_second_derivative, singularity_terms


# ---------------------------------------------------------------------------------------
# Algebra of Problem 1
# ---------------------------------------------------------------------------------------
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


class _ImpactData(NamedTuple):
    """What (5.5)-(5.9) fix from $a$ alone: $q^+$, $q^-$ and $P(q^-)$."""

    q_plus: jax.Array
    q_minus: jax.Array
    P: jax.Array


def _impact_data(model, a):
    q_plus, q_minus = impact_configuration(model, a)
    return _ImpactData(q_plus, q_minus, impact_velocity_matrix(model, q_minus))


def _relations(data, b, d):
    P = data.P
    h = (b - P[0, 0] * d) / P[0, 1]
    f = P[1, 0] * d + P[1, 1] * h
    return f, h


def velocity_relations(model, a, b, d):
    """$(f, h)$ from $(a, b, d)$ (thesis 5.9), derived from the impact map: solve
    $b = P_{11} d + P_{12} h$ for $h$, then $f = P_{21} d + P_{22} h$."""
    return _relations(_impact_data(model, a), b, d)


def _states_from(data, b, d, h=None):
    """Post- and pre-impact states from $b, d$ (5.9), or from $d, h$ with $b$ given by them."""
    if h is None:
        f, h = _relations(data, b, d)
    else:
        f = data.P[1, 0] * d + data.P[1, 1] * h
    x_plus = jnp.concatenate([data.q_plus, jnp.stack([b, f])])
    x_minus = jnp.concatenate([data.q_minus, jnp.stack([d, h])])
    return x_plus, x_minus


def _energy_gap(model, data, b, d):
    x_plus, x_minus = _states_from(data, b, d)
    return model.energy(x_minus) - model.energy(x_plus)


def _fit_quadratic(gap, like):
    """$(A, B, C)$ of a quadratic `gap(d)` from its values at $d = -1, 0, 1$ (exact); one
    trace of the energies, batched over the three values (`like`: their dtype)."""
    ds = jnp.array([-1.0, 0.0, 1.0]) * jnp.ones_like(jnp.asarray(like, dtype=float))
    fm, f0, fp = jax.vmap(gap)(ds)
    return 0.5 * (fp + fm) - f0, 0.5 * (fp - fm), f0


def _quadratic(model, data, b):
    return _fit_quadratic(lambda d: _energy_gap(model, data, b, d), b)


def quadratic_coefficients(model, a, b):
    """$(A, B, C)$ of $A d^2 + B d + C = E(c, d) - E(a, b)$ (thesis 5.13-5.14), from the
    energy difference at $d = -1, 0, 1$ (exact: it is a quadratic in $d$)."""
    return _quadratic(model, _impact_data(model, a), b)


#: Relative size of $P_{12}$ below which the roots of (5.13) label no family: with the
#: leg masses at the feet ($b = 0$) the pre-impact $\dot q_2$ does not enter the
#: post-impact $\dot q_1$, and (5.13) in $(a, b)$ degenerates.
_P12_DEGENERATE = 1e-8


def on_other_root(model, x_plus, x_minus, family):
    """Whether the gait through `x_plus`, `x_minus` has its $d$ at the root of (5.13) that
    is not `family`'s (its label: `other_cycle`). The family's root
    $(-B + s\\sqrt\\Delta)/2A$ lies on the side of the vertex $-B/2A$ where
    $s(2Ad + B) > 0$. False where (5.13) has no real root or the labelling degenerates
    ($P_{12} \approx 0$, `_P12_DEGENERATE`)."""
    n = model.n_dof
    a, b, d = x_plus[0], x_plus[n], x_minus[n]
    data = _impact_data(model, a)
    A, B, C = _quadratic(model, data, b)
    defined = jnp.abs(data.P[0, 1]) > _P12_DEGENERATE * jnp.max(jnp.abs(data.P))
    return defined & (B**2 - 4 * A * C >= 0) & (family_sign(family) * (2 * A * d + B) < 0)


def solve_for_d(model, a, b, family):
    """$d$ from (5.13): `"stable"` = thesis selector 2 ($-\\sqrt{}$, 7.3), `"unstable"` =
    selector 1 ($+\\sqrt{}$, 7.8); `family` may also be that sign. **Returns:** `(d, real)`
    where `real` is False when $B^2 - 4AC < 0$ (then `d` is the vertex $-B/2A$)."""
    return _solve_for_d(model, _impact_data(model, a), b, family)


def _solve_for_d(model, data, b, family):
    sign = family_sign(family)
    A, B, C = _quadratic(model, data, b)
    disc = B**2 - 4 * A * C
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
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
    """$(\\phi', \\phi'', dt/d\\theta)$ (5.19; $dt/d\\theta = \\pm 1/\\sqrt{\\dot\\theta^2}$) and
    a fourth rate, 1 where the ODE is singular ($\\dot\\theta^2 \\le 0$ or a non-finite
    rate), where the others are 0: the state stops there, the integration finishes in a
    few steps instead of shrinking its steps to the step limit (which, in a batch, every
    member would wait for), and `y[3] > 0` flags it."""
    model, E0, sign = args
    phi, dphi = y[0:1], y[1:2]
    ddphi, _, dth2, _ = phi_second_derivative(model, E0, theta, phi, dphi)
    rate = jnp.concatenate([dphi, ddphi, (sign / jnp.sqrt(jnp.where(dth2 > 0, dth2, 1.0)))[None]])
    ok = (dth2 > 0) & jnp.isfinite(rate).all()
    return jnp.concatenate([jnp.where(ok, rate, 0.0), jnp.where(ok, 0.0, 1.0)[None]])


#: Smallest step of the `phi` integration over s in [0, 1]: a member whose solution needs
#: shorter steps is singular there (it approaches a blow-up of phi', with shrinking
#: steps and finite rates) and fails at once (`dt_min_reached`) instead of spending the
#: step limit, which a vmapped batch would wait for. The converged gaits of both
#: families from 0.5 to 6 degrees take steps of at least 1.1e-3 (at 1e-12 and 1e-6).
_PHI_DTMIN = 1e-8


def _phi_error_norm(e):
    """The step-size controller's norm: the RMS of the first three components (the
    singularity flag of `_phi_field` is no part of the solution's error)."""
    return optx.rms_norm(e[:3])


# diffrax traces the field several times; jitted, the later traces reuse the first jaxpr.
@stored_jit
def _phi_field_unit(s, y, args):
    """`_phi_field` over $s \\in [0, 1]$, $\\theta = a + s (c - a)$: the integration
    interval is static, so diffrax inserts no runtime check of its direction (a host
    callback, which would keep the compiled program out of JAX's persistent cache).
    The steps and error estimates are those of the integration over $\\theta$."""
    a, span, field_args = args
    rate = _phi_field(a + s * span, y, field_args)
    return jnp.concatenate([span * rate[:3], rate[3:]])  # the flag counts in s


def _with_tolerance(config, tol):
    """`config` with `rtol = tol` and `atol` scaled alike (`tol` may be traced: the
    inexact Newton iterations of `damped_newton`); `tol=None` leaves it unchanged."""
    if tol is None:
        return config
    return config._replace(rtol=tol, atol=config.atol * (tol / config.rtol))


def _solver(name):
    return {"tsit5": diffrax.Tsit5, "dopri8": diffrax.Dopri8, "dopri5": diffrax.Dopri5}[name]()


def vhc_boundary(model, ab, family, config=VHC_CONFIG):
    """Integrate $\\phi'' = f_0$ (5.19) over $\\theta \\in [a, c]$ for given $(a, b)$; the
    residual of Problem 1 (5.20) and the data of the candidate gait."""
    a, b = ab[0], ab[1]
    data = _impact_data(model, a)
    d, real = _solve_for_d(model, data, b, family)
    return _boundary_abd(model, data, a, b, d, real, config)


def _boundary_abd(model, data, a, b, d, real, config, h=None):
    """`vhc_boundary` for a given $d$ (not necessarily a root of 5.13); with `h`, the
    pre-impact $\\dot q_2$ given too (`b` must equal $P_{11} d + P_{12} h$)."""
    real = jnp.asarray(real)
    d = jnp.where(real, d, -1.0)  # keep the arithmetic finite on failure
    x_plus, x_minus = _states_from(data, b, d, h)
    E0 = model.energy(x_plus)
    n = model.n_dof
    e, f = x_plus[1], x_plus[n + 1]
    c, g, h = x_minus[0], x_minus[1], x_minus[n + 1]
    # phi'(a) = f/b; M_theta > 0 and theta_dot^2 > 0 at both ends, else singular.
    y0 = jnp.stack([e, f / b, 0.0, 0.0])
    ok0 = jnp.isfinite(y0).all()
    y0 = jnp.where(ok0, y0, jnp.array([e, 0.0, 0.0, 0.0]))
    sign = jnp.sign(b)
    regular_start = ok0 & (b != 0) & (d != 0)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(_phi_field_unit),
        _solver(config.solver),
        t0=0.0,
        t1=1.0,
        dt0=1.0 / 64,
        y0=y0,
        # A member already singular at the start gets an empty interval (a few steps).
        args=(a, jnp.where(regular_start & real, c - a, 0.0), (model, E0, sign)),
        stepsize_controller=diffrax.PIDController(
            rtol=config.rtol,
            atol=config.atol,
            norm=_phi_error_norm,
            dtmin=_PHI_DTMIN,
        ),
        saveat=diffrax.SaveAt(t1=True),
        max_steps=config.max_steps,
        adjoint=diffrax.ForwardMode(),
        throw=False,
    )
    assert sol.ys is not None  # saved at t1
    yc = sol.ys[-1]
    # Both ends in one batched call (one trace of the mass matrix and energies).
    dth2, det = jax.vmap(lambda th, y: singularity_terms(model, E0, th, y[0:1], y[1:2]))(
        jnp.stack([a, c]), jnp.stack([y0[:2], yc[:2]])
    )
    dth2_a, dth2_c, det_a, det_c = dth2[0], dth2[1], det[0], det[1]
    residual = jnp.stack([yc[0] - g, yc[1] - h / d])
    singular = (
        ~regular_start
        | (sol.result != diffrax.RESULTS.successful)
        | ~jnp.isfinite(yc).all()
        | (yc[3] > 0)  # the ODE went singular on the way (`_phi_field`)
        | ~jnp.isfinite(residual).all()
        | (dth2_a <= 0)
        | (dth2_c <= 0)
        | (jnp.abs(det_a) < 1e-12)
        | (jnp.abs(det_c) < 1e-12)
    )
    code = RESULTS.where(
        ~real,
        RESULTS.no_real_root,
        RESULTS.where(singular, RESULTS.singular_phi_ode, RESULTS.successful),
    )
    ok = code == RESULTS.successful
    residual = jnp.where(ok, residual, jnp.zeros_like(residual))
    return BoundaryData(x_plus, x_minus, E0, yc[:2], yc[2], residual, code)


def _vhc_eval(model, ab, family, config=VHC_CONFIG, tol=None):
    bd = vhc_boundary(model, ab, family, _with_tolerance(config, tol))
    r = jnp.where(bd.result == RESULTS.successful, bd.residual, 1e3 * jnp.ones(2))
    return r, bd


def vhc_residual(model, ab, family, config=VHC_CONFIG):
    """The residual vector of Problem 1, $(\\phi(c) - g, \\phi'(c) - h/d)$ (5.20); a large
    constant where it is undefined (no real root, singular ODE), so Newton cannot stop
    there."""
    return _vhc_eval(model, ab, family, config)[0]


# ---------------------------------------------------------------------------------------
# The search's unknowns: (a, h)
# ---------------------------------------------------------------------------------------
def _quadratic_h(model, data, h):
    """$(A', B', C')$ of the energy gap as a quadratic in $d$ with $a$ and the pre-impact
    $h = \\dot q_2^-$ fixed: $b = P_{11} d + P_{12} h$, $f = P_{21} d + P_{22} h$ (5.7)."""

    def gap(d):
        x_plus, x_minus = _states_from(data, data.P[0, 0] * d + data.P[0, 1] * h, d, h)
        return model.energy(x_minus) - model.energy(x_plus)

    return _fit_quadratic(gap, h)


def _to_search(model, ab, family):
    """The search's unknowns $(a, h)$ of a guess $(a, b)$: $d$ is the `family` root of
    (5.13) (`family` may be its sign), $h = (b - P_{11} d)/P_{12}$; where (5.13) has no
    real root, $d$ is the vertex $-B/2A$."""
    a, b = ab[0], ab[1]
    data = _impact_data(model, a)
    A, B, C = _quadratic(model, data, b)
    disc = B**2 - 4 * A * C
    root = jnp.sqrt(jnp.where(disc > 0, disc, 0.0))
    d = (-B + family_sign(family) * root) / (2 * A)
    return jnp.stack([a, _relations(data, b, d)[1]])


def _to_search_near(model, ab, ah):
    """The search's unknowns $(a, h)$ of $(a, b)$ (a step in $(a, b)$ from `ah`), through
    the root of (5.13) nearer to the $d$ of `ah`; NaN where (5.13) has no real root."""
    a, b = ab[0], ab[1]
    data = _impact_data(model, a)
    A, B, C = _quadratic(model, data, b)
    disc = B**2 - 4 * A * C
    root = jnp.sqrt(jnp.where(disc > 0, disc, 0.0))
    d_now, _ = _smaller_root(_quadratic_h(model, _impact_data(model, ah[0]), ah[1]))
    lo, hi = (-B - root) / (2 * A), (-B + root) / (2 * A)
    d = jnp.where(jnp.abs(hi - d_now) < jnp.abs(lo - d_now), hi, lo)
    return jnp.where(disc < 0, jnp.nan, jnp.stack([a, _relations(data, b, d)[1]]))


def _from_search(model, ah):
    """$(a, b)$ of the search's unknowns $(a, h)$ (see `_vhc_eval_h`)."""
    a, h = ah[0], ah[1]
    data = _impact_data(model, a)
    d, _ = _smaller_root(_quadratic_h(model, data, h))
    return jnp.stack([a, data.P[0, 0] * d + data.P[0, 1] * h])


def _smaller_root(coefficients):
    A, B, C = coefficients
    disc = B**2 - 4 * A * C
    real = disc >= 0
    return (-B - jnp.sqrt(jnp.where(real, disc, 0.0))) / (2 * A), real


#: Residual (max-norm) above which the VHC search steps in (a, b), below it in (a, h)...
_FAR = 1e-2
#: ... and relative discriminant of (5.13) in (a, b) above which it does: next to a
#: double root the steps in (a, b) meet its square-root branch.
_FAR_DISCRIMINANT = 1e-3


def _vhc_eval_h(model, ah, family, config=VHC_CONFIG, tol=None):
    """Problem 1's residual (5.20) and boundary data in the unknowns $(a, h)$: $d$ is the
    smaller root of the energy quadratic in $d$ at fixed $(a, h)$ (`_quadratic_h`; its
    $A' > 0$, as the impact dissipates), then $b = P_{11} d + P_{12} h$. In these
    unknowns the gaits lie far from a double root (relative discriminant above 0.5 for
    every model tried, against $10^{-8}$ in $(a, b)$ for a heavy hip), nothing divides
    by $P_{12}$, and a family passes through a double root of (5.13) in $(a, b)$ without
    a branch point. The gait's `family` (its root of (5.13) in $(a, b)$) is checked at
    the end (`_unmirror`). That the gait's $d$ is the smaller root is measured, not
    enforced: a gait with the larger one would not be found (none is known)."""
    del family  # the gait's d is the smaller root for both families
    a, h = ah[0], ah[1]
    data = _impact_data(model, a)
    d, real = _smaller_root(_quadratic_h(model, data, h))
    b = data.P[0, 0] * d + data.P[0, 1] * h
    bd = _boundary_abd(model, data, a, b, d, real, _with_tolerance(config, tol), h)
    r = jnp.where(bd.result == RESULTS.successful, bd.residual, 1e3 * jnp.ones(2))
    return r, bd


def _finish_vhc(model, bd, iterations, solver_ok, family, error=jnp.inf):
    """The `Gait` of a (mirrored, see `vhc_search`) search, before `_unmirror`."""
    res = jnp.max(jnp.abs(bd.residual))
    converged = solver_ok & accepted(res, error)
    code = RESULTS.where(
        bd.result != RESULTS.successful,
        bd.result,
        RESULTS.where(converged, RESULTS.successful, RESULTS.not_converged),
    )
    res = jnp.where(bd.result == RESULTS.successful, res, jnp.inf)
    # the impact is checked by `_unmirror`, on the gait walking the guess's way
    return _make_gait(
        model,
        bd.x_plus,
        bd.x_minus,
        bd.T,
        bd.E0,
        iterations,
        res,
        code,
        _label(family),
        "vhc",
        jnp.asarray(True),
    )


def _unmirror(model, gait, up, family):
    """A gait searched mirrored (`up`: every velocity reversed, see `vhc_search`) turned
    back, its impact checked (`_make_gait`), and labelled with its root of (5.13) in
    $(a, b)$: `other_cycle` where that is not `family`'s."""
    n = model.n_dof
    s = jnp.where(up, -1.0, 1.0)
    flip = jnp.concatenate([jnp.ones(n), jnp.full(n, s)])
    x_plus, x_minus = gait.x_plus * flip, gait.x_minus * flip
    # the walking direction is judged here, on the gait turned back
    code = RESULTS.where(gait.result == RESULTS.infeasible_uphill, RESULTS.successful, gait.result)
    out = _make_gait(
        model,
        x_plus,
        x_minus,
        s * gait.T,
        gait.E0,
        gait.iterations,
        gait.residual,
        code,
        _label(family),
        "vhc",
    )
    # a gait (walking downhill, impact physical) whose d is the other root
    other = on_other_root(model, x_plus, x_minus, family)
    code = RESULTS.where(
        (out.result == RESULTS.successful) & other, RESULTS.other_cycle, out.result
    )
    return eqx.tree_at(lambda g: g.result, out, code)


def vhc_search(
    model,
    guess,
    family="stable",
    *,
    solver="newton",
    rtol=1e-11,
    atol=1e-11,
    max_steps=50,
    config=VHC_CONFIG,
    chord=False,
    axes=None,
    far=_FAR,
):
    """Solve thesis Problem 1 for $(a, b)$ from `guess` (pure; never raises).

    **Arguments:**

    - `model`: a two-DOF `WalkerModel` (e.g. `CompassGait`).
    - `guess`: $(a_0, b_0)$. The guess enters with $d$ its `family` root of the energy
      quadratic (5.13) (the vertex $-B/2A$ where (5.13) has no real root), and the gait
      found is checked to be of that family (`other_cycle` if its $d$ is the other
      root). Near the gait the search runs in unknowns $(a, h)$, $b$ linear in $(d, h)$
      by the impact relations, in which the gaits lie far from a double root of (5.13)
      (see `far`). A guess with $b_0 > 0$ (walking uphill, 7.17) is searched mirrored:
      every velocity reversed, which leaves the residual unchanged.
    - `family`: `"stable"` (thesis selector 2) or `"unstable"` (selector 1).
    - `solver`: `"newton"` (default: the library's damped Newton method, forward-mode
      Jacobian, steps damped Levenberg-Marquardt style where a full step fails), `"lm"`
      (optimistix's Levenberg-Marquardt only), `"optimistix"` (plain `optx.Newton`, which
      stalls from the thesis seed (7.2) for the unstable family) or `"optax"` (L-BFGS on
      the squared residual; slower, offered for comparison).
    - `rtol`, `atol`, `max_steps`: of the solver.
    - `config`: `SolverConfig` of the $\\phi''$ integration.
    - `chord`: `"newton"` only: finish with chord steps (the Jacobian kept once the
      residual is small): in large batches 1.6x the throughput, for one more compiled
      evaluation (1.5-2.2 s more to compile).
    - `far`: `"newton"` only: from points with a residual (max-norm) above `far` and a
      relative discriminant of (5.13) above $10^{-3}$ the steps are taken in $(a, b)$,
      the unknowns of the thesis, in which a guess far from the gait, such as the thesis
      seeds, is led in; elsewhere in $(a, h)$. `math.inf` (a Python float): in $(a, h)$
      throughout, for guesses predicted next to a gait (continuation, sweeps), with a
      smaller program to compile. May be traced.
    - `axes`: searches a batch. `guess` is then `(B, 2)` and `axes` gives the batch axis
      of each of `model`'s leaves (`0` or `None`, as `jax.vmap`'s `in_axes`). With
      `"newton"` one loop iterates every member, each stopping at its own convergence.

    **Returns:** a `Gait` (with a leading batch axis with `axes`).
    """
    if axes is not None and solver != "newton":
        return _each_member(
            vhc_search,
            model,
            guess,
            axes,
            family,
            solver=solver,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            config=config,
        )
    ab0 = jnp.asarray(guess, dtype=float)[..., :2]
    # The residual is even in the velocities: a guess walking uphill (b > 0, thesis 7.17)
    # is searched mirrored, downhill, where its family's root is the other one.
    up = ab0[..., 1] > 0
    ab0 = ab0 * jnp.stack([jnp.ones(up.shape), jnp.where(up, -1.0, 1.0)], axis=-1)
    signs = family_sign(family) * jnp.where(up, -1.0, 1.0)
    if axes is None:
        x0 = _to_search(model, ab0, signs)
    else:
        x0 = eqx.filter_vmap(_to_search, in_axes=(axes, 0, 0))(model, ab0, signs)
    # A guess that maps to no finite (a, h) (A = 0 or P12 = 0) is searched from (a, 0).
    x0 = jnp.where(jnp.isfinite(x0), x0, jnp.zeros_like(x0))
    res_fn = lambda x: _vhc_eval_h(model, x, family, config)[0]  # noqa: E731
    if solver == "newton":
        gait = _vhc_newton(
            model,
            x0,
            family,
            config,
            chord,
            axes,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            far=far,
        )
    else:
        if solver == "lm":
            x, iters = levenberg_marquardt(res_fn, x0, rtol, atol, 4 * max_steps)
        elif solver == "optimistix":
            sol = optx.root_find(
                lambda x, _: res_fn(x),
                optx.Newton(rtol=rtol, atol=atol),
                x0,
                max_steps=max_steps,
                throw=False,
            )
            x, iters = sol.value, sol.stats["num_steps"]
        elif solver == "optax":
            x, iters = optax_minimise(res_fn, x0, max_steps=20 * max_steps)
        else:
            raise ValueError(
                f"solver must be 'newton', 'lm', 'optimistix' or 'optax', got {solver!r}"
            )
        finite = jnp.isfinite(x).all()
        x = jnp.where(finite, x, x0)
        bd = _vhc_eval_h(model, x, family, config)[1]
        gait = _finish_vhc(model, bd, iters, finite, family)
    if axes is None:
        return _unmirror(model, gait, up, family)
    return eqx.filter_vmap(_unmirror, in_axes=(axes, 0, 0, None))(model, gait, up, family)


def _vhc_newton(
    model,
    ab0,
    family,
    config=VHC_CONFIG,
    chord=False,
    axes=None,
    rtol=1e-11,
    atol=1e-11,
    max_steps=50,
    far=_FAR,
):
    """`vhc_search` with `solver="newton"`."""

    def use_ab(m, ab, r):  # far from the gait, and from a double root of (5.13)
        A, B, C = quadratic_coefficients(m, ab[0], ab[1])
        return (jnp.max(jnp.abs(r)) > far) & (B**2 - 4 * A * C > _FAR_DISCRIMINANT * B**2)

    near_only = isinstance(far, float) and math.isinf(far)
    chart = None if near_only else (_from_search, _to_search_near, use_ab)
    return _newton_search(
        _vhc_eval_h,
        config,
        family,
        lambda m, ab, r, bd, k, err: _finish_vhc(m, bd, k, jnp.isfinite(ab).all(), family, err),
        model,
        ab0,
        axes,
        chord,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        tolerances=(_LOOSE_TOL, config.rtol),
        residual_cap=_RESIDUAL_CAP,
        chart=chart,
    )
