"""Multi-domain hybrid mechanical systems: a cycle of phases, each with its own dynamics,
guard and reset map.

A `MultiDomainModel` carries one padded state $x = (q, \\dot q)$ in every domain (e.g. the
kneed walker always carries stance, thigh and shank angles; with the knee locked the
thigh and shank angles are kept equal by a holonomic constraint). Domain $i$ has a
vector field, a guard (downward zero crossing ends the domain, with an optional
upward-crossing gate as in `_simulate._swing`) and a reset map into domain $i+1$; the
last reset is the heel strike with relabelling into domain 0. One *step* of the model
is the whole cycle, post-heel-strike to post-heel-strike, so `simulate`, `step_map`,
`fixed_point`, `jacobian` and everything built on `vhcjax.hybrid.step_unchecked` work unchanged: the
step hook `hybrid_step` below is what `vhcjax.hybrid.step_unchecked` dispatches to.

Locked joints are linear holonomic constraints $A q = \\text{const}$ (rows of $A$ constant).
Their dynamics and their plastic impacts follow from the generic Lagrangian layer by the
Lagrange-multiplier (KKT) method, no hand-derived equations:

- constrained dynamics $M\\ddot q = -C\\dot q - G + A^T\\lambda$, $A\\ddot q = 0$;
- joint-lock impact $M(\\dot q^+ - \\dot q^-) = A^T F$, $A\\dot q^+ = 0$;
- heel strike with locked joints: the augmented method of thesis (3.27) with the extra
  rows $[A\\;0]$ in the impulse constraint (joints stay locked through the impact).
"""

import abc
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp

from .. import mechanics as mech
from .._programs import stored_jit
from .._results import RESULTS, result_codes, results_from_codes
from ..mechanics import WalkerModel
from ._simulate import DEFAULT_CONFIG, StepResult, _swing, flow


# ---- generic constrained mechanics --------------------------------------------------------
def locked_acceleration(model, q, dq, A, generalized_force=None):
    """$\\ddot q$ of the system with the joints locked by $A q = $ const (KKT solve),
    under an optional generalized force (e.g. joint torques $Bu$).

    **Returns:** `(ddq, lam)`, with `lam` the constraint forces (generalized, per row of A).
    """
    M = mech.mass_matrix(model, q)
    n, k = q.shape[0], A.shape[0]
    kkt = jnp.block([[M, -A.T], [A, jnp.zeros((k, k), q.dtype)]])
    force = -mech.bias_forces(model, q, dq)
    if generalized_force is not None:
        force = force + generalized_force
    rhs = jnp.concatenate([force, jnp.zeros(k, q.dtype)])
    sol = jnp.linalg.solve(kkt, rhs)
    return sol[:n], sol[n:]


def lock_impact(model, q, dq_minus, A):
    """Plastic impact that locks the joints $A q = $ const (e.g. knee strike).

    $M(\\dot q^+ - \\dot q^-) = A^T F$, $A \\dot q^+ = 0$. **Returns:** `(dq_plus, F)`.
    """
    M = mech.mass_matrix(model, q)
    n, k = q.shape[0], A.shape[0]
    kkt = jnp.block([[M, -A.T], [A, jnp.zeros((k, k), q.dtype)]])
    rhs = jnp.concatenate([M @ dq_minus, jnp.zeros(k, q.dtype)])
    sol = jnp.linalg.solve(kkt, rhs)
    return sol[:n], sol[n:]


def augmented_impact_locked(model, q, dq_minus, A):
    """Heel strike by the augmented method (thesis 3.27-3.28) with joints kept locked.

    Extended coordinates $(q, z)$; impulse constraints $E\\dot x^+ = 0$ (contact point stops)
    and $[A\\;0]\\dot x^+ = 0$ (locked joints stay locked). **Returns:**
    `(dq_plus, dz_plus, impulse)` with `impulse` the contact impulse (world frame).
    """
    n, k = q.shape[0], A.shape[0]
    Mx = mech.extended_mass_matrix(model, q)
    E = mech.contact_jacobian(model, q)
    Ax = jnp.concatenate([A, jnp.zeros((k, 2), q.dtype)], axis=1)
    C = jnp.concatenate([E, Ax], axis=0)
    m = C.shape[0]
    dx_minus = jnp.concatenate([dq_minus, jnp.zeros(2, q.dtype)])
    kkt = jnp.block([[Mx, -C.T], [C, jnp.zeros((m, m), q.dtype)]])
    rhs = jnp.concatenate([Mx @ dx_minus, jnp.zeros(m, q.dtype)])
    sol = jnp.linalg.solve(kkt, rhs)
    return sol[:n], sol[n : n + 2], sol[n + 2 : n + 4]


