# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Adding a new model
#
# A walker is an `equinox.Module` that gives its energies, the contact point of the swing
# foot, a guard and a relabelling; mass matrix, Coriolis and gravity terms, the impact map
# and everything downstream (simulation, Newton shooting, Poincare multipliers, basins,
# VHC search and transverse linearization) come from autodiff. Here: a compass walker
# whose legs are **uniform rods** (with rotational inertia) and a point mass at the hip,
# in under 50 lines. Set `VHCJAX_FULL=1` for full-size runs.

# %%
import os
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import vhcjax as vj

FULL = os.environ.get("VHCJAX_FULL") == "1"


# %%
class RodWalker(vj.WalkerModel):
    """Two uniform rod legs (mass m, length l) and a hip point mass mH, on slope psi."""

    m: float | jax.Array = 5.0
    mH: float | jax.Array = 10.0
    l: float | jax.Array = 1.0
    g: float | jax.Array = 9.81
    psi: float | jax.Array = 0.05
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
        lin = self.mH * sq[0] + self.m * (sq[1] + sq[2])
        return 0.5 * (lin + rot)

    def potential_energy(self, q):
        hip, c1, c2, _ = self._pts(q)
        return self.g * (self.mH * hip[1] + self.m * (c1[1] + c2[1]))

    def contact_point(self, q):
        return self._pts(q)[3]

    def guard(self, q):  # heel strike: q1 + q2 + 2 psi crosses zero downward ...
        return q[0] + q[1] + 2 * self.psi

    def strike_gate(self, q):  # ... once the swing leg is ahead (no mid-swing scuffing)
        return q[1] - q[0]

    def relabel(self, q, dq):
        return q[::-1], dq[::-1]

    def fallen(self, q):
        return (jnp.cos(q[0] + self.psi) <= 0) | (jnp.abs(q[1] - q[0]) >= jnp.pi)

    def section_to_state(self, z):  # post-impact: q2 = -q1 - 2 psi
        return jnp.stack([z[0], -z[0] - 2 * self.psi, z[1], z[2]])

    def state_to_section(self, x):
        return jnp.stack([x[0], x[2], x[3]])

    slope_normal = property(lambda self: jnp.stack([jnp.sin(self.psi), jnp.cos(self.psi)]))
    time_scale = property(lambda self: jnp.sqrt(self.l / self.g))


# %% [markdown]
# ## Gait search (Newton shooting on the step-to-step map) and its confirmation

# %%
model = RodWalker(psi=jnp.asarray(0.03))
fp = vj.fixed_point(model, jnp.array([0.2, -1.0, -0.2]))
print("fixed point:", vj.result_names(fp.result), np.asarray(fp.z), "period", fp.periods)
assert fp.result == vj.RESULTS.successful

x_start = model.section_to_state(fp.z + jnp.array([0.0, 0.01, 0.0]))
sim = vj.simulate(model, x_start, 60)
z_path = jax.vmap(model.state_to_section)(sim.steps.x_plus)
dist = np.max(np.abs(np.asarray(z_path) - np.asarray(fp.z)), axis=1)
print(
    "simulation:",
    vj.result_names(sim.result),
    "| distance to the gait, first/last:",
    dist[0],
    dist[-1],
)
assert sim.result == vj.RESULTS.successful and dist[-1] < 1e-6 * max(dist[0], 1.0)

# %% [markdown]
# ## Stability, three ways
# Poincare multipliers (autodiff through the events), checked by finite differences and
# by the transverse linearization (thesis ch. 6, generic in n).

# %%
J = vj.poincare_jacobian(model, fp.z)
h = 1e-6
Jfd = np.stack(
    [
        (vj.step_map(model, fp.z + h * e).z_next - vj.step_map(model, fp.z - h * e).z_next)
        / (2 * h)
        for e in np.eye(3)
    ],
    axis=1,
)
ev = np.linalg.eigvals(np.asarray(J))
print("multipliers (jacfwd):", ev, "| max |J - J_fd|:", np.abs(np.asarray(J) - Jfd).max())

orb = eqx.filter_jit(vj.vhc_orbit)(model, fp.z)
tl = eqx.filter_jit(vj.transverse_linearization)(model, fp.x0, orb.x_minus, fp.periods[0])
print(
    "VHC arc:",
    vj.result_names(orb.result),
    "| returns to the gait to",
    np.abs(np.asarray(orb.z_next - fp.z)).max(),
    "| period",
    orb.period,
)
print("multipliers (transverse):", vj.result_names(tl.result), np.asarray(tl.multipliers))
ev_sorted = lambda e: np.sort_complex(np.asarray(e))  # noqa: E731
assert np.abs(ev_sorted(tl.multipliers) - ev_sorted(ev)).max() < 1e-6

# %% [markdown]
# ## A basin slice (section coordinates q1, dq1)
# Start points on a grid around the gait just after impact, each simulated for up to 40
# steps and labelled by where it went: back to the gait, fell, another cycle, or
# undecided.

# %%
import tempfile

# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_05_")
os.makedirs(OUT, exist_ok=True)

n = 41 if FULL else 9
bs = vj.basin_slice(model, fp.z, axes=(0, 1), half_widths=(0.02, 0.1), shape=(n, n), num_steps=40)
assert bs.label[n // 2, n // 2] == vj.CONVERGED  # the gait itself
counts = {name: int(np.sum(bs.label == code)) for code, name in enumerate(vj.LABEL_NAMES)}
print(f"basin slice, {n} x {n} start points:", ", ".join(f"{k} {v}" for k, v in counts.items()))
print(f"fraction back at the gait: {bs.fraction:.2f}")
path = os.path.join(OUT, "05_basin.png")
vj.plotting.plot_basin(bs, path, case="rod-legged walker, 0.03 rad")
print("wrote", path)
