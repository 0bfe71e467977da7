# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
# ---

# %% [markdown]
# # Orbital stabilization of unstable gaits by a hip torque
#
# The thesis ends with the remark (section 7.5) that its unstable gaits "can be stabilized
# and used to generate new walking motions for the actuated biped" with a controller from
# the transverse linearization. Here the compass gait gets a hip torque $u$ (equal and
# opposite on the two legs); along a gait the transverse linearization with input
# $\dot\zeta = A(s)\zeta + B(s)u$, $\zeta^+ = J\zeta^-$ gives an LQR gain $K(s)$ from the
# periodic hybrid Riccati equation (Shiriaev et al. 2008; Freidovich, Shiriaev and
# Manchester 2008; Manchester 2011), and $u = -K(s)\zeta$ holds the walker on the passive
# gait, with zero torque on the gait itself.
#
# Two gaits: the unstable period-1 gait at 3 degrees (a multiplier near 4.3) and the
# symmetric period-1 gait at 5 degrees, past its period doubling (unstable through a
# flip, a multiplier below -1). `VHCJAX_FULL=1` for full-size basins.

# %%
import math
import os
import tempfile

import jax
import numpy as np

import vhcjax as vj

FULL = os.environ.get("VHCJAX_FULL") == "1"
# Figures go to $VHCJAX_NOTEBOOK_OUT, or to a fresh temporary folder: never into the
# repository.
OUT = os.environ.get("VHCJAX_NOTEBOOK_OUT") or tempfile.mkdtemp(prefix="vhcjax_06_")
os.makedirs(OUT, exist_ok=True)

cases = {}
for name, deg, family in (("unstable 3 deg", 3.0, "unstable"), ("symmetric 5 deg", 5.0, "stable")):
    model = vj.CompassGait(psi=math.radians(deg))
    fam = vj.period1_family([math.radians(deg)], family)
    cases[name] = (model, fam.z[0])
    print(name, "gait z* =", np.round(np.asarray(fam.z[0]), 7))

# %% [markdown]
# ## Riccati solution and closed-loop multipliers, each two ways
# `stabilize` solves the Riccati equation by backward iteration and, independently,
# from the stable subspace of the Hamiltonian monodromy; the closed-loop multipliers come
# from the autodiff Poincare map of the controlled walker and from the transverse
# monodromy $J\Phi_{cl}$.

# %%
stab = {}
for name, (model, z) in cases.items():
    st = vj.stabilize(model, z)
    stab[name] = st
    print(
        f"{name}: Riccati two ways agree to {float(st.riccati_agreement):.1e}, "
        f"max gain {float(st.max_gain):.1f}"
    )
    print("  open loop  ", np.round(np.asarray(st.open_loop_multipliers), 6))
    print("  closed loop", np.round(np.asarray(st.closed_loop_multipliers), 6), "(Poincare)")
    print(
        "             ",
        np.round(np.asarray(st.closed_loop_multipliers_transverse), 6),
        "(transverse)",
    )

# %% [markdown]
# ## Recovery from a perturbation
# Every post-impact section coordinate perturbed by 0.01: the controlled walker returns
# to the unstable gait, the passive one leaves it.

# %%
errors = {}
for name, (model, z) in cases.items():
    x0 = model.section_to_state(z + 1e-2)
    out = []
    for fb in (stab[name].feedback, vj.ZeroFeedback()):
        sim = vj.simulate_closed_loop(model, x0, fb, 30)
        zs = np.asarray(jax.vmap(model.state_to_section)(sim.steps.x_plus))
        out.append(np.max(np.abs(zs - np.asarray(z)), axis=1))
        if isinstance(fb, vj.TransverseFeedback):
            print(
                f"{name}: largest torque {float(np.max(sim.max_abs_torque)):.3f} N m, "
                f"error after 30 steps {out[-1][-1]:.2e}"
            )
        else:
            print(f"{name}: passive walker, error after 30 steps {out[-1][-1]:.2e}")
    errors[name] = out

# %% [markdown]
# ## Basins with and without feedback, and with a torque limit
# A slice over $(q_1, \dot q_1)$ just after impact: the passive walker never returns to
# an unstable gait; with feedback a large region does. How large depends on the torque
# limit: the printed fractions of the slice's points that return, per limit (at the
# quick 9 x 9 grid one point is 1.2 % of the slice).

# %%
shape = (41, 41) if FULL else (9, 9)
kw = {
    "half_widths": (0.05, 0.3),
    "shape": shape,
    "num_steps": 25,
    "torque_points": 8,
    "config": vj.FAST_CONFIG,
}
for name, (model, z) in cases.items():
    st = stab[name]
    bp = vj.closed_loop_basin(model, vj.ZeroFeedback(), z, **kw)
    fractions = {}
    for lim in (0.5, 2.0, 8.0, math.inf):
        b = vj.closed_loop_basin(model, vj.with_torque_limit(st.feedback, lim), z, **kw)
        fractions[lim] = float(b.fraction)
    bc = vj.closed_loop_basin(model, st.feedback, z, **kw)
    limits = ", ".join(
        f"{'none' if math.isinf(k) else f'{k:g} N m'}: {v:.3f}" for k, v in fractions.items()
    )
    print(f"{name}: fraction returning, passive {float(bp.fraction):.3f}")
    print(f"  with feedback, by torque limit: {limits}")
    basin = {
        "z_star": np.asarray(z),
        "offsets_x": np.asarray(bc.offsets_x),
        "offsets_y": np.asarray(bc.offsets_y),
        "closed": np.asarray(bc.converged),
        "passive": np.asarray(bp.converged),
    }
    fname = os.path.join(OUT, "06_" + name.replace(" ", "_") + ".png")
    vj.plotting.plot_stabilization(
        fname,
        f"Compass gait, {name} gait, hip-torque LQR",
        np.asarray(st.system.s),
        np.asarray(st.riccati.K),
        errors[name][0],
        errors[name][1],
        basin,
    )
    print("wrote", fname)
