"""Speed of contraction to a gait: spectral radius of the step map, and what it means in
steps, predicted from the Floquet multipliers and measured from simulated recoveries.

Near a gait $z^*$ the step map is $z_{k+1} - z^* \\approx J (z_k - z^*)$, so errors shrink
asymptotically like $\\rho^k$ with $\\rho$ the spectral radius of $J = \\partial P/\\partial z$
(largest multiplier modulus). The number of steps that shrinks an error by a factor 10 is
$\\log 0.1 / \\log \\rho$. The measurement fits the decay rate of many simulated recoveries
from small random perturbations (least squares on $\\log \\|z_k - z^*\\|$), independently of
the Jacobian.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._programs import stored_jit
from .._results import result_names
from ..gait import section_in_units
from ..hybrid import DEFAULT_CONFIG, step_map
from ._gait_check import check_returns
from ._recovery import FELL, recover


class Contraction(eqx.Module):
    """Contraction to a gait.

    - `multipliers`: eigenvalues of the step-map Jacobian (complex), by modulus, descending.
    - `spectral_radius`: $\\rho = \\max |\\lambda|$.
    - `steps_10x`, `steps_100x`: $\\log 0.1/\\log\\rho$ and $\\log 0.01/\\log\\rho$ (predicted).
    - `measured_rate`: median over the recoveries of the fitted per-step decay factor.
    - `measured_rates`: the fitted factor of every recovery; NaN for a walker that fell
      or whose error grew tenfold (it left the gait's neighbourhood), so `measured_rate`
      is NaN where none stayed, as near an unstable gait.
    - `measured_steps_10x`, `measured_steps_100x`: median over recoveries of the first step
      at which the error is below 1/10 (1/100) of the initial error (NaN where none is).
    - `distance`: $\\|x_k - x^*\\|_\\infty$ (own units, as `Recovery.distance`) per recovery and step, shape `(batch, steps+1)`.
    - `fit_window`: the steps `(k0, k1)` used in the fit.
    """

    multipliers: jax.Array
    spectral_radius: jax.Array
    steps_10x: jax.Array
    steps_100x: jax.Array
    measured_rate: jax.Array
    measured_rates: jax.Array
    measured_steps_10x: jax.Array
    measured_steps_100x: jax.Array
    distance: jax.Array
    fit_window: tuple[int, int] = eqx.field(static=True)


def steps_to_shrink(rho, factor):
    """Steps for an error to shrink by `factor` (e.g. 10) at rate `rho`:
    $\\log(1/\\text{factor})/\\log\\rho$ (inf if $\\rho \\ge 1$)."""
    rho = jnp.asarray(rho)
    return jnp.where(rho < 1, jnp.log(1.0 / factor) / jnp.log(jnp.minimum(rho, 1 - 1e-16)), jnp.inf)


def _fit_rate(dist, k0, k1):
    """Least-squares slope of log(dist[k]) over k0..k1 -> per-step factor."""
    k = np.arange(k0, k1 + 1)
    y = np.log(np.asarray(dist)[:, k0 : k1 + 1])
    A = np.stack([k, np.ones_like(k)], axis=1).astype(float)
    coef, *_ = np.linalg.lstsq(A, y.T, rcond=None)
    return np.exp(coef[0])


def _first_below(dist, factor):
    d = np.asarray(dist)
    below = d[:, 1:] < d[:, :1] / factor
    return np.where(below.any(axis=1), below.argmax(axis=1) + 1, -1)


@host_only("`gait_multipliers` (its spectral radius is the predicted rate)")
def contraction(
    model,
    z_star,
    *,
    num_perturbations=32,
    scale=1e-3,
    num_steps=30,
    fit_window=(6, 30),
    key=None,
    config=DEFAULT_CONFIG,
):
    """Predicted and measured speed of contraction to the gait through `z_star`.

    **Arguments:**

    - `model`: a `WalkerModel`.
    - `z_star`: section coordinates of a (stable) gait.
    - `num_perturbations`: number of simulated recoveries.
    - `scale`: size ($\\infty$-norm) of the random initial perturbations in the walker's
      own units (rad, and velocities times `model.time_scale`), small enough for the linearization to hold.
    - `num_steps`: steps simulated per recovery, more than `fit_window[0]`.
    - `fit_window`: steps `(k0, k1)` over which the decay rate is fitted (after the
      transient of the fast modes, before the solver's error floor); `k1` is clipped to
      `num_steps`.
    - `key`: a `jax.random.PRNGKey` (default `PRNGKey(0)`).
    - `config`: `SolverConfig` (default tolerances 1e-10: the fit needs errors down to
      ~1e-9 resolved).

    **Returns:** a `Contraction`. Host-side (calls `numpy` for the fit); not jittable.
    A `z_star` that one step does not return to (`GAIT_TOL`) raises a `ValueError`.
    """
    k0, k1 = (int(k) for k in fit_window)
    k1 = min(k1, int(num_steps))
    if not 0 <= k0 < k1:
        raise ValueError(
            f"contraction: the fit needs steps k0 < k1 <= num_steps, got fit_window="
            f"{tuple(fit_window)} and num_steps={num_steps}"
        )
    if int(num_perturbations) < 1:
        raise ValueError(f"contraction: num_perturbations must be >= 1, got {num_perturbations}")
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"contraction: scale must be positive and finite, got {scale}")
    z_star = jnp.asarray(z_star, dtype=float)
    key = jax.random.PRNGKey(0) if key is None else key
    J, mr = _jacobian_and_step(model, z_star, config)
    check_returns(model, z_star, mr.z_next, "contraction", str(result_names(mr.result)))
    ev = np.linalg.eigvals(np.asarray(J)).astype(complex)  # complex even when all are real
    ev = ev[np.argsort(-np.abs(ev))]
    rho = float(np.abs(ev[0]))
    dz = jax.random.uniform(key, (num_perturbations, z_star.shape[0]), minval=-1.0, maxval=1.0)
    dz = scale * dz / jnp.max(jnp.abs(dz), axis=1, keepdims=True)
    # Perturbations in the walker's own units (velocities times the time scale), as the
    # distances of `recover`: a rescaled walker gets the same perturbations.
    ts = model.time_scale
    z_own = section_in_units(model, z_star, ts)
    z0 = jax.vmap(lambda d: section_in_units(model, z_own + d, 1.0 / ts))(dz)
    x0 = jax.vmap(model.section_to_state)(z0)
    x_star = model.section_to_state(z_star)
    # tol=0: nobody "converges", every recovery runs all steps (a full error history).
    rec = recover(model, x0, x_star, num_steps, tol=0.0, config=config, stop_when_converged=False)
    # A walker that fell, or whose error grew tenfold (it left the neighbourhood where the
    # linearization holds, e.g. for another gait), measures no decay rate.
    dist = np.asarray(rec.distance)
    up = (np.asarray(rec.label) != FELL) & (np.max(dist, axis=1) <= 10 * dist[:, 0])
    rates = np.where(up, _fit_rate(rec.distance, k0, k1), np.nan)
    m10 = np.where(up, _first_below(rec.distance, 10.0), -1)
    m100 = np.where(up, _first_below(rec.distance, 100.0), -1)
    return Contraction(
        multipliers=jnp.asarray(ev),
        spectral_radius=jnp.asarray(rho),
        steps_10x=steps_to_shrink(rho, 10.0),
        steps_100x=steps_to_shrink(rho, 100.0),
        measured_rate=jnp.asarray(np.median(rates[up]) if up.any() else np.nan),
        measured_rates=jnp.asarray(rates),
        measured_steps_10x=jnp.asarray(np.median(m10[m10 > 0]) if np.any(m10 > 0) else np.nan),
        measured_steps_100x=jnp.asarray(np.median(m100[m100 > 0]) if np.any(m100 > 0) else np.nan),
        distance=rec.distance,
        fit_window=(k0, k1),
    )


@stored_jit
def _jacobian_and_step(model, z, config):
    """The step map's Jacobian at `z` and, from the same pass, the step itself."""

    def one_step(zz):
        mr = step_map(model, zz, 1, config)
        return mr.z_next, mr

    return jax.jacfwd(one_step, has_aux=True)(z)
