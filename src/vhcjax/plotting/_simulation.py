"""Figures from a `Simulation`: states against time, phase portrait, step periods, and an
animation of the walker going down the slope (thesis Figs 7.2-7.4 and 3.5).

Simulate with `dense_points > 0` (e.g. `simulate(model, x0, 10, dense_points=40)`) for the
trajectory figures and the animation. matplotlib is imported lazily, with the Agg backend
when no backend has been chosen, so importing vhcjax never needs a display.
"""

import numpy as np

from ._common import pyplot


def _title(text, case):
    return f"{text}: {case}" if case else text


def _done(fig, path):
    if path is not None:
        fig.savefig(path, dpi=110, bbox_inches="tight")
        pyplot().close(fig)
    return fig


def _completed(sim):
    """Number of completed steps and the dense arrays restricted to them."""
    if sim.dense_t is None:
        raise ValueError("this figure needs a dense simulation: simulate(..., dense_points=N)")
    k = int(sim.num_successful)
    return k, np.asarray(sim.dense_t)[:k], np.asarray(sim.dense_x)[:k]


def _step_starts(sim, k):
    T = np.asarray(sim.steps.period)[:k]
    return np.concatenate([[0.0], np.cumsum(T)])[:k]


#: Names of the coordinates in legends, by number of joint angles: the compass gait's
#: two legs and the kneed walker's stance leg, swing thigh and swing shank.
_COORDINATE_NAMES = {2: ("stance", "swing"), 3: ("stance", "swing thigh", "swing shank")}


def plot_states(sim, axes=None, path=None, case=None):
    """$q$ and $\\dot q$ against time (thesis Fig 7.2): stance-leg angle and velocity in
    one colour, swing leg in another; the lines swap at each impact (relabelling), and the
    velocities jump.

    **Arguments:** `sim` (dense `Simulation`), `axes` (two matplotlib axes, optional),
    `path` (save the figure there and close it), `case` (what was simulated, named in
    the title, e.g. `"stable gait, 3 deg"`).

    **Returns:** the matplotlib figure.
    """
    plt = pyplot()
    k, t, x = _completed(sim)
    if axes is None:  # wider for more steps (up to 14 in), so the swings stay apart
        width = min(14.0, 6.0 + 0.2 * k)
        fig, axes = plt.subplots(2, 1, figsize=(width, 5), sharex=True)
    else:
        fig = axes[0].figure
    starts = _step_starts(sim, k)
    n = x.shape[-1] // 2
    names = _COORDINATE_NAMES.get(n, ("stance",) + ("",) * (n - 1))
    for i in range(k):
        tt = starts[i] + t[i]
        for j in range(n):
            lab = f" ({names[j]})" if names[j] else ""
            colour = ("C3", "C2", "C0", "C1", "C4")[j % 5]
            axes[0].plot(
                tt, x[i, :, j], colour, lw=1.0, label=f"$q_{j + 1}${lab}" if i == 0 else None
            )
            axes[1].plot(
                tt,
                x[i, :, n + j],
                colour,
                lw=1.0,
                label=f"$\\dot q_{j + 1}${lab}" if i == 0 else None,
            )
    axes[0].set_ylabel("angle (rad)")
    axes[1].set_ylabel("angular velocity (rad/s)")
    axes[1].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.margins(x=0.01)
        # beside the plot, not over it: the curves' peaks stay visible
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
    axes[0].set_title(_title(f"States against time ({k} steps)", case), fontsize=10)
    return _done(fig, path)


