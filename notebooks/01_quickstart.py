# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # vhcjax quick start
#
# Simulate the passive compass-gait biped of Anstensrud's thesis (Table 1 parameters) on a
# 3-degree slope, from the thesis's stable-gait state (7.5), and look at it.
# The same code runs on CPU or GPU; set `VHCJAX_FULL=1` for full-size runs.

# %%
import os

import jax
import jax.numpy as jnp
import numpy as np

import vhcjax as vj

FULL = os.environ.get("VHCJAX_FULL") == "1"
print("devices:", jax.devices(), "| float64:", jax.config.jax_enable_x64)

# %% [markdown]
# A model is an `equinox.Module` with float leaves (SI units, slope in radians).

# %%
model = vj.CompassGait(psi=jnp.deg2rad(3.0))
print(model)
print({k: float(v) for k, v in model.parameters().items()})

# %% [markdown]
# `simulate` runs steps of the hybrid dynamics: swing phase until the heel strike (an exact
# `diffrax.Event`), then the impact map. Each step carries a result code.

# %%
x0 = jnp.array([0.218669, -0.323389, -1.092386, -0.377377])  # thesis (7.5)
sim = vj.simulate(model, x0, 20 if FULL else 8, dense_points=60)
print("result:", vj.result_names(sim.result), "| steps:", int(sim.num_successful))
print("step periods (s):", np.round(np.asarray(sim.steps.period), 6))

# %% [markdown]
# Batches are `vmap`s: 1,000 (or 64) random starts near the gait, some of which fall.

# %%
n = 1000 if FULL else 64
key = jax.random.PRNGKey(0)
starts = x0 + 0.15 * jax.random.normal(key, (n, 4)) * jnp.array([0.3, 0.3, 1.0, 1.0])
batch = jax.jit(jax.vmap(lambda x: vj.simulate(model, x, 10, config=vj.FAST_CONFIG)))(starts)
names = np.asarray(vj.result_names(batch.result))
for name in np.unique(names):
    print(f"{name:>12s}: {np.sum(names == name)}")

# %% [markdown]
# Each walker's result code names what ended it: `successful` (all 10 steps walked),
# `fell`, or `bad_impact` (a heel strike whose contact impulse would pull the new stance
# foot into the ground: no physical step).
#
# Figures (thesis Figs 7.2-7.4) and the walker animation (Fig 3.5).

# %%
import tempfile

import matplotlib

matplotlib.use("Agg")
from vhcjax import plotting

# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_quickstart_")
os.makedirs(OUT, exist_ok=True)
case = "thesis (7.5), stable gait, 3 deg"
for name, fn in (
    ("states", plotting.plot_states),
    ("phase", plotting.plot_phase_portrait),
    ("periods", plotting.plot_step_periods),
):
    path = os.path.join(OUT, f"01_{name}.png")
    fn(sim, path=path, case=case)
    print("wrote", path)

# The animation: the 8 simulated steps in real time, 60 frames (a GIF written by Pillow).
path = os.path.join(OUT, "01_walker.gif")
frames = plotting.animate(sim, model, path, max_frames=60)
print("wrote", path, f"({frames} frames)")
