"""Numbers and figure of docs/simplest_walker.md (Garcia, Chatterjee, Ruina and Coleman
1998, "The simplest walking model"), computed with vhcjax.

Prints every number of the page and writes docs/figures/simplest_walker.png. Run from the
repository root: `python docs/simplest_walker.py`. The tests (`test_simplest_walker.py`)
check the printed numbers against an independent scipy computation.
"""

import math
import pathlib
import time

import jax.numpy as jnp
import numpy as np

import vhcjax as vj

FIGURE = pathlib.Path(__file__).resolve().parent / "figures" / "simplest_walker.png"
#: Slopes where the small-slope correction is fitted (rad).
SMALL_SLOPES = (1e-5, 1e-4, 1e-3)
#: Slopes of the two period-1 families (rad), and of the long simulations.
FAMILY_SLOPES = np.unique(
    np.round(np.r_[np.geomspace(1e-5, 0.02, 49), np.linspace(0.01, 0.02, 41), SMALL_SLOPES], 12)
)
CASCADE_SLOPES = np.round(np.arange(0.0140, 0.02001, 0.00005), 6)
CASCADE_STEPS = (400, 64)  # transient, recorded
#: Brackets (rad) of the flips of the period-2 and period-4 gaits (each attracts at the
#: lower end).
CASCADE_BRACKETS = {2: (0.0175, 0.0178), 4: (0.0181, 0.01818)}
#: Slopes (rad) where the script reports falls: the walker still walks, and falls.
FALL_CHECK = (0.0190, 0.0192)
#: Starts of the long simulations: the gait with these offsets on dq2 (rad/s).
STARTS = (1e-4, -1e-4, 3e-4, -3e-4, 1e-3, -1e-3, 3e-3, -3e-3)


def garcia(model, z):
    """The paper's variables of a section point: theta, theta', phi' (time unit sqrt(l/g))."""
    q1, dq1, dq2 = np.asarray(z, float)
    ts = float(model.time_scale)
    return q1 + float(model.psi), dq1 * ts, (dq1 - dq2) * ts


def multipliers(model, z):
    ev = np.linalg.eigvals(np.asarray(vj.poincare_jacobian(model, jnp.asarray(z))))
    return ev[np.argsort(-np.abs(ev))]


def family(family_name, slopes):
    """Period-1 gaits of `family_name` at `slopes` (ascending), continued from the
    reference gait: `(z, periods, multipliers)`, arrays over slopes."""
    ref_model, ref_z = vj.SimplestWalker().reference_gait(family_name)
    ref = vj.fixed_point(ref_model, ref_z)
    psi0 = float(ref_model.psi)
    out = {}
    for part in (slopes[slopes <= psi0][::-1], slopes[slopes > psi0]):
        model, z = ref_model, ref.z
        for psi in part:
            fp, model = vj.continue_fixed_point(model, z, model.with_slope(psi))
            assert vj.result_names(fp.result) == "successful", (family_name, psi)
            z = fp.z
            out[float(psi)] = (np.asarray(z), float(fp.periods[0]), multipliers(model, z))
    keys = sorted(out)
    return tuple(np.array([out[k][i] for k in keys]) for i in range(3))


def attractor(walker, stable_family, psi, k, num_steps=800):
    """Section point of the period-`k` attractor at slope `psi`: a simulation from the
    long-period gait (nearest slope of the family), perturbed by 1e-4 rad/s on dq2."""
    i = int(np.argmin(np.abs(FAMILY_SLOPES - psi)))
    model = walker.with_slope(psi)
    x0 = model.section_to_state(jnp.asarray(stable_family[0][i] + np.array([0.0, 0.0, 1e-4])))
    sim = vj.simulate(model, x0, num_steps)
    assert vj.result_names(sim.result) == "successful", psi
    fp = vj.fixed_point(model, model.state_to_section(sim.steps.x_plus[-1]), k)
    assert vj.result_names(fp.result) == "successful", (psi, k)
    return fp.z


def leading_coefficient(family_name):
    """$C$ of $\\theta^* \\approx C\\gamma^{1/3}$ as $\\gamma \\to 0$: $\\tanh(\\tau_0/2)^{2/3}$,
    $\\tau_0 = \\pi$ (short-period gait) or the root of $\\tan(\\tau/2) = -3\\tanh(\\tau/2)$
    in $(\\pi, 2\\pi)$ (long-period gait), by Newton's method."""
    if family_name == "unstable":
        return math.pi, math.tanh(math.pi / 2) ** (2 / 3)
    x = 1.9
    for _ in range(50):
        f = math.sin(x) + 3 * math.tanh(x) * math.cos(x)
        df = math.cos(x) + 3 * (math.cos(x) / math.cosh(x) ** 2 - math.tanh(x) * math.sin(x))
        x -= f / df
    return 2 * x, math.tanh(x) ** (2 / 3)