def plot_phase_portrait(sim, ax=None, path=None, case=None):
    """Phase portrait of one physical leg (thesis Fig 7.3): $(q, \\dot q)$ while it is the
    stance leg (red) and while it is the swing leg (green); impacts are the jumps.
    `case`: what was simulated, named in the title.

    **Returns:** the matplotlib figure.
    """
    plt = pyplot()
    k, _, x = _completed(sim)
    n = x.shape[-1] // 2
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.5, 4.5))
    else:
        fig = ax.figure
    for i in range(k):
        # The leg that is the stance leg in step 0: coordinate 1 while in stance, 2 (its
        # thigh, for a kneed walker) while swinging; relabelling swaps them at impact.
        stance = i % 2 == 0
        j = 0 if stance else 1
        ax.plot(
            x[i, :, j],
            x[i, :, j + n],
            "C3" if stance else "C2",
            label=("stance" if stance else "swing") if i < 2 else None,
        )
        if i + 1 < k:  # the impact: a jump in velocity at fixed angle
            ax.plot(
                [x[i, -1, j], x[i + 1, 0, 1 - j]],
                [x[i, -1, j + n], x[i + 1, 0, n + 1 - j]],
                ":",
                color="0.5",
                lw=0.8,
            )
    ax.set_xlabel("leg angle (rad)")
    ax.set_ylabel("leg angular velocity (rad/s)")
    ax.set_title(_title("Phase portrait of one leg", case), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _done(fig, path)


#: Smallest half-height of the step-period axis, relative to the mean period: variations
#: below it (e.g. 5e-11 s of rounding on a periodic gait) are not magnified into a curve.
MIN_PERIOD_SPAN = 1e-4


def plot_step_periods(sim, ax=None, path=None, case=None):
    """Time between consecutive impacts against step number (thesis Fig 7.4), one marker
    per step (no connecting lines: a period-4 pattern stays visible over hundreds of
    steps). The y-axis spans at least `MIN_PERIOD_SPAN` of the mean period either side,
    so that rounding-level differences of a periodic gait show as a flat row. Needs no
    dense output. `case`: what was simulated, named in the title.

    **Returns:** the matplotlib figure.
    """
    plt = pyplot()
    k = int(sim.num_successful)
    T = np.asarray(sim.steps.period)[:k]
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 3.5))
    else:
        fig = ax.figure
    ax.plot(np.arange(1, k + 1), T, "o" if k <= 60 else ".", ms=4 if k <= 60 else 2.5, ls="none")
    if k:
        mid, half = 0.5 * (T.max() + T.min()), 0.5 * (T.max() - T.min())
        half = max(1.1 * half, MIN_PERIOD_SPAN * abs(mid))
        ax.set_ylim(mid - half, mid + half)
    ax.set_xlabel("step number")
    ax.set_ylabel("step period (s)")
    ax.set_title(_title("Time between consecutive impacts", case), fontsize=10)
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _done(fig, path)


def walker_frames(sim, model):
    """World positions of the walker at every dense time of the completed steps.

    **Returns:** dict with `t` (absolute times), `q` (angles) and the 2-D positions of
    every point of `model.points` (compass gait: `stance_foot`, `hip`, `swing_foot`,
    `stance_mass`, `swing_mass`; shape `(frames, 2)`), the stance foot moving to the
    impact point after each step.
    """
    import jax

    k, t, x = _completed(sim)
    n = t.shape[1]
    q = x[..., : model.n_dof].reshape(-1, model.n_dof)
    pts = {name: np.asarray(v) for name, v in jax.vmap(model.points)(q).items()}
    # Stance foot of each step: the previous step's swing foot at impact.
    feet = np.zeros((k, 2))
    for i in range(1, k):
        feet[i] = feet[i - 1] + pts["swing_foot"][i * n - 1]
    base = np.repeat(feet, n, axis=0)
    out = {name: v + base for name, v in pts.items()}
    out["t"] = (_step_starts(sim, k)[:, None] + t).reshape(-1)
    out["q"] = q
    return out


class _WalkerArtists:
    """The artists of the walker figure, drawn once; `update(i)` moves them to frame `i`
    in a window of width 4 l that follows the hip (an animation frame costs a few
    `set_data` calls, not a redrawn figure)."""

    def __init__(self, ax, frames, psi, l, texts, name="walker"):
        self.ax, self.frames, self.psi, self.l, self.texts = ax, frames, psi, l, texts
        ax.set_title(f"{name} on a {np.degrees(psi):.2f} deg slope", fontsize=10)
        hips = frames["hip"][:, 0]
        xs = np.array([hips.min() - 3.0 * l, hips.max() + 3.0 * l])
        ax.plot(xs, -np.tan(psi) * xs, color="0.3", lw=1.5)  # the slope
        ax.fill_between(xs, -np.tan(psi) * xs, -np.tan(psi) * xs - 10.0 * l, color="0.85")
        (self.prints,) = ax.plot([], [], "v", color="0.4", ms=5)
        (self.stance,) = ax.plot(
            [], [], color="C3", lw=3, solid_capstyle="round", label="stance leg"
        )
        (self.swing,) = ax.plot([], [], color="C2", lw=3, solid_capstyle="round", label="swing leg")
        (self.masses,) = ax.plot([], [], "o", color="k", ms=5)
        (self.hip,) = ax.plot([], [], "o", color="k", ms=12)
        self.text = ax.text(
            0.02, 0.95, "", transform=ax.transAxes, va="top", family="monospace", fontsize=9
        )
        ax.legend(loc="upper right", fontsize=8)
        ax.set_aspect("equal")
        # The window follows the hip: fixed tick positions would slide with it, so the
        # scale is given by the leg (1 leg length = l m) instead of ticks.
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_xlabel(f"downhill; window 4 l wide (leg length l = {l:g} m)")
        # Footprints so far: the distinct stance-foot positions, in order.
        self.mass_names = [n for n in frames if n not in _JOINTS + ("t", "q")]
        feet = frames["stance_foot"]
        self.first_index = np.concatenate(
            [[0], np.nonzero(np.any(np.diff(feet, axis=0) != 0, axis=1))[0] + 1]
        )

    def update(self, i):
        f, l, psi = self.frames, self.l, self.psi
        hip = f["hip"][i]
        shown = f["stance_foot"][self.first_index[self.first_index <= i]]
        self.prints.set_data(shown[:, 0], shown[:, 1])
        for line, names in ((self.stance, _STANCE_CHAIN), (self.swing, _SWING_CHAIN)):
            p = np.stack([f[n][i] for n in names if n in f])
            line.set_data(p[:, 0], p[:, 1])
        m = np.stack([f[n][i] for n in self.mass_names])
        self.masses.set_data(m[:, 0], m[:, 1])
        self.hip.set_data([hip[0]], [hip[1]])
        q = f["q"][i]
        self.text.set_text(self.texts.format(t=f["t"][i], q1=q[0], q2=q[1]))
        hip_x = hip[0]
        y0 = -np.tan(psi) * hip_x
        self.ax.set_xlim(hip_x - 2.0 * l, hip_x + 2.0 * l)
        self.ax.set_ylim(y0 - 0.6 * l, y0 + 1.4 * l)


