"""Figures and animation from a dense simulation; the walker's geometry in the animation."""

import math

import _sim
import numpy as np

import vhcjax as vj
from vhcjax.plotting import _simulation as plotting

PNG = b"\x89PNG\r\n\x1a\n"


def test_figures_written(tmp_path):
    sim = _sim.thesis_walk_dense()
    for fn, name in (
        (plotting.plot_states, "states"),
        (plotting.plot_phase_portrait, "phase"),
        (plotting.plot_step_periods, "periods"),
    ):
        path = tmp_path / f"{name}.png"
        fn(sim, path=path)
        data = path.read_bytes()
        assert data[:8] == PNG and len(data) > 5000
    plotting.plot_walker(sim, vj.CompassGait(), frame=30, path=tmp_path / "frame.png")
    assert (tmp_path / "frame.png").read_bytes()[:8] == PNG


def test_animation_gif(tmp_path):
    from PIL import Image

    sim = _sim.thesis_walk_dense()
    n = plotting.animate(sim, vj.CompassGait(), tmp_path / "w.gif", max_frames=12)
    with Image.open(tmp_path / "w.gif") as im:
        assert im.n_frames == n == 12


def test_walker_frames_footprints_on_slope_and_step_length():
    """Footprints lie on the slope line and are one step length apart, the step length
    computed from the pre-impact angles: 2 l sin((q2 - q1)/2)."""
    sim = _sim.thesis_walk_dense()
    model = vj.CompassGait()
    fr = plotting.walker_frames(sim, model)
    psi, l = float(model.psi), float(model.l)
    n = np.asarray(sim.dense_t).shape[1]
    feet = fr["stance_foot"][::n]
    np.testing.assert_allclose(feet[:, 1], -math.tan(psi) * feet[:, 0], atol=1e-9)
    xm = np.asarray(sim.steps.x_minus)
    lengths = 2 * l * np.sin((xm[:, 1] - xm[:, 0]) / 2)
    np.testing.assert_allclose(
        np.linalg.norm(np.diff(feet, axis=0), axis=1), lengths[:-1], rtol=1e-9
    )
    assert np.all(np.diff(feet[:, 0]) > 0)  # downhill, toward +x
    # Rigid legs: hip-to-foot distances are l in every frame.
    np.testing.assert_allclose(np.linalg.norm(fr["hip"] - fr["stance_foot"], axis=1), l)
    np.testing.assert_allclose(np.linalg.norm(fr["hip"] - fr["swing_foot"], axis=1), l)
