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
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from ._compile import compile_pair, filter_jit, signature, top_level
from . import _poincare
from ._hybrid import DEFAULT_CONFIG, SolverConfig, _step
from ._results import RESULTS
from ._sharding import MAX_DISPATCH, device_multiple, host_workers, in_chunks, shard_batch
from ._vhc import phi_second_derivative, singularity_terms
from ._gait_derivatives import with_derivatives
from ._implicit import detach

FAMILIES = ("stable", "unstable")
METHODS = ("vhc", "shooting")

#: Settings of the $\phi''$ integration (smooth, no events: an 8th-order method).
VHC_CONFIG = SolverConfig(rtol=1e-12, atol=1e-12, max_steps=512, solver="dopri8")

#: A gait is accepted when the max-norm of its residual is below this.
SUCCESS_TOL = 1e-9

#: Loosest integration tolerance of the inexact Newton iterations (`damped_newton`).
_LOOSE_TOL = 1e-6
#: Trial tolerance of the inexact Newton iterations: this times the squared residual.
_TOL_FACTOR = 1e-4
#: Residual below which Newton keeps its Jacobian and evaluates the residual alone.
_CHORD_BELOW = 1e-3
#: The Newton-step convergence test of the searches also needs a residual below this.
_RESIDUAL_CAP = SUCCESS_TOL / 10

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


def _states_from(data, b, d):
    f, h = _relations(data, b, d)
    x_plus = jnp.concatenate([data.q_plus, jnp.stack([b, f])])
    x_minus = jnp.concatenate([data.q_minus, jnp.stack([d, h])])
    return x_plus, x_minus


def _states(model, a, b, d):
    return _states_from(_impact_data(model, a), b, d)


def _energy_gap(model, data, b, d):
    x_plus, x_minus = _states_from(data, b, d)
    return model.energy(x_minus) - model.energy(x_plus)


def energy_gap(model, a, b, d):
    """$E(c, d) - E(a, b)$ with $c, e, f, g, h$ eliminated (thesis 5.12-5.13)."""
    return _energy_gap(model, _impact_data(model, a), b, d)


def _quadratic(model, data, b):
    ds = jnp.array([-1.0, 0.0, 1.0]) * jnp.ones_like(jnp.asarray(b, dtype=float))
    # One trace of the energies, batched over the three values of d.
    fm, f0, fp = jax.vmap(lambda d: _energy_gap(model, data, b, d))(ds)
    return 0.5 * (fp + fm) - f0, 0.5 * (fp - fm), f0


def quadratic_coefficients(model, a, b):
    """$(A, B, C)$ of $A d^2 + B d + C = E(c, d) - E(a, b)$ (thesis 5.13-5.14), from the
    energy difference at $d = -1, 0, 1$ (exact: it is a quadratic in $d$)."""
    return _quadratic(model, _impact_data(model, a), b)


def family_sign(family):
    """The sign in front of the square root of (5.13): `"stable"` -> -1 (thesis selector
    2, 7.3), `"unstable"` -> +1 (selector 1, 7.8). Arrays pass through (traced signs let
    both families share one compiled function)."""
    if isinstance(family, str):
        if family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
        return jnp.asarray(-1.0 if family == "stable" else 1.0)
    return jnp.asarray(family, dtype=float)


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


def _phi_field_unit(s, y, args):
    """`_phi_field` over $s \\in [0, 1]$, $\\theta = a + s (c - a)$: the integration
    interval is static, so diffrax inserts no runtime check of its direction (a host
    callback, which would keep the compiled program out of JAX's persistent cache).
    The steps and error estimates are those of the integration over $\\theta$."""
    a, span, field_args = args
    rate = _phi_field(a + s * span, y, field_args)
    return jnp.concatenate([span * rate[:3], rate[3:]])  # the flag counts in s


# diffrax traces the field several times; jitted, the later traces reuse the first jaxpr.
_phi_field_unit_jit = eqx.filter_jit(_phi_field_unit)


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


def _boundary_abd(model, data, a, b, d, real, config):
    """`vhc_boundary` for a given $d$ (not necessarily a root of 5.13)."""
    real = jnp.asarray(real)
    d = jnp.where(real, d, -1.0)  # keep the arithmetic finite on failure
    x_plus, x_minus = _states_from(data, b, d)
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
        diffrax.ODETerm(_phi_field_unit_jit),
        _solver(config.solver),
        t0=0.0,
        t1=1.0,
        dt0=1.0 / 64,
        y0=y0,
        # A member already singular at the start gets an empty interval (a few steps).
        args=(a, jnp.where(regular_start & real, c - a, 0.0), (model, E0, sign)),
        stepsize_controller=diffrax.PIDController(
            rtol=config.rtol, atol=config.atol, norm=_phi_error_norm,
            dtmin=_PHI_DTMIN,
        ),
        saveat=diffrax.SaveAt(t1=True),
        max_steps=config.max_steps,
        adjoint=diffrax.ForwardMode(),
        throw=False,
    )
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
        ~real, RESULTS.no_real_root, RESULTS.where(singular, RESULTS.singular_phi_ode, RESULTS.successful)
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
# Gait assembly
# ---------------------------------------------------------------------------------------
def _derived(model, x_plus, x_minus, T):
    n = model.n_dof
    step_length = jnp.linalg.norm(model.contact_point(x_minus[:n]))
    speed = step_length / T
    # The potential energy is continuous through the impact: the loss is kinetic.
    ke = lambda x: model.kinetic_energy(x[:n], x[n:])  # noqa: E731
    return step_length, speed, ke(x_minus) - ke(x_plus)


def _make_gait(model, x_plus, x_minus, T, E0, iterations, residual, code, family, method,
               physical=None):
    """The `Gait`; `physical`: whether the impact at `x_minus` pushes the foot away from the
    ground (`None`: computed here)."""
    n = model.n_dof
    step_length, speed, loss = _derived(model, x_plus, x_minus, T)
    if physical is None:
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


