"""`vhcjax stabilize`: input checks (one line, exit 2) and one full run, checked against
itself two ways (multipliers) and against the gait (simulation)."""

import json

import numpy as np
import pytest
from _text import assert_plain_text

from vhcjax import cli


@pytest.mark.parametrize(
    "flags",
    [
        ["--r", "nan"],
        ["--r", "-1"],
        ["--torque-limit", "-1"],
        ["--torque-limit", "inf"],
        ["--perturbation", "inf"],
        ["--perturbation", "-0.1"],
        ["--q", "1,nan,1"],
        ["--q", "1,2"],
        ["--q", "a,b,c"],
        ["--q", "0,0,0"],
        ["--steps", "0"],
        ["--basin-grid", "1"],
        ["--slope-deg", "nan"],
        ["--model", "kneed", "--family", "stable"],
        ["--model", "kneed", "--q", "1,1,1"],
        ["--model", "kneed", "--r", "1,2,3"],
        ["--r", "1,2"],
        ["--model", "kneed", "--mass-leg", "5"],
    ],
)
def test_bad_input_is_one_line_exit_2(flags, capsys):
    assert cli.main(["stabilize", *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vhcjax stabilize: error:") and "\n" not in err


def _no_constants(name):
    raise AssertionError(f"JSON holds {name}")


def test_stabilize_json_and_png(tmp_path, capsys):
    png = tmp_path / "stab.png"
    argv = [
        "stabilize",
        "--slope-deg",
        "3",
        "--family",
        "unstable",
        "--torque-limit",
        "8",
        "--basin",
        "--basin-grid",
        "9",
        "--json",
        "--png",
        str(png),
    ]
    assert cli.main(argv) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=_no_constants)
    for key in (
        "result",
        "slope_deg",
        "family",
        "open_loop_multipliers",
        "closed_loop_multipliers",
        "closed_loop_multipliers_transverse",
        "stable",
        "max_gain",
        "simulation",
        "basin",
    ):
        assert key in out, key
    assert out["result"] == "successful" and out["stable"] is True
    assert out["slope_deg"] == 3.0 and out["family"] == "unstable"
    cl = np.array(out["closed_loop_multipliers"])
    np.testing.assert_allclose(cl, np.array(out["closed_loop_multipliers_transverse"]), atol=1e-6)
    assert np.max(np.hypot(cl[:, 0], cl[:, 1])) < 1
    ol = np.array(out["open_loop_multipliers"])
    assert np.max(np.hypot(ol[:, 0], ol[:, 1])) > 1
    sim = out["simulation"]
    assert {"x0", "x_final", "steps", "max_abs_torque"} <= set(sim)
    assert sim["steps"] == 30 and 0 < sim["max_abs_torque"] <= 8.0
    # x0 is the gait plus 0.01 on every section coordinate; x_final is back on the gait.
    z = np.array(out["gait"])
    x0, xf = np.array(sim["x0"]), np.array(sim["x_final"])
    np.testing.assert_allclose(x0[[0, 2, 3]], z + 0.01, atol=1e-12)
    np.testing.assert_allclose(xf[[0, 2, 3]], z, atol=1e-8)
    assert sim["recovered"] is True and "recovered_reason" not in sim
    b = out["basin"]
    assert b["passive_fraction"] == 0.0 and b["closed_loop_fraction"] > 0.5
    assert png.stat().st_size > 10_000


def test_without_basin_the_fractions_are_null_with_a_reason(capsys):
    argv = ["stabilize", "--steps", "30", "--perturbation", "1.0", "--json"]
    assert cli.main(argv) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out, parse_constant=_no_constants)
    assert out["basin"]["passive_fraction"] is None
    assert out["basin"]["closed_loop_fraction"] is None and out["basin"]["reason"]
    # so far off the gait both walkers fall at once: no final error, and why
    sim = out["simulation"]
    assert sim["result"] == "fell" and sim["steps_completed"] == 0
    assert sim["final_error"] is None and sim["final_error_reason"].startswith("fell after 0")
    assert sim["passive_final_error"] is None and sim["passive_final_error_reason"]
    # locally stable, but this start was not recovered: said beside the verdict
    assert out["stable"] is True and sim["recovered"] is False
    assert "not recovered (ended fell after 0 steps)" in sim["recovered_reason"]
    assert "warning: stable is the local verdict" in captured.err
    # the same in words (the programs are compiled)
    assert cli.main(argv[:-1] + ["--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "verdict with feedback: stable" in text and "True" not in text
    assert "without feedback: fell after 0 of 30 steps" in text


def test_a_saturated_torque_says_the_perturbation_was_not_recovered(capsys):
    argv = ["stabilize", "--torque-limit", "0.001", "--json"]
    assert cli.main(argv) == 0
    out = json.loads(capsys.readouterr().out, parse_constant=_no_constants)
    sim = out["simulation"]
    assert out["stable"] is True and sim["max_abs_torque"] <= 0.001
    # the unstable gait drifts away as if passive: the error equals the passive one
    assert sim["recovered"] is False and sim["final_error"] > 0.1
    assert abs(sim["final_error"] - sim["passive_final_error"]) < 0.01
    assert "torque limit of 0.001 N m saturates" in sim["recovered_reason"]
