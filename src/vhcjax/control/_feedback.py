"""Transverse-linearization feedback: $u = -K(s)\\,\\zeta$ on moving Poincare sections.

The state $x$ is projected onto the orbit along its own section $\\theta = q_1$ (thesis
ch. 6; Shiriaev et al. 2008): phase $s = (\\theta - \\theta^+)/(\\theta^- - \\theta^+)$,
transverse coordinates $\\zeta = w - w_\\star(s)$ with $w = x_{2..2n}$. The orbit
$w_\\star(s)$ is a cubic Hermite interpolant with the exact slopes $dw_\\star/ds$; the gain
$K(s)$ a Catmull-Rom cubic of the Riccati gains; outside $[0, 1]$ (perturbed states
before $\\theta^+$ or past $\\theta^-$) the end cubics extrapolate. On the orbit $\\zeta = 0$,
so the torque is zero: the controller holds the passive gait without changing it.
"""

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np


def _cell(s, n):
    """Cell index and local coordinate of `s` on the uniform grid of `n` cells."""
    x = s * n
    i = jnp.clip(jnp.floor(x), 0, n - 1).astype(int)
    return i, x - i


def hermite(values, slopes, s):
    """Cubic Hermite interpolation on a uniform grid over [0, 1] (`slopes` = d/ds)."""
    n = values.shape[0] - 1
    i, t = _cell(s, n)
    h = 1.0 / n
    h00 = 2 * t**3 - 3 * t**2 + 1
    h10 = t**3 - 2 * t**2 + t
    h01 = -2 * t**3 + 3 * t**2
    h11 = t**3 - t**2
    return h00 * values[i] + h10 * h * slopes[i] + h01 * values[i + 1] + h11 * h * slopes[i + 1]


def catmull_rom(values, s):
    """C1 cubic interpolation on a uniform grid over [0, 1], slopes by central differences
    (one-sided at the ends)."""
    n = values.shape[0] - 1
    inner = (values[2:] - values[:-2]) * (0.5 * n)
    slopes = jnp.concatenate(
        [((values[1] - values[0]) * n)[None], inner, ((values[-1] - values[-2]) * n)[None]]
    )
    return hermite(values, slopes, s)


class TransverseFeedback(eqx.Module):
    """The feedback law $u = \\mathrm{sat}(-K(s)\\zeta)$ of a stabilized gait (a pytree).

    Call as `feedback(x, model) -> u`. Fields:

    - `theta_plus`, `theta_minus`: phase end points ($q_1$ after and before impact).
    - `w`, `dw`: the orbit $w_\\star$ and $dw_\\star/ds$ on the phase grid `(N+1, 2n-1)`.
    - `K`: gains on the grid, `(N+1, m, 2n-1)`.
    - `torque_limit`: saturation $|u_i| \\le$ `torque_limit` (N m); `inf` for none.
    """

    theta_plus: jax.Array
    theta_minus: jax.Array
    w: jax.Array
    dw: jax.Array
    K: jax.Array
    torque_limit: jax.Array

    def phase(self, x):
        """Phase $s$ of the section through `x` (not clipped)."""
        return (x[0] - self.theta_plus) / (self.theta_minus - self.theta_plus)

    def orbit(self, s):
        """$w_\\star(s)$."""
        return hermite(self.w, self.dw, s)

    def gain(self, s):
        """$K(s)$, shape `(m, 2n-1)`."""
        return catmull_rom(self.K, s)

    def transverse(self, x):
        """$\\zeta = w - w_\\star(s)$: the transverse coordinates of `x`."""
        return x[1:] - self.orbit(self.phase(x))

    def __call__(self, x, model=None):
        s = self.phase(x)
        u = -self.gain(s) @ (x[1:] - self.orbit(s))
        return jnp.clip(u, -self.torque_limit, self.torque_limit)


class HybridTransverseFeedback(eqx.Module):
    """The feedback law of a gait of a multi-domain model: one `TransverseFeedback` per
    domain (`domains`), each on its own phase. The closed-loop step applies
    `in_domain(i)` in domain `i` (`vhcjax.closed_loop_step`)."""

    domains: tuple

    def in_domain(self, i):
        """The law of domain `i` (static int)."""
        return self.domains[i]

    @property
    def torque_limit(self):
        return self.domains[0].torque_limit

    def __call__(self, x, model=None):
        raise TypeError(
            "a multi-domain feedback law depends on the domain: use in_domain(i)(x, model)"
        )


def transverse_feedback(system, riccati, torque_limit: float | jax.Array = jnp.inf):
    """The `TransverseFeedback` of a `TransverseSystem` and its `RiccatiSolution` (a
    `HybridTransverseFeedback` for a `HybridTransverseSystem`)."""
    check_torque_limit(torque_limit)
    limit = jnp.asarray(torque_limit, float)
    if hasattr(system, "domains"):
        return HybridTransverseFeedback(
            tuple(
                TransverseFeedback(d.theta_plus, d.theta_minus, d.w, d.dw, riccati.K[i], limit)
                for i, d in enumerate(system.domains)
            )
        )
    return TransverseFeedback(
        system.theta_plus, system.theta_minus, system.w, system.dw, riccati.K, limit
    )


def check_torque_limit(torque_limit):
    """A one-line `ValueError` unless a concrete `torque_limit` is nonnegative (N m; `inf`
    for none, 0 for the passive walker through the same program): a negative limit would
    flip the torques' sign, a NaN one make them NaN."""
    if not isinstance(torque_limit, jax.core.Tracer) and not bool(
        np.all(np.asarray(torque_limit) >= 0)
    ):
        raise ValueError(
            f"torque_limit must be >= 0 (N m; inf for none, 0 for no torque), got {torque_limit}"
        )


def with_torque_limit(feedback, torque_limit):
    """`feedback` with another saturation level (a leaf: no recompilation)."""
    check_torque_limit(torque_limit)
    limit = jnp.asarray(torque_limit, float)
    if isinstance(feedback, HybridTransverseFeedback):
        return HybridTransverseFeedback(
            tuple(with_torque_limit(f, limit) for f in feedback.domains)
        )
    return eqx.tree_at(lambda f: f.torque_limit, feedback, limit)