def _finish_vhc(model, bd, iterations, solver_ok, family, config=VHC_CONFIG):
    res = jnp.max(jnp.abs(bd.residual))
    converged = solver_ok & (res < SUCCESS_TOL)
    code = RESULTS.where(
        bd.result != RESULTS.successful,
        bd.result,
        RESULTS.where(converged, RESULTS.successful, RESULTS.not_converged),
    )
    res = jnp.where(bd.result == RESULTS.successful, res, jnp.inf)
    return _make_gait(
        model, bd.x_plus, bd.x_minus, bd.T, bd.E0, iterations, res, code, _label(family), "vhc"
    )


def vhc_search(
    model, guess, family="stable", *, solver="newton", rtol=1e-11, atol=1e-11,
    max_steps=50, config=VHC_CONFIG, chord=False, axes=None,
):
    """Solve thesis Problem 1 for $(a, b)$ from `guess` (pure; never raises).

    **Arguments:**

    - `model`: a two-DOF `WalkerModel` (e.g. `CompassGait`).
    - `guess`: $(a_0, b_0)$.
    - `family`: `"stable"` (thesis selector 2) or `"unstable"` (selector 1).
    - `solver`: `"newton"` (default: `damped_newton`, forward-mode Jacobian, steps
      damped Levenberg-Marquardt style where a full step fails), `"lm"` (optimistix's
      Levenberg-Marquardt only), `"optimistix"` (plain `optx.Newton`, which stalls from
      the thesis seed (7.2) for the unstable family) or `"optax"` (L-BFGS on the squared
      residual; slower, offered for comparison).
    - `rtol`, `atol`, `max_steps`: of the solver.
    - `config`: `SolverConfig` of the $\\phi''$ integration.
    - `chord`: `"newton"` only: finish with chord steps (`damped_newton`'s
      `chord_below`): in large batches 1.6x the throughput, for one more compiled
      evaluation (1.5-2.2 s more to compile).
    - `axes`: searches a batch. `guess` is then `(B, 2)` and `axes` gives the batch axis
      of each of `model`'s leaves (`0` or `None`, as `jax.vmap`'s `in_axes`). With
      `"newton"` one loop iterates every member (`damped_newton_batch`).

    **Returns:** a `Gait` (with a leading batch axis with `axes`).
    """
    if axes is not None and solver != "newton":
        return _each_member(vhc_search, model, guess, axes, family, solver=solver, rtol=rtol,
                            atol=atol, max_steps=max_steps, config=config)
    ab0 = jnp.asarray(guess, dtype=float)[..., :2]
    res_fn = lambda ab: vhc_residual(model, ab, family, config)  # noqa: E731
    if solver == "newton":
        return _vhc_newton(model, ab0, family, config, chord, axes, rtol=rtol, atol=atol,
                           max_steps=max_steps)
    if solver == "lm":
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
    bd = vhc_boundary(model, ab, family, config)
    return _finish_vhc(model, bd, iters, finite, family, config)


def _evaluate_member(kind, model, x, family, config, tol):
    """The residual and aux of one member of a search: `kind` is the method."""
    if kind == "vhc":
        return _vhc_eval(model, x, family, config, tol)
    return _shoot_eval(model, x, config, tol)


@eqx.filter_jit
def _evaluate_batch(kind, config, axes, model, X, T, family):
    """`_evaluate_member` on a batch. Jitted with static `kind`, `config`, `axes`: the
    programs of the Newton and the chord loop (`stage`) trace it once between them."""
    member = lambda m, x, t: _evaluate_member(kind, m, x, family, config, t)  # noqa: E731
    return eqx.filter_vmap(member, in_axes=(axes, 0, 0))(model, X, T)


def _vhc_newton(model, ab0, family, config=VHC_CONFIG, chord=False, axes=None, stage=None,
                state=None, rtol=1e-11, atol=1e-11, max_steps=50):
    """`vhc_search` with `solver="newton"` (and its `stage`s, see `damped_newton_batch`)."""
    return _newton_search(
        "vhc", config, family,
        lambda m, ab, r, bd, k: _finish_vhc(m, bd, k, jnp.isfinite(ab).all(), family, config),
        model, ab0, axes, chord, stage, state, rtol=rtol, atol=atol, max_steps=max_steps,
        tolerances=(_LOOSE_TOL, config.rtol), residual_cap=_RESIDUAL_CAP,
    )


def _newton_search(kind, config, family, finish, model, x0, axes, chord, stage=None, state=None,
                   **newton):
    """`damped_newton` on one member (`axes=None`) or `damped_newton_batch` on a batch
    (`model` batched along `axes`, `x0`: `(B, n)`) of `_evaluate_member(kind, ...)`;
    `finish(model, x, r, aux, iterations) -> Gait` is written for one member. `stage`,
    `state`: as in `damped_newton_batch` (the `"chord"` stage returns the gaits)."""
    newton["chord_below"] = _CHORD_BELOW if chord else None
    if axes is None:
        def evaluate(x, tol):
            return _evaluate_member(kind, model, x, family, config, tol)

        x, r, aux, k = damped_newton(evaluate, x0, **newton)
        return finish(model, x, r, aux, k)
    fn = lambda X, T: _evaluate_batch(kind, config, axes, model, X, T, family)  # noqa: E731
    out = damped_newton_batch(fn, x0, stage=stage, state=state, **newton)
    if stage in ("newton", "init"):
        return out
    X, R, aux, k = out
    return eqx.filter_vmap(finish, in_axes=(axes, 0, 0, 0, 0))(model, X, R, aux, k)


def _each_member(search, model, guess, axes, family, **kwargs):
    """`search` on every member of a batch by `vmap` (the solvers without a batch loop)."""
    return eqx.filter_vmap(lambda m, g: search(m, g, family, **kwargs), in_axes=(axes, 0))(model, guess)


def _label(family):
    return family if isinstance(family, str) else ""


