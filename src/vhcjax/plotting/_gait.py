"""Gait-family figure: a, b, T and walking speed against slope, for both families.

matplotlib is imported when the figure is drawn.
"""

import numpy as np

from ._common import pyplot

_STYLE = {"stable": dict(color="C0", ls="-"), "unstable": dict(color="C3", ls="--")}


def plot_sweep(sweeps, path=None, case=None):
    """Plot the gaits of `sweeps` (`{"stable": Sweep, "unstable": Sweep}`, either may be
    missing) against slope; failed slopes are left out; `case` (e.g. the model) named in
    the title. Returns the figure; saved to `path` if given."""
    plt = pyplot()

    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5), sharex=True)
    panels = [
        ("a", "a = q1(0+) (rad)"),
        ("b", "b = dq1(0+) (rad/s)"),
        ("T", "step period T (s)"),
        ("speed", "walking speed (m/s)"),
    ]
    for fam, sw in sweeps.items():
        ok = np.asarray(sw.ok)
        deg = np.degrees(np.asarray(sw.psi))
        for ax, (key, label) in zip(axes.ravel(), panels):
            y = np.where(ok, np.asarray(getattr(sw.gaits, key)), np.nan)
            ax.plot(deg, y, label=f"{fam} family", lw=1.6, **_STYLE.get(fam, {}))
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("slope (deg)")
    axes[0, 0].legend()
    fig.suptitle(
        "Compass-gait periodic gaits against slope (continuation)" + (f": {case}" if case else "")
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig
