"""Figure of a stabilized gait (matplotlib, imported when the figure is drawn)."""

import numpy as np

from ._common import pyplot


def _label(name):
    """'delta dq2' -> TeX label and gain unit (N m per rad or per rad/s)."""
    sym = name.split()[-1]
    if sym.startswith("dq"):
        return rf"$\delta\dot q_{sym[2:]}$", "N m s/rad"
    return rf"$\delta q_{sym[1:]}$", "N m/rad"


def plot_stabilization(
    path,
    title,
    s,
    K,
    closed_errors,
    passive_errors,
    basin=None,
    *,
    coordinates=("delta q2", "delta dq1", "delta dq2"),
    torques=("hip",),
    reset_names=None,
):
    """Three panels: gains $K(s)$ against phase, recovery (error per step, closed loop and
    passive), basin slices with and without feedback (the last only when given).

    **Arguments:**

    - `path`: PNG file.
    - `title`: names the case (model, slope, gait).
    - `s`, `K`: phase grid and gains `(N+1, m, r)` (compass gait: r = 3), or
      `(num_domains, N+1, m, r)` for a multi-domain model (drawn domain after domain).
    - `closed_errors`, `passive_errors`: max-norm distance to the gait on the post-impact
      section after each step, in the walker's own units (rates times $\\sqrt{l/g}$).
    - `basin`: `None` or a dict with `z_star`, `offsets_x`, `offsets_y` and boolean grids
      `passive`, `closed` (converged), over section coordinates $(q_1, \\dot q_1)$.
    - `coordinates`, `torques`: names of the transverse coordinates (e.g. "delta dq2")
      and of the torques, for the legend; `reset_names`: the internal resets between
      domains (e.g. "knee strike"), marked on the gains panel.
    """
    plt = pyplot()

    K = np.asarray(K)
    s = np.asarray(s)
    domains = K.shape[0] if K.ndim == 4 else 1
    if K.ndim == 4:  # one phase per domain: the cycle's phase runs 0..num_domains
        s = np.concatenate([i + s for i in range(domains)])
        K = K.reshape(-1, *K.shape[2:])
    panels = 2 if basin is None else 3  # no empty panel where the basin is not computed
    fig, axes = plt.subplots(1, panels, figsize=(5 * panels, 5.2), dpi=110)
    ax = axes[0]
    styles = ("-", "--", ":")
    for i, torque in enumerate(torques):
        for j, name in enumerate(coordinates):
            lab, unit = _label(name)
            ax.plot(
                s,
                K[:, i, j],
                styles[i % 3],
                color=f"C{j}",
                label=f"{torque} gain on {lab} ({unit})",
            )
    if domains > 1:
        for i in range(1, domains):
            ax.axvline(i, color="k", lw=0.8, ls="-.")
            if reset_names is not None:
                ax.text(
                    i,
                    1.0,
                    f" {reset_names[i - 1]}",
                    transform=ax.get_xaxis_transform(),
                    va="top",
                    fontsize=8,
                )
        ax.set_xlabel("phase through the step, domain after domain")
    else:
        ax.set_xlabel(r"phase $s = (q_1 - q_1^+)/(q_1^- - q_1^+)$")
    names = " and ".join(torques)
    ax.set_ylabel(f"{names} torque gain $K(s)$ (units in legend)")
    ax.set_title("LQR gains along the step")
    ax.axhline(0, color="k", lw=0.5)
    ax.legend(fontsize=7 if len(torques) > 1 else 8)

    ax = axes[1]
    k = np.arange(1, len(closed_errors) + 1)
    ax.semilogy(k, np.maximum(closed_errors, 1e-16), "o-", ms=3, label="with feedback")
    ax.semilogy(k, np.maximum(passive_errors, 1e-16), "s-", ms=3, label="passive")
    ax.set_xlabel("step")
    ax.set_ylabel(r"$\|z_k - z_\star\|_\infty$ after impact (rad; rad/s $\times\sqrt{l/g}$)")
    ax.set_title("Recovery from the perturbed gait")
    ax.legend(fontsize=8)

    if basin is not None:
        ax = axes[2]
        z = basin["z_star"]
        X = z[0] + np.asarray(basin["offsets_x"])
        Y = z[1] + np.asarray(basin["offsets_y"])
        extent = (X[0], X[-1], Y[0], Y[-1])
        code = np.asarray(basin["closed"], int) + 2 * np.asarray(basin["passive"], int)
        from matplotlib.colors import ListedColormap

        cmap = ListedColormap(["#eeeeee", "#2ca02c", "#1f77b4", "#9467bd"])
        ax.imshow(
            code.T,
            origin="lower",
            extent=extent,
            aspect="auto",
            cmap=cmap,
            vmin=-0.5,
            vmax=3.5,
            interpolation="nearest",
        )
        ax.plot(z[0], z[1], "r*", ms=12, mec="k", label="gait")
        for c, name in (
            (1, "converges with feedback only"),
            (2, "converges passive only"),
            (3, "converges both"),
        ):
            ax.plot([], [], "s", color=cmap(c), label=name)
        ax.plot([], [], "s", color=cmap(0), label="does not converge")
        ax.set_xlabel(r"$q_1$ just after impact (rad)")
        ax.set_ylabel(r"$\dot q_1$ just after impact (rad/s)")
        ax.set_title(
            f"Basin slice: passive {np.mean(basin['passive']):.2f}, "
            f"with feedback {np.mean(basin['closed']):.2f}"
        )
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3)
    fig.suptitle(title, wrap=True)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
