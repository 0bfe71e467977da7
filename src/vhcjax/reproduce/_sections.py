"""The sections of `vhcjax reproduce`, one function per section of thesis chapter 7 and
per analysis of the library: `fn(run, sec)` computes, fills the report `Section` `sec`
and writes its figures into `run.out_dir`; what later sections reuse (the gaits of
chapter 7, their multipliers, the period-doubling slope) goes into the `Run`.

Compilation dominates the run time, so the sections share a few jitted entry points
with fixed batch shapes: `find_gaits` (batches of 8), the slope sweep (`vhcjax.sweep`),
`family_multipliers` (chunks of 8), one `simulate` shape, `jacobian`/`step_map` (k = 1).
"""

import dataclasses
import math
import os

import jax
import jax.numpy as jnp
import numpy as np

from .._results import RESULTS, result_codes, result_names
from ..gait import find_gaits, sweep
from ..hybrid import simulate
from ..models import CompassGait
from ..stability import (
    bifurcation_diagram,
    family_multipliers,
    period_doubling_slopes_from_diagram,
    period_k_orbit,
)
from ._report import THESIS

CHUNK = 8  # batch size of the family_multipliers calls (one program for all)
GUESS = (0.20, -1.0)  # thesis (7.2)


def _deg(x):
    return math.radians(x)


def _model(slope_deg):
    return CompassGait(psi=jnp.asarray(_deg(slope_deg)))


def _gaits(slopes_deg, guesses, family, method):
    """Gaits at `slopes_deg` from `guesses` (B, 2; `None`: from the model's reference gait)
    by `method` (`find_gaits`'s): one call (padded to
    a power of two, so that short vectors share one program; a single slope is sent
    twice, since `find_gaits` runs one member by a program of its own); numpy pytree."""
    slopes = np.atleast_1d(np.asarray(slopes_deg, float))
    n = len(slopes)
    if guesses is not None:
        guesses = np.broadcast_to(np.asarray(guesses, float), (n, 2))
    if n == 1:
        slopes = np.repeat(slopes, 2)
        guesses = None if guesses is None else np.repeat(guesses, 2, axis=0)
    guesses = None if guesses is None else jnp.asarray(guesses)
    g = find_gaits(CompassGait(), guesses, family, method, psi=jnp.radians(slopes))
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], g)


def _family(slopes_deg, family, method):
    """The `family` over `slopes_deg` by the library's slope sweep (`vhcjax.sweep`, by
    `method`): the `Sweep` and its gaits as a numpy pytree."""
    slopes = np.radians(np.asarray(slopes_deg, float))
    sw = sweep(CompassGait(), slopes, family, method, tangents=False)
    return sw, jax.tree_util.tree_map(np.asarray, sw.gaits)


def _member(g, i):
    return jax.tree_util.tree_map(lambda x: x[i] if isinstance(x, np.ndarray) else x, g)


def _multipliers(slopes_deg, zs):
    """Transverse and Poincare multipliers (and the hybrid step's period and x_minus) of
    period-1 gaits: `family_multipliers` on chunks of `CHUNK` (one program for all)."""
    slopes = np.atleast_1d(np.asarray(slopes_deg, float))
    zs = np.atleast_2d(np.asarray(zs, float))
    parts = [
        family_multipliers(CompassGait(), np.radians(slopes[s : s + CHUNK]), zs[s : s + CHUNK])
        for s in range(0, len(slopes), CHUNK)
    ]
    m = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)
    return {
        "transverse": m.transverse,
        "poincare": m.poincare,
        "period": m.period,
        "x_minus": m.x_minus,
        "result": result_codes(m.result),
    }


def _sim(model, x0, sizes, dense=True):
    """One simulation shape for every section (one compile)."""
    return simulate(
        model,
        jnp.asarray(x0, float),
        sizes["sim_steps"],
        dense_points=sizes["dense"] if dense else sizes["dense"],
    )


def _sorted_ev(ev):
    ev = np.asarray(ev)
    return ev[np.argsort(-np.abs(ev))]


def _split_ev(ev):
    """(real eigenvalue, re of the complex pair, |im| of the pair) of a 3-vector with
    one complex pair; None if all are real."""
    ev = np.asarray(ev)
    cplx = ev[np.abs(np.imag(ev)) > 1e-12]
    real = ev[np.abs(np.imag(ev)) <= 1e-12]
    if len(cplx) != 2 or len(real) != 1:
        return None
    return float(real[0].real), float(cplx[0].real), float(abs(cplx[0].imag))


def _c(ev):
    return [[float(e.real), float(e.imag)] for e in np.atleast_1d(ev)]


def _close(fig):
    import matplotlib.pyplot as plt

    plt.close(fig)


def _sim_figures(sim, out_dir, stem, sec, case):
    from .. import plotting as P

    for kind, fn in (
        ("states", P.plot_states),
        ("phase", P.plot_phase_portrait),
        ("periods", P.plot_step_periods),
    ):
        name = f"{stem}_{kind}.png"
        fn(sim, path=os.path.join(out_dir, name), case=case)
        sec.figures.append(name)


