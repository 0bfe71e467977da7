"""The `Gait` pytree: one periodic gait (thesis (5.2)) and the quantities derived from it."""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._results import RESULTS
from ..hybrid import SolverConfig

FAMILIES = ("stable", "unstable")
#: `"auto"`: the VHC search where it applies and succeeds, shooting wherever it fails.
METHODS = ("auto", "vhc", "shooting")

#: Settings of the $\phi''$ integration (smooth, no events: an 8th-order method).
VHC_CONFIG = SolverConfig(rtol=1e-12, atol=1e-12, max_steps=512, solver="dopri8")

#: A gait is accepted when the max-norm of its residual is below this, or (`accepted`)
#: when Newton's estimate of the error of its unknowns is below `ERROR_TOL`.
SUCCESS_TOL = 1e-9
#: Bound on Newton's error estimate $\|J^{-1}r\|_\infty$ (rad, rad/s) of an accepted
#: gait whose residual is above `SUCCESS_TOL` (`accepted`).
ERROR_TOL = 1e-10
#: ... and the residual such a gait may keep.
_NOISY_RESIDUAL = 1e-8

#: Loosest integration tolerance of the inexact Newton iterations (`damped_newton`).
_LOOSE_TOL = 1e-6
#: Residual below which Newton keeps its Jacobian and evaluates the residual alone.
_CHORD_BELOW = 1e-3
#: The Newton-step convergence test of the searches also needs a residual below this.
_RESIDUAL_CAP = SUCCESS_TOL / 10


def accepted(residual, error):
    """Whether a search ends at a gait: its residual (max-norm) is below `SUCCESS_TOL`, or
    Newton's estimate of the error of its unknowns, $\\|J^{-1}r\\|_\\infty$, is below
    `ERROR_TOL` with a residual below 1e-8. The second admits problems whose residual
    cannot be evaluated to `SUCCESS_TOL` (in the unknowns $(a, b)$ a heavy hip's rounded
    to a few 1e-9; none is known since the VHC search runs in $(a, h)$)."""
    return (residual < SUCCESS_TOL) | ((error < ERROR_TOL) & (residual < _NOISY_RESIDUAL))


