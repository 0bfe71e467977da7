"""The simplest walking model of Garcia, Chatterjee, Ruina and Coleman (1998).

Two rigid massless legs of length $l$ hinged at a hip of mass $M$, with point feet whose
masses $m$ are negligible ($m/M \\to 0$): the compass gait `CompassGait(m1=m, m2=m,
mH=M, a=l, b=0)` in the limit of light feet. The stance leg is an inverted pendulum that
the swing leg does not disturb, and the swing leg a pendulum hanging from the moving hip.
"""

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import trig
from ..mechanics import WalkerModel

#: Period-1 gaits of the walker at slope `_REFERENCE_SLOPE`, post-impact section points
#: $(q_1, \\dot q_1 \\sqrt{l/g}, \\dot q_2 \\sqrt{l/g})$ (angles in rad, rates in units of
#: $\\sqrt{g/l}$), from the scipy reference in Garcia's own variables (`tests/
#: _simplest_reference.py`, fixed-point residual below 1e-13).
_REFERENCE_SLOPE = 0.009
_REFERENCE_GAITS = {
    # the long-period gait (step period 3.8825 sqrt(l/g)): stable up to psi = 0.01509
    "stable": (0.19131090054438, -0.19983247300522, -0.18400947305687),
    # the short-period gait (step period 3.0961 sqrt(l/g)): unstable (a multiplier above 2
    # on every slope from 1e-7 to 0.03 rad)
    "unstable": (0.18493736981145, -0.20386692744350, -0.18872266659000),
}