# ---- the model interface ------------------------------------------------------------------
class MultiDomainModel(WalkerModel):
    """Abstract hybrid system with `num_domains` domains arranged in a cycle.

    Subclasses implement, besides the energies, `contact_point`, `fallen`, `relabel` and
    the section chart of `WalkerModel`:

    - `domain_vector_field(i, x, generalized_force=None)`: $\\dot x$ in domain `i`
      (static int), under an optional generalized force (joint torques $Bu$).
    - `domain_guard(i, q)`: scalar whose downward zero crossing ends domain `i`.
    - `domain_strike_gate(i, q)`: optional upward-crossing gate (default `None`).
    - `domain_reset(i, x_minus)`: `(x_plus, impulse, physical)` into domain `i + 1`
      (the last one is the heel strike with relabelling, into domain 0).
    - `domain_admissible(i, x)`: optional boolean check of the state entering domain `i`
      (default: always); a failure ends the step with `RESULTS.fell`.
    - `domain_constraint(i)`: optional constant matrix $A$ of the joints locked in
      domain `i` ($A q$ and $A\\dot q$ constant there), or `None` (default). The
      transverse linearization of the controllers (`stabilize`) works on the remaining coordinates.

    The section (`section_to_state`) lies at the start of domain 0.
    """

    num_domains: ClassVar[int]

    @abc.abstractmethod
    def domain_vector_field(self, i, x, generalized_force=None): ...

    @abc.abstractmethod
    def domain_guard(self, i, q): ...

    def domain_strike_gate(self, i, q):
        return None

    @abc.abstractmethod
    def domain_reset(self, i, x_minus): ...

    def domain_admissible(self, i, x):
        return jnp.asarray(True)

    def domain_constraint(self, i):
        return None

    # WalkerModel's single-domain hooks map to the heel strike (the last domain).
    def guard(self, q):
        return self.domain_guard(self.num_domains - 1, q)

    def impact(self, x_minus):
        return self.domain_reset(self.num_domains - 1, x_minus)

    def vector_field(self, t, x, args=None):
        raise NotImplementedError(
            "A multi-domain model has one vector field per domain: use "
            "`domain_vector_field(i, x)` or `vhcjax.multidomain_trajectory`."
        )

    def hybrid_step(self, x0, config=DEFAULT_CONFIG, alive=True, adjoint=None, vector_field=None):
        """One full cycle (all domains) from a post-heel-strike state: what `step`,
        `simulate` and everything built on them run for this model. Returns a `StepResult`
        with result codes (never raises). `vector_field` must be `None`: a multi-domain
        model takes one field per domain (`multidomain_step`'s `fields`)."""
        if vector_field is not None:
            raise ValueError(
                "a multi-domain model has one vector field per domain: pass them as "
                "`multidomain_step(model, x0, ..., fields=...)`"
            )
        return multidomain_step(self, x0, config, alive, adjoint)[0]


class DomainView(eqx.Module):
    """Domain `index` of a `MultiDomainModel`, seen as a single-domain model by
    `_simulate._swing` / `_simulate.flow` (vector field, guard, gate, fall test)."""

    model: MultiDomainModel
    index: int = eqx.field(static=True)

    @property
    def n_dof(self):
        return self.model.n_dof

    @property
    def time_scale(self):
        return self.model.time_scale

    def vector_field(self, t, x, args=None):
        del t, args
        return self.model.domain_vector_field(self.index, x)

    def guard(self, q):
        return self.model.domain_guard(self.index, q)

    def strike_gate(self, q):
        return self.model.domain_strike_gate(self.index, q)

    def fallen(self, q):
        return self.model.fallen(q)


class DomainInfo(eqx.Module):
    """Per-domain details of one cycle (leading axis: domain).

    - `x_start`, `x_end`: state entering the domain and just before its reset.
    - `duration`: time spent in the domain (s).
    - `impulse`: world-frame contact impulse of the reset (zero for internal impacts).
    - `result`: a `RESULTS` code per domain.
    """

    x_start: jax.Array
    x_end: jax.Array
    duration: jax.Array
    impulse: jax.Array
    result: RESULTS


