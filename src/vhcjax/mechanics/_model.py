"""The interface every walker model implements: energies, contact point, guard, relabelling.

A model is an `eqx.Module` whose physical parameters are float64 array leaves (Python
numbers and integer arrays are converted on construction), so `jax.vmap` and `jax.grad` over masses, lengths,
gravity and slope work out of the box, and a jitted function compiled for one model is
reused for every other parameter value (a Python float would be a static, compile-time
constant under `eqx.filter_jit`: one compilation per slope). From the
energies, `vhcjax.mechanics` derives the equations of motion and the impact map.
"""

import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np

from . import _lagrangian as mech


class WalkerModel(eqx.Module):
    """Abstract single-domain hybrid Lagrangian system with a point-foot heel strike.

    Subclasses implement:

    - `kinetic_energy(q, dq, base_velocity=None)`: kinetic energy with the stance foot
      moving at `base_velocity` (zero or `None` while it is pinned); used for the
      dynamics and for the augmented impact map (thesis 3.19-3.28).
    - `potential_energy(q)`.
    - `contact_point(q)`: the impacting foot relative to the stance foot (world frame).
    - `guard(q)`: scalar, positive during the swing, crossing zero *downward* at heel
      strike and never on mid-swing scuffing.
    - `relabel(q, dq)`: the coordinate swap of the legs at impact (thesis 3.32).
    - `fallen(q)`: boolean, the walker has fallen (hip on the ground, legs out of range).
    - `slope_normal`: unit normal of the walking surface (world frame).
    - `time_scale`: a characteristic time (s), used for default time limits.
    """

    n_dof: ClassVar[int]

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = getattr(self, field.name, None)
            if isinstance(value, float) or (isinstance(value, int) and not isinstance(value, bool)):
                # a transfer, not a conversion program (compiled and looked up per process)
                object.__setattr__(self, field.name, jax.device_put(np.float64(value)))
            elif isinstance(value, (np.ndarray, np.generic)) and value.dtype.kind in "iu":
                # integer arrays too: `validate` checks the float leaves
                object.__setattr__(self, field.name, jax.device_put(value.astype(np.float64)))
            elif isinstance(value, jax.Array) and value.dtype.kind in "iu":
                object.__setattr__(self, field.name, jnp.asarray(value, dtype=float))
            elif (
                isinstance(value, jax.Array)
                and value.weak_type
                and not isinstance(value, jax.core.Tracer)
            ):
                # `jnp.asarray(0.05)` is weakly typed, `np.radians(3.0)` is not: without this
                # the same walker at another slope would compile its jitted programs again
                object.__setattr__(self, field.name, jax.device_put(np.asarray(value)))

    #: Parameters that must be positive (masses, lengths, gravity) and that must not be
    #: negative (e.g. the slope), checked by `validate`; every float parameter must be
    #: finite. A model names its own: the base class knows nothing of their meaning.
    POSITIVE_FIELDS: ClassVar[tuple] = ()
    NONNEGATIVE_FIELDS: ClassVar[tuple] = ()

    def validate(self):
        """Boolean (traceable, per batch member under `vmap`): every float parameter
        finite, those in `POSITIVE_FIELDS` positive and those in `NONNEGATIVE_FIELDS`
        non-negative. Simulations of an invalid model end with `RESULTS.bad_input`.
        Subclasses may narrow the ranges further."""
        ok = jnp.asarray(True)
        for field in dataclasses.fields(self):
            v = getattr(self, field.name, None)
            if isinstance(v, float):  # a Python float parameter (a static leaf)
                v = jnp.asarray(v)
            if v is None or not eqx.is_inexact_array(v):
                continue
            ok = ok & jnp.all(jnp.isfinite(v))
            if field.name in self.POSITIVE_FIELDS:
                ok = ok & jnp.all(v > 0)
            elif field.name in self.NONNEGATIVE_FIELDS:
                ok = ok & jnp.all(v >= 0)
        return ok

    def __repr__(self):
        """`CompassGait(m1=5, m2=5, ..., psi=0.0523599)`: the parameter values (a 0-d array
        would print as `f64[]`)."""
        parts = []
        for field in dataclasses.fields(self):
            v = getattr(self, field.name, None)
            try:
                a = np.asarray(v)
                text = (
                    f"{a.item():.6g}"
                    if a.ndim == 0 and a.dtype.kind in "fiu"
                    else (
                        np.array2string(a, precision=6, separator=", ")
                        if a.dtype.kind in "fiu"
                        else repr(v)
                    )
                )
            except (
                jax.errors.TracerArrayConversionError,
                jax.errors.ConcretizationTypeError,
            ):  # a tracer (inside jit/vmap)
                text = repr(v)
            parts.append(f"{field.name}={text}")
        return f"{type(self).__name__}({', '.join(parts)})"

    # ---- model facts the algorithms read (slope, units, a known gait) -----------------
    #: The physical dimension of each float parameter: `"mass"` (kg), `"length"` (m),
    #: `"acceleration"` (gravity, m/s^2); parameters not named are dimensionless (angles,
    #: ratios). `in_own_units` and the unit-free algorithms read it.
    UNITS: ClassVar[dict] = {}

    def with_slope(self, psi):
        """This model on the slope `psi` (rad; may be an array, e.g. one slope per batch
        member). Models whose slope is not the field `psi` override it."""
        return eqx.tree_at(lambda m: m.psi, self, jnp.asarray(psi, dtype=float))

    def reference_gait(self, family="stable"):
        """A gait of `family` known on a model of this kind: `(model, z)` with `z` its
        section point (accurate enough to start Newton), from which `vhcjax.find_gait`
        continues the gait to other parameters. Models that know none raise
        `NotImplementedError`: give `find_gait` a guess."""
        raise NotImplementedError(
            f"{type(self).__name__} knows no reference gait: give find_gait a guess "
            "(a section point of the gait)"
        )

    def scales(self):
        r"""The walker's own units: `{"mass", "length", "acceleration", "time"}`, the sums
        of its parameters of each dimension (`UNITS`) and $\sqrt{L/g}$. Tolerances,
        thresholds and search ranges of the algorithms are relative to these."""
        sums: dict = {"mass": 0.0, "length": 0.0, "acceleration": 0.0}
        for name, kind in self.UNITS.items():
            sums[kind] = sums[kind] + jnp.asarray(getattr(self, name), dtype=float)
        for kind in sums:  # a model without parameters of a dimension: unit 1
            if isinstance(sums[kind], float):
                sums[kind] = jnp.asarray(1.0)
        sums["time"] = jnp.sqrt(sums["length"] / sums["acceleration"])
        return sums

    def in_own_units(self):
        """The same walker in its own units (`scales`): masses, lengths and gravity
        divided by their sums, so that they sum to 1. Its motions are this walker's with
        the same angles and time divided by `scales()["time"]`."""
        s = self.scales()
        out = self
        for name, kind in self.UNITS.items():
            value = jnp.asarray(getattr(self, name), dtype=float) / s[kind]
            out = eqx.tree_at(lambda m: getattr(m, name), out, value)
        return out

    @abc.abstractmethod
    def kinetic_energy(self, q, dq, base_velocity=None): ...

    @abc.abstractmethod
    def potential_energy(self, q): ...

    @abc.abstractmethod
    def contact_point(self, q): ...

    @abc.abstractmethod
    def guard(self, q):
        """The heel-strike guard: crosses zero downward at heel strike. Dimensionless
        (an angle, or a height in leg lengths), as is `strike_gate`: the event root
        finder's tolerance is absolute on it."""

    @abc.abstractmethod
    def relabel(self, q, dq) -> tuple[jax.Array, jax.Array]: ...

    def strike_gate(self, q):
        """Optional: a function crossing zero *upward* when a heel strike becomes possible
        (the swing leg has passed the stance leg). `None` (the default) means no gate."""
        return None

    @abc.abstractmethod
    def fallen(self, q): ...

    @abc.abstractmethod
    def section_to_state(self, z):
        """Post-impact state from coordinates `z` (length 2n-1) on the post-impact section."""

    @abc.abstractmethod
    def state_to_section(self, x):
        """Coordinates on the post-impact section of a post-impact state `x`."""

    @property
    @abc.abstractmethod
    def slope_normal(self) -> jax.Array: ...

    @property
    @abc.abstractmethod
    def time_scale(self): ...

    # ---- derived quantities (generic) -------------------------------------------------
    def mass_matrix(self, q):
        return mech.mass_matrix(self, q)

    def coriolis_matrix(self, q, dq):
        return mech.coriolis_matrix(self, q, dq)

    def gravity_vector(self, q):
        return mech.gravity_vector(self, q)

    def acceleration(self, q, dq, generalized_force=None):
        return mech.acceleration(self, q, dq, generalized_force)

    def energy(self, x):
        n = self.n_dof
        return mech.energy(self, x[:n], x[n:])

    def vector_field(self, t, x, args=None):
        """$\\dot x = (\\dot q, \\ddot q)$ with diffrax's `(t, y, args)` signature."""
        del t, args
        n = self.n_dof
        q, dq = x[:n], x[n:]
        return jnp.concatenate([dq, self.acceleration(q, dq)])

    def impact(self, x_minus):
        """Reset map: augmented impact (thesis 3.27) followed by relabelling (3.32).

        **Returns:** `(x_plus, impulse, physical)` where `impulse` is the contact impulse
        on the new stance foot (world frame) and `physical` says that it pushes the foot
        away from the ground (no pulling impulse).
        """
        n = self.n_dof
        q, dq = x_minus[:n], x_minus[n:]
        dq_plus, _, impulse = mech.augmented_impact(self, q, dq)
        q_new, dq_new = self.relabel(q, dq_plus)
        physical = jnp.dot(impulse, self.slope_normal) > 0
        return jnp.concatenate([q_new, dq_new]), impulse, physical