def damped_newton(fn, x0, *, rtol=1e-11, atol=1e-11, max_steps=50, max_trials=10,
                  tolerances=None, chord_below=None, residual_cap=jnp.inf):
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
    far from it the damped steps turn toward steepest descent, which lets the VHC search
    leave the edge of the region where (5.13) has real roots (plain Newton stalls there
    from the thesis seed (7.2) for the unstable family).

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

    **Returns:** `(x, r, aux, iterations)` at the last accepted point; `iterations`
    counts accepted steps.
    """
    call = (lambda y, tol: fn(y)) if tolerances is None else fn

    def one(X, tol):  # the batch of one member that `damped_newton_batch` iterates
        return jax.tree_util.tree_map(lambda a: jnp.asarray(a)[None], call(X[0], tol[0]))

    out = damped_newton_batch(one, x0[None], rtol=rtol, atol=atol, max_steps=max_steps,
                              max_trials=max_trials, tolerances=tolerances,
                              chord_below=chord_below, residual_cap=residual_cap)
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


def damped_newton_batch(fn, X0, *, rtol=1e-11, atol=1e-11, max_steps=50, max_trials=10,
                        tolerances=None, chord_below=None, residual_cap=jnp.inf, stage=None,
                        state=None):
    r"""`damped_newton` on every member of a batch at once, written out along the leading
    axis (`X0`: `(B, n)`; `fn(X, tol) -> (R, aux)` with `tol`: `(B,)`, each row of `R`
    depending on its own row of `X` only, every leaf of `aux` with the batch axis first).

    The loop runs while any member is still iterating; members that have stopped keep
    their state. This is what `jax.vmap` makes of `damped_newton`, but the residual is
    differentiated *after* it is batched: tracing does not have to batch the (three
    times larger) forward-mode evaluation (measured: 0.6-0.8 s less tracing for 128
    members with the chord finish). `tolerances` as in `damped_newton` (`None`: `tol` is
    ignored).

    `stage` splits the two loops into two programs (compiled concurrently by
    `_compile.compile_pair`): `"newton"` returns the loop state after the Newton loop,
    `"chord"` runs the chord loop from that `state` (`X0` then only gives shapes), and
    `"init"` returns the loop's initial state, which has the shapes of `"newton"`'s and
    needs only the residual traced (not its forward mode).

    **Returns:** `(X, R, aux, iterations)`, each with the leading batch axis.
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

    if stage not in ("chord", "init"):  # those have no forward-mode evaluation to trace
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
        return jnp.where(first, loose, jnp.clip(_TOL_FACTOR * norm(R) ** 2, final, loose))

    def solve(A, b):
        return jnp.linalg.solve(A, b[..., None])[..., 0]

    def iterating(carry):
        k, trials, done, chord = carry[4], carry[5], carry[6], carry[8]
        return (k < max_steps) & (trials < max_trials) & ~done & ~chord

    def chord_iterating(carry):
        return (carry[4] < max_steps) & (carry[5] < max_trials) & ~carry[6]

    def make_body(evaluate, active):
        def body(carry):
            X, R, J, aux, k, trials, done, lam, chord = carry
            first = k < 0  # the first pass only evaluates R, J at the guesses
            # Trial step from the accepted point (X, R, J): Newton, or damped after a failure.
            Jt = jnp.swapaxes(J, -1, -2)
            JtJ = Jt @ J
            newton = trials == 0
            dX = solve(where(newton, J, JtJ + lam[:, None, None] * eye),
                       where(newton, R, (Jt @ R[..., None])[..., 0]))
            dX = where(jnp.isfinite(dX).all(-1) & ~first, dX, jnp.zeros_like(dX))
            # A damped trial with no step ($J^Tr = 0$, or no finite solution, e.g. J = 0
            # where the residual is undefined): the member cannot move, so it stops as
            # after `max_trials` failures instead of re-evaluating the same point.
            stuck = ~first & ~newton & ~(norm(dX) > 0)
            tol = trial_tolerance(R, first)
            R_t, J_t, aux_t = evaluate(X - dX, tol, J)
            improved = first | (
                jnp.isfinite(R_t).all(-1) & jnp.isfinite(J_t).all((-2, -1))
                & (jnp.sum(R_t**2, -1) < jnp.sum(R**2, -1))
            )
            X_new, R_new, J_new, aux_new = pick(improved, (X - dX, R_t, J_t, aux_t), (X, R, J, aux))
            size = atol + rtol * norm(X - dX)
            small = ~first & (norm(dX) < atol + rtol * norm(X))
            # The Newton step from the trial point estimates its error (to first order).
            close = (norm(solve(J_t, R_t)) < size) & (norm(R_t) < residual_cap)
            exact = True if tolerances is None else tol <= final
            done_new = improved & exact & (small | close | (norm(R_t) < atol))
            chord_new = chord
            if chord_below is not None:
                chord_new = chord | (improved & (norm(R_new) < chord_below))
            # After a failure: grow lambda from a scale of J^T J; after a success: Newton again.
            lam_start = 1e-3 * norm(jnp.diagonal(JtJ, axis1=-2, axis2=-1))
            lam_new = jnp.where(improved, 0.0, jnp.where(newton, lam_start, 10.0 * lam))
            trials_new = jnp.where(improved, 0, jnp.where(stuck, max_trials, trials + 1))
            new = (X_new, R_new, J_new, aux_new, k + improved, trials_new, done_new, lam_new,
                   chord_new)
            return pick(active(carry), new, carry)  # stopped members keep their state

        return body

    if stage == "chord":
        carry = state
    else:
        # Shapes from the residual alone: `J[i] = dR[i]/dX[i]` (`batch_jacobian`).
        R_shape, aux_shape = jax.eval_shape(lambda X, tol: residual_jaxpr(X, tol, *rconsts), X0, tol0)
        J_shape = jax.ShapeDtypeStruct(R_shape.shape + (n,), R_shape.dtype)
        zeros = lambda t: jax.tree_util.tree_map(  # noqa: E731
            lambda l: jnp.zeros(l.shape, l.dtype) + jnp.reshape(tie, (B,) + (1,) * (len(l.shape) - 1)).astype(l.dtype), t)
        init = (X0, zeros(R_shape), zeros(J_shape), zeros(aux_shape),
                tie.astype(int) - 1, tie.astype(int), tie != 0, tie, tie != 0)
        if stage == "init":
            return init
        carry = jax.lax.while_loop(lambda c: jnp.any(iterating(c)), make_body(evaluate, iterating),
                                   init)
    if stage == "newton":
        return carry
    if chord_below is not None:  # the chord loop: the same steps, the residual alone
        def residual(X, tol, J):
            R, aux = residual_jaxpr(X, tol, *rconsts)
            return R, J, aux

        carry = jax.lax.while_loop(lambda c: jnp.any(chord_iterating(c)),
                                   make_body(residual, chord_iterating), carry)
    X, R, _, aux, k = carry[:5]
    return X, R, aux, k


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