def _five_figures(sims, out_dir, sec):
    """Step periods of the whole run from (7.14) (Fig 7.12); states and phase portrait of
    the first simulation (leaving the period-1 gait) and of the last (the attractor)."""
    from types import SimpleNamespace

    from .. import plotting as P

    periods = np.concatenate([np.asarray(s.steps.period)[: int(s.num_successful)] for s in sims])
    fake = SimpleNamespace(num_successful=len(periods), steps=SimpleNamespace(period=periods))
    name = "fig7_12_five_deg_periods.png"
    fig = P.plot_step_periods(
        fake, case="stable family at 5 deg (unstable period 1), from (7.14); thesis Fig 7.12"
    )
    fig.savefig(os.path.join(out_dir, name), dpi=120, bbox_inches="tight")
    _close(fig)
    sec.figures.append(name)
    for label, sim in (("start", sims[0]), ("attractor", sims[-1])):
        for kind, fn in (("states", P.plot_states), ("phase", P.plot_phase_portrait)):
            name = f"fig7_13_14_five_deg_{label}_{kind}.png"
            fn(
                sim,
                path=os.path.join(out_dir, name),
                case=f"5 deg, from (7.14), {'first steps' if label == 'start' else 'attractor'}",
            )
            sec.figures.append(name)


def _multiplier_figure(sets, labels, out_dir, name, title, sec):
    from ..plotting import plot_multipliers_complex

    fig = plot_multipliers_complex(sets, labels, os.path.join(out_dir, name), title=title)
    _close(fig)
    sec.figures.append(name)


def _gait_rows(sec, g, eq_abcd, eq_state, check):
    for k in "abcdefgh":
        sec.compare(k, eq_abcd, k, float(getattr(g, k)), check)
    if eq_state:
        for k, v in (("q1", g.a), ("q2", g.e), ("dq1", g.b), ("dq2", g.f)):
            sec.compare(f"{k}*(0)", eq_state, k, float(v), check)


def _return_check(g, mult, i):
    """VHC gait vs one step of the hybrid simulator (in `_multipliers`): pre-impact state
    and period."""
    dx = float(np.max(np.abs(mult["x_minus"][i] - np.asarray(g.x_minus))))
    dT = float(abs(mult["period"][i] - float(g.T)))
    return dx, dT


def _ev_check(mult, i):
    return float(
        np.max(np.abs(_sorted_ev(mult["transverse"][i]) - _sorted_ev(mult["poincare"][i])))
    )


#: The gaits of chapter 7 (`Run.gaits` keys) in words.
GAIT_WORDS = {
    "stable3": "stable gait at 3 deg",
    "unstable3": "unstable gait at 3 deg",
    "stable5": "stable family at 5 deg",
    "stable287": "stable gait at 2.87 deg",
    "stable43": "stable gait at 4.3 deg",
    "uphill": "uphill seed at 3 deg",
}


#: `Gait.found_by` in words.
METHOD_WORDS = {"vhc": "the VHC search", "shooting": "shooting"}


def _found_by(g, name):
    """The method that found the gait `g` (`None` where its search failed)."""
    return g.found_by if name == "successful" else None


def _result_words(name):
    """A search's result code in words: `"found"`, else the code's description."""
    if name == "successful":
        return "found"
    return f"{name.replace('_', ' ')} ({RESULTS[getattr(RESULTS, name)].rstrip('.')})"


@dataclasses.dataclass
class Run:
    """What the sections share: where figures go, the sizes of the mode, and the results
    later sections reuse."""

    out_dir: str
    sizes: dict
    #: The gait search (`find_gaits`' `method`: "auto", "vhc" or "shooting").
    method: str = "auto"
    #: The gaits of chapter 7 (numpy `Gait`s): stable3, unstable3, stable5, stable287,
    #: stable43 (the flip bracket's lower end) and uphill.
    gaits: dict = dataclasses.field(default_factory=dict)
    #: Multipliers, period and x_minus of the period-1 gaits (rows by `mult_index`).
    mult: dict = dataclasses.field(default_factory=dict)
    mult_index: dict = dataclasses.field(default_factory=dict)
    #: The period-doubling slope (deg), once located.
    pd_deg: float = math.nan