class SimplestWalker(WalkerModel):
    """The simplest walking model (Garcia, Chatterjee, Ruina and Coleman 1998, "The
    simplest walking model: stability, complexity, and scaling", J. Biomech. Eng. 120).

    A hip of mass `M` on two massless legs of length `l` with point feet of vanishing
    mass. State $x = (q_1, q_2, \\dot q_1, \\dot q_2)$ as for `CompassGait`: $q_1$ the
    stance leg and $q_2$ the swing leg, absolute angles from the world vertical,
    counter-clockwise positive; the walker moves downhill toward $+x$ with
    $\\dot q_1 < 0$. The paper's variables are $\\theta = q_1 + \\psi$ (stance leg from
    the slope normal), $\\phi = q_1 - q_2$ (swing leg behind the stance leg) and
    $\\gamma = \\psi$, with time in units of $\\sqrt{l/g}$; its equations in these
    variables are

    $$\\ddot q_1 = \\tfrac{g}{l}\\sin q_1, \\qquad
    \\ddot q_2 = -\\tfrac{g}{l}\\sin q_2 + \\ddot q_1 \\cos(q_1 - q_2)
    - \\dot q_1^2 \\sin(q_1 - q_2),$$

    that is $\\ddot\\theta = \\sin(\\theta - \\gamma)$ and $\\ddot\\phi = \\sin(\\theta -
    \\gamma) + (\\dot\\theta^2 - \\cos(\\theta - \\gamma))\\sin\\phi$ (the paper's equations
    of motion with foot-to-hip mass ratio $\\beta = m/M \\to 0$). Angles do not depend on
    `M`, `l` and `g`; times scale with $\\sqrt{l/g}$, energies with $Mgl$.

    **Fields:**

    - `M`: hip mass (kg), default 1.
    - `l`: leg length (m), default 1.
    - `g`: gravity (m/s^2), default 1 (so that times are in the paper's units).
    - `psi`: slope angle (rad), default 0.009 (the paper's example slope).
    - `min_strike_angle`: how far (rad) the swing leg must be ahead of the stance leg
      before a foot-ground crossing counts as a heel strike; default 0. Before that the
      foot scuffs through the slope as the legs pass, which the paper ignores.
    """

    M: float | jax.Array = 1.0
    l: float | jax.Array = 1.0
    g: float | jax.Array = 1.0
    psi: float | jax.Array = _REFERENCE_SLOPE
    min_strike_angle: float | jax.Array = 0.0

    n_dof: ClassVar[int] = 2
    POSITIVE_FIELDS: ClassVar[tuple] = ("M", "l", "g")
    NONNEGATIVE_FIELDS: ClassVar[tuple] = ("min_strike_angle",)
    UNITS: ClassVar[dict] = {"M": "mass", "l": "length", "g": "acceleration"}

    @property
    def time_scale(self):
        return jnp.sqrt(self.l / self.g)

    @property
    def slope_normal(self):
        return jnp.stack([jnp.sin(self.psi), jnp.cos(self.psi)])

    # ---- kinematics ---------------------------------------------------------------------
    def points(self, q):
        """Positions (world frame, stance foot at the origin) of the stance foot, the hip
        and the swing foot: a dict of 2-vectors."""
        s1, c1 = trig.sin_cos(q[0])
        s2, c2 = trig.sin_cos(q[1])
        hip = self.l * jnp.stack([-s1, c1])
        return {
            "stance_foot": jnp.zeros(2, hip.dtype),
            "hip": hip,
            "swing_foot": hip + self.l * jnp.stack([s2, -c2]),
        }

    def contact_point(self, q):
        return self.points(q)["swing_foot"]

    # ---- energies -------------------------------------------------------------------------
    def kinetic_energy(self, q, dq, base_velocity=None):
        """Kinetic energy of the hip, $\\tfrac12 M |v_H|^2$ (the feet carry none in the
        limit); with `base_velocity` the stance foot translates. It does not involve
        $\\dot q_2$, so the mass matrix derived from it is singular: see `acceleration`."""
        _, v = jax.jvp(lambda qq: self.points(qq)["hip"], (q,), (dq,))
        if base_velocity is not None:
            v = v + base_velocity
        return 0.5 * self.M * jnp.sum(v * v)

    def potential_energy(self, q):
        """Gravitational energy of the hip, $Mgl(\\cos q_1 - 1)$, zero with the stance
        leg vertical."""
        return self.M * self.g * self.l * (trig.cos(q[0]) - 1.0)

    # ---- dynamics (the limit equations, not the energy-derived ones) ------------------------
    def acceleration(self, q, dq, generalized_force=None):
        """$\\ddot q$ of the limit equations (see the class docstring).

        The mass matrix of the energies is singular here (the swing leg has no mass), so
        the generic forward dynamics $M^{-1}(\\tau - C\\dot q - G)$ of
        `vhcjax.acceleration` cannot be used: the swing-leg equation is the
        $m \\to 0$ limit of the foot's own equation of motion, divided by $m$.

        **Arguments:**

        - `q`, `dq`: joint angles and rates.
        - `generalized_force`: must be `None`. A torque on the massless swing leg would
          give it an infinite acceleration, so forces are not supported (a
          `NotImplementedError`).
        """
        if generalized_force is not None:
            raise NotImplementedError(
                "SimplestWalker.acceleration: generalized forces are not supported (the "
                "massless swing leg would have an infinite acceleration); use CompassGait "
                "with light feet for actuated or pushed walkers"
            )
        s1, c1 = trig.sin_cos(q[0])
        s12, c12 = trig.sin_cos(q[0] - q[1])
        w2 = self.g / self.l
        ddq1 = w2 * s1
        ddq2 = -w2 * trig.sin(q[1]) + ddq1 * c12 - dq[0] ** 2 * s12
        return jnp.stack([ddq1, ddq2])

    def impact(self, x_minus):
        """Heel strike in the limit of light feet, followed by relabelling.

        Angular momentum of the hip about the landing foot is conserved, and the foot
        that lifts off carries none about the hip:
        $\\dot q_1^+ = \\cos(q_1^- - q_2^-)\\,\\dot q_1^-$ and $\\dot q_2^+ =
        \\cos^2(q_1^- - q_2^-)\\,\\dot q_1^-$ after the leg swap $q^+ = (q_2^-, q_1^-)$
        (the paper's $\\dot\\theta^+ = \\cos 2\\theta\\,\\dot\\theta^-$, $\\dot\\phi^+ =
        \\cos 2\\theta\\,(1 - \\cos 2\\theta)\\,\\dot\\theta^-$ on the heel-strike surface
        $\\phi = 2\\theta$). The pre-impact swing rate does not enter.

        **Returns:** `(x_plus, impulse, physical)` as `WalkerModel.impact`: `impulse` is
        the contact impulse on the new stance foot (world frame, N s), the change of the
        hip's momentum $M(v_H^+ - v_H^-)$ (the massless legs pass it on along the new
        stance leg), and `physical` says that it pushes the foot away from the slope.
        """
        q1, q2, dq1, _ = x_minus
        c = trig.cos(q1 - q2)
        dq1_plus = c * dq1
        s1, c1 = trig.sin_cos(q1)
        s2, c2 = trig.sin_cos(q2)
        # hip velocity l dq (-cos, -sin) of the leg it turns about: before, the old stance
        # leg q1; after, the new stance leg (the old swing leg, q2)
        v_minus = self.l * dq1 * jnp.stack([-c1, -s1])
        v_plus = self.l * dq1_plus * jnp.stack([-c2, -s2])
        impulse = self.M * (v_plus - v_minus)
        x_plus = jnp.stack([q2, q1, dq1_plus, c * dq1_plus])
        physical = jnp.dot(impulse, self.slope_normal) > 0
        return x_plus, impulse, physical

    # ---- hybrid structure -----------------------------------------------------------------
    def strike_gate(self, q):
        """$q_2 - q_1 - \\delta$ (as `CompassGait.strike_gate`): the swing leg is ahead
        of the stance leg by $\\delta$ = `min_strike_angle`."""
        return q[1] - q[0] - self.min_strike_angle

    def guard(self, q):
        """Heel-strike guard $q_1 + q_2 + 2\\psi$ $(= 2\\theta - \\phi)$, zero where the
        legs are symmetric about the slope normal (the paper's $\\phi = 2\\theta$) and
        positive while the swing foot is above the slope with the swing leg ahead; heel
        strike is its downward crossing after the `strike_gate` has opened."""
        return q[0] + q[1] + 2 * self.psi

    def relabel(self, q, dq):
        """Swap stance and swing legs."""
        return q[::-1], dq[::-1]

    def fallen(self, q):
        """Hip on the ground, or legs folded past each other by more than half a turn."""
        return (trig.cos(q[0] + self.psi) <= 0.0) | (jnp.abs(q[1] - q[0]) >= jnp.pi)

    # ---- Poincare section at the start of a step ---------------------------------------------
    def section_to_state(self, z):
        """Post-impact state from section coordinates $z = (q_1, \\dot q_1, \\dot q_2)$,
        with $q_2 = -q_1 - 2\\psi$ (as `CompassGait`)."""
        return jnp.stack([z[0], -z[0] - 2 * self.psi, z[1], z[2]])

    def state_to_section(self, x):
        """Section coordinates $(q_1, \\dot q_1, \\dot q_2)$ of a post-impact state."""
        return jnp.stack([x[0], x[2], x[3]])

    # ---- parameters -------------------------------------------------------------------------
    def with_slope(self, psi):
        """This walker on the slope `psi` (rad), as a JAX leaf (no recompiles)."""
        return eqx.tree_at(lambda m: m.psi, self, jnp.asarray(psi, float))

    def reference_gait(self, family="stable"):
        """A walker with a known period-1 gait of `family`, and the gait's section point.

        The walker is this one on the slope 0.009 rad (its `M`, `l`, `g` kept: the
        gait's angles do not depend on them and its rates scale with $\\sqrt{g/l}$). The
        families are the paper's two period-1 gaits: `"stable"`, the long-period gait
        (stable on slopes up to about 0.0151 rad), and `"unstable"`, the short-period
        gait. Either holds while `min_strike_angle` is below the angle between the legs
        at heel strike (about 0.4 rad).

        **Returns:** `(model, z)`, `z` = $(q_1, \\dot q_1, \\dot q_2)$ after heel strike,
        accurate to about 1e-11 (a seed for `vhcjax.fixed_point`).
        """
        if family not in _REFERENCE_GAITS:
            raise ValueError(
                f"family must be one of {', '.join(map(repr, _REFERENCE_GAITS))}, got {family!r}"
            )
        q1, dq1, dq2 = _REFERENCE_GAITS[family]
        rate = 1.0 / self.time_scale
        z = jnp.stack([jnp.asarray(q1, float), dq1 * rate, dq2 * rate])
        return self.with_slope(_REFERENCE_SLOPE), z

    def validate(self):
        """Boolean: all parameters finite, `M`, `l`, `g` positive, `min_strike_angle`
        non-negative, slope in (0, 30) deg."""
        psi = jnp.asarray(self.psi, float)
        return super().validate() & (psi > 0) & (psi < math.radians(30.0))
