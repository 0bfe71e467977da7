"""Generic Lagrangian mechanics by automatic differentiation, for any number of DOF.

A model supplies its kinetic energy $K(q, \\dot q, \\dot z)$ (with $\\dot z$ the velocity
of the stance foot, zero while it is pinned), its potential energy $P(q)$ and the position
of the impacting contact point; everything else is derived here:

- mass matrix $M(q) = \\partial^2 K / \\partial \\dot q^2$ (thesis 2.9, 3.8);
- Coriolis/centrifugal matrix $C(q, \\dot q)$ from the Christoffel symbols (2.10, 3.9);
- gravity vector $G(q) = \\partial P / \\partial q$ (2.11, 3.10);
- forward dynamics $\\ddot q = -M^{-1}(C \\dot q + G)$ (3.7);
- the impact map by the augmented (impulsive) method (3.19)-(3.28): extended
  coordinates $x = (q, z)$, $M_x(\\dot x^+ - \\dot x^-) = E^T F$, $E \\dot x^+ = 0$.

No hand-expanded expressions: the thesis closed forms are test oracles only.
"""

import jax
import jax.numpy as jnp


def mass_matrix(model, q):
    """$M(q)$: the Hessian of the kinetic energy in $\\dot q$ (exact: $K$ is quadratic)."""
    n = q.shape[0]
    zeros = jnp.zeros(n, q.dtype)
    return jax.hessian(lambda dq: model.kinetic_energy(q, dq))(zeros)


def extended_mass_matrix(model, q):
    """$M_x(q)$ of thesis (3.22): Hessian of $K$ in $(\\dot q, \\dot z)$, stance foot free."""
    n = q.shape[0]
    zeros = jnp.zeros(n + 2, q.dtype)
    return jax.hessian(lambda v: model.kinetic_energy(q, v[:n], v[n:]))(zeros)


def gravity_vector(model, q):
    """$G(q) = \\partial P/\\partial q$ (thesis 2.11)."""
    return jax.grad(model.potential_energy)(q)


def coriolis_matrix(model, q, dq):
    """$C(q, \\dot q)$ with Christoffel symbols of the first kind (thesis 2.10).

    $C_{kj} = \\sum_i \\tfrac12(\\partial_i M_{kj} + \\partial_j M_{ki} - \\partial_k M_{ij})
    \\dot q_i$, so that $\\dot M - 2C$ is skew-symmetric.
    """
    dM = jax.jacfwd(lambda qq: mass_matrix(model, qq))(q)  # dM[k, j, i] = d M_kj / d q_i
    term1 = jnp.einsum("kji,i->kj", dM, dq)
    term2 = jnp.einsum("kij,i->kj", dM, dq)
    term3 = jnp.einsum("ijk,i->kj", dM, dq)
    return 0.5 * (term1 + term2 - term3)


def coriolis_product(model, q, dq):
    """$C(q,\\dot q)\\dot q$ computed without forming $C$ (no gravity).

    $C\\dot q = \\dot M \\dot q - \\tfrac12 \\partial_q(\\dot q^T M \\dot q)$, with both terms by
    forward/reverse autodiff of the kinetic energy.
    """

    def momentum(qq):
        return jax.grad(lambda v: model.kinetic_energy(qq, v))(dq)

    _, mdot_dq = jax.jvp(momentum, (q,), (dq,))
    dK_dq = jax.grad(lambda qq: model.kinetic_energy(qq, dq))(q)
    return mdot_dq - dK_dq


def bias_forces(model, q, dq):
    """$C(q,\\dot q)\\dot q + G(q)$ (thesis 3.7), without forming $C$."""
    return coriolis_product(model, q, dq) + gravity_vector(model, q)


def solve_small(A, b):
    """$A^{-1} b$; for 2x2 systems by the explicit inverse, else `jnp.linalg.solve`.

    Under `vmap` on CPU a batched LU of tiny matrices costs more than the rest of the
    vector field together; the 2x2 formula is exact to rounding for the (symmetric
    positive definite, well-conditioned) mass matrices met here.
    """
    if A.shape == (2, 2) and b.shape == (2,):
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        return jnp.stack([A[1, 1] * b[0] - A[0, 1] * b[1], A[0, 0] * b[1] - A[1, 0] * b[0]]) / det
    return jnp.linalg.solve(A, b)


def det_small(A):
    """$\\det A$; for 2x2 by the explicit formula (see `solve_small`), else `jnp.linalg.det`."""
    if A.shape == (2, 2):
        return A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    return jnp.linalg.det(A)


def acceleration(model, q, dq, generalized_force=None):
    """Forward dynamics $\\ddot q = M^{-1}(\\tau - C\\dot q - G)$ (thesis 3.7)."""
    rhs = -bias_forces(model, q, dq)
    if generalized_force is not None:
        rhs = rhs + generalized_force
    return solve_small(mass_matrix(model, q), rhs)


def energy(model, q, dq):
    """Total mechanical energy $K + P$ (thesis 4.7)."""
    return model.kinetic_energy(q, dq) + model.potential_energy(q)


def contact_jacobian(model, q):
    """$E = \\partial \\Upsilon / \\partial (q, z)$ of thesis (3.25), shape (2, n+2)."""
    Jq = jax.jacfwd(model.contact_point)(q)
    return jnp.concatenate([Jq, jnp.eye(2, dtype=q.dtype)], axis=1)


def augmented_impact(model, q, dq_minus):
    """Plastic impact of the contact point by the augmented method (thesis 3.27-3.28).

    Solves
    $\\begin{bmatrix} M_x & -E^T \\\\ E & 0 \\end{bmatrix}
    \\begin{bmatrix} \\dot x^+ \\\\ F \\end{bmatrix} =
    \\begin{bmatrix} M_x \\dot x^- \\\\ 0 \\end{bmatrix}$
    with $\\dot x^- = (\\dot q^-, 0)$ (stance foot pinned before impact).

    **Returns:** `(dq_plus, dz_plus, impulse)`: joint velocities just after impact in the
    *pre-impact* labelling, the velocity of the old stance foot (it lifts off), and the
    contact impulse $F$ (world frame, N s) on the impacting foot.
    """
    n = q.shape[0]
    Mx = extended_mass_matrix(model, q)
    E = contact_jacobian(model, q)
    dx_minus = jnp.concatenate([dq_minus, jnp.zeros(2, dq_minus.dtype)])
    kkt = jnp.block([[Mx, -E.T], [E, jnp.zeros((2, 2), q.dtype)]])
    rhs = jnp.concatenate([Mx @ dx_minus, jnp.zeros(2, q.dtype)])
    sol = jnp.linalg.solve(kkt, rhs)
    return sol[:n], sol[n : n + 2], sol[n + 2 :]