# ---- 1: the gaits of chapter 7 in one batched VHC search --------------------------
def gaits(run, sec):
    # stable family: 3 deg (7.4), 5 deg (7.13), 2.87 deg (7.1), 4.30 deg (flip bracket),
    # and the uphill seed (7.17) with the same (minus) root
    # The thesis seeds are seeds of Problem 1 (the VHC search); shooting alone starts
    # from the model's reference gait instead (continuation in the slope). The uphill
    # solution (7.17)-(7.18) is one of Problem 1: always the VHC search's.
    stable = [3.0, 5.0, 2.87, 4.3]
    if run.method == "shooting":
        st = _gaits(stable, None, "stable", "shooting")
        up = _member(_gaits([3.0], [(0.20, 1.0)], "stable", "vhc"), 0)
        un = _gaits([3.0], None, "unstable", "shooting")
    else:
        seeds = [GUESS, GUESS, GUESS, GUESS, (0.20, 1.0)]
        st = _gaits([*stable, 3.0], seeds, "stable", run.method)
        up = _member(st, 4)
        un = _gaits([3.0], [GUESS], "unstable", run.method)
    run.gaits["stable3"], run.gaits["stable5"], run.gaits["stable287"], run.gaits["stable43"] = (
        _member(st, i) for i in range(4)
    )
    run.gaits["uphill"] = up
    run.gaits["unstable3"] = _member(un, 0)
    slopes = [3.0, 3.0, 5.0, 2.87]
    keys = ["stable3", "unstable3", "stable5", "stable287"]
    zs = np.stack([np.asarray(run.gaits[k].z) for k in keys])
    run.mult = _multipliers(slopes, zs)
    run.mult_index = {k: i for i, k in enumerate(keys)}
    names = {k: result_names(run.gaits[k].result) for k in keys + ["uphill"]}
    sec.results = {
        k: {
            p: float(getattr(run.gaits[k], p))
            for p in ("a", "b", "c", "d", "e", "f", "g", "h", "T", "E0", "residual")
        }
        | {"result": names[k], "found_by": _found_by(run.gaits[k], names[k])}
        for k in keys + ["uphill"]
    }
    for k in keys:
        i = run.mult_index[k]
        dx, dT = _return_check(run.gaits[k], run.mult, i)
        sec.results[k]["hybrid_step_x_minus_diff"] = dx
        sec.results[k]["hybrid_step_period_diff"] = dT
    sec.text(
        "search results",
        "-",
        "; ".join(
            f"{GAIT_WORDS[k]}: {_result_words(v)}"
            + (f" by {METHOD_WORDS[run.gaits[k].found_by]}" if v == "successful" else "")
            for k, v in names.items()
        ),
        "computed",
        "the uphill seed is expected to give no passive gait (thesis 7.17-7.18)",
    )
    how = {
        "auto": "the VHC search (thesis Problem 1), with shooting (Problem 2) for any gait "
        "it misses",
        "vhc": "the VHC search (thesis Problem 1) alone",
        "shooting": "shooting (thesis Problem 2) alone",
    }[run.method]
    seeds = (
        "from the model's reference gait, continued in the slope (the thesis seeds are "
        "seeds of Problem 1); the uphill seed (7.17) by the VHC search, since (7.18) is a "
        "solution of Problem 1"
        if run.method == "shooting"
        else "from the thesis seed (7.2) a0 = 0.20, b0 = -1.0 (uphill: b0 = +1.0, 7.17), "
        "with the minus root of (5.13) (7.3) for the stable family and the plus root (7.8) "
        "for the unstable one"
    )
    sec.notes.append(
        f"The gaits of chapter 7 come from batched calls of `find_gaits` ({how}; the "
        f"search results name the method that found each gait), {seeds}; the slope "
        "sweeps and the bifurcation diagram follow the families with `vhcjax.sweep`."
    )


# ---- 2: stable gait at 3 degrees (7.4), (7.5), period ----------------------------
def stable3(run, sec):
    g = run.gaits["stable3"]
    i = run.mult_index["stable3"]
    dx, dT = _return_check(g, run.mult, i)
    check = f"hybrid step from (a,b,e,f) lands on (c,d,g,h) to {dx:.1e}"
    _gait_rows(sec, g, "7.4", "7.5", check)
    sec.compare(
        "step period T (s)",
        "T",
        "T",
        float(g.T),
        f"hybrid simulator period differs by {dT:.1e} s",
        digits=9,
    )
    sec.value("energy E0 (J)", float(g.E0), "energy of the post-impact state (5.10)")
    sec.value("step length (m)", float(g.step_length), "from the impact configuration")
    sec.value("speed (m/s)", float(g.speed), "step length / T")
    sec.notes.append(
        "The thesis's last digits of the velocities (b, d, f and especially h) are the "
        "inaccurate ones: it used fminsearch and ode45 with abstol 1e-6; ours solve the "
        "VHC boundary problem to 1e-12 and are confirmed by the hybrid simulator."
    )


# ---- 3: eigenvalues (7.6) --------------------------------------------------------
def eig3(run, sec):
    m = run.mult
    i = run.mult_index["stable3"]
    tr, pc = _sorted_ev(m["transverse"][i]), _sorted_ev(m["poincare"][i])
    diff = _ev_check(m, i)
    sp = _split_ev(tr)
    assert sp is not None  # the stable 3-deg gait has a complex pair (thesis 7.6)
    check = f"transverse linearization = Poincare-map Jacobian (autodiff) to {diff:.1e}"
    sec.compare("lambda1 (real)", "7.6", "lambda1", sp[0], check, 6)
    sec.compare("Re lambda2,3", "7.6", "re_lambda23", sp[1], check, 6)
    sec.compare("|Im lambda2,3|", "7.6", "abs_im_lambda23", sp[2], check, 6)
    sec.value("spectral radius", float(np.max(np.abs(tr))), check, 6)
    sec.value(
        "det Xi (ours) / thesis product 0.04422",
        float(np.prod(tr).real),
        "product of the thesis eigenvalues: 0.04422",
        5,
    )
    sec.results = {"transverse": _c(tr), "poincare": _c(pc), "max_diff": diff}
    _multiplier_figure(
        [tr, pc, np.array([0.123, 0.127 - 0.586j, 0.127 + 0.586j])],
        ["transverse linearization", "Poincare (autodiff)", "thesis (7.6)"],
        run.out_dir,
        "fig7_1_multipliers_stable_3deg.png",
        "stable gait, 3 deg (thesis Fig 7.1)",
        sec,
    )
    sec.notes.append(
        "The thesis eigenvalues (7.6) differ from ours; our two independent computations "
        "(transverse linearization rebuilt from the VHC, and the Jacobian of the hybrid "
        "step map by forward-mode autodiff through the heel-strike event) agree, and "
        "the test suite also checks them against central finite differences of the step "
        "map and a second Poincare section (docs/stability.md)."
    )