class Gait(eqx.Module):
    """A periodic gait (one step, symmetric), thesis (5.2).

    - `a, b, e, f`: post-impact $q_1, \\dot q_1, q_2, \\dot q_2$.
    - `c, d, g, h`: pre-impact $q_1, \\dot q_1, q_2, \\dot q_2$.
    - `T`: step period (s); `E0`: energy along the step (J, zero with both legs vertical
      and at rest, thesis 5.10).
    - `x_plus`, `x_minus`: post- and pre-impact states $[q, \\dot q]$.
    - `step_length`: distance between the feet at heel strike (m); `speed`: step length
      over period (m/s); `energy_loss`: kinetic energy lost in the impact (J).
    - `iterations`, `residual`: of the search (max-norm of the final residual, in the
      walker's own units: angles and velocities times `scales()["time"]`).
    - `shooting`: boolean, found by shooting (Problem 2) rather than by the VHC search
      (per member in a batch; `found_by` names it).
    - `result`: a `RESULTS` code.
    - `family`, `method`: static labels, the family and method asked for (`"auto"`,
      `"vhc"`, `"shooting"`): two calls with the same arguments give pytrees of one
      structure; `found_by` says which method found each gait.
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
    shooting: jax.Array
    result: RESULTS
    family: str = eqx.field(static=True, default="stable")
    method: str = eqx.field(static=True, default="vhc")

    @property
    def z(self):
        """Section coordinates $(q_1, \\dot q_1, \\dot q_2)$ of the post-impact state."""
        return jnp.stack([self.a, self.b, self.f], axis=-1)

    @property
    def found_by(self):
        """`"vhc"` or `"shooting"`: the method that found the gait (host side; a list for
        a batch)."""
        import numpy as np

        by = np.where(np.asarray(self.shooting), "shooting", "vhc")
        return str(by) if by.ndim == 0 else by.tolist()

    def params(self):
        """`{"a": ..., ..., "h": ..., "T": ..., "E0": ...}` (arrays)."""
        return {k: getattr(self, k) for k in ("a", "b", "c", "d", "e", "f", "g", "h", "T", "E0")}


def family_sign(family):
    """The sign in front of the square root of (5.13): `"stable"` -> -1 (thesis selector
    2, 7.3), `"unstable"` -> +1 (selector 1, 7.8). Arrays pass through (traced signs let
    both families share one compiled function)."""
    if isinstance(family, str):
        if family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
        return jnp.asarray(-1.0 if family == "stable" else 1.0)
    return jnp.asarray(family, dtype=float)


def _derived(model, x_plus, x_minus, T):
    n = model.n_dof
    step_length = jnp.linalg.norm(model.contact_point(x_minus[:n]))
    speed = step_length / T
    # The potential energy is continuous through the impact: the loss is kinetic.
    ke = lambda x: model.kinetic_energy(x[:n], x[n:])  # noqa: E731
    return step_length, speed, ke(x_minus) - ke(x_plus)


def _make_gait(
    model, x_plus, x_minus, T, E0, iterations, residual, code, family, method, physical=None
):
    """The `Gait`; `physical`: whether the impact at `x_minus` pushes the foot away from the
    ground (`None`: computed here)."""
    n = model.n_dof
    step_length, speed, loss = _derived(model, x_plus, x_minus, T)
    if physical is None:
        _, _, physical = model.impact(x_minus)
    # A periodic solution walking uphill in negative time (thesis 7.17-7.18).
    uphill = (x_plus[n] > 0) | (T < 0)
    code = RESULTS.where((code == RESULTS.successful) & uphill, RESULTS.infeasible_uphill, code)
    code = RESULTS.where((code == RESULTS.successful) & ~physical, RESULTS.bad_impact, code)
    code = RESULTS.where(model.validate(), code, RESULTS.bad_input)
    return Gait(
        a=x_plus[0],
        b=x_plus[n],
        c=x_minus[0],
        d=x_minus[n],
        e=x_plus[1],
        f=x_plus[n + 1],
        g=x_minus[1],
        h=x_minus[n + 1],
        T=T,
        E0=E0,
        x_plus=x_plus,
        x_minus=x_minus,
        step_length=step_length,
        speed=speed,
        energy_loss=loss,
        iterations=jnp.asarray(iterations),
        residual=residual,
        shooting=jnp.asarray(method == "shooting"),
        result=code,
        family=family,
        method=method,
    )


def section_in_units(model, z, factor):
    """Section point `z` of `model` with its velocities multiplied by `factor` (angles
    unchanged): `factor = model.scales()["time"]` takes it to the walker's own units
    (`in_own_units`), its inverse back."""
    n = model.n_dof
    x = model.section_to_state(z)
    return model.state_to_section(x * jnp.concatenate([jnp.ones(n), jnp.full(n, factor)]))


def gait_in_units(gait, model):
    """`gait`, found on `model.in_own_units()`, in the units of `model`: the same angles,
    velocities divided by the time unit, the period times it; energies, step length and
    speed computed on `model`. Codes, iterations and the (dimensionless) residual are
    kept. One gait (`vmap` it for a batch)."""
    ts = model.scales()["time"]
    n = model.n_dof
    v = jnp.concatenate([jnp.ones(n), jnp.full(n, 1.0 / ts)])
    x_plus, x_minus = gait.x_plus * v, gait.x_minus * v
    out = _make_gait(
        model,
        x_plus,
        x_minus,
        gait.T * ts,
        model.energy(x_plus),
        gait.iterations,
        gait.residual,
        gait.result,
        gait.family,
        gait.method,
        jnp.asarray(True),  # the impact was checked in the search
    )
    return eqx.tree_at(lambda g: g.shooting, out, gait.shooting)


def _label(family):
    return family if isinstance(family, str) else ""
