"""A passive kneed walker with point feet (McGeer 1990; Hsu Chen 2007): a multi-domain model.

Links: a straight stance leg, and a swing leg made of a thigh and a shank joined by a free
knee. One step (one cycle) has two domains:

0. *unlocked*: three DOF (stance, thigh, shank) with a free knee, until the knee
   straightens (knee strike, $q_2 - q_3$ crosses zero downward): a plastic impact locks
   the knee (`_multidomain.lock_impact`);
1. *locked*: the knee is held straight ($q_3 = q_2$, a holonomic constraint, dynamics by
   `_multidomain.locked_acceleration`), until heel strike ($q_1 + q_2 + 2\\psi$ crosses zero
   downward); a plastic impact with both knees locked (`augmented_impact_locked`), then
   relabelling: the old swing leg becomes the (straight) stance leg and the old stance leg
   the new swing leg, whose knee unlocks.
"""

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .. import trig
from ..hybrid import (
    MultiDomainModel,
    augmented_impact_locked,
    lock_impact,
    locked_acceleration,
)

_KNEE = np.array([[0.0, 1.0, -1.0]])  # A q = q2 - q3 = 0: knee locked
#: Section point of the default walker's gait (`reference_gait`).
_REFERENCE_Z = (0.188185460239, -1.109587331253, -0.057148106788)
#: Knee flexion below which a state entering the unlocked domain is hyperextended (rad).
_KNEE_TOL = 1e-9