complete_guess_jit = filter_jit(complete_guess)


def _shoot_eval(model, z, config=DEFAULT_CONFIG, tol=None):
    sr = _step(model, model.section_to_state(z), _with_tolerance(config, tol))
    r = model.state_to_section(sr.x_plus) - z
    return jnp.where(sr.result == RESULTS.successful, r, 1e3 * jnp.ones_like(r)), sr


def shooting_search(
    model, guess, family="stable", *, solver="newton", rtol=1e-12, atol=1e-12, max_steps=40,
    config=DEFAULT_CONFIG, chord=False, axes=None,
):
    """Solve Problem 2, $P(z) = z$ for the step-to-step map $P$ on the post-impact section
    (`vhcjax._poincare.step_map`), from `guess` (pure; never raises).

    `guess` is $(a_0, b_0, f_0)$ on the post-impact section, or $(a_0, b_0)$ completed by
    `complete_guess` with the `family` root. `solver="newton"` uses `damped_newton`
    (forward-mode Jacobian through the heel-strike event); `"optimistix"` uses
    `vhcjax._poincare.fixed_point` (plain `optx.Newton`). The `family` label is checked:
    a fixed point whose $d$ is the other root of (5.13) gets `RESULTS.other_cycle`.
    `chord`: as in `vhc_search` (1.6-1.8x the batched throughput). `axes`: a batch of guesses,
    as in `vhc_search`.

    **Returns:** a `Gait` (`method="shooting"`).
    """
    guess = jnp.asarray(guess, dtype=float)
    if axes is not None and solver != "newton":
        return _each_member(shooting_search, model, guess, axes, family, solver=solver,
                            rtol=rtol, atol=atol, max_steps=max_steps, config=config)
    z0 = _section_points(model, guess, family, axes)
    if solver == "newton":
        return _shooting_newton(model, z0, family, config, chord, axes, rtol=rtol, atol=atol,
                                max_steps=max_steps)
    if solver != "optimistix":
        raise ValueError(f"solver must be 'newton' or 'optimistix' for shooting, got {solver!r}")
    fp = _poincare.fixed_point(
        model, z0, 1, rtol=rtol, atol=atol, max_steps=max_steps, config=config
    )
    sr = _step(model, fp.x0, config)
    return _shooting_gait(model, fp.x0, sr.x_minus, fp.periods[0], fp.iterations, fp.residual,
                          fp.result, family, sr.result != RESULTS.bad_impact)


def _section_points(model, guess, family, axes=None):
    """Guesses on the post-impact section: `(a, b, f)` as given, `(a, b)` completed by
    `complete_guess` (per member when `axes` gives a batch)."""
    if guess.shape[-1] == 3:
        return guess
    if axes is None:
        return complete_guess(model, guess, family)
    complete = lambda m, g: complete_guess(m, g, family)  # noqa: E731
    return eqx.filter_vmap(complete, in_axes=(axes, 0))(model, guess)


def _shooting_newton(model, z0, family, config=DEFAULT_CONFIG, chord=False, axes=None,
                     stage=None, state=None, rtol=1e-12, atol=1e-12, max_steps=40):
    """`shooting_search` with `solver="newton"` from section points `z0` (and its
    `stage`s, see `damped_newton_batch`)."""
    def finish(model, z, r, sr, iters):
        res = jnp.max(jnp.abs(r))
        ok = (sr.result == RESULTS.successful) & jnp.isfinite(z).all()
        code = RESULTS.where(
            sr.result != RESULTS.successful,
            sr.result,
            RESULTS.where(ok & (res < SUCCESS_TOL), RESULTS.successful, RESULTS.not_converged),
        )
        return _shooting_gait(model, model.section_to_state(z), sr.x_minus, sr.period,
                              iters, res, code, family, sr.result != RESULTS.bad_impact)

    return _newton_search(
        "shooting", config, family, finish, model, z0, axes, chord, stage, state, rtol=rtol,
        atol=atol, max_steps=max_steps, tolerances=(_LOOSE_TOL, config.rtol),
        residual_cap=_RESIDUAL_CAP,
    )


def _shooting_gait(model, x_plus, x_minus, T, iters, res, code, family, physical):
    """`physical`: the step's impact was checked (`_step` flags `RESULTS.bad_impact`)."""
    E0 = model.energy(x_plus)
    # Which root of the energy quadratic A d^2 + B d + C (5.13) is this gait's d? The
    # family's root (-B + sign sqrt(disc)) / 2A lies on the side of the vertex -B/2A
    # where sign (2 A d + B) > 0; d is nearer the other root iff that is negative.
    n = model.n_dof
    a, b = x_plus[0], x_plus[n]
    A, B, C = _quadratic(model, _impact_data(model, a), b)
    d = x_minus[n]
    wrong = (B**2 - 4 * A * C >= 0) & (family_sign(family) * (2 * A * d + B) < 0)
    code = RESULTS.where((code == RESULTS.successful) & wrong, RESULTS.other_cycle, code)
    return _make_gait(
        model, x_plus, x_minus, T, E0, iters, res, code, _label(family), "shooting", physical
    )


