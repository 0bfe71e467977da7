"""`vhcjax simulate`: JSON output checked against the scipy reference, every bad input."""

import json
import math
import os
import shutil
import subprocess
import sys

import _paths  # noqa: F401  (puts benchmarks/ on sys.path)
import numpy as np
import pytest
import scipy_reference as ref
from _text import assert_plain_text

from vhcjax import cli

THESIS_7_5 = ["0.218669", "-0.323389", "-1.092386", "-0.377377"]


def run_cli(capsys, *argv):
    code = cli.main(["simulate", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_output_matches_scipy_reference(capsys):
    code, out, err = run_cli(
        capsys, "--slope-deg", "3", "--x0", *THESIS_7_5, "--steps", "3", "--json"
    )
    assert code == 0, err
    data = json.loads(out)  # exactly one JSON object on stdout
    assert data["result"] == "successful"
    assert len(data["steps"]) == 3
    r = ref.simulate(ref.Params(), np.array(THESIS_7_5, float), 3)
    for s, rs in zip(data["steps"], r):
        assert set(s) == {"x_plus", "x_minus", "period", "result"}
        assert s["result"] == "successful"
        assert abs(s["period"] - rs.period) < 1e-8
        np.testing.assert_allclose(s["x_plus"], rs.x_plus, atol=1e-7)
        np.testing.assert_allclose(s["x_minus"], rs.x_minus, atol=1e-7)


def test_table_output_and_default_start(capsys):
    code, out, err = run_cli(capsys, "--steps", "3")
    assert code == 0, err
    assert "result: successful (3/3 steps)" in out
    assert "0.7343" in out
    assert "q1 0.218669 rad" in out and "angles in rad" in out  # the start, with units
    assert_plain_text(out)


def test_a_fall_is_reported_not_an_error(capsys):
    # Backward push: the walker falls back in the first step.
    code, out, err = run_cli(
        capsys, "--x0", "0.1", str(-0.1 - 2 * math.radians(3)), "1.5", "0", "--steps", "3", "--json"
    )
    assert code == 0, err
    data = json.loads(out)
    assert data["result"] == "fell"
    assert len(data["steps"]) == 1 and data["steps"][0]["result"] == "fell"
    assert data["steps"][0]["x_plus"] is None


BAD = [
    (["--mass-hip", "0"], "--mass-hip must be positive"),
    (["--mass-leg", "-1"], "--mass-leg must be positive"),
    (["--a", "0"], "the swing leg then has no inertia"),
    (["--a", "-1"], "--a must be positive"),
    (["--b", "-0.5"], "--b must be positive"),
    (["--gravity", "0"], "--gravity must be positive"),
    (["--slope-deg", "0"], "--slope-deg must be in (0, 30)"),
    (["--slope-deg", "30"], "--slope-deg must be in (0, 30)"),
    (["--slope-deg", "-3"], "--slope-deg must be in (0, 30)"),
    (["--slope-deg", "nan"], "--slope-deg must be a finite number"),
    (["--mass-hip", "inf"], "--mass-hip must be a finite number"),
    (["--x0", "0.2", "nan", "-1", "-0.3"], "--x0 must be a finite number"),
    (["--x0", "1.7", "-1.8", "-1", "-0.3"], "hip below the slope"),
    (["--x0", "-0.3", "0.1", "-1", "-0.3"], "swing foot below the slope"),
    (["--steps", "0"], "--steps must be in"),
    (["--animate", "walker.mp4"], "needs a .gif"),
]


@pytest.mark.parametrize("argv, message", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_one_line_error_exit_2(capsys, argv, message):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vhcjax simulate: error:"), err
    assert message in lines[0]
    assert "Traceback" not in err


def test_installed_entry_point_subprocess():
    exe = shutil.which("vhcjax") or os.path.join(os.path.dirname(sys.executable), "vhcjax")
    proc = subprocess.run(
        [exe, "simulate", "--slope-deg", "45"], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert (
        proc.stderr.strip()
        == "vhcjax simulate: error: --slope-deg must be in (0, 30) degrees, got 45"
    )


@pytest.mark.slow
def test_plots_and_animation_written(capsys, tmp_path):
    gif = tmp_path / "walker.gif"
    code, out, err = run_cli(
        capsys, "--steps", "1", "--plots", str(tmp_path / "figs"), "--animate", str(gif)
    )
    assert code == 0, err
    for name in ("states.png", "phase.png", "periods.png"):
        data = (tmp_path / "figs" / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 40  # 1 step x 40 dense points
