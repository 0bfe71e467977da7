"""The passive compass-gait biped of thesis chapter 3 (Fig. 3.1, Table 1)."""

import dataclasses
import math
from typing import ClassVar

import jax
import jax.numpy as jnp

from .. import trig
from ..mechanics import WalkerModel


def _zeros2(like):
    return jnp.zeros(2, dtype=jnp.result_type(like, float))


#: Section points of the default walker's two gaits at 3 degrees (`reference_gait`).
_REFERENCE_Z = {
    "stable": (0.218668802939, -1.092383589884, -0.377373948907),
    "unstable": (0.204675539342, -1.210571842398, -0.712488824701),
}


class CompassGait(WalkerModel):
    """Planar compass-gait biped on a slope (thesis chapter 3).

    Point masses: stance leg `m1` at distance `b` from its foot, hip `mH`, swing leg `m2`
    at distance `a` below the hip; leg length $l = a + b$. State $x = (q_1, q_2, \\dot q_1,
    \\dot q_2)$ with $q_1$ the stance leg and $q_2$ the swing leg, absolute angles from the
    world vertical, counter-clockwise positive; the walker moves downhill toward $+x$
    with $\\dot q_1 < 0$.

    **Fields** (defaults are thesis Table 1):

    - `m1`, `m2`: leg masses (kg), default 5.
    - `mH`: hip mass (kg), default 10.
    - `a`: hip to leg centre of mass (m), default 0.5.
    - `b`: leg centre of mass to foot (m), default 0.5.
    - `g`: gravity (m/s^2), default 9.81.
    - `psi`: slope angle (rad), default 3 degrees.
    - `min_strike_angle`: how far (rad) the swing leg must be ahead of the stance leg
      before a foot-ground crossing counts as a heel strike; default 0. Crossings before
      that are mid-swing scuffing, which the thesis ignores (3.2).
    """

    m1: float | jax.Array = 5.0
    m2: float | jax.Array = 5.0
    mH: float | jax.Array = 10.0
    a: float | jax.Array = 0.5
    b: float | jax.Array = 0.5
    g: float | jax.Array = 9.81
    psi: float | jax.Array = math.radians(3.0)
    min_strike_angle: float | jax.Array = 0.0

    n_dof: ClassVar[int] = 2
    UNITS: ClassVar[dict] = {
        "m1": "mass",
        "m2": "mass",
        "mH": "mass",
        "a": "length",
        "b": "length",
        "g": "acceleration",
    }

    def reference_gait(self, family="stable"):
        r"""The gaits of the default walker (thesis Table 1) at 3 degrees, $z = (q_1,
        \dot q_1, \dot q_2)$ after impact: `"stable"` (7.4) and `"unstable"` (7.9). Seeds
        for continuation (tests check the gaits found from them). The model is this one
        with the Table 1 values (a subclass keeps its own further parameters)."""
        z = _REFERENCE_Z.get(family)
        if z is None:
            raise ValueError(f"family must be 'stable' or 'unstable', got {family!r}")
        table1 = dict(m1=5.0, m2=5.0, mH=10.0, a=0.5, b=0.5, g=9.81, psi=math.radians(3.0))
        return dataclasses.replace(self, min_strike_angle=0.0, **table1), jnp.asarray(z)

    @property
    def l(self):
        return self.a + self.b

    @property
    def time_scale(self):
        return jnp.sqrt(self.l / self.g)

    @property
    def slope_normal(self):
        return jnp.stack([jnp.sin(self.psi), jnp.cos(self.psi)])

    def parameters(self):
        """The constants $p_1, \\dots, p_{11}$ of thesis (3.8)-(3.10) and (3.17), as a dict."""
        m1, m2, mH, a, b, g, l = self.m1, self.m2, self.mH, self.a, self.b, self.g, self.l
        return {
            "p1": mH * l**2 + m1 * b**2 + m2 * l**2,
            "p2": m2 * l * a,
            "p3": m2 * a**2,
            "p4": (m1 * b + m2 * l + mH * l) * g,
            "p5": m2 * a * g,
            "p6": m1 * l**2 + mH * l**2 + m2 * b**2,
            "p7": m1 * a * l,
            "p8": m1 * a**2,
            "p9": m1 * a * b,
            "p10": m2 * l * b + mH * l**2 + m1 * l * b,
            "p11": m2 * a * b,
        }

    # ---- kinematics ---------------------------------------------------------------------
    def points(self, q):
        """Positions (world frame, stance foot at the origin) of the stance-leg mass, hip,
        swing-leg mass and swing foot: a dict of 2-vectors (thesis 3.3, appendix C.2)."""
        s1, c1 = trig.sin_cos(q[0])
        s2, c2 = trig.sin_cos(q[1])
        up1 = jnp.stack([-s1, c1])  # unit vector from the stance foot to the hip
        down2 = jnp.stack([s2, -c2])  # unit vector from the hip to the swing foot
        hip = self.l * up1
        return {
            "stance_foot": jnp.zeros(2, hip.dtype),
            "stance_mass": self.b * up1,
            "hip": hip,
            "swing_mass": hip + self.a * down2,
            "swing_foot": hip + self.l * down2,
        }

    def contact_point(self, q):
        return self.points(q)["swing_foot"]

    # ---- energies -------------------------------------------------------------------------
    def kinetic_energy(self, q, dq, base_velocity=None):
        """Kinetic energy of the three point masses (thesis 3.5); with `base_velocity` the
        stance foot translates (extended coordinates of thesis 3.19-3.22)."""
        v0 = _zeros2(q) if base_velocity is None else base_velocity

        _, v = jax.jvp(self.points, (q,), (dq,))
        v1, vH, v2 = v["stance_mass"] + v0, v["hip"] + v0, v["swing_mass"] + v0
        # Squares summed elementwise, not `v @ v`: under nested autodiff and vmap XLA
        # compiles every small dot_general as a kernel of its own (slow to compile).
        return 0.5 * (
            self.m1 * jnp.sum(v1 * v1) + self.mH * jnp.sum(vH * vH) + self.m2 * jnp.sum(v2 * v2)
        )

    def potential_energy(self, q):
        """Gravitational energy (thesis 3.4), zero with both legs vertical, as in (5.10)."""
        pts = self.points(q)
        zero = self.points(jnp.zeros_like(q))

        def height(p):
            return (
                self.m1 * p["stance_mass"][1] + self.mH * p["hip"][1] + self.m2 * p["swing_mass"][1]
            )

        return self.g * (height(pts) - height(zero))

    # ---- hybrid structure -----------------------------------------------------------------
    def switching_surface(self, q):
        """$H(q) = \\cos(q_1 + \\psi) - \\cos(q_2 + \\psi)$ (thesis 3.31)."""
        return trig.cos(q[0] + self.psi) - trig.cos(q[1] + self.psi)

    def swing_foot_height(self, q):
        """Height of the swing foot above the slope (m), $l H(q)/\\cos\\psi$."""
        return self.l * self.switching_surface(q) / jnp.cos(self.psi)

    def hip_height(self, q):
        """Height of the hip above the slope, measured along the normal (m)."""
        return self.l * trig.cos(q[0] + self.psi)

    def strike_gate(self, q):
        """$q_2 - q_1 - \\delta$: the swing leg is ahead of the stance leg by $\\delta$ =
        `min_strike_angle` (default 0). Heel strikes are only looked for after this gate
        opens, so the mid-swing scuffing of equal legs (the $q_1 = q_2$ branch of 3.31,
        which the thesis ignores) can never be taken for a heel strike."""
        return q[1] - q[0] - self.min_strike_angle

    def guard(self, q):
        """Heel-strike guard $q_1 + q_2 + 2\\psi$: zero on the heel-strike branch of (3.31)
        ($q_2 = -q_1 - 2\\psi$, thesis 5.5), positive while the swing foot is above the
        slope with the swing leg ahead; heel strike is its downward crossing after the
        `strike_gate` has opened. (With the swing leg ahead the foot height above the
        slope is $2l\\sin(\\tfrac{q_1+q_2+2\\psi}{2})\\sin(\\tfrac{q_2-q_1}{2})/\\cos\\psi$.)"""
        return q[0] + q[1] + 2 * self.psi

    def input_matrix(self, q):
        """$B(q)$ of $M\\ddot q + C\\dot q + G = B u$: one hip torque $u$ (N m) acting on the
        relative angle $q_2 - q_1$, equal and opposite on the two legs (Freidovich,
        Shiriaev and Manchester 2008). Shape (2, 1)."""
        return jnp.array([[-1.0], [1.0]], dtype=jnp.asarray(q).dtype)

    def relabel(self, q, dq):
        """Swap stance and swing legs (thesis 3.32)."""
        return q[::-1], dq[::-1]

    # ---- Poincare section at the start of a step ---------------------------------------------
    def section_to_state(self, z):
        """Post-impact state from section coordinates $z = (q_1, \\dot q_1, \\dot q_2)$.

        Just after impact $q_2 = -q_1 - 2\\psi$ (relabelled heel-strike branch of 3.31,
        thesis 5.5-5.6: $e = c = -a - 2\\psi$).
        """
        return jnp.stack([z[0], -z[0] - 2 * self.psi, z[1], z[2]])

    def state_to_section(self, x):
        """Section coordinates $(q_1, \\dot q_1, \\dot q_2)$ of a post-impact state."""
        return jnp.stack([x[0], x[2], x[3]])

    def fallen(self, q):
        """Hip on the ground, or legs folded past each other by more than half a turn."""
        return (trig.cos(q[0] + self.psi) <= 0.0) | (jnp.abs(q[1] - q[0]) >= jnp.pi)

    # ---- thesis closed forms (reference implementations, used by tests) -----------------
    def impact_momentum(self, x_minus):
        """Impact map by conservation of angular momentum (thesis 3.17, 3.34), followed by
        relabelling. The printed (3.17)/(3.34) lack `- p9` in the first entry of
        $\\mathcal Q_-$; the appendix MATLAB code has it and it is used here."""
        p = self.parameters()
        q1, q2, dq1, dq2 = x_minus
        c12 = jnp.cos(q1 - q2)
        Qp = jnp.array(
            [[p["p8"] - p["p7"] * c12, -p["p7"] * c12 + p["p6"]], [p["p8"], -p["p7"] * c12]]
        )
        Qm = jnp.array([[p["p10"] * c12 - p["p9"], -p["p11"]], [-p["p9"], 0.0 * c12]])
        dq_plus = jnp.linalg.solve(Qp, Qm @ jnp.stack([dq1, dq2]))
        return jnp.stack([q2, q1, dq_plus[1], dq_plus[0]])

    def validate(self):
        """Boolean: all parameters finite, masses, gravity and the hip-to-mass distance `a`
        positive, `b` non-negative (`b = 0`: the leg masses at the feet), slope in
        (0, 30) deg (and the checks of `WalkerModel.validate` for the fields subclasses
        add). `a = 0` is invalid: the leg masses would sit at the hip, where the swing leg
        has no inertia and its motion is undetermined."""
        positive = jnp.stack(
            [jnp.asarray(v, float) for v in (self.m1, self.m2, self.mH, self.a, self.g)]
        )
        b = jnp.asarray(self.b, float)
        psi = jnp.asarray(self.psi, float)
        return (
            super().validate()
            & jnp.all(jnp.isfinite(positive))
            & jnp.all(positive > 0)
            & jnp.isfinite(b)
            & (b >= 0)
            & jnp.isfinite(psi)
            & (psi > 0)
            & (psi < math.radians(30.0))
        )
