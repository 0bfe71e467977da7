"""`vhcjax gait` / `vhcjax sweep`: JSON schema, values, CSV/PNG output, errors."""

import csv
import json
import os
import subprocess
import sys

import numpy as np
import pytest

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
    fd = np.linalg.eigvals(
        np.asarray(vj.stability.finite_difference_jacobian_jit(vj.CompassGait(), z))
    )
    ev = np.array(out["multipliers_poincare"])
    np.testing.assert_allclose(
        sorted(np.abs(ev[:, 0] + 1j * ev[:, 1])), sorted(np.abs(fd)), atol=1e-6
    )
    assert out["max_abs_multiplier"] == pytest.approx(max(np.abs(fd)), abs=1e-6)


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
    # the columns, in order, then the stability columns
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
    assert "found at 3 of 3" in capsys.readouterr().out


SCRIPT_CACHE = """
import logging, sys
import vhcjax as vj
logging.basicConfig(stream=sys.stderr)
logging.getLogger("jax._src.compiler").setLevel(logging.DEBUG)
vj.enable_compilation_cache(sys.argv[1])
for method in ("vhc", "shooting"):
    g = vj.find_gait(vj.CompassGait(), "stable", method, guess=(0.2, -1.0))
    print(repr(float(g.a)), repr(float(g.b)), repr(float(g.T)))
"""


def test_compiled_search_kept_on_disk_and_read_back(tmp_path):
    """`enable_compilation_cache`: the programs of both searches are stored, traced
    (`programs/`) and compiled (neither holds a host callback); a second process reads
    both back (JAX reports two cache hits) and finds the same gaits."""
    cache = tmp_path / "xla"
    env = dict(os.environ, VHCJAX_PROGRAMS="on")
    cmd = [sys.executable, "-c", SCRIPT_CACHE, str(cache)]
    first = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    stored = sorted(p.name for p in cache.iterdir())
    assert sum(name.startswith("jit__search-") for name in stored) == 2, stored
    traced = sorted(p.name for p in (cache / "programs").iterdir())
    assert sum(name.startswith("search-") for name in traced) == 2, traced
    second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr[-2000:]
    assert second.stderr.count("Persistent compilation cache hit for 'jit__search'") == 2
    assert second.stdout == first.stdout


def test_kneed_walker_gait_and_multipliers(capsys):
    """`vhcjax gait --model kneed --method shooting` at the kneed walker's slope (0.0504
    rad): the gait repeats under simulation, its multipliers are those of the library's
    Poincare Jacobian (and the VHC search is refused with one line)."""
    import json

    import jax.numpy as jnp

    rc = main(
        [
            "gait",
            "--model",
            "kneed",
            "--method",
            "shooting",
            "--slope-deg",
            "2.887707287459349",
            "--json",
        ]
    )
    assert rc == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["result"] == "successful" and rec["stable"] is True
    np.testing.assert_allclose(rec["z"], [0.18818546, -1.10958733, -0.05714811], atol=1e-8)
    np.testing.assert_allclose(rec["period"], 0.56432817, atol=1e-8)
    kw = vj.KneedWalker()
    sim = vj.simulate(kw, jnp.asarray(rec["x0"]), 3)
    np.testing.assert_allclose(np.asarray(sim.steps.x_plus[-1]), rec["x0"], atol=1e-9)
    ev = sorted(
        np.abs(np.asarray(rec["multipliers"])[:, 0] + 1j * np.asarray(rec["multipliers"])[:, 1])
    )
    from vhcjax.stability import finite_difference_jacobian  # central differences

    ref = np.asarray(finite_difference_jacobian(kw, jnp.asarray(rec["z"])))
    np.testing.assert_allclose(ev, sorted(np.abs(np.linalg.eigvals(ref))), atol=1e-5)
    assert main(["gait", "--model", "kneed", "--slope-deg", "3"]) == 2
