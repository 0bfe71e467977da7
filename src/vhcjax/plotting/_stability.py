"""Stability figures: multipliers in the complex plane (thesis Figs 7.1, 7.8, 7.15),
multipliers against slope, and the bifurcation diagram (Goswami et al. 1998 style).

matplotlib is imported lazily (Agg backend): the library does not need it otherwise.
"""

import numpy as np

from ._common import pyplot


def plot_multipliers_complex(sets, labels=None, path=None, title=None):
    """Multipliers in the complex plane with the unit circle.

    `sets`: a list of complex arrays (e.g. transverse and Poincare multipliers of one
    gait, or several gaits); `labels`: legend entries. Returns the figure; saved to
    `path` if given.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 5))
    t = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(t), np.sin(t), color="0.5", lw=1, label="unit circle")
    ax.axhline(0, color="0.85", lw=0.8)
    ax.axvline(0, color="0.85", lw=0.8)
    # Open markers of distinct shapes, smaller for each later set and drawn above the
    # earlier ones: multipliers of several sets that nearly coincide (ours and the
    # thesis's 0.123 beside 0.1316) all stay visible.
    markers = ["o", "x", "s", "+", "^", "v", "D"]
    rmax = 1.0
    for i, ev in enumerate(sets):
        ev = np.atleast_1d(np.asarray(ev))
        rmax = max(rmax, float(np.max(np.abs(ev))))
        lab = None if labels is None else labels[i]
        ax.plot(
            np.real(ev),
            np.imag(ev),
            markers[i % len(markers)],
            ms=max(4.0, 12.0 - 2.5 * i),
            mfc="none",
            mew=1.4,
            ls="none",
            zorder=3 + i,
            label=lab,
        )
    lim = 1.15 * rmax
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("Re $\\lambda$")
    ax.set_ylabel("Im $\\lambda$")
    if title:
        ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=120)
    return fig


def plot_multipliers_vs_slope(slopes_deg, families, path=None, case=None):
    """Moduli of the multipliers against slope; `case` (e.g. the method and model) named
    in the title.

    `families`: dict name -> complex array (B, 2n-1) of multipliers at `slopes_deg`.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    styles = {0: "-", 1: "--", 2: ":"}
    colors = ["C0", "C3", "C2", "C1"]
    for j, (name, ev) in enumerate(families.items()):
        ev = np.asarray(ev)
        for i in range(ev.shape[1]):
            ax.plot(
                slopes_deg,
                np.abs(ev[:, i]),
                styles.get(i, "-"),
                color=colors[j % 4],
                label=f"{name} |$\\lambda_{i + 1}$|",
            )
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("slope (deg)")
    ax.set_ylabel("multiplier modulus")
    ax.set_title("Multipliers of the period-1 gaits" + (f": {case}" if case else ""), fontsize=10)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=120)
    return fig


def _branch(ax, x, y, stable, color, label):
    """Solid where stable, dashed where unstable."""
    x, y, stable = np.asarray(x), np.asarray(y), np.asarray(stable, bool)
    first = {True: True, False: True}
    for s in (True, False):
        yy = np.where(stable == s, y, np.nan)
        # connect across the stability change so the line is continuous
        for i in range(1, len(x)):
            if stable[i] != stable[i - 1] and stable[i] == s:
                yy[i - 1] = y[i - 1]
        ax.plot(
            x,
            yy,
            "-" if s else "--",
            color=color,
            lw=1.2,
            alpha=0.75,
            zorder=2,
            label=f"{label} ({'stable' if s else 'unstable'})" if first[s] else None,
        )
        first[s] = False


def plot_bifurcation(diagram, branches=(), path=None, flips_deg=(), case=None, no_gait_deg=()):
    """Bifurcation diagram: step periods of the last recorded steps against slope.

    - `diagram`: a `BifurcationDiagram`.
    - `branches`: tuples `(label, slopes_deg, periods (B,) or (B, k), stable (B,))`
      overlaid (solid stable, dashed unstable).
    - `flips_deg`: slopes of period doubling, marked by thin vertical lines.
    - `case`: named in the title (e.g. the model).
    - `no_gait_deg`: slopes where no period-1 gait was found (not simulated).

    Slopes where the walker fell, or where no gait was found, have no step period: they
    are marked in a row of their own below the diagram.

    **Returns:** the matplotlib figure.
    """
    plt = pyplot()
    deg = np.degrees(np.asarray(diagram.psi))
    P = np.asarray(diagram.periods)
    ok = ~np.asarray(diagram.fell)
    no_gait = np.asarray(no_gait_deg, float)
    row = bool(np.any(~ok) or no_gait.size)
    if row:
        fig, (ax, low) = plt.subplots(
            2, 1, figsize=(8, 5.6), sharex=True, gridspec_kw={"height_ratios": [12, 1]}
        )
    else:
        fig, ax = plt.subplots(figsize=(8, 5))
        low = None
    xs = np.repeat(deg[ok], P.shape[1])
    ax.plot(xs, P[ok].ravel(), ".", color="k", ms=1.2, mew=0, zorder=3)
    ax.plot([], [], ".", color="k", ms=5, label="simulation (last steps)")  # legend key
    colors = ["C0", "C2", "C1", "C4"]
    for j, (label, sdeg, per, stable) in enumerate(branches):
        per = np.asarray(per)
        per = per[:, None] if per.ndim == 1 else per
        for i in range(per.shape[1]):
            _branch(ax, sdeg, per[:, i], stable, colors[j % 4], label if i == 0 else "_" + label)
    for i, f in enumerate(flips_deg):
        label = "period doubling (multiplier -1)" if i == 0 else None
        for a in (ax,) if low is None else (ax, low):
            a.axvline(f, color="0.45", lw=0.8, ls=":", label=label if a is ax else None)
    if low is not None:
        if np.any(~ok):
            low.plot(deg[~ok], np.zeros(np.sum(~ok)), "x", color="C3", ms=5, label="fell")
        if no_gait.size:
            low.plot(no_gait, np.zeros(no_gait.size), "|", color="0.3", ms=9, label="no gait")
        low.set_yticks([])
        low.set_ylim(-1, 1)
        low.set_ylabel("no gait /\nfalls", rotation=0, ha="right", va="center", fontsize=8)
        low.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
        low.set_xlabel("slope (deg)")
    else:
        ax.set_xlabel("slope (deg)")
    ax.set_ylabel("step period (s)")
    ax.set_title(
        "Compass gait: step periods after transients (Goswami et al. 1998)"
        + (f"\n{case}" if case else ""),
        fontsize=10,
    )
    handles, labels = ax.get_legend_handles_labels()
    keep = [(h, lab) for h, lab in zip(handles, labels) if not lab.startswith("_")]
    ax.legend([h for h, _ in keep], [lab for _, lab in keep], fontsize=8, loc="upper left")
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=130, bbox_inches="tight")
    return fig