def _search(model, guess, sign, method, solver="newton", chord=False, axes=None):
    if method == "vhc":
        return vhc_search(model, guess, sign, solver=solver, chord=chord, axes=axes)
    if method == "shooting":
        return shooting_search(
            model, guess, sign, solver="optimistix" if solver == "optimistix" else "newton",
            chord=chord, axes=axes,
        )
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


_search_jit = filter_jit(_search)


def _relabel(gait, family):
    import dataclasses

    return dataclasses.replace(gait, family=family)


def _check(family, method):
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def reference_model(like=None):
    """The default model (thesis Table 1) at 3 degrees, where `reference_guess` holds."""
    from ._compass_gait import CompassGait

    return CompassGait(psi=_REFERENCE_PSI)


def reference_guess(family="stable"):
    """$(a, b)$ of the `family` gait of the default model at 3 degrees (a seed)."""
    return jnp.asarray(_REFERENCE_AB[family])


# ---------------------------------------------------------------------------------------
# Continuation (homotopy in the parameters; sweeps in the slope)
# ---------------------------------------------------------------------------------------
_HOMOTOPY_LEAVES = ("m1", "m2", "mH", "a", "b", "g", "psi")


def _unknowns(gait, method):
    return jnp.stack([gait.a, gait.b]) if method == "vhc" else jnp.stack([gait.a, gait.b, gait.f])


def _residual(model, z, sign, method):
    if method == "vhc":
        return vhc_residual(model, z, sign)
    return _shoot_eval(model, z)[0]


def _tangent(path, s, z, sign, method):
    r"""$dz^*/ds = -(\partial r/\partial z)^{-1}\,\partial r/\partial s$ along `path(s)` (implicit
    differentiation of the residual; one forward-mode Jacobian in $(z, s)$)."""
    k = z.shape[0]
    J = jax.jacfwd(lambda w: _residual(path(w[k]), w[:k], sign, method))(
        jnp.concatenate([z, jnp.asarray(s, z.dtype)[None]])
    )
    t = -jnp.linalg.solve(J[:, :k], J[:, k])
    return jnp.where(jnp.isfinite(t).all(), t, jnp.zeros_like(t))


def _path(start, end):
    r"""$s \mapsto$ model with every physical leaf interpolated geometrically (they are
    positive) from `start` (s = 0) to `end` (s = 1); `s` may leave [0, 1]."""

    def path(s):
        m = end
        for name in _HOMOTOPY_LEAVES:
            p0 = jnp.asarray(getattr(start, name), dtype=float)
            p1 = jnp.asarray(getattr(end, name), dtype=float)
            m = eqx.tree_at(lambda mm: getattr(mm, name), m, p0 * (p1 / p0) ** s)
        return m

    return path


def _continue(start, end, s_buf, n, z0, sign, method):
    """Follow the solution of the model `_path(start, end)(s)` through `s_buf[:n]`
    (a `fori_loop` with a dynamic length over a fixed-size buffer), from the seed `z0` at
    `s_buf[0]`, with a tangent predictor. A failed point does not move the anchor: the
    next one is predicted from the last success.

    **Returns:** a batched `Gait` (one per buffer entry; entries from `n` on are unset)
    and the tangents $dz^*/ds$ (zero where the search failed).
    """
    path = _path(start, end)
    s0 = s_buf[0]
    t0 = _tangent(path, s0, z0, sign, method)
    shape = jax.eval_shape(lambda: _search(path(s0), z0, sign, method))
    buf = jax.tree_util.tree_map(lambda l: jnp.zeros((s_buf.shape[0],) + l.shape, l.dtype), shape)
    tbuf = jnp.zeros((s_buf.shape[0], z0.shape[0]), z0.dtype)

    def body(i, carry):
        s_good, z_good, t_good, buf, tbuf = carry
        s = s_buf[i]
        gait = _search(path(s), z_good + t_good * (s - s_good), sign, method)
        ok = gait.result == RESULTS.successful
        z_new = _unknowns(gait, method)
        t_new = _tangent(path, s, z_new, sign, method)
        ok_t = ok & jnp.any(t_new != 0)
        buf = jax.tree_util.tree_map(lambda b, v: b.at[i].set(v), buf, gait)
        tbuf = tbuf.at[i].set(jnp.where(ok, t_new, 0.0))
        return (
            jnp.where(ok, s, s_good), jnp.where(ok, z_new, z_good),
            jnp.where(ok_t, t_new, t_good), buf, tbuf,
        )

    init = (s0, z0, t0, buf, tbuf)
    _, _, _, buf, tbuf = jax.lax.fori_loop(0, n, body, init)
    return buf, tbuf


_continue_jit = filter_jit(_continue)


def _pow2(n, lo=16):
    return max(lo, 1 << (int(n) - 1).bit_length())


def _run_continuation(start, end, s_values, z0, sign, method):
    """Host wrapper: pad `s_values` to a power of two (fewer recompiles), run, unpad."""
    import numpy as np

    s_values = np.asarray(s_values, dtype=float)
    n = len(s_values)
    s_buf = np.concatenate([s_values, np.full(_pow2(n) - n, s_values[-1])])
    # `n` traced: every length up to the buffer size shares one compilation.
    gaits, tangents = _continue_jit(start, end, jnp.asarray(s_buf), jnp.asarray(n), z0, sign, method)
    return jax.tree_util.tree_map(lambda x: x[:n], gaits), tangents[:n]


_HOMOTOPY_STEPS = 16


def _seed(sign, method):
    ref = reference_model()
    ab = jnp.where(sign < 0, reference_guess("stable"), reference_guess("unstable"))
    # Compiled: op by op, its ~250 small operations each compiled a program of their own
    # (7 s in a fresh process, against 0.7 s as one program).
    return ab if method == "vhc" else complete_guess_jit(ref, ab, sign)