# ---- 4: unperturbed and perturbed simulations (Figs 7.2-7.7, 7.7) -----------------
def simulations(run, sec):
    g = run.gaits["stable3"]
    model = _model(3.0)
    x_star = np.array([float(g.a), float(g.e), float(g.b), float(g.f)])
    sim = _sim(model, x_star, run.sizes)
    T = np.asarray(sim.steps.period)
    drift = float(np.max(np.abs(np.asarray(sim.steps.x_plus) - x_star)))
    sec.value(
        "steps simulated from the gait",
        int(sim.num_successful),
        f"result {result_names(sim.result)}",
        4,
    )
    sec.value(
        "max |x+ - x*| over all steps (rad, rad/s)",
        drift,
        "stays on the gait: the VHC gait is a fixed point of the simulator",
        3,
    )
    sec.compare(
        "step period (simulated, s)",
        "T",
        "T",
        float(np.mean(T)),
        f"spread over {len(T)} steps {np.ptp(T):.1e} s",
        9,
    )
    _sim_figures(sim, run.out_dir, "fig7_2_4_stable_3deg", sec, "stable gait, 3 deg")
    # perturbed start (7.7): our gait + 0.01 on every component, as the thesis
    x_pert = x_star + 0.01
    for k, idx in (("q1", 0), ("q2", 1), ("dq1", 2), ("dq2", 3)):
        sec.compare(f"perturbed {k}(0)", "7.7", k, float(x_pert[idx]), "our (7.5) + 0.01", 7)
    simp = _sim(model, x_pert, run.sizes)
    xp = np.asarray(simp.steps.x_plus)
    err = np.max(np.abs(xp - x_star), axis=1)
    ok = int(simp.num_successful)
    tol = 1e-3
    conv = next((k for k in range(ok) if np.all(err[k:ok] < tol)), None)
    t_imp = np.cumsum(np.asarray(simp.steps.period))
    # decay per step from the simulation vs the spectral radius
    rho = float(np.max(np.abs(run.mult["transverse"][0])))
    sel = [k for k in range(1, ok) if 1e-8 < err[k] < 1e-3]
    rate = float(np.exp(np.polyfit(sel, np.log(err[sel]), 1)[0])) if len(sel) >= 4 else float("nan")
    check = f"error decays by {rate:.3f} per step in the simulation; spectral radius {rho:.3f}"
    sec.compare(
        f"steps until within {tol:g} of the gait",
        "conv",
        "steps",
        None if conv is None else conv + 1,
        check,
        3,
    )
    sec.compare(
        "seconds until within 1e-3",
        "conv",
        "seconds",
        None if conv is None else float(t_imp[conv]),
        check,
        3,
    )
    sec.value(
        "final |x+ - x*| of the perturbed run",
        float(err[ok - 1]),
        f"{ok} steps, result {result_names(simp.result)}",
        3,
    )
    sec.results = {
        "unperturbed_periods": T,
        "unperturbed_drift": drift,
        "perturbed_error": err,
        "perturbed_periods": np.asarray(simp.steps.period),
        "steps_to_1e-3": conv,
        "decay_rate_simulated": rate,
        "spectral_radius": rho,
    }
    _sim_figures(simp, run.out_dir, "fig7_5_7_perturbed_3deg", sec, "3 deg, perturbed start (7.7)")
    sec.notes.append(
        'The thesis\'s convergence times ("approximately 10 steps", "7 seconds") do '
        "not state a tolerance; ours use 1e-3 (max-norm of the post-impact state, a 10x "
        "reduction of the 0.01 perturbation), so only the order of magnitude compares."
    )


# ---- 5: unstable gait at 3 degrees (7.9)-(7.11), Figs 7.8-7.11 ---------------------
def unstable3(run, sec):
    g = run.gaits["unstable3"]
    m = run.mult
    i = run.mult_index["unstable3"]
    dx, dT = _return_check(g, m, i)
    _gait_rows(sec, g, "7.9", "7.10", f"hybrid step lands on (c,d,g,h) to {dx:.1e}")
    tr, pc = _sorted_ev(m["transverse"][i]), _sorted_ev(m["poincare"][i])
    diff = _ev_check(m, i)
    # simulate from the thesis's printed (7.10) (rounded: leaves the unstable gait)
    model = _model(3.0)
    x_star = np.array([float(g.a), float(g.e), float(g.b), float(g.f)])
    x_t = np.array([float(THESIS["7.10"][k]) for k in ("q1", "q2", "dq1", "dq2")])
    sim = _sim(model, x_t, run.sizes)
    err = np.max(np.abs(np.asarray(sim.steps.x_plus) - x_star), axis=1)
    ok = int(sim.num_successful)
    sel = [k for k in range(ok) if 1e-6 < err[k] < 1e-2]
    growth = (
        float(np.exp(np.polyfit(sel, np.log(err[sel]), 1)[0])) if len(sel) >= 3 else float("nan")
    )
    check = f"transverse = Poincare to {diff:.1e}; simulated growth per step {growth:.2f}"
    for k, ev in zip(("lambda3", "lambda2", "lambda1"), tr):
        sec.compare(k, "7.11", k, float(ev.real), check, 6)
    sec.results = {
        "transverse": _c(tr),
        "poincare": _c(pc),
        "max_diff": diff,
        "simulated_growth_per_step": growth,
        "error": err,
        "result": result_names(sim.result),
    }
    _multiplier_figure(
        [tr, pc, np.array([0.066, 0.408, 4.857])],
        ["transverse linearization", "Poincare (autodiff)", "thesis (7.11)"],
        run.out_dir,
        "fig7_8_multipliers_unstable_3deg.png",
        "unstable gait, 3 deg (thesis Fig 7.8)",
        sec,
    )
    _sim_figures(sim, run.out_dir, "fig7_9_11_unstable_3deg", sec, "unstable gait, 3 deg")
    sec.notes.append(
        f"Simulated from the thesis's printed (7.10) (6 decimals, so ~1e-6 off the gait): "
        f"the error grows by about {growth:.2f} per step (our largest multiplier "
        f"{abs(tr[0]):.3f}, thesis 4.857) until the walker leaves the gait; "
        f"after {ok} steps: {result_names(sim.result)}, final distance to the unstable "
        f"gait {err[ok - 1]:.2g}."
    )