#: Points drawn as the legs (a point a model lacks, e.g. a knee, is skipped); every other
#: point of `model.points` is drawn as a mass.
_STANCE_CHAIN = ("stance_foot", "stance_knee", "hip")
_SWING_CHAIN = ("hip", "knee", "swing_foot")
_JOINTS = _STANCE_CHAIN + _SWING_CHAIN


def _leg_length(frames):
    """Stance foot to hip at the first frame (m): the window scale of the figure."""
    return float(np.linalg.norm(frames["hip"][0] - frames["stance_foot"][0]))


_TEXT = "t = {t:5.2f} s\nq1 = {q1:+.3f} rad\nq2 = {q2:+.3f} rad"


def plot_walker(sim, model, frame=0, ax=None, path=None):
    """One frame of the animation: slope, stance leg (red), swing leg (green), hip and
    leg masses, time and angles.

    **Returns:** the matplotlib figure.
    """
    plt = pyplot()
    frames = walker_frames(sim, model)
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 3.2))
    else:
        fig = ax.figure
    _WalkerArtists(
        ax, frames, float(model.psi), _leg_length(frames), _TEXT, type(model).__name__
    ).update(frame)
    return _done(fig, path)


def animate(sim, model, path, *, fps=None, max_frames=300):
    """Animation of the walker going down the slope (thesis Fig 3.5), saved as a GIF.

    **Arguments:**

    - `sim`: a dense `Simulation`; `model`: the model that produced it.
    - `path`: output file (`.gif`) or binary file object; written as a GIF by Pillow.
    - `fps`: frames per second; default: real time (dense points per step / period).
    - `max_frames`: frames are subsampled evenly beyond this.

    **Returns:** the number of frames written.
    """
    plt = pyplot()
    from PIL import Image

    frames = walker_frames(sim, model)
    nframes = len(frames["t"])
    if nframes == 0:
        raise ValueError("no completed step to animate")
    idx = np.unique(np.linspace(0, nframes - 1, min(nframes, max_frames)).round().astype(int))
    if fps is None:
        duration = frames["t"][-1] - frames["t"][0]
        fps = max(1.0, min(50.0, len(idx) / max(duration, 1e-9)))
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=80)
    artists = _WalkerArtists(
        ax, frames, float(model.psi), _leg_length(frames), _TEXT, type(model).__name__
    )

    def update(j):
        artists.update(idx[j])
        return ()

    images = []
    for j in range(len(idx)):  # one draw per frame, straight into Pillow
        update(j)
        fig.canvas.draw()
        # `buffer_rgba` is on every Agg-based canvas (the default one and the interactive
        # ones), not on the FigureCanvasBase that matplotlib's stubs give `fig.canvas`.
        rgba = fig.canvas.buffer_rgba()  # pyright: ignore[reportAttributeAccessIssue]  # Agg API
        images.append(
            Image.fromarray(np.asarray(rgba)).convert(
                "P", palette=Image.Palette.ADAPTIVE, colors=64
            )
        )
    plt.close(fig)
    images[0].save(  # GIF whatever the name: `path` may be a file object or a pipe
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=int(round(1000.0 / fps)),
        loop=0,
    )
    return len(idx)
