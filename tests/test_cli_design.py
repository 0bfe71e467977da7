"""`vhcjax design` / `vhcjax atlas`: JSON keys, CSV/PNG output, one-line errors."""

import csv
import json
import math

import numpy as np
import pytest
from _text import assert_plain_text

from vhcjax.cli import main

DESIGN_KEYS = {
    "objective",
    "slope_deg",
    "vary",
    "result",
    "iterations",
    "initial",
    "optimum",
    "history",
    "projected_gradient",
    "stationarity",
    "sampling_radius",
    "result_reason",
}


@pytest.mark.parametrize(
    "argv,msg",
    [
        (
            ["design", "--objective", "speed", "--vary", "mass-hip", "--slope-deg", "nan"],
            "--slope-deg",
        ),
        (["design", "--objective", "speed", "--vary", "legs"], "--vary"),
        (["design", "--objective", "speed", "--vary", "a,a"], "--vary"),
        (["design", "--objective", "speed", "--vary", "a", "--bounds", "a=0.9:0.1"], "--bounds"),
        (["design", "--objective", "speed", "--vary", "a", "--bounds", "a=nan:1"], "--bounds"),
        (["design", "--objective", "speed", "--vary", "a", "--bounds", "b=0.1:0.9"], "--bounds"),
        (["design", "--objective", "speed", "--vary", "a", "--bounds", "a=0.6:0.9"], "bounds"),
        (["design", "--objective", "speed", "--vary", "a", "--steps", "0"], "--steps"),
        (
            ["design", "--objective", "speed", "--vary", "a", "--learning-rate", "-1"],
            "--learning-rate",
        ),
        (
            ["design", "--objective", "speed", "--vary", "a", "--learning-rate", "inf"],
            "--learning-rate",
        ),
        (["design", "--objective", "speed", "--vary", "a", "--mass-hip", "-3"], "--mass-hip"),
        (["atlas", "--mass-ratio", "1:0:1", "--length-ratio", "1"], "--mass-ratio"),
        (["atlas", "--mass-ratio", "1,x", "--length-ratio", "1"], "--mass-ratio"),
        (["atlas", "--mass-ratio", "1:1e12:1e-6", "--length-ratio", "1"], "--mass-ratio"),
        (["atlas", "--mass-ratio", "2", "--length-ratio", "-1"], "--length-ratio"),
        (["atlas", "--mass-ratio", "2", "--length-ratio", "nan"], "--length-ratio"),
        (["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--slope-deg", "45"], "--slope-deg"),
        (
            ["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--scan-step-deg", "0"],
            "--scan-step-deg",
        ),
        (
            ["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--scan-max-deg", "0.5"],
            "--scan-max-deg",
        ),
        (["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--gravity", "inf"], "--gravity"),
    ],
)
def test_errors_are_one_line(capsys, argv, msg):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err


def test_bad_objective_exits_2():
    assert main(["design", "--objective", "beauty", "--vary", "a"]) == 2


def test_design_json_png(tmp_path, capsys):
    png = tmp_path / "d.png"
    argv = [
        "design",
        "--objective",
        "speed",
        "--vary",
        "mass-hip,a",
        "--steps",
        "3",
        "--bounds",
        "mass-hip=5:20,a=0.3:0.7",
        "--json",
        "--png",
        str(png),
    ]
    rc = main(argv)
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert DESIGN_KEYS <= set(out)
    assert out["vary"] == ["mass-hip", "a"] and out["slope_deg"] == 3.0
    for key in ("initial", "optimum"):
        assert set(out[key]["params"]) == {"mass-hip", "mass-leg", "a", "b", "gravity"}
        assert set(out[key]["gradient"]) == {"mass-hip", "a"}
    assert len(out["optimum"]["x0"]) == 4 and len(out["optimum"]["multipliers"]) == 3
    assert len(out["history"]) == out["iterations"] + 1
    steps = [h["step"] for h in out["history"]]
    assert steps[0] == "start" and set(steps[1:]) <= {"adam", "gradient sampling"}
    assert out["optimum"]["value"] >= out["initial"]["value"]  # speed is maximised
    assert png.stat().st_size > 10_000
    # in words, with units (the same run again: its programs are compiled)
    assert main(argv[: argv.index("--json")] + ["--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "design: maximise the speed of the stable gait at slope 3 deg" in text
    assert " m/s -> " in text and " kg" in text and "  a: 0.5 -> " in text


def test_atlas_json_csv_png(tmp_path, capsys):
    csv_path, png = tmp_path / "a.csv", tmp_path / "a.png"
    argv = ["atlas", "--mass-ratio", "2", "--length-ratio", "0.9,1", "--slope-deg", "3"]
    rc = main([*argv, "--json", "--csv", str(csv_path), "--png", str(png)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert set(out) == {"mass_ratio", "length_ratio", "cells"}
    assert out["mass_ratio"] == [2.0] and out["length_ratio"] == [0.9, 1.0]
    for c in out["cells"]:
        assert {
            "mass_ratio",
            "length_ratio",
            "flip_slope_deg",
            "stable_range_deg",
            "spectral_radius",
        } <= set(c)
    table1 = out["cells"][1]
    assert abs(table1["flip_slope_deg"] - 4.390898) < 1e-4  # `period_doubling_slope`
    lo, hi = table1["stable_range_deg"]
    assert lo <= 3.0 < hi == table1["flip_slope_deg"]
    assert 0 < table1["spectral_radius"] < 1
    rows = list(csv.DictReader(open(csv_path)))
    assert len(rows) == 2 and math.isclose(
        float(rows[1]["flip_slope_deg"]), table1["flip_slope_deg"]
    )
    assert png.stat().st_size > 10_000
    assert "NaN" not in json.dumps(out) and "Infinity" not in json.dumps(out)
    assert np.isfinite(float(rows[0]["spectral_radius"]))
    # in words, one line per cell (the same programs)
    assert main([*argv, "--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "found in 2 of 2 cells" in text and "mu 2, beta 1: flip at 4.3909" in text
    # with a checkpoint folder: the same JSON, and again from the folder alone
    ck = tmp_path / "ck"
    for _ in range(2):
        assert main([*argv, "--json", "--checkpoint", str(ck)]) == 0
        assert json.loads(capsys.readouterr().out) == out
    assert sorted(p.name for p in ck.iterdir()) == ["cells-000000-000001.csv", "manifest.json"]
    # a folder of another run is refused in one line, before any work
    assert main([*argv[:-1], "3.5", "--checkpoint", str(ck)]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds a run with other settings (slope)" in err and "\n" not in err


def test_ratio_ranges_never_pass_stop():
    from vhcjax.cli._design import parse_values

    assert parse_values("1:2:1.5", "--mass-ratio") == [1.0]
    assert parse_values("1:2:0.5", "--mass-ratio") == [1.0, 1.5, 2.0]
