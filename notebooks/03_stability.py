# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Stability and bifurcations
#
# Floquet multipliers of periodic gaits two independent ways, the transverse
# linearization of thesis chapter 6 (rebuilt from the virtual holonomic constraint) and
# the Jacobian of the hybrid step-to-step map by forward-mode autodiff through the
# heel-strike event; then the loss of stability of the stable family by period doubling
# and the bifurcation diagram. The same code runs on CPU or GPU; `VHCJAX_FULL=1` for
# full sizes.

# %%
import math
import os

import numpy as np

import vhcjax as vj
from vhcjax import plotting

FULL = os.environ.get("VHCJAX_FULL") == "1"
# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
import tempfile

OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_notebook_")
os.makedirs(OUT, exist_ok=True)

# %% [markdown]
# ## Both gaits at 3 degrees, both methods, one batched call
# `family_multipliers(model, slopes, z)` vmaps the two computations over gaits; the
# batch shape is fixed at 8 here so that every call below reuses one compilation.

# %%
B = 8


def multipliers(psis, zs):
    psis, zs = np.asarray(psis, float), np.asarray(zs, float)
    n = len(psis)
    pad = (-n) % B
    p = np.concatenate([psis, np.repeat(psis[:1], pad)])
    z = np.concatenate([zs, np.repeat(zs[:1], pad, 0)])
    out = [
        vj.family_multipliers(vj.CompassGait(), p[i : i + B], z[i : i + B])
        for i in range(0, len(p), B)
    ]
    tr = np.concatenate([np.asarray(o.transverse) for o in out])[:n]
    pc = np.concatenate([np.asarray(o.poincare) for o in out])[:n]
    return tr, pc


fp = [vj.period1_family([math.radians(3.0)], f) for f in ("stable", "unstable")]
z3 = np.concatenate([np.asarray(f.z) for f in fp])
tr, pc = multipliers(np.radians([3.0, 3.0]), z3)
for name, t, p in zip(("stable", "unstable"), tr, pc):
    print(f"{name:>8s} gait: transverse {np.round(t, 5)}")
    print(f"{'':>8s}       Poincare   {np.round(p, 5)}   max diff {np.max(np.abs(t - p)):.1e}")
path = os.path.join(OUT, "03_multipliers_3deg.png")
fig = plotting.plot_multipliers_complex(
    [tr[0], pc[0], tr[1], pc[1]],
    ["stable: transverse", "stable: Poincare", "unstable: transverse", "unstable: Poincare"],
    path,
    title="3 deg",
)
print("wrote", path)

# %% [markdown]
# ## The stable family along the slope
# Period-1 gaits by continuation, then their multipliers: a real multiplier leaves the
# unit circle through -1 (period doubling, a flip).

# %%
n = 64 if FULL else 8
slopes = np.linspace(3.0, 5.0, n)
fam = vj.period1_family(np.radians(slopes), "stable")
tr, pc = multipliers(np.radians(slopes), np.asarray(fam.z))
rho = np.max(np.abs(tr), axis=1)
for s, r, d in zip(slopes, rho, np.max(np.abs(tr - pc), axis=1)):
    print(
        f"  {s:5.2f} deg: spectral radius {r:.4f} ({'stable' if r < 1 else 'unstable'}),"
        f" transverse - Poincare {d:.1e}"
    )

# %% [markdown]
# ## The period-doubling slope
# `det(I + J)` changes sign where a real multiplier crosses -1; refine the bracket found
# on the grid with regula falsi (`period_doubling_slope`, full mode) or by three more
# grids of B slopes through the same compiled call (quick mode; each one narrows the
# bracket 7-fold).

# %%
i = int(np.argmax(rho >= 1)) - 1
if FULL:
    pd = vj.period_doubling_slope(
        math.radians(slopes[i]), math.radians(slopes[i + 1]), np.asarray(fam.z[i])
    )
    pd_deg = math.degrees(pd.psi)
    print("multipliers at the flip:", np.round(pd.multipliers, 5))
else:
    a, b = slopes[i], slopes[i + 1]
    for _ in range(3):
        s = np.linspace(a, b, B)
        f = vj.period1_family(np.radians(s), "stable")
        t, _ = multipliers(np.radians(s), np.asarray(f.z))
        det = np.prod(1 + t, axis=1).real
        k = int(np.where(np.sign(det[:-1]) != np.sign(det[1:]))[0][0])
        a, b = s[k], s[k + 1]
    pd_deg = 0.5 * (a + b)
    print(f"bracket: {a:.5f} to {b:.5f} deg")
print(f"period doubling at {pd_deg:.5f} deg (thesis: 'about 4.4')")

# %% [markdown]
# ## Bifurcation diagram
# Long batched simulations from the period-1 gait at each slope; the step periods of the
# last steps against slope (Goswami et al. 1998). Quick mode: few slopes and short runs.

# %%
nb = 128 if FULL else 8
sb = np.linspace(4.0, 5.3, nb)
fb = vj.period1_family(np.radians(sb), "stable")
diag = vj.bifurcation_diagram(
    np.radians(sb),
    np.asarray(fb.z),
    num_transient=300 if FULL else 40,
    num_record=64 if FULL else 16,
)
print(
    "pattern (steps per repetition; 0 aperiodic or unsettled, -1 fell):",
    {round(float(a), 2): int(p) for a, p in zip(sb, diag.period_pattern)},
)
path = os.path.join(OUT, "03_bifurcation.png")
fig = plotting.plot_bifurcation(
    diag, [("period 1", sb, np.asarray(fb.periods), sb < pd_deg)], path, flips_deg=[pd_deg]
)
print("wrote", path)
