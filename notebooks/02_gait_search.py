# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Gait search and slope sweeps
#
# Periodic gaits of the compass-gait biped two ways: the virtual-holonomic-constraint
# search of the thesis (Problem 1: two unknowns, the reduced `phi''` ODE in `theta`) and
# shooting on the full hybrid dynamics (Problem 2), then both gait families along the
# slope. The same code runs on CPU or GPU; set `VHCJAX_FULL=1` for full sizes.

# %%
import math
import os

import jax
import jax.numpy as jnp
import numpy as np

import vhcjax as vj

FULL = os.environ.get("VHCJAX_FULL") == "1"
model = vj.CompassGait(psi=math.radians(3.0))

# %% [markdown]
# ## Problem 1 (VHC search) from the thesis seed (7.2)
# The stable family takes the minus root of the energy quadratic (5.13) (thesis 7.3),
# the unstable family the plus root (7.8). One batched call finds both seeds' gaits;
# `find_gaits` never raises and returns a result code per member.

# %%
slopes = np.radians([3.0, 3.0, 5.0, 2.87])
guesses = np.array([[0.20, -1.0], [0.20, 1.0], [0.20, -1.0], [0.20, -1.0]])
g = vj.find_gaits(vj.CompassGait(), guesses, "stable", psi=slopes)
print("results:", vj.result_names(g.result))
s3 = 0
for k in "abcdefgh":
    print(f"  {k} = {float(getattr(g, k)[s3]): .6f}")
print(f"  T = {float(g.T[s3]):.6f} s, E0 = {float(g.E0[s3]):.6f} J")
print(
    "seed (0.20, +1.0) gives the uphill solution (7.18):",
    vj.result_names(g.result)[1],
    np.round(np.asarray(g.z[1]), 6),
)

# %% [markdown]
# ## Cross-check: the hybrid simulator returns to the gait
# One step of the full hybrid dynamics (swing + heel-strike event + impact map) from the
# VHC gait's post-impact state lands on its pre-impact state and returns to it.

# %%
x_plus = jnp.asarray(g.x_plus[s3])
sr = vj.step(model, x_plus)
print("pre-impact state: VHC vs simulator:", float(jnp.max(jnp.abs(sr.x_minus - g.x_minus[s3]))))
print("post-impact state after one step:  ", float(jnp.max(jnp.abs(sr.x_plus - x_plus))))
print("step period: VHC vs simulator:     ", abs(float(sr.period) - float(g.T[s3])))

# %% [markdown]
# ## Problem 2 (shooting) in full mode
# Newton on the step-to-step map (Jacobian by forward-mode autodiff through the event).
# A second compiled search: only with `VHCJAX_FULL=1`.

# %%
if FULL:
    sh = vj.find_gait(model, "stable", "shooting", guess=(0.20, -1.0))
    print("shooting - VHC:", np.max(np.abs(np.asarray(sh.z) - np.asarray(g.z[s3]))))

# %% [markdown]
# ## Both families against slope
# A vector of slopes solved in one batched call (same compiled function as above when
# the batch has the same size); failed members are re-seeded from their solved
# neighbours (the library's `vhcjax.sweep` does a proper continuation with a secant
# predictor, at the cost of one more compile).

# %%
n = 64 if FULL else 8
sl = np.linspace(1.0, 6.0, n)


def family(fam):
    gg = vj.find_gaits(vj.CompassGait(), np.tile([0.20, -1.0], (n, 1)), fam, psi=np.radians(sl))
    for _ in range(4):
        ok = np.array(vj.result_names(gg.result)) == "successful"
        if ok.all():
            break
        idx = np.where(ok)[0]
        near = idx[np.argmin(np.abs(sl[idx][None] - sl[:, None]), axis=1)]
        r = (sl / sl[near]) ** (1 / 3)  # small-slope scaling of passive gaits
        seeds = np.stack([np.asarray(gg.a)[near] * r, np.asarray(gg.b)[near] * r], 1)
        g2 = vj.find_gaits(vj.CompassGait(), seeds, fam, psi=np.radians(sl))
        take = (np.array(vj.result_names(g2.result)) == "successful") & ~ok
        gg = jax.tree_util.tree_map(  # keep the new solutions where the old ones failed
            lambda x, y: jnp.where(take.reshape((-1,) + (1,) * (x.ndim - 1)), y, x), gg, g2
        )
    return gg


fams = {f: family(f) for f in ("stable", "unstable")}
for f, gg in fams.items():
    ok = np.array(vj.result_names(gg.result)) == "successful"
    T = np.asarray(gg.T)[ok]
    print(f"{f} family: {ok.sum()} of {n} slopes; T from {T.min():.4f} to {T.max():.4f} s")

# %%
# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
import tempfile

OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_notebook_")
os.makedirs(OUT, exist_ok=True)
sweeps = {f: vj.Sweep(jnp.radians(sl), gg) for f, gg in fams.items()}
path = os.path.join(OUT, "02_families.png")
vj.plotting.plot_sweep(sweeps, path)
print("wrote", path)
