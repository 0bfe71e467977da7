"""`vhcjax gait` / `vhcjax sweep`: JSON schema, values, CSV/PNG output, errors."""

import csv
import json

import numpy as np
import pytest
from _text import assert_plain_text

import vhcjax as vj
from vhcjax import gait as G
from vhcjax.cli import main


def test_gait_json(capsys):
    rc = main(
        [
            "gait",
            "--slope-deg",
            "3",
            "--family",
            "stable",
            "--method",
            "vhc",
            "--guess",
            "0.2",
            "-1.0",
            "--json",
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    # the multipliers add keys; these must be there
    assert {
        "result",
        "slope_deg",
        "family",
        "method",
        "x0",
        "params",
        "iterations",
        "residual",
    } <= set(out)
    assert out["result"] == "successful" and out["family"] == "stable" and out["method"] == "vhc"
    assert set(out["params"]) == set("abcdefgh") | {"T", "E0"}
    g = G.find_gait(vj.CompassGait(), "stable", guess=(0.2, -1.0))
    np.testing.assert_allclose(out["x0"], np.asarray(g.x_plus), atol=1e-14)
    # x0 is (a, e, b, f) and the thesis (7.5) to its printed digits
    p = out["params"]
    assert out["x0"] == [p["a"], p["e"], p["b"], p["f"]]
    np.testing.assert_allclose(out["x0"][:2], [0.218669, -0.323389], atol=6e-7)
    # by default the multipliers of the Poincare-map Jacobian (autodiff) only; they are
    # those of central differences of the step map
    assert out["multipliers"] is None and out["transverse_result"] == "not_requested"
    assert "--transverse" in out["multipliers_reason"]
    z = np.array([out["x0"][0], out["x0"][2], out["x0"][3]])
    fd = np.linalg.eigvals(np.asarray(vj.stability.finite_difference_jacobian(vj.CompassGait(), z)))
    ev = np.array(out["multipliers_poincare"])
    np.testing.assert_allclose(
        sorted(np.abs(ev[:, 0] + 1j * ev[:, 1])), sorted(np.abs(fd)), atol=1e-6
    )
    assert out["max_abs_multiplier"] == pytest.approx(max(np.abs(fd)), abs=1e-6)


def test_gait_text_names_every_number_and_shows_the_transverse_multipliers(capsys):
    """Without --json: the gait parameters with units and meaning, the verdict with its
    reason, and with --transverse the transverse multipliers beside the Poincare ones."""
    assert main(["gait", "--slope-deg", "3", "--quiet"]) == 0
    plain = capsys.readouterr().out
    assert_plain_text(plain)
    assert "a =  0.218668803 rad    q1 just after impact" in plain
    assert "T =  0.734346391 s      step period" in plain
    assert "verdict: stable (largest multiplier modulus 0.579952 < 1)" in plain
    assert "transverse" not in plain
    assert main(["gait", "--slope-deg", "3", "--transverse", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "multipliers (transverse linearization): -0.199726 + 0.544476i" in text
    assert "the two computations agree to" in text
    # `multipliers` runs the same programs: a table of both computations, with moduli
    assert main(["multipliers", "--slope-deg", "3", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "post-impact state: q1 0.21866880 rad, dq1 -1.09238359 rad/s" in text
    assert "-0.19972613 + 0.54447606i" in text and "0.57995233" in text


@pytest.mark.parametrize(
    "argv,msg",
    [
        (["gait", "--slope-deg", "40"], "--slope-deg"),
        (["gait", "--slope-deg", "nan"], "--slope-deg"),
        (["gait", "--mass-hip", "-1"], "--mass-hip"),
        (["gait", "--guess", "nan", "1"], "--guess"),
        (["sweep", "--slope-deg", "1:0.5:0.1"], "--slope-deg"),
        (["sweep", "--slope-deg", "1:2"], "--slope-deg"),
        (["sweep", "--slope-deg", "0:2:1"], "--slope-deg"),
    ],
)
def test_errors_are_one_line(capsys, argv, msg):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and "\n" not in err


def test_bad_choice_exits_2(capsys):
    assert main(["gait", "--family", "sideways"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--family" in err and "\n" not in err


@pytest.mark.slow
def test_sweep_csv_png(tmp_path, capsys):
    csv_path, png_path = tmp_path / "s.csv", tmp_path / "s.png"
    rc = main(
        [
            "sweep",
            "--slope-deg",
            "2.5:3.5:0.5",
            "--family",
            "both",
            "--csv",
            str(csv_path),
            "--png",
            str(png_path),
            "--transverse",
        ]
    )
    assert rc == 0
    rows = list(csv.DictReader(open(csv_path)))
    assert len(rows) == 6
    # the gait columns, in order, then the stability columns
    assert list(rows[0])[1:15] == [
        "slope_deg",
        "result",
        "a",
        "b",
        "c",
        "d",
        "e",
        "f",
        "g",
        "h",
        "T",
        "E0",
        "step_length",
        "speed",
    ]
    assert "mult1_re" in rows[0] and "stable" in rows[0]
    # two ways: the transverse linearization (asked for) and the Poincare-map Jacobian
    for r in rows:
        assert r["transverse_result"] == "successful"
        for k in range(1, 4):
            for part in ("re", "im"):
                t, p = float(r[f"mult{k}_{part}"]), float(r[f"pmult{k}_{part}"])
                assert abs(t - p) < 1e-6 * float(r["max_abs_multiplier"])
    # the stable family is stable at these slopes, the unstable one is not
    assert all(r["stable"] in ("True", "true", "1") for r in rows if r["family"] == "stable")
    assert all(r["stable"] in ("False", "false", "0") for r in rows if r["family"] == "unstable")
    assert all(r["result"] == "successful" for r in rows)
    r3 = [r for r in rows if r["family"] == "unstable" and float(r["slope_deg"]) == 3.0][0]
    np.testing.assert_allclose(float(r3["a"]), 0.204676, atol=6e-7)  # thesis (7.9)
    assert png_path.stat().st_size > 10_000
    text = capsys.readouterr().out
    assert "stable family: gait found at 3 of 3 slopes (2.5 to 3.5 deg)" in text
    assert_plain_text(text)
    # the same sweep as JSON carries the same stability columns (same programs)
    args = ["sweep", "--slope-deg", "2.5:3.5:0.5", "--family", "both", "--transverse"]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for r in rows:
        j = out["families"][r["family"]]["rows"][[2.5, 3.0, 3.5].index(float(r["slope_deg"]))]
        for key in ("mult1_re", "pmult1_re", "max_abs_multiplier"):
            assert j[key] == pytest.approx(float(r[key]), abs=1e-12)
        assert str(j["stable"]) == r["stable"]
    # without an output that shows multipliers, --transverse is refused, not ignored
    assert main(args) == 2
    assert "--transverse" in capsys.readouterr().err
