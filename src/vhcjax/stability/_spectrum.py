"""Floquet multipliers and spectral radius of a gait, differentiable in the model parameters.

The multipliers are the eigenvalues of $J = \\partial P/\\partial z$, the Jacobian of the
step-to-step map at the gait's section point $z^*$ (forward mode through the heel-strike
event, `_poincare.jacobian`). Their derivative with respect to a parameter $p$ is the
eigenvalue perturbation formula $\\mathrm d\\lambda_i = w_i^H\\,\\mathrm dJ\\,v_i/(w_i^H v_i)$
with the total $\\mathrm dJ = \\partial_z J\\,\\mathrm dz^* + \\partial_p J\\,\\mathrm dp$
(forward over forward mode); $\\mathrm dz^*$ is the implicit derivative that `find_gait`
attaches to the gait. So `jax.grad` of the spectral radius of `find_gait(model(p))` is
exact, without differentiating the search.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from .._results import RESULTS
from ..hybrid import DEFAULT_CONFIG, step_map
from ..hybrid._poincare import _jacobian as jacobian  # wrapped in `linearised` below
from ..solvers import detach, eigenvalues, linearised
from ._multipliers import returns_to


class GaitSpectrum(eqx.Module):
    """Multipliers of a period-1 gait (Poincare map on the post-impact section).

    - `multipliers`: eigenvalues of $J$, complex, sorted by modulus (descending).
    - `spectral_radius`: $\\max_i |\\lambda_i|$; the gait is stable when it is below 1.
    - `jacobian`: $J = \\partial P/\\partial z$ at the gait.
    - `result`: the gait's code where it failed; else `bad_input` for an invalid model
      (a NaN or negative parameter), `not_a_gait` where one step from the gait does
      not return to it (a gait of another model, say); a result other than
      `successful` has zero derivatives.
    """

    multipliers: jax.Array
    spectral_radius: jax.Array
    jacobian: jax.Array
    result: RESULTS


def _step_jacobian(z, model, config):
    return jacobian(model, z, 1, config)


def _spectrum_one(model, gait, config):
    z = model.state_to_section(gait.x_plus)
    # A gait of this model: valid parameters, and one step from it comes back to it.
    valid = model.validate() if hasattr(model, "validate") else jnp.asarray(True)
    back = step_map(detach(model), jax.lax.stop_gradient(z), 1, config)
    periodic = (back.result == RESULTS.successful) & returns_to(model, z, back.z_next)
    code = RESULTS.where(
        ~valid,
        RESULTS.bad_input,
        RESULTS.where(
            gait.result != RESULTS.successful,
            gait.result,
            RESULTS.where(periodic, RESULTS.successful, RESULTS.not_a_gait),
        ),
    )
    ok = code == RESULTS.successful
    J = linearised(_step_jacobian, config)(z, model)
    J = jnp.where(ok, J, jax.lax.stop_gradient(J))
    lam = eigenvalues(J)
    return GaitSpectrum(lam, jnp.abs(lam[0]), J, code)


def gait_spectrum(model, gait, *, config=DEFAULT_CONFIG):
    """The Floquet multipliers and spectral radius of `gait` (from `find_gait` or
    `find_gaits`, on `model`), differentiable with respect to the model parameters.

    **Arguments:**

    - `model`: the model the gait was found on (batched leaves as in `find_gaits`).
    - `gait`: a `Gait`, batched or not.
    - `config`: `SolverConfig` of the step map.

    **Returns:** a `GaitSpectrum` (batched like `gait`). `eig` runs on the CPU.
    """
    if jnp.ndim(gait.a) == 0:
        return _spectrum_one(model, gait, config)
    B = jnp.shape(gait.a)[0]
    axes = jax.tree_util.tree_map(
        lambda x: 0 if (eqx.is_array(x) and jnp.ndim(x) > 0) else None, model
    )
    model = jax.tree_util.tree_map(
        lambda x: (
            jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:])
            if (eqx.is_array(x) and jnp.ndim(x) > 0)
            else x
        ),
        model,
    )
    return eqx.filter_vmap(lambda m, g: _spectrum_one(m, g, config), in_axes=(axes, 0))(model, gait)