class KneedWalker(MultiDomainModel):
    """Planar passive walker with knees and point feet on a slope.

    State $x = (q_1, q_2, q_3, \\dot q_1, \\dot q_2, \\dot q_3)$: stance leg, swing thigh and
    swing shank, absolute angles from the world vertical, counter-clockwise positive (as
    `CompassGait`); the walker moves downhill toward $+x$ with $\\dot q_1 < 0$. The knee is
    flexed when $q_2 > q_3$ (shank behind the thigh).

    **Fields** (defaults: Hsu Chen 2007, "Passive dynamic walking with knees: a point
    foot model", MIT thesis, after McGeer 1990; leg length $L = 1$ m):

    - `ms`, `mt`, `mh`: shank, thigh and hip masses (kg): 0.05, 0.5, 0.5.
    - `a1`, `b1`: shank, foot to shank mass and shank mass to knee (m): 0.375, 0.125.
    - `a2`, `b2`: thigh, knee to thigh mass and thigh mass to hip (m): 0.175, 0.325.
    - `g`: gravity (m/s^2), 9.81.
    - `psi`: slope (rad), default 0.0504 (the slope of the Chen gait).
    """

    ms: float | jax.Array = 0.05
    mt: float | jax.Array = 0.5
    mh: float | jax.Array = 0.5
    a1: float | jax.Array = 0.375
    b1: float | jax.Array = 0.125
    a2: float | jax.Array = 0.175
    b2: float | jax.Array = 0.325
    g: float | jax.Array = 9.81
    psi: float | jax.Array = 0.0504

    n_dof: ClassVar[int] = 3
    num_domains: ClassVar[int] = 2
    POSITIVE_FIELDS: ClassVar[tuple] = ("ms", "mt", "mh", "a1", "b1", "a2", "b2", "g")
    NONNEGATIVE_FIELDS: ClassVar[tuple] = ("psi",)
    UNITS: ClassVar[dict] = {
        "ms": "mass",
        "mt": "mass",
        "mh": "mass",
        "a1": "length",
        "b1": "length",
        "a2": "length",
        "b2": "length",
        "g": "acceleration",
    }

    def reference_gait(self, family="stable"):
        r"""The default walker's gait at its default slope (0.0504 rad), $z = (q_1, \dot q_1,
        \dot q_2)$ after heel strike; it has one family (`"stable"`)."""
        if family != "stable":
            raise ValueError(f"KneedWalker has one gait family, 'stable'; got {family!r}")
        return KneedWalker(), jnp.asarray(_REFERENCE_Z)

    @property
    def ls(self):
        return self.a1 + self.b1

    @property
    def lt(self):
        return self.a2 + self.b2

    @property
    def L(self):
        return self.ls + self.lt

    @property
    def time_scale(self):
        return jnp.sqrt(self.L / self.g)

    @property
    def slope_normal(self):
        return jnp.stack([jnp.sin(self.psi), jnp.cos(self.psi)])

    # ---- kinematics -------------------------------------------------------------------
    def points(self, q):
        """World positions (stance foot at the origin) of the masses, hip, knee and feet."""
        (s1, c1), (s2, c2), (s3, c3) = (trig.sin_cos(q[i]) for i in range(3))
        up1 = jnp.stack([-s1, c1])
        d2 = jnp.stack([s2, -c2])
        d3 = jnp.stack([s3, -c3])
        hip = self.L * up1
        knee = hip + self.lt * d2
        return {
            "stance_foot": jnp.zeros(2, hip.dtype),
            "stance_shank": self.a1 * up1,
            "stance_knee": self.ls * up1,
            "stance_thigh": (self.ls + self.a2) * up1,
            "hip": hip,
            "swing_thigh": hip + self.b2 * d2,
            "knee": knee,
            "swing_shank": knee + self.b1 * d3,
            "swing_foot": knee + self.ls * d3,
        }

    _MASSES: ClassVar[tuple] = (
        ("stance_shank", "ms"),
        ("stance_thigh", "mt"),
        ("hip", "mh"),
        ("swing_thigh", "mt"),
        ("swing_shank", "ms"),
    )

    def contact_point(self, q):
        return self.points(q)["swing_foot"]

    def kinetic_energy(self, q, dq, base_velocity=None):
        v0 = jnp.zeros(2, jnp.result_type(q, float)) if base_velocity is None else base_velocity
        _, vel = jax.jvp(self.points, (q,), (dq,))
        return 0.5 * sum(getattr(self, m) * jnp.sum((vel[p] + v0) ** 2) for p, m in self._MASSES)

    def potential_energy(self, q):
        pts, zero = self.points(q), self.points(jnp.zeros_like(q))
        return self.g * sum(getattr(self, m) * (pts[p][1] - zero[p][1]) for p, m in self._MASSES)

    def angular_momentum(self, q, dq, about, base_velocity=None):
        """Angular momentum (z component) of all point masses about the point `about`
        (world frame), the stance foot moving at `base_velocity` (default: pinned)."""
        return self._momentum(q, dq, about, [p for p, _ in self._MASSES], base_velocity)

    def swing_leg_momentum(self, q, dq, base_velocity=None):
        """Angular momentum of the swing thigh and shank about the hip."""
        about = self.points(q)["hip"]
        return self._momentum(q, dq, about, ["swing_thigh", "swing_shank"], base_velocity)

    def stance_leg_momentum(self, q, dq, base_velocity=None):
        """Angular momentum of the stance leg (shank and thigh masses) about the hip."""
        about = self.points(q)["hip"]
        return self._momentum(q, dq, about, ["stance_shank", "stance_thigh"], base_velocity)

    def _momentum(self, q, dq, about, names, base_velocity):
        v0 = jnp.zeros(2, jnp.result_type(q, float)) if base_velocity is None else base_velocity
        pts, vel = jax.jvp(self.points, (q,), (dq,))
        mass = dict(self._MASSES)
        total = 0.0
        for p in names:
            r = pts[p] - about
            v = vel[p] + v0
            total = total + getattr(self, mass[p]) * (r[0] * v[1] - r[1] * v[0])
        return total

    # ---- domains ------------------------------------------------------------------------
    def domain_vector_field(self, i, x, generalized_force=None):
        q, dq = x[:3], x[3:]
        if i == 0:
            ddq = self.acceleration(q, dq, generalized_force)
        else:
            ddq, _ = locked_acceleration(self, q, dq, _KNEE.astype(q.dtype), generalized_force)
        return jnp.concatenate([dq, ddq])

    def domain_constraint(self, i):
        """The knee is locked ($q_2 - q_3$ constant) in domain 1."""
        return None if i == 0 else _KNEE

    def input_matrix(self, q):
        """$B(q)$ of $M\\ddot q + C\\dot q + G = B u$: a hip torque $u_1$ on the relative
        angle $q_2 - q_1$ (stance leg and swing thigh) and a knee torque $u_2$ on
        $q_3 - q_2$ (thigh and shank), N m. With the knee locked the knee torque is
        taken up by the lock. Shape (3, 2)."""
        return jnp.array([[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]], dtype=jnp.asarray(q).dtype)

    def knee_angle(self, q):
        """Knee flexion $q_2 - q_3$ (positive flexed, zero straight)."""
        return q[1] - q[2]

    def domain_guard(self, i, q):
        """Domain 0: knee flexion (knee strike when it returns to zero). Domain 1: the
        heel-strike guard $q_1 + q_2 + 2\\psi$ (straight legs, swing leg ahead: checked by
        `domain_admissible`)."""
        if i == 0:
            return self.knee_angle(q)
        return q[0] + q[1] + 2 * self.psi

    def domain_admissible(self, i, x):
        """Entering the unlocked domain the knee must not be hyperextended (flexion at
        least -1e-9 rad: the knee stop); entering the locked domain the swing leg must be
        ahead of the stance leg (else its straightened foot is below the slope)."""
        if i == 0:
            return self.knee_angle(x[:3]) >= -_KNEE_TOL
        return x[1] > x[0]

    def domain_reset(self, i, x_minus):
        q, dq = x_minus[:3], x_minus[3:]
        if i == 0:
            dq_plus, _ = lock_impact(self, q, dq, _KNEE.astype(q.dtype))
            extending = dq[1] - dq[2] <= 0  # the knee was straightening
            x_plus = jnp.concatenate([q, dq_plus])
            return x_plus, jnp.zeros(2, q.dtype), extending
        dq_plus, _, impulse = augmented_impact_locked(self, q, dq, _KNEE.astype(q.dtype))
        q_new, dq_new = self.relabel(q, dq_plus)
        physical = jnp.dot(impulse, self.slope_normal) > 0
        return jnp.concatenate([q_new, dq_new]), impulse, physical

    def relabel(self, q, dq):
        """Old swing leg (straight, angle $q_2 = q_3$) becomes the stance leg; the old
        stance leg becomes the new swing thigh and shank (knee straight, then free)."""
        return (
            jnp.stack([q[1], q[0], q[0]]),
            jnp.stack([dq[1], dq[0], dq[0]]),
        )

    def fallen(self, q):
        """Hip on the ground, legs folded past each other, or the knee bent or
        hyperextended by more than 90 degrees."""
        return (
            (trig.cos(q[0] + self.psi) <= 0.0)
            | (jnp.abs(q[1] - q[0]) >= jnp.pi)
            | (jnp.abs(q[1] - q[2]) >= 0.5 * jnp.pi)
        )

    # ---- section at the start of the step (post heel strike) -----------------------------
    def section_to_state(self, z):
        """Post-heel-strike state from $z = (q_1, \\dot q_1, \\dot q_2)$.

        After heel strike the new swing knee is straight with equal thigh and shank
        velocities (the impact acts with the knee locked, and relabelling copies the old
        stance leg into both), and $q_2 = -q_1 - 2\\psi$ (the heel-strike surface). So the
        post-impact set is 3-dimensional: $q_3 = q_2$, $\\dot q_3 = \\dot q_2$.
        """
        q2 = -z[0] - 2 * self.psi
        return jnp.stack([z[0], q2, q2, z[1], z[2], z[2]])

    def state_to_section(self, x):
        return jnp.stack([x[0], x[3], x[4]])