def continue_to_model(model, family="stable", method="vhc", num=_HOMOTOPY_STEPS):
    """The `family` gait of `model` without a guess: homotopy from the default model at
    3 degrees (thesis Table 1, `reference_model`) to `model`, all physical parameters at
    once (geometric interpolation), in `num` steps with a tangent predictor.

    **Returns:** a `Gait` (never raises; check `result`).
    """
    import numpy as np

    _check(family, method)
    sign = family_sign(family)
    gaits, _ = _run_continuation(
        reference_model(), model, np.linspace(0.0, 1.0, num), _seed(sign, method), sign, method
    )
    return _relabel(jax.tree_util.tree_map(lambda x: x[-1], gaits), family)


def find_gait(model, family="stable", method="vhc", guess=None, *, solver="newton", throw=True):
    """Find the periodic gait of `family` on `model`.

    **Arguments:**

    - `model`: a `CompassGait` (any masses, lengths, gravity, slope).
    - `family`: `"stable"` or `"unstable"` (the root of the energy quadratic, 7.3/7.8).
    - `method`: `"vhc"` (Problem 1) or `"shooting"` (Problem 2).
    - `guess`: $(a_0, b_0)$ (or $(a_0, b_0, f_0)$ for shooting). `None`: continue the
      known default-model gait to `model` (homotopy in the parameters).
    - `solver`: VHC only: `"newton"` (default), `"lm"`, `"optimistix"` or `"optax"`.
    - `throw`: raise if no gait was found.

    Differentiable (`jax.grad`, `jax.jacfwd`, ...) with respect to every model parameter:
    exact derivatives by the implicit function theorem at the gait, never through the
    search (`vhcjax._implicit`).

    **Returns:** a `Gait`.
    """
    _check(family, method)
    # Derivatives by the implicit function theorem, never through the search (_implicit).
    params, model = model, detach(model)
    if guess is None:
        gait = continue_to_model(model, family, method)
    else:
        guess = detach(jnp.asarray(guess, dtype=float))
        gait = _search_jit(model, guess, family_sign(family), method, solver)
        gait = _relabel(gait, family)
    gait = with_derivatives(params, gait, method, family_sign(family))
    if throw:
        err = gait.result != RESULTS.successful
        gait = eqx.tree_at(lambda g: g.a, gait, gait.result.error_if(gait.a, err))
    return gait


# ---------------------------------------------------------------------------------------
# Batches
# ---------------------------------------------------------------------------------------
# Members per device of one dispatch. Measured on the 2-core CPU (VHC search, one device):
# 751 / 970 / 1,047 / 1,031 / 1,039 gaits/s at 32 / 64 / 128 / 256 / 512 members, so
# batches run as chunks of 128 per device (also below `_sharding.MAX_DISPATCH`: 1,024
# hung). Smaller batches pad to the next power of two from 8 (at most 2x the work; each
# bucket is one compilation).
_BUCKETS = (1, 8, 16, 32, 64, 128)
_MAX_CHUNK = 128
# Guessed batches of at least this many members per device finish with chord steps.
_CHORD_MIN_MEMBERS = 64
# Batches of at most this many members per host worker are not split over workers (the
# run is short next to its compilation; splitting would compile a second bucket).
_MIN_SPLIT = 8
# Guessed batches of at most this many members per host worker (on one device, outside
# any JAX transformation) are solved one member at a time by the one-member program,
# from the host workers. Measured at B = 10 on the 2-core CPU: it compiles in 3.6-3.7 s
# against 4.6-5.0 s (VHC) and 5.5-5.6 s (shooting) for the batched program, and runs
# 1.6-1.9x slower (0.01-0.03 s more for ten gaits): a small batch is done sooner unless
# the same call is repeated some 50 (VHC) to 150 (shooting) times (`vectorise=True`).
_ONE_BY_ONE = 8
assert _MAX_CHUNK <= MAX_DISPATCH


