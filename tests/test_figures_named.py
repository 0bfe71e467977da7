"""Every figure function draws what its name says: each panel holds data, has
axis labels with the quantity named by the function, and the title names the case.

Inputs are small synthetic results (the figures' contract is their drawing, not the
computation), except the simulation figures, which take a real dense simulation.
"""

from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import vhcjax as vj
from vhcjax import plotting as P
from vhcjax.robustness import CONVERGED, FELL

CASE = "stable gait, 3.5 deg"
RNG = np.random.default_rng(0)


def _sim():
    import jax.numpy as jnp

    x0 = jnp.array([0.218669, -0.323389, -1.092386, -0.377377])
    return vj.simulate(vj.CompassGait(), x0, 3, dense_points=12)


def _sweep():
    psi = np.radians(np.linspace(1, 5, 9))
    gaits = SimpleNamespace(a=0.2 + 0.01 * psi, b=-1 - psi, T=0.7 + psi, speed=0.5 + psi)
    return {"stable": SimpleNamespace(ok=np.ones(9, bool), psi=psi, gaits=gaits)}


def _basin():
    label = np.full((6, 5), CONVERGED)
    label[0, :] = FELL
    return SimpleNamespace(
        axes=(0, 1),
        z_star=np.array([0.22, -1.09, -0.38]),
        offsets_x=np.linspace(-0.05, 0.05, 5),
        offsets_y=np.linspace(-0.3, 0.3, 6),
        label=label,
        steps=RNG.integers(1, 20, (6, 5)),
        tol=1e-4,
        area=0.01,
        fraction=0.8,
    )


def _contraction():
    d = 1e-3 * 0.58 ** np.arange(12)[None, :] * (1 + 0.1 * RNG.random((4, 12)))
    return SimpleNamespace(
        distance=d, spectral_radius=0.58, measured_rate=0.57, steps_10x=4.2, steps_100x=8.4
    )


def _terrain():
    T = 0.73 + 0.01 * RNG.random((2, 8))
    return (
        np.array([-0.005, 0.002]),
        SimpleNamespace(
            step_times=T,
            distance=1e-3 * 0.6 ** np.arange(9)[None] * np.ones((2, 1)),
            label=np.array([0, 0]),
        ),
        0.734,
    )


def _slope():
    return SimpleNamespace(
        dz=np.array([0.5, -1.2, 3.0]),
        dperiod=0.3,
        dstep_length=0.8,
        dspeed=1.1,
        dmodulus=np.array([2.0, 2.0, -0.3]),
    )


def _bif():
    psi = np.radians(np.linspace(4, 5, 6))
    return SimpleNamespace(
        psi=psi, periods=0.7 + 0.01 * RNG.random((6, 8)), fell=np.array([False] * 5 + [True])
    )


ev = np.array([-0.2 + 0.54j, -0.2 - 0.54j, 0.13])

#: name -> (call returning a figure, words its axis labels must hold)
FIGURES = {
    "plot_states": (lambda: P.plot_states(_sim(), case=CASE), ["angle", "velocity", "time"]),
    "plot_phase_portrait": (
        lambda: P.plot_phase_portrait(_sim(), case=CASE),
        ["angle", "velocity"],
    ),
    "plot_step_periods": (
        lambda: P.plot_step_periods(_sim(), case=CASE),
        ["step number", "period"],
    ),
    "plot_sweep": (lambda: P.plot_sweep(_sweep(), case=CASE), ["slope", "speed", "period"]),
    "plot_basin": (lambda: P.plot_basin(_basin(), case=CASE), ["q_1", "dot q_1"]),
    "plot_contraction": (
        lambda: P.plot_contraction(_contraction(), case=CASE),
        ["step", "x_k - x^*"],
    ),
    "plot_terrain": (lambda: P.plot_terrain(*_terrain(), case=CASE), ["step time", "x_k"]),
    "plot_push": (
        lambda: P.plot_push(
            np.linspace(0, 0.75, 4),
            RNG.random((4, 4, 2)),
            np.radians([0, 180]),
            RNG.random((4, 2)),
            case=CASE,
        ),
        ["phase", "largest push"],
    ),
    "plot_slope": (
        lambda: P.plot_slope(_slope(), case=CASE),
        ["rad / deg", "rad/s / deg", "s / deg", "m / deg", "m/s / deg"],
    ),
    "plot_multipliers_complex": (
        lambda: P.plot_multipliers_complex([ev], ["Poincare"], title=CASE),
        ["Re", "Im"],
    ),
    "plot_multipliers_vs_slope": (
        lambda: P.plot_multipliers_vs_slope(
            np.linspace(1, 5, 5), {"stable": np.tile(ev, (5, 1))}, case=CASE
        ),
        ["slope", "multiplier"],
    ),
    "plot_bifurcation": (lambda: P.plot_bifurcation(_bif(), case=CASE), ["slope", "step period"]),
}