# ---- 6: 5 degrees (7.13)-(7.16), Figs 7.12-7.15 -----------------------------------
def five(run, sec):
    S = run.sizes
    g = run.gaits["stable5"]
    m = run.mult
    i = run.mult_index["stable5"]
    dx, dT = _return_check(g, m, i)
    _gait_rows(sec, g, "7.13", "7.14", f"hybrid step lands on (c,d,g,h) to {dx:.1e}")
    tr, pc = _sorted_ev(m["transverse"][i]), _sorted_ev(m["poincare"][i])
    diff = _ev_check(m, i)
    check = f"transverse = Poincare to {diff:.1e} (period-1 gait: unstable)"
    sp = _split_ev(tr)
    if sp is None:  # ours are all real: compare the smallest with lambda1
        sec.compare("lambda1 (real)", "7.16", "lambda1", float(tr[-1].real), check, 6)
        sec.compare("Re lambda2,3", "7.16", "re_lambda23", float(tr[1].real), check, 6)
        sec.compare("|Im lambda2,3|", "7.16", "abs_im_lambda23", 0.0, check, 6)
    else:
        sec.compare("lambda1 (real)", "7.16", "lambda1", sp[0], check, 6)
        sec.compare("Re lambda2,3", "7.16", "re_lambda23", sp[1], check, 6)
        sec.compare("|Im lambda2,3|", "7.16", "abs_im_lambda23", sp[2], check, 6)
    sec.value("largest multiplier of the period-1 gait", float(tr[0].real), check, 6)
    # the attractor: simulate from (7.14), then Newton on P^4 (k=1 maps composed)
    model = _model(5.0)
    x_t = np.array([float(THESIS["7.14"][k]) for k in ("q1", "q2", "dq1", "dq2")])
    sims = [_sim(model, x_t, S)]
    for _ in range(S["settle_rounds"]):
        sims.append(_sim(model, np.asarray(sims[-1].steps.x_plus)[-1], S))
    if any(result_names(s.result) != "successful" for s in sims):
        sec.notes.append("The simulation from (7.14) did not complete all steps.")
    _five_figures(sims, run.out_dir, sec)
    x = np.asarray(sims[-1].steps.x_plus)[-1]
    z = np.asarray(model.state_to_section(jnp.asarray(x)))
    o4 = period_k_orbit(model, z, 4)
    p4 = {
        "z": o4.z,
        "periods": o4.periods,
        "residual": o4.residual,
        "multipliers": o4.multipliers,
        "multipliers_fd": o4.multipliers_fd,
    }
    # cross-check: the hybrid simulator from the orbit's first point returns after 4
    simc = _sim(model, np.asarray(model.section_to_state(jnp.asarray(p4["z"]))), S, dense=False)
    zc = np.asarray(jax.vmap(model.state_to_section)(simc.steps.x_plus))
    ret = float(np.max(np.abs(zc[3] - p4["z"])))
    ret1 = float(np.max(np.abs(zc[0] - p4["z"])))
    minimal = 4 if ret1 > 1e-6 and float(np.max(np.abs(zc[1] - p4["z"]))) > 1e-6 else 0
    sec.compare(
        "minimal period of the attracting gait (steps)",
        "7.15",
        "period",
        minimal if p4["residual"] < 1e-9 else None,
        f"simulator returns after 4 steps to {ret:.1e}; not after 1 or 2 ({ret1:.1e})",
        2,
    )
    ev4 = p4["multipliers"]
    fd_diff = float(np.max(np.abs(ev4 - p4["multipliers_fd"])))
    for j, ev in enumerate(ev4):
        sec.value(
            f"P^4 multiplier {j + 1} (Re)",
            float(ev.real),
            f"autodiff vs central finite differences {fd_diff:.1e}",
            6,
        )
    for j, T in enumerate(p4["periods"]):
        sec.value(
            f"period-4 gait step {j + 1} period (s)",
            float(T),
            "simulator step periods from the orbit point: "
            f"{float(np.asarray(simc.steps.period)[j]):.6f}",
            7,
        )
    sec.results = {
        "transverse": _c(tr),
        "poincare": _c(pc),
        "max_diff": diff,
        "period4": {k: (_c(v) if k.startswith("multipliers") else v) for k, v in p4.items()},
        "period4_return": ret,
    }
    _multiplier_figure(
        [tr, pc, ev4, np.array([0.092, -0.346 - 0.429j, -0.346 + 0.429j])],
        [
            "period-1 gait: transverse",
            "period-1 gait: Poincare (autodiff)",
            "period-4 gait: multipliers of P^4",
            "thesis (7.16)",
        ],
        run.out_dir,
        "fig7_15_multipliers_5deg.png",
        "5 deg (thesis Fig 7.15)",
        sec,
    )
    sec.notes.append(
        "(7.13)/(7.14) is the symmetric period-1 gait (c = e, g = a), our stable family "
        "at 5 deg, past the period-doubling slope: its multiplier below -1 makes it "
        "unstable (as the thesis's own Fig 7.12 shows: it leaves after a few impacts). "
        "The walker settles on a stable gait of minimal period 4 (found by Newton on "
        "P^4 from the settled simulation); the thesis's eigenvalues (7.16) belong to "
        "neither."
    )


