"""Figures of a design run and of an atlas (matplotlib, imported when a figure is drawn)."""

import math

import numpy as np

from ._common import pyplot

#: Units of the parameters a design varies (CLI names).
UNITS = {"mass-hip": "kg", "mass-leg": "kg", "a": "m", "b": "m", "gravity": "m/s^2"}

_LABELS = {
    "spectral-radius": "spectral radius",
    "flip-slope": "flip slope (deg)",
    "speed": "speed (m/s)",
}


def _value(objective, v):
    return math.degrees(v) if objective == "flip-slope" else v


def plot_design(result, path, slope_deg):
    """Objective and the varied parameters against iteration (two panels)."""
    plt = pyplot()

    it = [h["iteration"] for h in result.history]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax1.plot(it, [_value(result.objective, h["value"]) for h in result.history], "o-")
    ax1.set_ylabel(_LABELS[result.objective])
    ax1.grid(alpha=0.3)
    for name in result.vary:
        lo, hi = result.bounds[name]
        ax2.plot(
            it,
            [(h["params"][name] - lo) / (hi - lo) for h in result.history],
            "o-",
            label=f"{name}: {lo:g} to {hi:g} {UNITS[name]}",
        )
    ax2.set_ylim(-0.05, 1.05)
    sampled = [h["iteration"] for h in result.history if h.get("step") == "gradient sampling"]
    if sampled:  # where Adam stalled at a kink and gradient sampling took over
        for ax in (ax1, ax2):
            ax.axvline(sampled[0] - 0.5, color="0.5", linestyle=":")
        ax1.annotate(
            "gradient sampling from here",
            (sampled[0] - 0.5, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(4, -4),
            textcoords="offset points",
            va="top",
            fontsize=8,
            color="0.3",
        )
    ax2.set_xlabel("iteration")
    ax2.set_ylabel("position within bounds")
    ax2.legend()
    ax2.grid(alpha=0.3)
    fig.suptitle(
        f"Compass-gait design: {result.objective} at {slope_deg:g} deg, "
        f"varying {', '.join(result.vary)} ({result.result})"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_atlas(at, path, *, mass_leg, leg_length, gravity):
    """Heat map of the flip slope over (mass ratio, length ratio), with contours."""
    plt = pyplot()

    deg = np.degrees(at.flip_slope)
    fig, ax = plt.subplots(figsize=(7, 5.5))
    mu, beta = at.mass_ratio, at.length_ratio

    def edges(v):
        if len(v) == 1:
            return np.array([v[0] - 0.5, v[0] + 0.5])
        mid = 0.5 * (v[1:] + v[:-1])
        return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])

    mesh = ax.pcolormesh(
        edges(mu), edges(beta), np.ma.masked_invalid(deg).T, shading="flat", cmap="viridis"
    )
    fig.colorbar(mesh, ax=ax, label="first period-doubling slope (deg)")
    if len(mu) > 1 and len(beta) > 1 and np.isfinite(deg).sum() > 3:
        cs = ax.contour(mu, beta, np.ma.masked_invalid(deg).T, colors="white", linewidths=0.8)
        ax.clabel(cs, fmt="%.2f", fontsize=8)
    ax.set_xlabel(r"mass ratio $\mu = m_H / m$")
    ax.set_ylabel(r"length ratio $\beta = b / a$")
    ax.set_title(
        f"Compass gait: flip slope of the stable gait on a {len(mu)} x {len(beta)} "
        f"grid\nm = {mass_leg:g} kg, l = {leg_length:g} m, g = {gravity:g} m/s^2; "
        "blank: no flip found",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
