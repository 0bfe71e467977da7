"""Sensitivity of a gait to the slope: derivatives of the fixed point, step period, speed
and Floquet multipliers with respect to $\\psi$, by implicit differentiation through the
fixed-point equation.

With $z^*(\\psi)$ defined by $P(z^*, \\psi) = z^*$, the implicit function theorem gives
$\\mathrm d z^*/\\mathrm d\\psi = (I - J)^{-1}\\,\\partial P/\\partial\\psi$ with
$J = \\partial P/\\partial z$; both partial derivatives are forward-mode autodiff through
the heel-strike event. Period and step length are functions of $(z, \\psi)$ differentiated
the same way (total derivative). The multipliers' derivatives use the eigenvalue
perturbation formula $\\mathrm d\\lambda_i = w_i^H\\,\\mathrm dJ\\,v_i / (w_i^H v_i)$ with
$\\mathrm dJ$ the directional derivative of the Jacobian along $(\\mathrm dz^*, 1)$
(forward over forward, one trace). Finite differences of re-solved gaits check all of it in the tests.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._programs import stored_jit
from ..hybrid import DEFAULT_CONFIG
from ..solvers import implicit_outputs, linearised
from ._gait_check import require_gait


@stored_jit
def gait_outputs(model, z, config=DEFAULT_CONFIG):
    """$(P(z), T, L, v)$: next section point, step period (s), step length (m, foot to foot
    at heel strike) and mean speed $L/T$ (m/s, along the slope) of one step from `z`."""
    from ..hybrid import step_unchecked

    x0 = model.section_to_state(z)
    sr = step_unchecked(model, x0, config)
    L = jnp.linalg.norm(model.contact_point(sr.x_minus[: model.n_dof]))
    return model.state_to_section(sr.x_plus), sr.period, L, L / sr.period


class SlopeSensitivity(eqx.Module):
    """Values at the gait and their derivatives with respect to the slope $\\psi$ (per rad).

    - `z`, `dz`: fixed point (section coordinates) and $\\mathrm dz^*/\\mathrm d\\psi$.
    - `period`, `dperiod`: step period (s) and its derivative.
    - `step_length`, `dstep_length`: step length (m).
    - `speed`, `dspeed`: mean speed (m/s).
    - `multipliers`, `dmultipliers`: Floquet multipliers (complex, by modulus) and their
      derivatives; `dmodulus`: derivatives of their moduli.
    - `jacobian`, `djacobian`: $J$ and $\\mathrm dJ/\\mathrm d\\psi$ (total).
    """

    z: jax.Array
    dz: jax.Array
    period: jax.Array
    dperiod: jax.Array
    step_length: jax.Array
    dstep_length: jax.Array
    speed: jax.Array
    dspeed: jax.Array
    multipliers: np.ndarray
    dmultipliers: np.ndarray
    dmodulus: np.ndarray
    jacobian: jax.Array
    djacobian: jax.Array


def _fixed_point_fn(z, model, config):
    """Residual $P(z) - z$ of the step map and the outputs $(P(z), T, L, v)$."""
    out = gait_outputs(model, z, config)
    return out[0] - z, out


def _step_jacobian(z, model, config):
    return jax.jacfwd(lambda zz: gait_outputs(model, zz, config)[0])(z)


def _implicit(model, z, config):
    # The general mechanism (`_implicit`): the fixed point and its outputs carry
    # implicit-function-theorem tangents, the step-map Jacobian its forward-over-forward
    # one; one `jax.jvp` along the slope gives every total derivative.
    values = gait_outputs(model, z, config)

    def along(psi):
        m = model.with_slope(psi)
        zz, outs = implicit_outputs(_fixed_point_fn, z, m, values, True, static=(config,))
        return zz, outs, linearised(_step_jacobian, config)(zz, m)

    psi = jnp.asarray(model.psi, dtype=float)
    (_, outs, J), (dz, douts, dJ) = jax.jvp(along, (psi,), (jnp.ones_like(psi),))
    return outs, dz, douts[1:], J, dJ


@host_only("`jax.jacfwd` of `find_gait` with respect to the slope")
def slope_sensitivity(model, z_star, *, config=DEFAULT_CONFIG):
    """Derivatives with respect to the slope of the gait through `z_star` (a fixed point
    of the step map of `model`, e.g. from `vhcjax.fixed_point`).

    **Returns:** a `SlopeSensitivity`. The eigen-decomposition runs on the host (numpy).
    A `z_star` that one step does not return to (`GAIT_TOL`) raises a `ValueError`.
    """
    require_gait(model, z_star, "slope_sensitivity")
    z = jnp.asarray(z_star, dtype=float)
    (zn, T, L, v), dz, (dT, dL, dv), J, dJ = _implicit(model, z, config)
    lam, dlam, dmod = eigenvalue_derivatives(np.asarray(J), np.asarray(dJ))
    return SlopeSensitivity(z, dz, T, dT, L, dL, v, dv, lam, dlam, dmod, J, dJ)


def eigenvalue_derivatives(J, dJ):
    """Eigenvalues of `J` by modulus (descending, complex even when all are real), their
    derivatives along `dJ` ($\\dot\\lambda_i = w_i \\dot J v_i$ with left eigenvectors
    $W = V^{-1}$) and the derivatives of their moduli. Host-side (numpy)."""
    lam, V = (x.astype(complex) for x in np.linalg.eig(J))
    order = np.argsort(-np.abs(lam))
    lam, V = lam[order], V[:, order]
    W = np.linalg.inv(V)  # rows: left eigenvectors with W V = I
    dlam = np.einsum("ij,jk,ki->i", W, dJ, V)
    dmod = np.real(np.conj(lam) * dlam) / np.abs(lam)
    return lam, dlam, dmod