# ---- 7: uphill infeasible solution (7.17)-(7.18) ----------------------------------
def uphill(run, sec):
    g = run.gaits["uphill"]
    u = run.gaits["unstable3"]
    rev = float(np.max(np.abs(np.array([g.a - u.a, g.e - u.e, g.b + u.b, g.f + u.f]))))
    name = result_names(g.result)
    sec.text(
        "result code",
        "non-feasible",
        name,
        "agrees" if name == "infeasible_uphill" else "differs",
        f"residual {float(g.residual):.1e}",
    )
    check = f"= unstable gait (7.10) with velocities reversed, to {rev:.1e}"
    for k, v in (("q1", g.a), ("q2", g.e), ("dq1", g.b), ("dq2", g.f)):
        sec.compare(f"{k}*(0)", "7.18", k, float(v), check, 7)
    sec.results = {
        "result": name,
        "residual": float(g.residual),
        "z": np.asarray(g.z),
        "reversal_diff": rev,
    }


# ---- 8: ref [5] gait at 2.87 deg (7.1) ---------------------------------------------
def ref5(run, sec):
    g = run.gaits["stable287"]
    i = run.mult_index["stable287"]
    dx, dT = _return_check(g, run.mult, i)
    check = f"hybrid step lands on (c,d,g,h) to {dx:.1e}"
    for k, v in (("q1", g.a), ("q2", g.e), ("dq1", g.b), ("dq2", g.f)):
        sec.compare(f"{k}*(0)", "7.1", k, float(v), check, 7)
    tr = _sorted_ev(run.mult["transverse"][i])
    sec.value(
        "spectral radius",
        float(np.max(np.abs(tr))),
        f"transverse = Poincare to {_ev_check(run.mult, i):.1e}",
        5,
    )
    sec.results = {"z": np.asarray(g.z), "T": float(g.T), "multipliers": _c(tr)}
    sec.notes.append(
        "Ref. [5]'s values are printed to 5 decimals; the stable gait at "
        "2.87 deg (our VHC search from the thesis seed)."
    )


# ---- 9: slope sweeps of both families ---------------------------------------------
def sweeps(run, sec):
    S = run.sizes
    n = S["sweep_n"]
    slopes = np.linspace(*S["sweep_range"], num=n)
    sw, mults = {}, {}
    for fam in ("stable", "unstable"):
        sw[fam], g = _family(slopes, fam, run.method)
        ok = np.array(result_names(g.result)) == "successful"
        z = np.asarray(g.z)
        mm = _multipliers(slopes, z)
        mults[fam] = (ok, mm)
        xm = np.max(np.abs(mm["x_minus"] - np.asarray(g.x_minus)), axis=1)
        evd = np.max(
            np.abs(np.sort_complex(mm["transverse"]) - np.sort_complex(mm["poincare"])), axis=1
        )
        rho = np.max(np.abs(mm["transverse"]), axis=1)
        sec.value(
            f"{fam} family: slopes found",
            int(ok.sum()),
            f"of {n} in {slopes[0]:g}..{slopes[-1]:g} deg; hybrid step lands on the "
            "VHC pre-impact state "
            f"to {np.max(xm[ok]):.1e}",
            3,
        )
        sec.value(
            f"{fam} family: max |transverse - Poincare|",
            float(np.max(evd[ok])),
            "two independent multiplier computations at every slope",
            2,
        )
        if fam == "unstable":
            all_unstable = bool(np.all(rho[ok] > 1)) and ok.all()
            sec.text(
                f"unstable family: exists and is unstable on [{slopes[0]:g}, 6] deg "
                "(thesis: (0, 6])",
                "yes",
                "yes" if all_unstable else "no",
                "agrees" if all_unstable else "differs",
                f"min spectral radius {np.min(rho[ok]):.3f} (> 1)",
            )
        else:
            st = rho < 1
            last = slopes[ok & st].max() if np.any(ok & st) else float("nan")
            sec.value(
                "stable family: last stable slope on the grid (deg)",
                last,
                "see the period-doubling section for the exact slope",
                4,
            )
        sec.results[fam] = {
            "slopes_deg": slopes,
            "ok": ok,
            "a": g.a,
            "b": g.b,
            "f": g.f,
            "T": g.T,
            "speed": g.speed,
            "spectral_radius": rho,
            "max_ev_diff": evd,
            "max_x_minus_diff": xm,
        }
    from ..plotting import plot_multipliers_vs_slope, plot_sweep

    fig = plot_sweep(
        sw, os.path.join(run.out_dir, "sweep_families.png"), case="default model (thesis Table 1)"
    )
    _close(fig)
    sec.figures.append("sweep_families.png")
    fams = {f"{f} family": mults[f][1]["poincare"] for f in mults}
    okall = mults["stable"][0] & mults["unstable"][0]
    fig = plot_multipliers_vs_slope(
        slopes[okall],
        {k: v[okall] for k, v in fams.items()},
        os.path.join(run.out_dir, "multipliers_vs_slope.png"),
        case="Poincare-map Jacobian, default model",
    )
    if fig is not None:
        _close(fig)
    sec.figures.append("multipliers_vs_slope.png")


