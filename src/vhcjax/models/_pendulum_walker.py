"""A three-DOF single-domain walker: the compass gait with a pendulum hanging from the hip.

A point mass `mp` on a massless rod of length `lp`, hinged (frictionless) at the hip, is
the simplest passive third degree of freedom that keeps the energy conserved between
impacts (a spring-loaded torso would too; a damper would not). It is the test model of
the n-DOF virtual-holonomic-constraint and transverse-linearization code: its stable
passive gait has 5 Poincare multipliers.
"""

from typing import ClassVar

import jax
import jax.numpy as jnp

from .. import trig
from ._compass_gait import CompassGait

#: Section point of the default walker's stable gait (`reference_gait`).
_REFERENCE_Z = (0.216679352100, -0.033752463767, -1.093187725656, -0.377948486809, -0.491198861942)


class PendulumWalker(CompassGait):
    """Compass gait (thesis Table 1 defaults) plus a hip pendulum.

    State $x = (q_1, q_2, q_3, \\dot q_1, \\dot q_2, \\dot q_3)$: stance leg, swing leg and
    pendulum, absolute angles from the world vertical, counter-clockwise positive (the
    pendulum hangs at $q_3 = 0$). Section coordinates $z = (q_1, q_3, \\dot q_1, \\dot q_2,
    \\dot q_3)$ with $q_2 = -q_1 - 2\\psi$ after impact.

    **Fields:** those of `CompassGait`, plus `mp` (kg, default 0.5) and `lp` (m, default
    0.8; shorter or lighter pendulums give gaits that are unstable or closer to
    neutral: at `mp = 0.5` the largest multiplier modulus is about 1.04 at
    `lp = 0.4` and 0.97 at `lp = 0.9`).
    """

    mp: float | jax.Array = 0.5
    lp: float | jax.Array = 0.8

    POSITIVE_FIELDS: ClassVar[tuple] = ("mp", "lp")  # besides `CompassGait.validate`
    UNITS: ClassVar[dict] = {**CompassGait.UNITS, "mp": "mass", "lp": "length"}

    def reference_gait(self, family="stable"):
        r"""The default walker's stable gait at 3 degrees, $z = (q_1, q_3, \dot q_1,
        \dot q_2, \dot q_3)$ (it has one known family)."""
        if family != "stable":
            raise ValueError(f"PendulumWalker knows one gait family, 'stable'; got {family!r}")
        return PendulumWalker(), jnp.asarray(_REFERENCE_Z)

    n_dof: ClassVar[int] = 3

    def points(self, q):
        pts = super().points(q)
        pts["pendulum"] = pts["hip"] + self.lp * jnp.stack([trig.sin(q[2]), -trig.cos(q[2])])
        return pts

    def kinetic_energy(self, q, dq, base_velocity=None):
        v0 = jnp.zeros(2, jnp.result_type(q, float)) if base_velocity is None else base_velocity
        vp = jax.jvp(lambda qq: self.points(qq)["pendulum"], (q,), (dq,))[1] + v0
        legs = super().kinetic_energy(q[:2], dq[:2], base_velocity)
        return legs + 0.5 * self.mp * jnp.sum(vp * vp)

    def potential_energy(self, q):
        y = self.points(q)["pendulum"][1] - self.points(jnp.zeros_like(q))["pendulum"][1]
        return super().potential_energy(q[:2]) + self.mp * self.g * y

    def relabel(self, q, dq):
        """Swap the legs; the pendulum keeps its angle and rate."""
        perm = jnp.array([1, 0, 2])
        return q[perm], dq[perm]

    def section_to_state(self, z):
        return jnp.stack([z[0], -z[0] - 2 * self.psi, z[1], z[2], z[3], z[4]])

    def state_to_section(self, x):
        return jnp.stack([x[0], x[2], x[3], x[4], x[5]])