def multidomain_step(model, x0, config=DEFAULT_CONFIG, alive=True, adjoint=None, fields=None):
    """One cycle of a `MultiDomainModel` through all its domains.

    `fields`: optional vector fields `(t, x, args) -> xdot`, one per domain, replacing
    the model's (e.g. the walker under a feedback law, as `closed_loop_step` runs it).

    **Returns:** `(StepResult, DomainInfo)`; the `StepResult` has the pre-heel-strike state
    as `x_minus`, the total cycle time as `period` and the heel-strike impulse.
    """
    x0 = jnp.asarray(x0, dtype=float)
    finite0 = jnp.all(jnp.isfinite(x0))
    alive = jnp.asarray(alive) & finite0
    x_safe = jnp.where(finite0, x0, jnp.zeros_like(x0))
    t_max = config.t_max_factor * model.time_scale
    x = x_safe
    code = RESULTS.successful
    total = jnp.zeros((), x_safe.dtype)
    starts, ends, durations, impulses, codes = [], [], [], [], []
    impulse = jnp.zeros(2, x_safe.dtype)
    x_minus = x_safe
    for i in range(model.num_domains):  # static
        ok_before = code == RESULTS.successful
        admissible = model.domain_admissible(i, x)
        code = RESULTS.where(ok_before & ~admissible, RESULTS.fell, code)
        live = alive & (code == RESULTS.successful)
        view = DomainView(model, i)
        field = None if fields is None else fields[i]
        x_end, dt, code_i = _swing(view, x, t_max, live, config, adjoint, field)
        x_plus, impulse, physical = model.domain_reset(i, x_end)
        finite = jnp.all(jnp.isfinite(x_plus)) & jnp.all(jnp.isfinite(impulse))
        ok_i = code_i == RESULTS.successful
        code_i = RESULTS.where(ok_i & ~physical, RESULTS.bad_impact, code_i)
        code_i = RESULTS.where((code_i == RESULTS.successful) & ~finite, RESULTS.nonfinite, code_i)
        code = RESULTS.where(code == RESULTS.successful, code_i, code)
        ok = code == RESULTS.successful
        starts.append(x)
        ends.append(jnp.where(jnp.all(jnp.isfinite(x_end)), x_end, x))
        durations.append(jnp.where(live, dt, 0.0))
        impulses.append(jnp.where(ok, impulse, 0.0))
        codes.append(code)
        total = total + jnp.where(live, dt, 0.0)
        x_minus = ends[-1]
        x = jnp.where(ok, x_plus, x)
    code = RESULTS.where(finite0, code, RESULTS.nonfinite)
    ok = code == RESULTS.successful
    x_plus = jnp.where(ok, x, x_safe)
    impulse = jnp.where(ok, impulse, jnp.zeros_like(impulse))
    result_stack = results_from_codes(jnp.stack([result_codes(c) for c in codes]))
    info = DomainInfo(
        jnp.stack(starts),
        jnp.stack(ends),
        jnp.stack(durations),
        jnp.stack(impulses),
        result_stack,
    )
    return StepResult(x_minus, x_plus, total, impulse, code), info


def _domain_grids(model, info, num_points, config, fields=None):
    """States on `num_points` equally spaced times of each domain of a cycle (`info`); a
    domain not reached (the cycle failed before it) holds the last state reached.
    `fields`: the cycle's vector fields, if not the model's (as `multidomain_step`)."""
    ts_all, xs_all = [], []
    for i in range(model.num_domains):
        dur = info.duration[i]
        ts = jnp.linspace(0.0, 1.0, num_points) * dur
        ys = flow(
            DomainView(model, i),
            info.x_start[i],
            dur + 1e-12 * model.time_scale,
            config,
            saveat=diffrax.SaveAt(ts=ts),
            event=False,
            vector_field=None if fields is None else fields[i],
        ).ys
        assert ys is not None  # saved at ts
        if i:  # reached only if every earlier domain succeeded
            reached = result_codes(info.result)[i - 1] == result_codes(RESULTS.successful)
            ys = jnp.where(reached, ys, xs_all[-1][-1])
        ts_all.append(ts)
        xs_all.append(ys)
    return jnp.stack(ts_all), jnp.stack(xs_all)


@stored_jit
def multidomain_trajectory(model, x0, num_points=50, config=DEFAULT_CONFIG):
    """Dense trajectory of one cycle, per domain, for plots and invariant checks.

    **Returns:** `(ts, xs, info)`: times (domain-local, shape `(num_domains, num_points)`),
    states (`(num_domains, num_points, 2n)`) and the `DomainInfo` of the cycle.
    """
    _, info = multidomain_step(model, x0, config)
    ts, xs = _domain_grids(model, info, num_points, config)
    return ts, xs, info


def dense_cycle(model, x0, num_points, config=DEFAULT_CONFIG, alive=True, fields=None):
    """One cycle and its states on `num_points` times per domain, joined, as
    `vhcjax.simulate(..., dense_points=num_points)` returns them for a multi-domain model.
    `fields`: vector fields per domain replacing the model's (as `multidomain_step`).

    **Returns:** `(StepResult, ts, xs)`: the cycle (as `multidomain_step`), times from its
    start (shape `(num_domains * num_points,)`) and states (`(..., 2n)`)."""
    sr, info = multidomain_step(model, x0, config, alive, None, fields)
    ts, xs = _domain_grids(model, info, num_points, config, fields)
    starts = jnp.concatenate([jnp.zeros(1, ts.dtype), jnp.cumsum(info.duration)[:-1]])
    return sr, (ts + starts[:, None]).reshape(-1), xs.reshape(-1, xs.shape[-1])