# ---- 10: period doubling ----------------------------------------------------------
def doubling(run, sec):
    S = run.sizes
    lo, hi = 4.3, 4.45
    z_lo = np.asarray(run.gaits["stable43"].z)
    res = {}
    for method in ("poincare", "transverse"):
        a, b = lo, hi
        fa = fb = float("nan")
        for _ in range(S["pd_rounds"]):
            s = np.linspace(a, b, CHUNK)
            g = _gaits(s, z_lo[:2], "stable", run.method)
            mm = _multipliers(s, np.asarray(g.z))
            f = np.prod(1 + mm[method], axis=1).real  # det(I + J)
            k = np.where(np.sign(f[:-1]) != np.sign(f[1:]))[0]
            if len(k) == 0:
                a = b = float("nan")
                break
            a, b = s[k[0]], s[k[0] + 1]
            fa, fb = f[k[0]], f[k[0] + 1]
        res[method] = (a * fb - b * fa) / (fb - fa) if np.isfinite(a) else float("nan")
        res[method + "_bracket"] = (a, b)
    pd = res["poincare"]
    run.pd_deg = pd
    d = abs(res["poincare"] - res["transverse"])
    sec.compare(
        "period-doubling slope (deg)",
        "pd",
        "slope_deg",
        pd,
        f"root of det(I+J) from the transverse multipliers: "
        f"{res['transverse']:.6f} (diff {d:.1e}); library "
        f"`period_doubling_slope` (tests): 4.390898",
        7,
    )
    w = res["poincare_bracket"][1] - res["poincare_bracket"][0]
    sec.value("bracket width (deg)", w, "regula falsi inside the last bracket", 2)
    sec.results = {k: v for k, v in res.items()}


# ---- 11: bifurcation diagram ------------------------------------------------------
def bifurcation(run, sec):
    S = run.sizes
    n = S["bif_n"]
    slopes = np.linspace(*S["bif_range"], num=n)
    _, g = _family(slopes, "stable", run.method)
    ok = np.array(result_names(g.result)) == "successful"
    mm = _multipliers(slopes, np.asarray(g.z))
    diag = bifurcation_diagram(
        np.radians(slopes[ok]),
        np.asarray(g.z)[ok],
        num_transient=S["bif_transient"],
        num_record=S["bif_record"],
    )
    sim_pd = [math.degrees(p) for p in period_doubling_slopes_from_diagram(diag)]
    pd = run.pd_deg
    stable1 = np.max(np.abs(mm["poincare"]), axis=1) < 1  # the verdict's method
    from ..plotting import plot_bifurcation

    fig = plot_bifurcation(
        diag,
        [("period 1", slopes[ok], np.asarray(g.T)[ok], stable1[ok])],
        os.path.join(run.out_dir, "bifurcation.png"),
        flips_deg=[pd],
        case="stable family, default model (thesis Table 1)",
        no_gait_deg=slopes[~ok],
    )
    _close(fig)
    sec.figures.append("bifurcation.png")
    pat = np.asarray(diag.period_pattern)
    s_ok = slopes[ok]
    two = np.flatnonzero(pat >= 2)
    if len(two):  # the first simulated slope with a period-2 (or longer) pattern
        i2 = int(two[0])
        before = (
            f"; at the previous slope, {s_ok[i2 - 1]:.3f} deg, {_pattern_word(int(pat[i2 - 1]))}"
            if i2 > 0
            else "; it is the first slope simulated"
        )
        sec.value(
            "first slope with period >= 2 in simulation (grid slope, deg)",
            float(s_ok[i2]),
            f"step periods repeat there: {_pattern_word(int(pat[i2]))}{before}; "
            f"period doubling by the multipliers (Newton) at {pd:.5f} deg; grid step "
            f"{slopes[1] - slopes[0]:.3f} deg",
            4,
        )
    else:
        sec.text(
            "first slope with period >= 2 in simulation",
            "-",
            f"none in {s_ok[0]:.2f}-{s_ok[-1]:.2f} deg",
            "(no thesis value)",
            f"period doubling by the multipliers (Newton) at {pd:.5f} deg",
        )
    sec.value("slopes simulated / fell", int(ok.sum()), f"{int(np.sum(diag.fell))} fell", 4)
    sec.results = {
        "slopes_deg": slopes[ok],
        "pattern": pat,
        "fell": diag.fell,
        "period_doubling_simulation_deg": sim_pd,
        "periods": diag.periods,
    }
    sec.notes.append(
        f"Each slope is simulated from its period-1 gait (+1e-4 rad/s on dq2) for "
        f"{S['bif_transient']} transient and {S['bif_record']} recorded steps, at an "
        "integration tolerance of 1e-8 (relative and absolute). The recorded step periods "
        "repeat, by slope: " + _pattern_words(slopes[ok], pat) + "."
    )


def _pattern_word(p):
    """A period pattern (`detect_period`: k > 0 steps per repetition, 0 no repetition
    found, -1 fell) in words."""
    if p > 1:
        return f"every {p} steps"
    if p == 1:
        return "every step"
    if p == 0:
        return "no repetition found (chaotic, or not settled)"
    return "none: the walker fell"


