"""Result codes carried by every returned pytree (diffrax/optimistix style)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


class RESULTS(eqx.Enumeration):
    """What happened to a computation, per batch member.

    Use `RESULTS.where(pred, a, b)` under `jit`, `result == RESULTS.successful` to test,
    and `RESULTS[result]` (outside `jit`) for the message.
    """

    successful = ""
    no_impact = "No heel strike before the time limit."
    fell = "The walker fell: hip reached the ground or a leg left its range."
    bad_impact = (
        "Impact is not physical: the contact impulse would pull the new stance foot "
        "into the ground."
    )
    nonfinite = "A non-finite state or parameter was encountered."
    max_steps_reached = "The ODE solver hit `max_steps` before the step ended."
    not_converged = "The gait search did not converge."
    no_real_root = "No real root of the energy quadratic for d (thesis 5.13)."
    singular_phi_ode = (
        "The phi'' ODE is singular along the arc (kinetic term or determinant vanishes)."
    )
    infeasible_uphill = (
        "Solution of Problem 1 with positive velocities: a negative-time (uphill) "
        "motion, not a passive gait (thesis 7.17-7.18)."
    )
    bad_input = "Invalid input (non-positive mass or length, slope out of range, or NaN)."
    other_cycle = "Settled on a different cycle (not the target gait)."
    undecided = (
        "Neither converged to the gait, nor fell, nor settled on a cycle in the step budget."
    )
    phase_not_monotone = (
        "The phase variable q1 is not monotone along the orbit: the transverse "
        "linearization (thesis ch. 6) does not apply; the Poincare-map Jacobian decides."
    )
    ill_conditioned = (
        "The transverse coordinates are ill-conditioned (condition number of [L; m^T] "
        "above 1e8, or the flow nearly tangent to an impact surface); the Poincare-map "
        "Jacobian decides."
    )
    methods_disagree = (
        "The transverse linearization and the Poincare-map Jacobian disagree by more than "
        "1e-6 (relative to the spectral radius), or the transverse construction does not "
        "reproduce the orbit; the Poincare-map Jacobian decides."
    )
    not_requested = (
        "The transverse linearization was not asked for; the Poincare-map Jacobian decides."
    )
    riccati_ill_conditioned = (
        "The Hamiltonian monodromy cannot be computed in double precision (fast modes "
        "over a long phase, e.g. a light joint with a cheap torque: its flow overflows, "
        "exhausts max_steps or loses its symplectic structure); the backward Riccati "
        "iteration decides."
    )
    orbit_not_closed = (
        "The tabulated orbit does not come back to its start (by more than 1e-6 relative "
        "to max(1, |x|)): the state is not on a period-1 gait, or the phase grid "
        "(num_points) is too coarse for the orbit."
    )
    not_a_gait = (
        "The state is not a period-1 gait: one step moves it on the section by more than "
        "1e-6 relative to max(1, |z|), so its Jacobian's eigenvalues are not Floquet "
        "multipliers."
    )
    other_root = (
        "At or before this slope the family passes through a double root of the energy "
        "quadratic (thesis 5.13) and goes on as a gait of the other family (set by "
        "sweeps)."
    )


_Item = type(RESULTS.successful)  # the class of the items (and of batches of them)


def result_names(result) -> list[str] | str:
    """Names of result codes (outside `jit`): `'successful'`, `'fell'`, ...

    Accepts a `RESULTS` item (possibly batched) or an integer array of codes; returns a
    string for a scalar and a (nested) list of strings for a batch.
    """
    codes = np.asarray(result_codes(result))
    lookup = {int(result_codes(item)): name for name, item in RESULTS._name_to_item.items()}
    if codes.ndim == 0:
        return lookup[int(codes)]
    return np.vectorize(lambda c: lookup[int(c)], otypes=[object])(codes).tolist()


def result_codes(result) -> jax.Array | np.ndarray:
    """The integer codes of a (batched) `RESULTS` item, as an array (an array of codes is
    returned as it is). Traceable."""
    return result._value if isinstance(result, _Item) else result


def results_from_codes(codes) -> RESULTS:
    """The (batched) `RESULTS` item whose integer codes are `codes`: the inverse of
    `result_codes`. Traceable."""
    codes = jnp.asarray(codes, dtype=np.asarray(result_codes(RESULTS.successful)).dtype)
    return eqx.tree_at(result_codes, RESULTS.successful, codes)
