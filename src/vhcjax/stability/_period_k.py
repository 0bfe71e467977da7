"""Period-k gaits: fixed points of $P^k$ (k = 2, 4, ...) with their multipliers, by
autodiff and by finite differences."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._results import RESULTS
from ..hybrid import (
    DEFAULT_CONFIG,
    FAST_CONFIG,
    check_map_steps,
    check_section_shape,
    jacobian,
    simulate,
    step_map,
)
from ..hybrid._simulate import section_units
from ._multipliers import _sort


class PeriodKOrbit(eqx.Module):
    """A fixed point of $P^k$: `z` (its first point), `orbit` (k, 2n-1) the k points,
    `periods` (k,), `multipliers` of $P^k$ (Poincare, and by finite differences),
    `residual`, `result`, `minimal_period` (the smallest j with $P^j(z) = z$)."""

    z: np.ndarray
    orbit: np.ndarray
    periods: np.ndarray
    multipliers: np.ndarray
    multipliers_fd: np.ndarray
    residual: float
    result: RESULTS
    minimal_period: int


def settle(model, z0, num_steps=400, config=FAST_CONFIG):
    """Post-impact section coordinates after `num_steps` steps from `z0` (None if the
    walker fell): a seed for period-k searches on an attractor."""
    sim = simulate(model, model.section_to_state(jnp.asarray(z0, float)), num_steps, config=config)
    if sim.result != RESULTS.successful:
        return None
    return np.asarray(model.state_to_section(sim.steps.x_plus[-1]))


@host_only("`fixed_point(model, z0, k)` and `poincare_multipliers(model, z, k)`")
def period_k_orbit(model, z0, k, config=DEFAULT_CONFIG, *, iterations=20, h=1e-6):
    """Newton on $P^k(z) = z$ from `z0` (e.g. the section point after many steps of
    `simulate` on an attractor), with multipliers of $P^k$ by autodiff and by central
    finite differences.

    $P^k$ and its Jacobian are composed from $k$ one-step maps and one-step Jacobians
    (autodiff through each heel strike): the compiled one-step programs serve every $k$.
    Residuals, the finite-difference step `h` and the test for a shorter period are in
    the walker's own units (angles, and rates times `model.time_scale`).
    Newton stops at a residual below 1e-12 (`successful`), after `iterations`
    (`not_converged`), or at a failed step (its code; `residual` is then `inf`: the
    failed map holds its state, which is no convergence). An invalid model is
    `bad_input`, with zero periods and multipliers (nothing computed); a `k` that is not
    a positive integer, or a `z0` of another shape, is a `ValueError`.
    """
    k = check_map_steps(k)
    check_section_shape(model, jnp.asarray(z0), "z0")
    if not bool(model.validate()):  # an invalid model takes no step: nothing computed
        z = np.asarray(z0, float)
        none = np.zeros(len(z), complex)
        orbit = np.tile(z, (k, 1))
        return PeriodKOrbit(z, orbit, np.zeros(k), none, none, np.inf, RESULTS.bad_input, k)

    def Pk(z, jac):
        J, orbit, periods, code = np.eye(len(z)), [], [], RESULTS.successful
        for _ in range(k):
            orbit.append(z)
            if jac:
                J = np.asarray(jacobian(model, jnp.asarray(z), 1, config)) @ J
            r = step_map(model, jnp.asarray(z), 1, config)
            periods.append(float(r.periods[0]))
            if code == RESULTS.successful:
                code = r.result
            z = np.asarray(r.z_next)
        return z, J, np.stack(orbit), np.asarray(periods), code

    unit = np.asarray(section_units(model))
    z = np.asarray(z0, float)
    for _ in range(iterations):
        zk, J, orbit, periods, code = Pk(z, True)
        res = float(np.max(np.abs(zk - z) / unit))
        if code != RESULTS.successful or not np.isfinite(res) or res < 1e-12:
            break
        z = z - np.linalg.solve(J - np.eye(len(z)), zk - z)
    else:
        zk, J, orbit, periods, code = Pk(z, True)
        res = float(np.max(np.abs(zk - z) / unit))
    if code == RESULTS.successful and not res < 1e-12:
        code = RESULTS.not_converged
    if code != RESULTS.successful and not code == RESULTS.not_converged:
        res = float("inf")
    eye = np.eye(len(z))
    Jfd = np.stack(
        [
            (Pk(z + h * u * e, False)[0] - Pk(z - h * u * e, False)[0]) / (2 * h * u)
            for e, u in zip(eye, unit)
        ],
        axis=1,
    )
    minimal = k
    for j in range(1, k):
        if k % j == 0 and np.max(np.abs(orbit[j] - orbit[0]) / unit) < 1e-7:
            minimal = j
            break
    return PeriodKOrbit(
        z,
        orbit,
        periods,
        np.asarray(_sort(jnp.linalg.eigvals(J))),
        np.asarray(_sort(jnp.linalg.eigvals(Jfd))),
        res,
        code,
        minimal,
    )