#: Figures of the control and parameter studies: drawn from real results by the tests of
#: `vhcjax stabilize` and `vhcjax design` / `vhcjax atlas` (PNG written, checked there).
TESTED_ELSEWHERE = {"plot_walker", "plot_stabilization", "plot_design", "plot_atlas"}


def test_every_public_figure_function_is_covered():
    public = {n for n in dir(P) if n.startswith("plot_")} - TESTED_ELSEWHERE
    assert public == set(FIGURES)


@pytest.mark.parametrize("name", sorted(FIGURES))
def test_figure_draws_what_its_name_says(name):
    make, words = FIGURES[name]
    fig = make()
    try:
        panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
        assert panels
        labels = []
        for ax in panels:
            assert ax.lines or ax.patches or ax.images or ax.collections, (name, ax)
            assert ax.get_xlabel() or not ax.get_xticks().size or ax.get_ylabel()
            assert ax.get_ylabel(), (name, "no y label")
            labels += [ax.get_xlabel(), ax.get_ylabel()]
        text = " ".join(labels).replace("$", "").replace("\\", "")
        for w in words:
            assert w in text, (name, w, text)
        titles = [ax.get_title() for ax in panels] + [
            fig._suptitle.get_text() if fig._suptitle else ""
        ]
        assert any(CASE in t for t in titles), (name, titles)
    finally:
        plt.close(fig)


@pytest.mark.parametrize("name", sorted(FIGURES))
def test_dimensionless_axes_carry_no_unit(name):
    """A dimensionless quantity is written without a unit: no "(1)" or "(-)"."""
    fig = FIGURES[name][0]()
    try:
        for ax in fig.axes:
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                assert not label.rstrip().endswith(("(1)", "(-)")), (name, label)
    finally:
        plt.close(fig)


def test_state_legends_sit_beside_the_curves():
    """The legends of the states figure are outside its panels: they cover no peak."""
    fig = P.plot_states(_sim(), case=CASE)
    try:
        fig.canvas.draw()
        for ax in fig.axes:
            box = ax.get_legend().get_window_extent()
            assert box.x0 >= ax.get_window_extent().x1, "legend over the curves"
    finally:
        plt.close(fig)


def _marked(line):
    """The line draws markers (points), not only a line."""
    return line.get_marker() not in (None, "None", "", " ")


def test_bifurcation_marks_falls_in_a_row_of_their_own():
    """Falls have no step period: they are drawn in a row below the diagram, not at an
    arbitrary period in it; the period-doubling line has a legend entry."""
    fig = P.plot_bifurcation(_bif(), flips_deg=[4.5], case=CASE, no_gait_deg=[4.1])
    try:
        main, row = fig.axes
        dots = [line for line in main.lines if _marked(line)]
        periods = np.concatenate([np.asarray(line.get_ydata(), float) for line in dots])
        assert periods.min() >= 0.7 and not any(line.get_marker() == "x" for line in dots)
        assert "falls" in row.get_ylabel() and "no gait" in row.get_ylabel()
        marks = {line.get_label(): len(line.get_xdata()) for line in row.lines if _marked(line)}
        assert marks["fell"] == 1 and marks["no gait"] == 1
        legend = [t.get_text() for t in main.get_legend().get_texts()]
        assert any("period doubling" in t for t in legend)
    finally:
        plt.close(fig)


def test_multipliers_that_nearly_coincide_stay_visible():
    """Every set of multipliers is drawn with open markers of its own shape and size, the
    later ones above: the thesis's 0.123 does not hide our 0.1316 (Fig 7.1)."""
    thesis = np.array([0.123, 0.127 - 0.586j, 0.127 + 0.586j])
    fig = P.plot_multipliers_complex([ev, ev, thesis], ["ours", "ours again", "thesis"])
    try:
        points = [line for line in fig.axes[0].lines if _marked(line)]
        assert len(points) == 3
        assert all(line.get_markerfacecolor() == "none" for line in points)
        assert len({line.get_marker() for line in points}) == 3
        sizes = [line.get_markersize() for line in points]
        assert sizes == sorted(sizes, reverse=True)
        orders = [line.get_zorder() for line in points]
        assert orders == sorted(orders)
    finally:
        plt.close(fig)
