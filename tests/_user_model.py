"""A walker model written as a user would (the docs' new-model notebook): two uniform
rod legs and a hip point mass. `TRACES[0]` counts how often JAX traced its dynamics."""

from typing import ClassVar

import jax
import jax.numpy as jnp

import vhcjax as vj

TRACES = [0]


class RodWalker(vj.WalkerModel):
    """Two uniform rod legs (mass m, length l) and a hip point mass mH, on slope psi."""

    m: float | jax.Array = 5.0
    mH: float | jax.Array = 10.0
    l: float | jax.Array = 1.0
    g: float | jax.Array = 9.81
    psi: float | jax.Array = 0.03
    n_dof: ClassVar[int] = 2

    def _pts(self, q):  # hip, the two rod centres, swing foot
        hip = self.l * jnp.stack([-jnp.sin(q[0]), jnp.cos(q[0])])
        down = jnp.stack([jnp.sin(q[1]), -jnp.cos(q[1])])
        return hip, hip / 2, hip + self.l / 2 * down, hip + self.l * down

    def kinetic_energy(self, q, dq, base_velocity=None):
        v0 = jnp.zeros(2) if base_velocity is None else base_velocity
        vh, v1, v2, _ = jax.jvp(self._pts, (q,), (dq,))[1]
        rot = self.m * self.l**2 / 12 * (dq[0] ** 2 + dq[1] ** 2)  # rod spin
        sq = [(v + v0) @ (v + v0) for v in (vh, v1, v2)]
        return 0.5 * (self.mH * sq[0] + self.m * (sq[1] + sq[2]) + rot)

    def potential_energy(self, q):
        TRACES[0] += 1  # Python runs here only while JAX traces
        hip, c1, c2, _ = self._pts(q)
        return self.g * (self.mH * hip[1] + self.m * (c1[1] + c2[1]))

    def contact_point(self, q):
        return self._pts(q)[3]

    def guard(self, q):
        return q[0] + q[1] + 2 * self.psi

    def strike_gate(self, q):
        return q[1] - q[0]

    def relabel(self, q, dq):
        return q[::-1], dq[::-1]

    def fallen(self, q):
        return (jnp.cos(q[0] + self.psi) <= 0) | (jnp.abs(q[1] - q[0]) >= jnp.pi)

    def section_to_state(self, z):
        return jnp.stack([z[0], -z[0] - 2 * self.psi, z[1], z[2]])

    def state_to_section(self, x):
        return jnp.stack([x[0], x[2], x[3]])

    slope_normal = property(lambda self: jnp.stack([jnp.sin(self.psi), jnp.cos(self.psi)]))
    time_scale = property(lambda self: jnp.sqrt(self.l / self.g))
