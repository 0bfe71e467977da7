# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Robustness of the stable 3-degree gait
#
# How fast the walker returns to its gait, how large a disturbance it survives (a slice
# of the basin of attraction), and how sensitive the gait is to pushes at the hip and to
# the slope. Every classification is a batched (`vmap`) simulation; derivatives are
# forward-mode autodiff through the heel-strike event. The same code runs on CPU or GPU;
# `VHCJAX_FULL=1` for full sizes (in quick mode the grids are tiny and the expensive
# slope derivatives are skipped).

# %%
import math
import os

import jax.numpy as jnp
import numpy as np

import vhcjax as vj
from vhcjax import plotting

FULL = os.environ.get("VHCJAX_FULL") == "1"
# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
import tempfile

OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_notebook_")
os.makedirs(OUT, exist_ok=True)
model = vj.CompassGait(psi=math.radians(3.0))

# %% [markdown]
# The gait from the VHC search (thesis seed 7.2), and its period from one simulated step.

# %%
g = vj.find_gait(model, "stable", guess=(0.20, -1.0))
z_star = np.asarray(g.z)
x_star = jnp.asarray(g.x_plus)
T = float(g.T)
print("gait z* =", np.round(z_star, 7), " T =", round(T, 7), "s")

# %% [markdown]
# ## Basin of attraction: a slice in the (q1, dq1) plane
# Each grid point is simulated (at most `num_steps` steps, tolerance 1e-8) until it
# returns within 1e-4 of the gait or falls.

# %%
shape = (101, 101) if FULL else (9, 9)
b = vj.basin_slice(
    model,
    z_star,
    axes=(0, 1),
    half_widths=(0.08, 0.4),
    shape=shape,
    num_steps=50 if FULL else 30,
    chunk=1024 if FULL else 81,
)
print(f"converging fraction {b.fraction:.3f}, area {b.area:.4g} rad^2/s")
print("largest offsets from the gait up to which every grid point converges:")
for key, name, unit in (("x", "q1", "rad"), ("y", "dq1", "rad/s")):
    print(
        f"  {name}: {b.max_converging['-' + key]:.4f} {unit} down, {b.max_converging['+' + key]:.4f} {unit} up"
    )
path = os.path.join(OUT, "04_basin.png")
plotting.plot_basin(b, path, case="stable gait, 3 deg")
print("wrote", path)

# %% [markdown]
# ## Pushes at the hip
# Linear sensitivity of the next post-impact state to a hip impulse at phase s of the
# step (autodiff through the pushed step), and the largest impulse after which the walker
# still returns to the gait (batched bisection).

# %%
phases = np.arange(20 if FULL else 3) / (20 if FULL else 3)
angles = np.radians([0.0, 90.0, 180.0, 270.0] if FULL else [0.0, 180.0])
D = np.asarray(vj.push_sensitivity_autodiff(model, x_star, T, jnp.asarray(phases)))
res = vj.max_push(
    model,
    x_star,
    T,
    phases,
    angles,
    p_max=20.0,
    iterations=12 if FULL else 4,
    scan=8 if FULL else 3,
)
print("largest impulse survived (N s) at phase s of the step:")
for j, a in enumerate(angles):
    cells = ", ".join(f"s = {s:.2f}: {p:.3f}" for s, p in zip(phases, res.largest[:, j]))
    deg = round(math.degrees(a))
    way = {0: "forward", 90: "up", 180: "backward", 270: "down"}[deg]
    print(f"  {way} ({deg} deg): {cells}")
path = os.path.join(OUT, "04_push.png")
plotting.plot_push(phases, D, angles, res.largest, path, p_max=20.0)
print("wrote", path)

# %% [markdown]
# ## Sensitivity to the slope (full mode)
# d/dpsi of the fixed point, period, step length, speed and multipliers by implicit
# differentiation (forward-over-forward autodiff through the event: an expensive
# compilation, so only with `VHCJAX_FULL=1`).

# %%
if FULL:
    sens = vj.slope_sensitivity(model, z_star)
    print("dz*/dpsi =", np.asarray(sens.dz), " dT/dpsi =", float(sens.dperiod))
    path = os.path.join(OUT, "04_slope.png")
    plotting.plot_slope(sens, path)
    print("wrote", path)