def _pattern_words(slopes_deg, pattern):
    """The period patterns of a bifurcation diagram in words, slope range by slope range:
    `"every step from 3.50 to 4.37 deg; every 2 steps from 4.40 to 4.90 deg; ..."`."""
    words = _pattern_word
    runs = []
    for s, p in zip(slopes_deg, (int(v) for v in pattern)):
        if runs and runs[-1][0] == p:
            runs[-1][2] = s
        else:
            runs.append([p, s, s])
    return "; ".join(
        f"{words(p)} at {a:.2f} deg" if a == b else f"{words(p)} from {a:.2f} to {b:.2f} deg"
        for p, a, b in runs
    )


# ---- 12: basin slice --------------------------------------------------------------
def basin(run, sec):
    S = run.sizes
    from ..plotting import plot_basin
    from ..robustness import basin_slice

    model = _model(3.0)
    z = np.asarray(run.gaits["stable3"].z)
    b = basin_slice(
        model,
        z,
        axes=(0, 1),
        half_widths=(0.08, 0.4),
        shape=S["basin"],
        num_steps=S["basin_steps"],
        chunk=S["basin_chunk"],
    )
    plot_basin(b, os.path.join(run.out_dir, "basin_q1_dq1.png"), case="stable gait, 3 deg")
    sec.figures.append("basin_q1_dq1.png")
    counts = {
        n: int(np.sum(b.label == i))
        for i, n in enumerate(("converged", "fell", "other_cycle", "undecided"))
    }
    cy, cx = b.label.shape[0] // 2, b.label.shape[1] // 2
    centre = "returns" if b.label[cy, cx] == 0 else "does not return"
    sec.value(
        "converging fraction of the slice",
        b.fraction,
        f"{S['basin'][0]} x {S['basin'][1]} grid; the gait itself (grid centre) {centre}",
        4,
    )
    words = ("returned", "fell", "settled on another gait", "undecided")
    sec.value(
        "converging area (rad^2/s)",
        b.area,
        ", ".join(f"{n} {w}" for n, w in zip(counts.values(), words)),
        4,
    )
    axes = {"x": ("q1", "rad"), "y": ("dq1", "rad/s")}
    for k, v in b.max_converging.items():
        name, unit = axes[k[1]]
        sec.value(
            f"largest converging offset {k[0]}{name} ({unit})",
            v,
            "every grid point up to it on the line through the gait returns",
            3,
        )
    sec.results = {
        "fraction": b.fraction,
        "area": b.area,
        "counts": counts,
        "max_converging": b.max_converging,
    }


# ---- 13: push sensitivity ---------------------------------------------------------
def push(run, sec):
    S = run.sizes
    from ..plotting import plot_push
    from ..robustness import max_push, push_sensitivity_autodiff

    model = _model(3.0)
    g = run.gaits["stable3"]
    x_star = jnp.asarray([g.a, g.e, g.b, g.f], float)
    T = float(g.T)
    phases = np.arange(S["push_phases"]) / S["push_phases"]
    angles = np.radians(np.asarray(S["push_angles"]))
    D = np.asarray(push_sensitivity_autodiff(model, x_star, T, jnp.asarray(phases)))
    res = max_push(
        model,
        x_star,
        T,
        phases,
        angles,
        p_max=20.0,
        iterations=S["push_iterations"],
        scan=S["push_scan"],
    )
    plot_push(
        phases,
        D,
        angles,
        res.largest,
        os.path.join(run.out_dir, "push.png"),
        p_max=20.0,
        case="stable gait, 3 deg",
    )
    sec.figures.append("push.png")
    j = int(np.argmin(np.where(np.isfinite(res.largest), res.largest, np.inf)))
    s, a = np.unravel_index(j, res.largest.shape)
    sec.value(
        "smallest largest-survived impulse (N s)",
        float(res.largest[s, a]),
        f"at phase {phases[s]:.2f}, direction {np.degrees(angles[a]):.0f} deg; "
        f"bracket [{float(res.threshold.lo.reshape(res.largest.shape)[s, a]):.3g}, "
        f"{float(res.threshold.hi.reshape(res.largest.shape)[s, a]):.3g}] "
        "(lower end survives, upper end falls)",
        3,
    )
    sec.value(
        "max |dx+/dP| (per N s)",
        float(np.max(np.linalg.norm(D, axis=1))),
        "autodiff; = transverse linearization with input term in the tests",
        3,
    )
    sec.results = {
        "phases": phases,
        "angles_deg": np.degrees(angles),
        "largest": res.largest,
        "sensitivity": D,
    }


#: The sections in the order they run: (key, title, function).
SECTIONS = [
    ("gaits", "Gait search (Problem 1) for every gait of chapter 7", gaits),
    ("stable3", "Stable gait at 3 deg: (7.4), (7.5), step period", stable3),
    ("eig3", "Eigenvalues of the stable gait (7.6), Fig 7.1", eig3),
    (
        "sims",
        "Simulations of the stable gait, unperturbed and perturbed (7.7), Figs 7.2-7.7",
        simulations,
    ),
    ("unstable3", "Unstable gait at 3 deg: (7.9)-(7.11), Figs 7.8-7.11", unstable3),
    ("five", "5 deg: (7.13)-(7.16), Figs 7.12-7.15", five),
    ("uphill", "Uphill non-feasible solution (7.17)-(7.18)", uphill),
    ("ref5", "Gait of ref. [5] at 2.87 deg (7.1)", ref5),
    ("sweeps", "Slope sweeps of both families", sweeps),
    ("doubling", "Period-doubling slope", doubling),
    ("bifurcation", "Bifurcation diagram", bifurcation),
    ("basin", "Basin of attraction slice (3 deg)", basin),
    ("push", "Push sensitivity (3 deg)", push),
]
