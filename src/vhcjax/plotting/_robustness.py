"""Figures for the robustness analyses (matplotlib, imported when a figure is drawn)."""

import numpy as np

from ._common import pyplot


def _save(fig, path):
    """Save to `path` (if given) and close; return the figure either way."""
    if path is not None:
        fig.savefig(path)
        pyplot().close(fig)
    return fig


def _case(title, case):
    return f"{title}: {case}" if case else title


SECTION_LABELS = (r"$q_1$ (rad)", r"$\dot q_1$ (rad/s)", r"$\dot q_2$ (rad/s)")
SECTION_SYMBOLS = (r"$q_1$", r"$\dot q_1$", r"$\dot q_2$")
SECTION_UNITS = ("rad", "rad/s", "rad/s")


def plot_basin(b, path=None, title=None, case=None):
    """Basin slice coloured by steps to converge; fallers grey, other cycles red,
    undecided white; the gait marked by a star (compare Schwab and Wisse 2001).
    `case` (e.g. `"stable gait, 3 deg"`) is named in the title. Returns the figure."""
    from matplotlib.colors import ListedColormap
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    from ..robustness import CONVERGED, FELL, OTHER_CYCLE, UNDECIDED

    ix, iy = b.axes
    X = b.z_star[ix] + b.offsets_x
    Y = b.z_star[iy] + b.offsets_y
    fig, ax = plt.subplots(figsize=(6.4, 5.2), dpi=130)
    extent = (X[0], X[-1], Y[0], Y[-1])
    steps = np.where(b.label == CONVERGED, b.steps, np.nan).astype(float)
    im = ax.imshow(
        steps,
        origin="lower",
        extent=extent,
        aspect="auto",
        cmap="viridis_r",
        interpolation="nearest",
    )
    for lab, color in ((FELL, "#bdbdbd"), (OTHER_CYCLE, "#d62728"), (UNDECIDED, "#ffffff")):
        mask = np.where(b.label == lab, 1.0, np.nan)
        if np.any(b.label == lab):
            ax.imshow(
                mask,
                origin="lower",
                extent=extent,
                aspect="auto",
                cmap=ListedColormap([color]),
                interpolation="nearest",
            )
    ax.plot(
        b.z_star[ix], b.z_star[iy], marker="*", color="red", ms=14, mec="k", label="gait", ls="none"
    )
    cb = fig.colorbar(im, ax=ax)
    cb.ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    cb.set_label(f"steps to converge (within {b.tol:g} of the gait, own units)")
    ax.set_xlabel(SECTION_LABELS[ix] + " just after impact")
    ax.set_ylabel(SECTION_LABELS[iy] + " just after impact")
    other = [k for k in range(len(b.z_star)) if k not in b.axes]
    fixed = ", ".join(f"{SECTION_SYMBOLS[k]} = {b.z_star[k]:.4f}" for k in other)
    ax.set_title(
        title
        or _case("Basin of attraction", case)
        + f", slice ({fixed}); grey: falls\n"
        f"converging area {b.area:.4g} {SECTION_UNITS[ix]} x {SECTION_UNITS[iy]}, "
        f"fraction {b.fraction:.3f}",
        fontsize=9,
    )
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_contraction(c, path=None, case=None):
    """Simulated recovery errors vs step with the multiplier prediction $\\rho^k$; `case`
    named in the title. Returns the figure."""
    plt = pyplot()
    d = np.asarray(c.distance)
    k = np.arange(d.shape[1])
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=130)
    for row in d:
        ax.semilogy(k, row, color="C0", alpha=0.35, lw=1)
    rho = float(c.spectral_radius)
    ref = np.median(d[:, 0]) * rho**k
    ax.semilogy(k, ref, "k--", lw=1.5, label=rf"$\rho^k$, $\rho$ = {rho:.4f} (multipliers)")
    rate = float(c.measured_rate)
    fitted = f"fitted rate {rate:.4f}" if np.isfinite(rate) else "none stayed near the gait"
    ax.semilogy([], [], color="C0", label=f"simulated recoveries ({fitted})")
    ax.set_xlabel("step k")
    ax.set_ylabel(r"$\|x_k - x^*\|_\infty$ after impact (rad; rad/s $\times$ time scale)")
    ax.set_title(
        _case("Contraction", case) + f"\nerror /10 in {float(c.steps_10x):.2f} steps, /100 in "
        f"{float(c.steps_100x):.2f} (predicted)",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_terrain(heights, rec, period, path=None, gsn=None, case=None):
    """Step times and distance to the gait after a floor step of each height; `case`
    named in the title. Returns the figure."""
    plt = pyplot()
    T = np.asarray(rec.step_times)
    d = np.asarray(rec.distance)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), dpi=130)
    cmap = plt.get_cmap("coolwarm")
    hs = np.asarray(heights)
    hmax = max(np.max(np.abs(hs)), 1e-12)
    for i, h in enumerate(hs):
        n = int(np.sum(T[i] > 0))
        c = cmap(0.5 + 0.5 * h / hmax)
        lbl = f"h = {1000 * h:+.1f} mm" + (" (falls)" if int(rec.label[i]) == 1 else "")
        a1.plot(np.arange(n), T[i, :n], "o-", ms=3, color=c, label=lbl)
        # from step 1 (step 0 is the gait itself: its distance is rounding)
        a2.semilogy(np.arange(1, n + 1), d[i, 1 : n + 1], "o-", ms=3, color=c)
    a1.axhline(period, color="k", lw=0.8, ls="--", label="gait period")
    a1.set_xlabel("step (0 = the step onto the new level)")
    a1.set_ylabel("step time (s)")
    a1.legend(fontsize=7)
    a2.set_xlabel("step")
    a2.set_ylabel(r"$\|x_k - x^*\|_\infty$ after impact (rad; rad/s $\times$ time scale)")
    # below 1e-7 the distances are the recovery integration's own error (rtol 1e-8)
    a2.set_ylim(bottom=max(1e-7, a2.get_ylim()[0]))
    title = _case("Recovery from a single step up (+) / down (-)", case)
    if gsn is not None:
        title += f"; gait sensitivity norm {gsn:.3g} s/m"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_push(phases, sens, angles, largest, path=None, unit="N s", p_max=None, case=None):
    """Left: norm of the post-impact state's sensitivity to a unit hip impulse vs phase
    (forward and upward). Right: largest push survived vs phase, per direction. `case`
    named in the title. Returns the figure."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), dpi=130)
    S = np.asarray(sens)
    a1.plot(phases, np.linalg.norm(S[:, :, 0], axis=1), "o-", ms=3, label="horizontal (+x)")
    a1.plot(phases, np.linalg.norm(S[:, :, 1], axis=1), "s-", ms=3, label="vertical (+y)")
    a1.set_xlabel("phase s of the push in the step")
    a1.set_ylabel(r"$\|\partial x^+ / \partial P\|_2$  (per N s)")
    a1.set_title("Linear sensitivity of the next post-impact state", fontsize=9)
    a1.legend(fontsize=8)
    for j, a in enumerate(angles):
        a2.plot(phases, largest[:, j], "o-", ms=3, label=f"{np.degrees(a):.0f} deg")
    if p_max is not None:
        a2.axhline(p_max, color="k", lw=0.8, ls=":", label="search bound (survived beyond)")
    a2.set_xlabel("phase s of the push in the step")
    a2.set_ylabel(f"largest push survived ({unit})")
    a2.set_title(
        "Largest push after which the walker returns to the gait\n"
        "(0 deg = forward, 90 = up, 180 = backward, 270 = down)",
        fontsize=9,
    )
    a2.legend(fontsize=8)
    fig.suptitle(_case("Hip pushes along the step", case), fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_slope(sens, path=None, case=None):
    """Slope derivatives (per degree of slope) of the gait quantities, one panel per unit
    (rad, rad/s, s, m, m/s, and the dimensionless multiplier moduli), each with a legend.

    **Arguments:** `sens` (a `SlopeSensitivity`), `path` (save there and close),
    `case` (named in the title, e.g. `"stable gait, 3 deg"`). **Returns:** the figure.
    """
    plt = pyplot()
    deg = np.pi / 180
    dz = np.asarray(sens.dz) * deg
    dmod = np.asarray(sens.dmodulus) * deg
    panels = [
        ("rad / deg", [(r"$q_1^*$", dz[0])]),
        ("rad/s / deg", [(r"$\dot q_1^*$", dz[1]), (r"$\dot q_2^*$", dz[2])]),
        ("s / deg", [("step period T", float(sens.dperiod) * deg)]),
        ("m / deg", [("step length L", float(sens.dstep_length) * deg)]),
        ("m/s / deg", [("speed v", float(sens.dspeed) * deg)]),
        ("1 / deg", [(f"$|\\lambda_{i + 1}|$", v) for i, v in enumerate(dmod)]),
    ]
    fig, axes = plt.subplots(2, 3, figsize=(9.5, 5.4), dpi=120)
    for ax, (unit, bars) in zip(axes.ravel(), panels):
        for k, (name, v) in enumerate(bars):
            ax.bar([k], [v], color=f"C{k}", label=f"{name}: {v:+.3g}")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks([])
        ax.set_xlim(-0.8, max(len(bars), 2) - 0.2)
        ax.set_ylabel(f"derivative ({unit})")
        ax.legend(fontsize=7, loc="best")
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(
        "Sensitivity of the gait to the slope, per degree (implicit "
        "differentiation)" + (f": {case}" if case else ""),
        fontsize=10,
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path)
        plt.close(fig)
    return fig
