"""Virtual holonomic constraints $q = \\Phi(\\theta) = (\\theta, \\phi(\\theta))$, derived generically.

For a model with $n$ DOF, $\\theta = q_1$ and $\\phi: \\mathbb R \\to \\mathbb R^{n-1}$. With
$\\Phi' = (1, \\phi')$, $\\Phi'' = (0, \\phi'')$ the equations of motion along the constraint
read (thesis 2.48-2.50, 4.4-4.6)

$$\\alpha(\\theta)\\ddot\\theta + \\beta(\\theta)\\dot\\theta^2 + \\gamma(\\theta) = 0, \\quad
\\alpha = M\\Phi',\\ \\beta = M\\Phi'' + C(\\Phi, \\Phi')\\Phi',\\ \\gamma = G(\\Phi)$$

($n$ equations). The energy along the constraint is (4.8, 5.10)
$E = \\tfrac12 M_\\theta \\dot\\theta^2 + P(\\Phi)$ with $M_\\theta = \\Phi'^T M \\Phi'$, which is the
combination of the $n$ equations with the weights $\\mu = \\Phi'$ (thesis 4.24).

The ODE for $\\phi''$ (thesis 5.19) follows without any hand expansion: with
$\\dot\\theta^2 = 2(E_0 - P(\\Phi))/M_\\theta$ (5.18), the equations of motion are linear in
$(\\ddot\\theta, \\phi'')$:
$$[M\\Phi' \\;\\; M_{:,2:}\\dot\\theta^2] (\\ddot\\theta, \\phi'') = -\\dot\\theta^2 C(\\Phi,\\Phi')\\Phi'
- G(\\Phi).$$
"""

import jax
import jax.numpy as jnp

from .. import mechanics as mech


def constraint(theta, phi, dphi):
    """$\\Phi(\\theta)$ and $\\Phi'(\\theta)$ from $\\theta$ and $(\\phi, \\phi')$ (arrays of n-1)."""
    theta = jnp.asarray(theta)
    q = jnp.concatenate([theta[None], jnp.atleast_1d(phi)])
    dq_dtheta = jnp.concatenate([jnp.ones((1,), q.dtype), jnp.atleast_1d(dphi)])
    return q, dq_dtheta


def reduced_coefficients(model, theta, phi, dphi, ddphi):
    """$(\\alpha, \\beta, \\gamma)$ of the n reduced equations (thesis 2.50; 4.6 for n = 2).

    Each is an array of length n: row i is equation i of the equations of motion with
    the constraint substituted.
    """
    q, dPhi = constraint(theta, phi, dphi)
    ddPhi = jnp.concatenate([jnp.zeros((1,), q.dtype), jnp.atleast_1d(ddphi)])
    M = mech.mass_matrix(model, q)
    alpha = M @ dPhi
    beta = M @ ddPhi + mech.coriolis_product(model, q, dPhi)
    gamma = mech.gravity_vector(model, q)
    return alpha, beta, gamma


def reduced_mass(model, theta, phi, dphi):
    """$M_\\theta = \\Phi'^T M(\\Phi) \\Phi'$, so that $K = \\tfrac12 M_\\theta\\dot\\theta^2$ (4.22)."""
    q, dPhi = constraint(theta, phi, dphi)
    return dPhi @ mech.mass_matrix(model, q) @ dPhi


def reduced_energy(model, theta, dtheta, phi, dphi):
    """Energy along the constraint, thesis (5.10): $\\tfrac12 M_\\theta\\dot\\theta^2 + P(\\Phi)$."""
    q, _ = constraint(theta, phi, dphi)
    return 0.5 * reduced_mass(model, theta, phi, dphi) * dtheta**2 + model.potential_energy(q)


def _theta_dot_squared(model, E0, q, M_theta):
    return 2.0 * (E0 - model.potential_energy(q)) / M_theta


def _linear_system(model, E0, q, dPhi):
    r"""$A$ of the equations of motion, linear in $(\ddot\theta, \phi'')$ once
    $\dot\theta^2$ comes from the energy (5.18); also $M$ and $\dot\theta^2$."""
    M = mech.mass_matrix(model, q)
    M_dPhi = M @ dPhi
    dtheta_sq = _theta_dot_squared(model, E0, q, dPhi @ M_dPhi)  # (5.18), M computed once
    A = jnp.concatenate([M_dPhi[:, None], M[:, 1:] * dtheta_sq], axis=1)
    return A, dtheta_sq


def phi_second_derivative(model, E0, theta, phi, dphi):
    r"""$\phi''(\theta)$ (thesis 5.19), by solving the equations of motion.

    **Returns:** `(ddphi, ddtheta, dtheta_sq, det)`: the constraint curvature (n-1), the
    acceleration $\ddot\theta$, $\dot\theta^2$ from the energy, and the determinant of the
    linear system (zero where the ODE is singular).
    """
    q, dPhi = constraint(theta, phi, dphi)
    A, dtheta_sq = _linear_system(model, E0, q, dPhi)
    rhs = -dtheta_sq * mech.coriolis_product(model, q, dPhi) - mech.gravity_vector(model, q)
    sol = mech.solve_small(A, rhs)
    return sol[1:], sol[0], dtheta_sq, mech.det_small(A)


def singularity_terms(model, E0, theta, phi, dphi):
    r"""$(\dot\theta^2, \det A / \prod_j \|A_{:,j}\|)$ of `phi_second_derivative`
    without the forces: where the ODE (5.19) is singular ($\dot\theta^2 \le 0$ or
    $\det A = 0$). The determinant is taken relative to the product of the column norms
    (Hadamard's bound, so it lies in [-1, 1]): unit-free, the same for a walker and its
    scaled copy. Inputs are `stop_gradient`-ed: a check, not part of any derivative."""
    E0, theta, phi, dphi = jax.lax.stop_gradient((E0, theta, phi, dphi))
    A, dtheta_sq = _linear_system(model, E0, *constraint(theta, phi, dphi))
    scale = jnp.prod(jnp.sqrt(jnp.sum(A * A, axis=0)))
    return dtheta_sq, mech.det_small(A) / jnp.where(scale > 0, scale, 1.0)


def theta_dynamics_coefficients(model, theta, phi, dphi):
    """Scalar reduced dynamics $\\alpha_0\\ddot\\theta + \\beta_0\\dot\\theta^2 + \\gamma_0 = 0$ free of $\\phi''$.

    Weights $w = e_1^T M(\\Phi)^{-1}$ eliminate $\\phi''$ (for n = 2 they are the thesis
    weights (6.9) divided by $\\det M$, which gives (6.11) divided by $\\alpha_0 = \\det M$):
    $\\alpha_0 = 1$, $\\beta_0 = w\\,C(\\Phi,\\Phi')\\Phi'$, $\\gamma_0 = w\\,G(\\Phi)$.
    """
    q, dPhi = constraint(theta, phi, dphi)
    M = mech.mass_matrix(model, q)
    w = jnp.linalg.solve(M.T, jnp.eye(q.shape[0], dtype=q.dtype)[0])
    beta0 = w @ mech.coriolis_product(model, q, dPhi)
    gamma0 = w @ mech.gravity_vector(model, q)
    return jnp.ones_like(beta0), beta0, gamma0
