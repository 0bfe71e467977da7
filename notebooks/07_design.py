# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Designing a walker by gradient, and the parameter atlas
#
# Every gait output is differentiable with respect to the model parameters: `find_gait`
# attaches exact derivatives by the implicit function theorem at the converged gait
# (the Newton iterations are never differentiated), and `gait_spectrum` adds the
# derivatives of the Floquet multipliers by eigenvalue perturbation. So `jax.grad` of the
# spectral radius of a gait is one call, and a walker can be designed by gradient descent.
#
# Here: the most robust walker at 3 degrees (smallest spectral radius of the step map,
# the fastest return to the gait) over the hip mass and the position of the leg's centre
# of mass, within bounds, checked against a batched grid; then a small atlas of the flip
# slope over mass and length ratios. `VHCJAX_FULL=1` for full sizes.

# %%
import math
import os
import tempfile

import jax
import matplotlib.pyplot as plt
import numpy as np

import vhcjax as vj

FULL = os.environ.get("VHCJAX_FULL") == "1"
# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_07_")
os.makedirs(OUT, exist_ok=True)
model = vj.CompassGait(psi=math.radians(3.0))

# %% [markdown]
# ## Exact derivatives of a gait
# The derivative of the spectral radius with respect to the hip mass, in reverse mode
# through the gait search.

# %%
g0 = vj.find_gait(model, method="shooting")


def radius(mH):
    m = vj.CompassGait(mH=mH, psi=math.radians(3.0))
    g = vj.find_gait(m, method="shooting", guess=g0.z)
    return vj.gait_spectrum(m, g).spectral_radius


rho, drho = jax.value_and_grad(radius)(10.0)
print(f"spectral radius {float(rho):.6f}, d/dmH = {float(drho):.6f} per kg")

# %% [markdown]
# ## The most robust walker at 3 degrees
# Projected Adam, then gradient sampling, over the hip mass (5 to 30 kg) and the
# distance `b` from foot to the leg's centre of mass (0.3 to 0.7 m; `a` stays 0.5 m).

# %%
res = vj.design(
    "spectral-radius",
    ["mass-hip", "b"],
    model=model,
    bounds={"mass-hip": (5.0, 30.0), "b": (0.3, 0.7)},
    steps=40 if FULL else 6,
    learning_rate=0.1,
)
print(f"design stopped ({res.result}) after {res.iterations} iterations")
print(
    "start  ",
    {k: round(v, 4) for k, v in res.initial["params"].items()},
    "radius",
    round(res.initial["value"], 6),
)
print(
    "optimum",
    {k: round(v, 4) for k, v in res.optimum["params"].items()},
    "radius",
    round(res.optimum["value"], 6),
)
print("multipliers at the optimum:", np.round(res.optimum["multipliers"], 5))

# %% [markdown]
# The minimum of a spectral radius usually lies where a complex pair of multipliers
# meets the real axis, where the radius is not differentiable: Adam stalls there, and the
# design goes on by gradient sampling along that kink (the `step` of each history
# entry). A batched grid of gaits over the same bounds is the independent check.

# %%
n = 40 if FULL else 8
H, Bb = np.meshgrid(np.linspace(5.0, 30.0, n), np.linspace(0.3, 0.7, n), indexing="ij")
grid = vj.CompassGait(mH=H.ravel(), b=Bb.ravel(), psi=math.radians(3.0))
gs = vj.find_gaits(grid, np.tile(np.asarray(g0.z), (H.size, 1)), method="shooting")
rho_grid = np.where(
    np.asarray(gs.result == vj.RESULTS.successful),
    np.asarray(vj.gait_spectrum(grid, gs).spectral_radius),
    np.nan,
).reshape(H.shape)
i, j = np.unravel_index(np.nanargmin(rho_grid), H.shape)
print(f"grid minimum {rho_grid[i, j]:.5f} at mH = {H[i, j]:.2f} kg, b = {Bb[i, j]:.3f} m")

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
it = [h["iteration"] for h in res.history]
ax1.plot(it, [h["value"] for h in res.history], "o-")
ax1.set_xlabel("iteration (-)")
ax1.set_ylabel("spectral radius (-)")
ax1.set_title(f"design: {res.result}")
mesh = ax2.pcolormesh(H, Bb, rho_grid, shading="nearest", vmax=0.7)
fig.colorbar(mesh, ax=ax2, label="spectral radius (-)", extend="max")
ax2.plot(
    [h["params"]["mass-hip"] for h in res.history],
    [h["params"]["b"] for h in res.history],
    "o-",
    color="tab:orange",
    label="design iterates",
)
ax2.plot(H[i, j], Bb[i, j], "r*", markersize=12, label="grid minimum")
ax2.set_xlabel("hip mass (kg)")
ax2.set_ylabel("b (m)")
ax2.set_title("white: no gait found from the start gait")
ax2.legend(loc="upper right", fontsize=8)
fig.suptitle("Most robust compass gait at 3 deg: gradient design and grid")
fig.tight_layout()
fig.savefig(os.path.join(OUT, "07_design.png"))

# %% [markdown]
# ## The atlas: first period-doubling slope over mass and length ratios
# The dimensionless walker depends on $\mu = m_H/m$ and $\beta = b/a$ only; each cell is
# the slope at which the stable gait period-doubles.

# %%
mu = np.linspace(1.0, 4.0, 7 if FULL else 2)
beta = np.linspace(0.7, 1.3, 7 if FULL else 2)
at = vj.atlas(mu, beta, slope=math.radians(3.0))
for i, m in enumerate(mu):
    for j, b in enumerate(beta):
        flip = np.degrees(at.flip_slope[i, j])
        print(f"mH/m = {m:.2f}, b/a = {b:.2f}: the stable gait period-doubles at {flip:.4f} deg")

fig, ax = plt.subplots(figsize=(6, 4.5))
mesh = ax.pcolormesh(mu, beta, np.degrees(at.flip_slope).T, shading="nearest")
fig.colorbar(mesh, ax=ax, label="flip slope (deg)")
ax.set_xlabel(r"mass ratio $m_H/m$ (-)")
ax.set_ylabel(r"length ratio $b/a$ (-)")
ax.set_title("Compass gait: first period-doubling slope")
fig.tight_layout()
fig.savefig(os.path.join(OUT, "07_atlas.png"))