def _bucket(n):
    for b in _BUCKETS:
        if n <= b:
            return b
    return -(-n // _BUCKETS[-1]) * _BUCKETS[-1]


def _padded_size(B, mesh):
    """Batch size after padding: a bucket per device, times the device count."""
    if B == 1:
        return 1
    k = device_multiple(mesh)
    return _bucket(-(-B // k)) * k


def _chunk_size(B, workers, mesh):
    """Members per dispatch: at most `_MAX_CHUNK` per device, and with several host
    workers (CPU cores, `_sharding.host_workers`) a batch of more than `_MIN_SPLIT` per
    worker is split into one bucket-sized chunk per worker, so that all cores work."""
    k = device_multiple(mesh)
    chunk = _MAX_CHUNK * k
    if workers > 1 and B > _MIN_SPLIT * workers:
        chunk = min(chunk, _bucket(-(-B // (workers * k))) * k)
    return chunk


def _one_by_one(B, workers, mesh, vectorise=None):
    """Whether a guessed batch of `B` is solved member by member (`find_gaits`'s
    `vectorise`; `None`: up to `_ONE_BY_ONE` members per host worker)."""
    if vectorise is None:
        vectorise = B > _ONE_BY_ONE * workers
    return B > 1 and not vectorise and device_multiple(mesh) == 1 and top_level()


def _batched_axes(model):
    return jax.tree_util.tree_map(
        lambda x: 0 if (eqx.is_array(x) and jnp.ndim(x) > 0) else None, model
    )


@filter_jit
def _search_batch(model, guesses, sign, method, solver, axes, chord):
    return _search(model, guesses, sign, method, solver, chord, axes)


@filter_jit
def _search_one(model, guesses, sign, method, solver, chord):
    """`_search` on a batch of one member, unbatched inside."""
    one = jax.tree_util.tree_map(lambda x: x[0] if (eqx.is_array(x) and jnp.ndim(x) > 0) else x, model)
    gait = _search(one, guesses[0], sign, method, solver, chord)
    return jax.tree_util.tree_map(lambda x: x[None], gait)


def _search_stage(model, guesses, sign, method, axes, chord, stage, state=None):
    """One `stage` of the batched Newton search (see `damped_newton_batch`): `"newton"`
    returns the loop state, `"chord"` the gaits (after the chord loop if `chord`),
    `"init"` the initial loop state (for its shapes)."""
    if stage == "chord":
        x0 = state[0]  # shapes only
    elif method == "vhc":
        x0 = guesses
    else:
        x0 = _section_points(model, guesses, sign, axes)
    search = _vhc_newton if method == "vhc" else _shooting_newton
    return search(model, x0, sign, chord=chord, axes=axes, stage=stage, state=state)


def _staged_search(model, guesses, sign, method, axes, chord):
    """`_search_batch` (one device) as two programs compiled concurrently
    (`_compile.compile_pair`): the Newton loop, then the chord loop (with `chord`) and
    the assembly of the gaits. The second is compiled in the background from the loop
    state's shapes (`"init"`: the residual traced, not yet its forward mode) while the
    Newton loop is traced and compiled."""
    first, second = compile_pair(
        ("search", method, chord, signature((model, guesses, sign))),
        lambda m, g, s: _search_stage(m, g, s, method, axes, chord, "newton"),
        lambda m, g, s, state: _search_stage(m, g, s, method, axes, chord, "chord", state),
        lambda m, g, s: _search_stage(m, g, s, method, axes, chord, "init"),
        (model, guesses, sign),
        names=("search_newton_loop", "search_chord_loop_and_gaits"),
    )
    return second(model, guesses, sign, first(model, guesses, sign))


def _from_reference(model, sign, method, num=_HOMOTOPY_STEPS):
    s_buf = jnp.linspace(0.0, 1.0, num)
    gaits, _ = _continue(reference_model(), model, s_buf, num, _seed(sign, method), sign, method)
    return jax.tree_util.tree_map(lambda x: x[-1], gaits)


@filter_jit
def _from_reference_batch(model, sign, method, num, axes):
    return eqx.filter_vmap(lambda m: _from_reference(m, sign, method, num), in_axes=(axes,))(model)


def find_gaits(model, guesses=None, family="stable", method="vhc", *, psi=None, solver="newton",
               mesh=None, chord=None, vectorise=None):
    """Batched `find_gait` over guesses, slopes and model parameters (one Newton loop over
    the batch; other solvers by `vmap`), never raises.

    **Arguments:**

    - `model`: a `CompassGait`; any parameter may be an array with a leading batch axis.
    - `guesses`: `(B, 2)` (or `(B, 3)` for shooting) seeds, or `None` for continuation
      from the reference gait (per member).
    - `family`, `method`, `solver`: as in `find_gait`.
    - `psi`: optional `(B,)` slopes (rad), replacing `model.psi`.
    - `mesh`: a `jax.sharding.Mesh` with a `"batch"` axis; default: all local devices.
    - `chord`: with `guesses`, finish Newton with chord steps (see `vhc_search`).
      `None` (default): where a device holds 64 or more members, the throughput regime; smaller batches
      (latency, where compile time dominates) compile one evaluation fewer. It pays off
      after about 7,000 (VHC) / 9,000 (shooting) gaits per session on a 2-core CPU: a
      one-off batch smaller than that finishes sooner with `chord=False`.
    - `vectorise`: with `guesses`, on one device and outside JAX transformations: `True`
      solves the batch as one vectorised Newton loop, `False` one member at a time by
      the one-member program (below). `None` (default): one member at a time for at most
      8 members per core, vectorised above.

    A small batch with guesses (at most 8 members per core, on one device) is solved one
    member at a time by the program of a batch of one, from a thread per core: for ten
    gaits on a 2-core CPU it compiles in 3.6 s instead of 4.6-5.5 s and runs 0.01-0.03 s
    longer, and each gait is bitwise that of a one-member call. The vectorised loop pays
    off where the same small batch is solved some 50 (VHC) to 150 (shooting) times
    (`vectorise=True`). Larger batches run as one vectorised Newton loop:

    Batches are padded to a few bucket sizes per device (1, 8, 16, 32, 64, 128) with copies of
    the first member, so that new sizes rarely recompile; larger batches run in chunks of
    128 per device (the fastest size measured), all padded to the same program. On a CPU
    the chunks run concurrently, one per core (`_sharding.host_workers`; XLA runs each
    program on one core), and a batch of more than 8 members per core is split into one
    chunk per core. Each padded batch is split over the devices of `mesh` (several GPUs,
    or CPU devices with `XLA_FLAGS=--xla_force_host_platform_device_count=N`). Results do
    not depend on the threads; a different split (another program size) changes them by
    rounding only (3.4e-13 measured), with the same result codes. On one device each
    padded batch is compiled as two programs at once, the Newton loop and the rest
    (`_compile.compile_pair`, kept until `vj.clear_caches()`); inside a JAX
    transformation, as one.

    Differentiable like `find_gait`; a failed member has zero derivatives.

    **Returns:** a `Gait` with a leading batch axis; check `result` per member.
    """
    _check(family, method)
    if psi is not None:
        model = _with_psi(model, jnp.asarray(psi, dtype=float))
    # Derivatives by the implicit function theorem, never through the search (_implicit).
    params, model = model, detach(model)
    if guesses is not None:
        guesses = detach(guesses)
    return with_derivatives(params, _find_gaits(model, guesses, family, method, solver, mesh,
                                                chord, vectorise), method, family_sign(family))


def _find_gaits(model, guesses, family, method, solver, mesh, chord, vectorise):
    sizes = [jnp.shape(x)[0] for x in jax.tree_util.tree_leaves(model) if eqx.is_array(x) and jnp.ndim(x) > 0]
    if guesses is not None:
        guesses = jnp.atleast_2d(jnp.asarray(guesses, dtype=float))
        sizes.append(guesses.shape[0])
    if not sizes:
        raise ValueError("find_gaits needs a batch: guesses, psi or batched model parameters")
    B = max(sizes)
    workers = host_workers(mesh)
    chunk = _chunk_size(B, workers, mesh)
    if guesses is not None and _one_by_one(B, workers, mesh, vectorise):
        chunk = 1
    if chord is None:  # members per device of one dispatch (every chunk: one program)
        chord = _padded_size(min(B, chunk), mesh) // device_multiple(mesh) >= _CHORD_MIN_MEMBERS
    sign = family_sign(family)
    if B <= chunk:
        gaits = _find_chunk(model, guesses, B, _padded_size(B, mesh), sign, method, solver, mesh, chord)
        return _relabel(gaits, family)

    def part(x, i, j):
        if eqx.is_array(x) and jnp.ndim(x) > 0:
            return jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:])[i:j]
        return x

    gaits = in_chunks(
        lambda i, j: _find_chunk(
            jax.tree_util.tree_map(lambda x: part(x, i, j), model),
            None if guesses is None else part(guesses, i, j),
            j - i, chunk, sign, method, solver, mesh, chord,
        ),
        B, chunk, workers,
    )
    return _relabel(gaits, family)


def _find_chunk(model, guesses, B, P, sign, method, solver, mesh, chord):
    """`find_gaits` on one dispatch of `B` members: pad to `P` (a bucket times the device
    count), search, unpad."""
    if P == 1 and guesses is not None:  # one member: no batching to trace or run
        return _search_one(model, guesses, sign, method, solver, bool(chord))

    def pad(x):
        x = jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:])
        x = jnp.concatenate([x, jnp.broadcast_to(x[:1], (P - B,) + x.shape[1:])])
        return shard_batch(x, mesh)

    model = jax.tree_util.tree_map(
        lambda x: pad(x) if (eqx.is_array(x) and jnp.ndim(x) > 0) else x, model
    )
    axes = _batched_axes(model)
    if guesses is None:
        gaits = _from_reference_batch(model, sign, method, _HOMOTOPY_STEPS, axes)
    elif solver == "newton" and device_multiple(mesh) == 1 and top_level():
        gaits = _staged_search(model, pad(guesses), sign, method, axes, bool(chord))
    else:
        gaits = _search_batch(model, pad(guesses), sign, method, solver, axes, bool(chord))
    return jax.tree_util.tree_map(lambda x: x[:B], gaits)


# ---------------------------------------------------------------------------------------
# Sweeps in the slope
# ---------------------------------------------------------------------------------------
class Sweep(eqx.Module):
    """A gait family along a vector of slopes.

    - `psi`: the slopes (rad), as given.
    - `gaits`: a batched `Gait`, one per slope (failed members carry their code).
    - `tangent`: $dz^*/d\\psi$ at each slope where the gait was found (for fold detection).
    """

    psi: jax.Array
    gaits: Gait
    tangent: jax.Array

    @property
    def ok(self):
        return self.gaits.result == RESULTS.successful

    def ends(self):
        """Where the family stops existing or stops being found, as a list of dicts
        `{"slope_deg", "last_slope_deg", "result", "reason"}` (host side)."""
        import numpy as np

        from ._results import result_names

        ok = np.asarray(self.ok)
        names = result_names(self.gaits.result)
        names = [names] if isinstance(names, str) else names
        deg = np.degrees(np.asarray(self.psi))
        tan = np.abs(np.asarray(self.tangent)).max(axis=-1) if ok.any() else None
        out = []
        for i in range(len(ok)):
            if ok[i]:
                continue
            prev = i - 1 if i > 0 and ok[i - 1] else (i + 1 if i + 1 < len(ok) and ok[i + 1] else None)
            if prev is None:
                continue
            reason = {
                "no_real_root": "the energy quadratic (5.13) has no real root for d",
                "singular_phi_ode": "the phi'' ODE becomes singular along the arc",
                "infeasible_uphill": "the solution turned into an uphill (negative-time) one",
            }.get(names[i], names[i])
            if names[i] == "not_converged" and tan is not None and tan[prev] > 50:
                reason = f"fold: |dz*/dpsi| = {tan[prev]:.3g} at the last gait found"
            out.append(
                {"slope_deg": float(deg[i]), "last_slope_deg": float(deg[prev]),
                 "result": names[i], "reason": reason}
            )
        return out


def sweep(model, slopes, family="stable", method="vhc"):
    """The `family` gait along the slopes `slopes` (rad) by continuation.

    Starts at the slope closest to 3 degrees (reached from the reference gait by
    homotopy in the model parameters, so no guess is needed), then follows the family
    up and down the slope vector with a tangent predictor ($dz^*/d\\psi$ by implicit
    differentiation), each direction one jitted loop. Slopes where the family is not
    found keep their failure code; the next slope is predicted from the last success,
    so an isolated failure does not end the sweep. `Sweep.ends()` says where and why
    the family ends. Give the slopes in order (increasing or decreasing).

    **Returns:** a `Sweep` (`tangent` is $dz^*/d\\psi$).
    """
    import numpy as np

    _check(family, method)
    psi = np.asarray(slopes, dtype=float).reshape(-1)
    k = int(np.argmin(np.abs(psi - _REFERENCE_PSI)))
    sign = family_sign(family)
    anchor_model = _with_psi(model, psi[k])
    anchor = continue_to_model(anchor_model, family, method)
    z0 = _unknowns(anchor, method)
    # Slope path psi = psi_k * e^s: s = log(psi / psi_k).
    end = _with_psi(model, psi[k] * math.e)
    up, t_up = _run_continuation(anchor_model, end, np.log(psi[k:] / psi[k]), z0, sign, method)
    parts, tans = [up], [t_up]
    if k > 0:
        down, t_down = _run_continuation(
            anchor_model, end, np.log(psi[k::-1] / psi[k]), z0, sign, method
        )
        rev = jax.tree_util.tree_map(lambda x: x[1:][::-1], down)
        parts, tans = [rev, up], [t_down[1:][::-1], t_up]
    gaits = jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *parts)
    # d/dpsi = (d/ds) / psi on this path.
    tangent = jnp.concatenate(tans) / jnp.asarray(psi)[:, None]
    return Sweep(jnp.asarray(psi), _relabel(gaits, family), tangent)