def correction(slopes, theta, c):
    """Least-squares $D$ in $\\theta^*/\\gamma^{1/3} = C + D\\gamma^{2/3}$ (C given)."""
    u = slopes ** (2 / 3)
    return float(np.sum(u * (theta / slopes ** (1 / 3) - c)) / np.sum(u * u))


def main():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_start = time.time()
    walker = vj.SimplestWalker()
    print("gaits at psi = 0.009 rad (theta*, theta'*, phi'*, tau, |multipliers|)")
    for name in ("stable", "unstable"):
        model, z0 = walker.reference_gait(name)
        fp = vj.fixed_point(model, z0)
        th, dth, dph = garcia(model, fp.z)
        ev = multipliers(model, fp.z)
        print(
            f"  {name:8s} {th:.8f} {dth:.8f} {dph:.8f} {float(fp.periods[0]):.6f}",
            " ".join(f"{abs(e):.6f}" for e in ev[:2]),
            f"({ev[0]:.6f})",
        )

    fam = {name: family(name, FAMILY_SLOPES) for name in ("stable", "unstable")}
    small = np.isin(FAMILY_SLOPES, SMALL_SLOPES)
    print(f"small slopes: theta* = C gamma^(1/3) + D gamma (C derived, D fitted at {SMALL_SLOPES})")
    coef = {}
    for name in ("stable", "unstable"):
        tau0, c = leading_coefficient(name)
        theta = fam[name][0][:, 0] + FAMILY_SLOPES
        d = correction(FAMILY_SLOPES[small], theta[small], c)
        coef[name] = (c, d)
        print(f"  {name:8s} tau0 = {tau0:.6f}, C = {c:.6f}, D = {d:.3f}")

    ev = fam["stable"][2]
    lam = np.min(ev.real * (np.abs(ev.imag) < 1e-12) + 10 * (np.abs(ev.imag) >= 1e-12), axis=1)
    i = int(np.argmax(lam < -1.0))
    pd = vj.period_doubling_slope(
        FAMILY_SLOPES[i - 1],
        FAMILY_SLOPES[i],
        fam["stable"][0][i - 1],
        model=walker,
        tol=1e-10,
    )
    print(f"flip: psi = {pd.psi:.10f} rad, multipliers {np.round(pd.multipliers.real, 6)}")

    # the flips of the period-2 and period-4 gaits: from the attractor at the lower end of
    # a bracket (`CASCADE_BRACKETS`)
    flips = [pd.psi]
    for k, (lo, hi) in CASCADE_BRACKETS.items():
        z = attractor(walker, fam["stable"], lo, k)
        pdk = vj.period_doubling_slope(lo, hi, np.asarray(z), model=walker, k=k, tol=1e-10)
        flips.append(pdk.psi)
        print(
            f"flip of the period-{k} gait: psi = {pdk.psi:.10f} rad, its point "
            f"{np.array2string(np.asarray(pdk.z), precision=10)}, multipliers of P^{k} "
            f"{np.round(pdk.multipliers.real, 6)}"
        )
    ratio = (flips[1] - flips[0]) / (flips[2] - flips[1])
    print(f"ratio of the first two cascade intervals {ratio:.2f}")

    # the attractor over slopes: walkers started near the long-period gait (unstable past
    # the flip), `len(STARTS)` starts per slope
    zc, _, _ = family("stable", CASCADE_SLOPES)
    offsets = np.zeros((len(STARTS), 3))
    offsets[:, 2] = STARTS
    diagram = vj.bifurcation_diagram(
        np.repeat(CASCADE_SLOPES, len(STARTS)),
        (zc[:, None, :] + offsets[None]).reshape(-1, 3),
        model=walker,
        num_transient=CASCADE_STEPS[0],
        num_record=CASCADE_STEPS[1],
        perturbation=0.0,
    )
    shape = (len(CASCADE_SLOPES), len(STARTS))
    pattern = np.asarray(diagram.period_pattern).reshape(shape)[:, 0]
    fell = np.asarray(diagram.fell).reshape(shape)
    periods = np.asarray(diagram.periods).reshape(shape + (-1,))[:, 0]
    print(f"attractor from the first start (dq2 + {STARTS[0]:g}), steps per repetition:")
    # past the last flip computed (the grid's own period-4 and period-8 onsets come
    # early: just below a flip the slowly fading alternation passes for twice the period)
    k = int(np.argmax(CASCADE_SLOPES > flips[-1]))
    k += int(np.argmax(pattern[k:] == 0))
    print(f"  no period up to 32 from psi = {CASCADE_SLOPES[k]:.5f}")
    n_steps = sum(CASCADE_STEPS)
    none = CASCADE_SLOPES[~fell.any(axis=1)]
    every = CASCADE_SLOPES[fell.all(axis=1)]
    print(f"  {len(STARTS)} starts: none fell within {n_steps} steps up to psi = {none.max():.5f}")
    print(f"  {len(STARTS)} starts: every one fell from psi = {every.min():.5f}")
    for psi in FALL_CHECK:
        i = int(np.argmin(np.abs(CASCADE_SLOPES - psi)))
        model = walker.with_slope(psi)
        x0 = model.section_to_state(jnp.asarray(zc[i] + offsets[0]))
        sim = vj.simulate(model, x0, n_steps)
        print(
            f"  psi = {psi}: {int(fell[i].sum())} of {len(STARTS)} fell; the first start "
            f"walks {int(sim.num_successful)} steps ({vj.result_names(sim.result)})"
        )
    print(f"  number fallen per slope {dict(zip(CASCADE_SLOPES.tolist(), fell.sum(1).tolist()))}")
    print(f"  pattern {dict(zip(CASCADE_SLOPES.tolist(), pattern.tolist()))}")

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    ax = axes[0]
    for name, label, color in (("stable", "long period", "C0"), ("unstable", "short period", "C3")):
        theta = fam[name][0][:, 0] + FAMILY_SLOPES
        c, _ = coef[name]
        ax.semilogx(FAMILY_SLOPES, theta / FAMILY_SLOPES ** (1 / 3), color=color, label=label)
        ax.axhline(c, ls="--", color=color, lw=0.8, label=f"$C$ = {c:.6f} (small-slope limit)")
    ax.set_xlabel("slope $\\gamma$ (rad)")
    ax.set_ylabel("$\\theta^* / \\gamma^{1/3}$ (angles in rad)")
    ax.set_title("period-1 gaits: $\\theta^* \\approx C\\gamma^{1/3}$", fontsize=10)
    ax.legend(fontsize=8)

    ax = axes[1]
    mods = np.abs(fam["stable"][2][:, :2])
    ax.semilogx(FAMILY_SLOPES, mods[:, 0], "C0", label="largest $|\\lambda|$")
    ax.semilogx(FAMILY_SLOPES, mods[:, 1], "C0--", label="second $|\\lambda|$")
    ax.axhline(1.0, color="k", lw=0.6)
    ax.axvline(pd.psi, color="C1", lw=0.8, label=f"flip, $\\gamma$ = {pd.psi:.5f} rad")
    ax.set_xlabel("slope $\\gamma$ (rad)")
    ax.set_ylabel("multiplier modulus $|\\lambda|$")
    ax.set_title("long-period gait: Poincaré multipliers", fontsize=10)
    ax.legend(fontsize=8)

    ax = axes[2]
    walking = ~fell[:, 0]
    for psi, row in zip(CASCADE_SLOPES[walking], periods[walking]):
        ax.plot(np.full(len(row), psi), row, ",", color="C0")
    ax.plot(
        CASCADE_SLOPES[~walking],
        np.full((~walking).sum(), periods[walking].min()),
        "x",
        color="C3",
        ms=3,
        label=f"fell within {sum(CASCADE_STEPS)} steps",
    )
    ax.axvline(pd.psi, color="C1", lw=0.8)
    ax.set_xlabel("slope $\\gamma$ (rad)")
    ax.set_ylabel(f"step period $\\tau$, last {CASCADE_STEPS[1]} steps ($\\sqrt{{l/g}}$)")
    ax.set_title("attractor from the long-period gait", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    fig.suptitle("Simplest walking model (Garcia et al. 1998), $m/M \\to 0$", fontsize=11)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=110)
    print(f"wrote {FIGURE.name} ({time.time() - t_start:.0f} s)")


if __name__ == "__main__":
    main()
