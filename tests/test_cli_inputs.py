"""Every numeric flag of every command is checked before any work: NaN, inf,
negative, zero and out-of-range values give one line on stderr and exit status 2; output
paths that cannot be written are refused before the work; Ctrl-C ends a run at once.

The flags are read from the parser itself, so that a new numeric flag without a check
fails `test_every_numeric_flag_is_checked`. All but the Ctrl-C test run in-process and
stop before JAX is used (they take milliseconds).
"""

import argparse
import json
import math
import os
import re
import signal
import subprocess
import sys
import time

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import vhcjax as vj
from vhcjax._json import to_jsonable
from vhcjax.cli import build_parser, main
from vhcjax.cli._common import Parser, parse_range

#: Arguments each command needs besides the flag under test.
REQUIRED = {
    "sweep": ["--slope-deg", "2:3:0.5"],
    "bifurcation": ["--slope-deg", "2:3:0.5"],
    "reproduce": ["--out", "/tmp/vhcjax-never-written"],
    "design": ["--objective", "speed", "--vary", "a"],
    "atlas": ["--mass-ratio", "1,2", "--length-ratio", "1"],
}
#: Checked after parsing by `model_from_args` (messages "--mass-hip must be positive").
MODEL_FLAGS = {"--slope-deg", "--mass-hip", "--mass-leg", "--a", "--b", "--gravity"}


def _subparsers():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def _numeric_actions():
    for name, p in _subparsers().items():
        for a in p._actions:
            if a.option_strings and a.type is not None and a.type not in (str,):
                yield name, a


def _bad_values(action):
    """NaN, infinities, and the values just outside the flag's range."""
    flag = action.option_strings[0]
    if flag == "--b":  # 0 is valid: the leg masses at the feet
        return ["nan", "inf", "-inf", "-1"]
    if flag in MODEL_FLAGS:
        return ["nan", "inf", "-inf", "-1", "0"]
    kind, lo, hi, lo_open, hi_open = action.type.bounds
    out = ["nan", "inf", "-inf"] if kind is float else ["nan", "1.5", "x"]
    if lo is not None:
        out.append(str(lo) if lo_open else str(lo - 1))
        if lo > 0:
            out.append("-1")
    if hi is not None:
        out.append(str(hi) if hi_open else str(hi + 1 if kind is int else hi * 2 + 1))
    return out


CASES = [
    (cmd, a.option_strings[0], a.nargs, v) for cmd, a in _numeric_actions() for v in _bad_values(a)
]


def test_every_numeric_flag_is_checked():
    """Every numeric flag is parsed by a `number` type (the strict number syntax of
    `read_number`, finite, range-checked; model flags' ranges are checked by
    `model_from_args`); plain `float`/`int` would let NaN and `1_0` through."""
    seen = set()
    for cmd, a in _numeric_actions():
        flag = a.option_strings[0]
        seen.add(cmd)
        assert hasattr(a.type, "bounds"), f"{cmd} {flag} has an unchecked type {a.type}"
    assert seen == set(_subparsers())  # every command: --num-processes, --process-id
    assert len(CASES) > 150


@pytest.mark.parametrize(
    "cmd, flag, nargs, value", CASES, ids=[f"{c} {f} {v}" for c, f, _, v in CASES]
)
def test_bad_numeric_value_one_line_exit_2(capsys, cmd, flag, nargs, value):
    n = nargs if isinstance(nargs, int) else 1
    t0 = time.perf_counter()
    code = main([cmd, *REQUIRED.get(cmd, []), flag, *([value] * n)])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"vhcjax {cmd}: error:"), err
    assert flag in lines[0] and "Traceback" not in err
    # refused before any work: well under a command's compile time (generous for a loaded
    # machine; the refusal itself takes milliseconds)
    assert time.perf_counter() - t0 < 15.0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["basin", "--grid", "20000", "20000"], "at most 4,000,000"),
        (["contraction", "--perturbations", "100000", "--steps", "100000"], "at most 50,000,000"),
        (["sweep", "--slope-deg", "1:nan:0.5"], "finite"),
        (["sweep", "--slope-deg", "1:2:0"], "STEP > 0"),
        (["sweep", "--slope-deg", "1:1e9:1e-3"], "at most 100000"),
        (["bifurcation", "--slope-deg", "29:31:1"], "(0, 30)"),
        (["basin", "--axes", "q1,q1"], "two different"),
        (["simulate", "--animate", "walk.mp4"], ".gif"),
        (["gait", "--transverse", "--no-stability"], "--no-stability"),
        (["gait", "--model", "kneed", "--method", "shooting", "--transverse"], "Poincare map"),
        (["sweep", "--slope-deg", "1:2:1e-300"], "1e+300 values"),
        (["stabilize", "--q", "1e300,1,1"], "[1e-08, 1e+08]"),
        (["stabilize", "--r", "1e-300"], "[1e-08, 1e+08]"),
        (["stabilize", "--q", "-1,1,1"], "--q must be >= 0"),
        (["stabilize", "--r", "1,1"], "needs 1 weight (hip), got 2"),
        (["stabilize", "--basin-grid", "5"], "give --basin too"),
        (["sweep", "--slope-deg", "1e-300:1:0.5"], "slopes below"),
        (["push", "--phases", "10000", "--directions-deg", "0", "90"], "at most 10,000"),
        (["gait", "--slope-deg", "1e-300"], "are not solved without --guess"),
        (["sweep", "--slope-deg", "1:2:0.5", "--png", "/dev/null/x.png"], "is not a folder"),
        (
            ["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--scan-step-deg", "1e-6"],
            "at most 2000",
        ),
        (
            ["design", "--objective", "speed", "--vary", "a", "--bounds", "a=0.1:1e300"],
            "at most 1000",
        ),
        (
            [
                "design",
                "--objective",
                "speed",
                "--vary",
                "mass-hip",
                "--bounds",
                "mass-hip=1:40,mass-hip=2:30",
            ],
            "twice",
        ),
    ],
)
def test_other_refusals(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_range_never_passes_stop():
    assert parse_range("1:2:0.4") == pytest.approx([1.0, 1.4, 1.8])
    assert parse_range("1:2:0.5") == pytest.approx([1.0, 1.5, 2.0])
    assert parse_range("0.1:0.3:0.1")[-1] == 0.3  # not 0.30000000000000004
    assert parse_range("0.3:1.5:0.3")[2] == 0.9  # not 0.8999999999999999
    assert len(parse_range("0.5:6:0.1")) == 56


def test_negative_scientific_notation_is_a_number():
    args = build_parser().parse_args(["simulate", "--x0", "0.2", "-0.3", "-1e2", "1e2"])
    assert args.x0 == [0.2, -0.3, -1e2, 1e2]
    args = build_parser().parse_args(["slope-sensitivity", "--heights-mm", "-1.5e1", "-2E0"])
    assert args.heights_mm == [-15.0, -2.0]
    assert Parser()._negative_number_matcher.match("-inf")  # then refused as not finite


def _unwritable_cases(tmp_path):
    missing = str(tmp_path / "missing" / "out")
    folder = str(tmp_path)  # an existing directory where a file is expected
    cases = []
    for cmd, flag, ext in [
        ("sweep", "--csv", "csv"),
        ("sweep", "--png", "png"),
        ("bifurcation", "--csv", "csv"),
        ("bifurcation", "--png", "png"),
        ("bifurcation", "--png-multipliers", "png"),
        ("multipliers", "--png", "png"),
        ("contraction", "--png", "png"),
        ("basin", "--png", "png"),
        ("slope-sensitivity", "--png", "png"),
        ("push", "--png", "png"),
        ("simulate", "--animate", "gif"),
        ("design", "--png", "png"),
        ("atlas", "--csv", "csv"),
        ("atlas", "--png", "png"),
        ("stabilize", "--png", "png"),
    ]:
        for path in (f"{missing}.{ext}", f"/proc/vhcjax-test.{ext}", folder):
            if flag == "--animate" and path == folder:
                continue  # refused for its suffix (tested above)
            cases.append([cmd, *REQUIRED.get(cmd, []), flag, path])
    for cmd, flag, ext in [
        ("sweep", "--png", "xyz"),
        ("multipliers", "--png", "docx"),
        ("stabilize", "--png", "xyz"),
        ("slope-sensitivity", "--png", "xyz"),
    ]:  # a figure format matplotlib does not write
        cases.append([cmd, *REQUIRED.get(cmd, []), flag, str(tmp_path / f"figure.{ext}")])
    for cmd, flag in [("sweep", "--png"), ("bifurcation", "--png-multipliers")]:
        # no suffix: matplotlib would write another file (name.png)
        cases.append([cmd, *REQUIRED.get(cmd, []), flag, str(tmp_path / "figure")])
    same = str(tmp_path / "same.png")  # two outputs in one file: the second would win
    cases.append(["sweep", *REQUIRED["sweep"], "--csv", same, "--png", same])
    cases.append(
        ["bifurcation", *REQUIRED["bifurcation"], "--png", same, "--png-multipliers", same]
    )
    for cmd, flag in [("simulate", "--plots"), ("reproduce", "--out")]:
        for path in ("/proc/vhcjax-test", str(tmp_path / "file")):
            cases.append([cmd, flag, path])
    (tmp_path / "file").write_text("not a directory")
    return cases


def test_unwritable_outputs_refused_before_work(tmp_path, capsys):
    before = set(os.listdir(tmp_path))
    for argv in _unwritable_cases(tmp_path):
        t0 = time.perf_counter()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and argv[-2] in err, (argv, err)
        assert time.perf_counter() - t0 < 15.0, argv  # before any work (see above)
    assert set(os.listdir(tmp_path)) == before | {"file"}  # nothing left behind


def test_json_never_holds_nan():
    import numpy as np

    nulls = []
    out = to_jsonable(
        {
            "a": float("nan"),
            "b": np.array([1.0, np.inf]),
            "c": [np.float64(-np.inf), 2],
            "d": np.array([1 + 1j, np.nan]),
        },
        nulls,
    )
    text = json.dumps(out, allow_nan=False)
    assert "NaN" not in text and "Infinity" not in text
    assert out["b"] == [1.0, None] and out["c"] == [None, 2]
    assert nulls == ["a", "b[1]", "c[0]", "d[1][0]"]


def test_print_json_nulls_have_a_reason(capsys):
    from vhcjax.cli import print_json

    print_json({"a": float("nan"), "a_reason": "no recovery shrank 100x", "b": [1.0, np.inf]})
    out = json.loads(capsys.readouterr().out)
    assert out["a"] is None and out["b"] == [1.0, None]
    assert set(out["null_fields"]) == {"b[1]"}  # "a" is explained by "a_reason"


def test_ctrl_c_stops_reproduce_at_once(tmp_path):
    """SIGINT to `vhcjax reproduce --quick` a few seconds in: exit 130 within seconds, one
    line on stderr, and nothing left in the output folder."""
    env = dict(os.environ)
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from vhcjax.cli import main; sys.exit(main())",
            "reproduce",
            "--quick",
            "--quiet",
            "--out",
            str(out),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(6.0)
    assert proc.poll() is None, proc.communicate()
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=30)
    assert time.perf_counter() - t0 < 5.0
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == ["vhcjax reproduce: interrupted"], stderr
    # nothing at all: no report, no figure, no partial file or hidden work folder
    assert (os.listdir(out) if out.exists() else []) == []


def _start_reproduce(out, prelude=""):
    """`vhcjax reproduce --quick` in a process of its own (`prelude`: Python run first),
    once its hidden work folder (where its figures go until the report is done) exists
    in `out`."""
    env = dict(os.environ)
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            prelude + "import sys; from vhcjax.cli import main; sys.exit(main())",
            "reproduce",
            "--quick",
            "--quiet",
            "--out",
            str(out),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while not (out.exists() and os.listdir(out)):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.1)
    return proc


@pytest.mark.parametrize(
    "sig, line",
    [(signal.SIGTERM, "terminated (SIGTERM)"), (signal.SIGHUP, "hung up (SIGHUP)")],
    ids=["SIGTERM", "SIGHUP"],
)
def test_sigterm_and_sighup_stop_like_ctrl_c(tmp_path, sig, line):
    """A batch scheduler's time limit (SIGTERM) or a closed terminal (SIGHUP) while
    `vhcjax reproduce` works: one line, exit status 128 + the signal, within seconds,
    and its work folder removed with whatever it held."""
    out = tmp_path / "out"
    proc = _start_reproduce(out)
    assert [n.startswith(".reproduce-") for n in os.listdir(out)] == [True]
    t0 = time.perf_counter()
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=30)
    assert time.perf_counter() - t0 < 5.0
    assert proc.returncode == 128 + sig, stderr
    assert stderr.strip().splitlines() == [f"vhcjax reproduce: {line}"], stderr
    assert os.listdir(out) == []


def test_an_ignored_hangup_stays_ignored(tmp_path):
    """`nohup vhcjax ...`: started with SIGHUP ignored, the command keeps working through
    a hangup (and still stops on SIGTERM)."""
    out = tmp_path / "out"
    ignored = "import signal; signal.signal(signal.SIGHUP, signal.SIG_IGN); "
    proc = _start_reproduce(out, ignored)
    proc.send_signal(signal.SIGHUP)
    time.sleep(1.0)
    assert proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert os.listdir(out) == []


def test_a_model_flag_given_at_another_models_default_is_not_ignored():
    from vhcjax.cli._common import CLIError, walker_from_args

    def walker(*argv):
        return walker_from_args(build_parser().parse_args(["simulate", *argv]))

    assert float(walker("--model", "kneed", "--mass-hip", "10").mh) == 10.0
    assert float(walker("--model", "kneed", "--gravity", "9.81").g) == 9.81
    assert float(walker("--model", "kneed").mh) == 0.5  # its own default
    assert float(walker().mH) == 10.0 and float(walker("--mass-hip", "3").mH) == 3.0
    for flag, value in (("--mass-leg", "5"), ("--a", "0.5"), ("--b", "0.5")):
        with pytest.raises(CLIError, match=flag):
            walker("--model", "kneed", flag, value)


def test_no_gait_is_a_failed_computation_not_bad_input(capsys):
    # valid flags, but no gait from a seed whose walker falls: exit 1, one line
    assert main(["contraction", "--gait", "0.6", "-0.5", "0", "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert "gait found from --gait" in err and "(fell:" in err
    assert "\n" not in err and "error" not in err


def test_where_the_vhc_search_does_not_apply_shooting_finds_the_gait(capsys):
    """With a light hip (0.5 kg) the stance angle is not monotone over the step, so the
    VHC search's phi'' ODE is singular (`singular_phi_ode`): `gait` (`--method auto`)
    says so and finds the gait by shooting (stable, largest multiplier 0.398, which the
    transverse linearization cannot confirm: `phase_not_monotone`, its multipliers and
    their disagreement are null); `--method vhc` fails with a hint; the robustness
    commands analyse the gait shooting found."""
    assert main(["gait", "--mass-hip", "0.5", "--json", "--quiet"]) == 0
    captured = capsys.readouterr()
    rec = json.loads(captured.out)
    assert rec["method"] == "shooting" and "found by shooting" in rec["method_reason"]
    assert "did not find this gait" in captured.err
    assert rec["stable"] is True and abs(rec["max_abs_multiplier"] - 0.3984) < 1e-3
    assert rec["multipliers"] is None and rec["transverse_disagreement"] is None
    assert main(["gait", "--mass-hip", "0.5", "--method", "vhc", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "singular_phi_ode" in err and "try --method auto" in err
    argv = ["contraction", "--mass-hip", "0.5", "--perturbations", "4", "--steps", "8"]
    assert main(argv + ["--json", "--quiet"]) == 0
    c = json.loads(capsys.readouterr().out)
    x0 = rec["x0"]
    np.testing.assert_allclose(c["gait"], [x0[0], x0[2], x0[3]], atol=1e-9)


def test_a_sweep_that_finds_nothing_says_why():
    """`vhcjax sweep` with no gait at any slope has no end to report: its summary says
    which codes it met, how often, and, after one method alone, points to `auto`."""
    from vhcjax.cli._gait import _none_found

    rows = [{"result": "singular_phi_ode"}] * 3 + [{"result": "not_converged"}]
    reason = _none_found(rows, "vhc", "stable")
    assert reason.startswith("no gait found: singular_phi_ode at 3 slopes, not_converged at 1")
    assert "phi'' ODE is singular" in reason and reason.endswith("try --method auto")
    assert _none_found([{"result": "fell"}], "shooting", "stable").endswith("try --method auto")
    assert not _none_found([{"result": "fell"}], "auto", "stable").endswith("auto")
    # a family followed onto the other root of (5.13) at every slope (a light hip's
    # unstable family at 2-4 degrees, tests/test_sweep.py) is said to be that
    reason = _none_found([{"result": "other_cycle"}] * 5, "auto", "unstable")
    assert reason.startswith("no gait found: other_cycle at 5 slopes")
    assert "other root of the energy quadratic (5.13), of the stable family" in reason


def test_robustness_commands_analyse_the_gait_that_gait_finds(capsys):
    """Without `--gait` the robustness commands analyse the stable gait as `vhcjax gait`
    finds it (VHC continuation), made a fixed point of the step map by shooting: at 0.5
    degrees Newton from the 3-degree gait would land on an unstable gait (spectral
    radius 1.97). The two agree to 1e-9, and the gait is stable (0.539)."""
    assert main(["gait", "--slope-deg", "0.5", "--json", "--quiet"]) == 0
    g = json.loads(capsys.readouterr().out)
    argv = ["contraction", "--slope-deg", "0.5", "--perturbations", "4", "--steps", "8"]
    assert main(argv + ["--json", "--quiet"]) == 0
    c = json.loads(capsys.readouterr().out)
    x0 = g["x0"]
    np.testing.assert_allclose(c["gait"], [x0[0], x0[2], x0[3]], atol=1e-9)
    assert c["gait_stable"] is True
    np.testing.assert_allclose(c["spectral_radius"], g["max_abs_multiplier"], atol=1e-8)


_M = vj.CompassGait()
_Z = jnp.array([0.2186688, -1.09238359, -0.37737395])
_X = np.asarray(_M.section_to_state(_Z))


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: vj.stabilize(_M, _M.section_to_state(_Z)), "shape (3,)"),
        (lambda: vj.transverse_system(_M, _Z), "shape (4,)"),
        (lambda: vj.transverse_system(_M, _M.section_to_state(_Z), num_points=1), ">= 2"),
        (lambda: vj.closed_loop_step(_M, _Z, vj.ZeroFeedback(1)), "shape (4,)"),
        (lambda: vj.simulate_closed_loop(_M, jnp.zeros(6), vj.ZeroFeedback(1), 3), "(4,)"),
        (
            lambda: vj.simulate_closed_loop(_M, _M.section_to_state(_Z), vj.ZeroFeedback(1), -3),
            "nonnegative",
        ),
        (lambda: vj.simulate(vj.KneedWalker(), jnp.zeros(6), -1), "nonnegative"),
        (lambda: vj.period_k_orbit(_M, _Z, 0), "positive integer"),
        (lambda: vj.period_k_orbit(_M, _Z, 2.5), "positive integer"),
        (lambda: vj.period_k_orbit(_M, jnp.zeros(4), 2), "shape (3,)"),
        (lambda: vj.design("speed", ["a"], steps=-5), "steps"),
        (lambda: vj.design("speed", ["a"], learning_rate=float("nan")), "learning_rate"),
        (lambda: vj.design("speed", ["a"], model=vj.KneedWalker()), "CompassGait"),
        (lambda: vj.atlas(np.array([]), [1.0]), "non-empty"),
        (lambda: vj.atlas([2.0], [1.0], step=0.0), "step"),
        (lambda: vj.atlas([2.0], [1.0], gravity=-9.81), "gravity"),
        (lambda: vj.atlas([2.0], [1.0], psi_start=0.1, psi_max=0.05), "psi_max"),
        (lambda: vj.fixed_point(_M, _Z, k=0), "positive integer"),
        (lambda: vj.fixed_point(_M, _Z, k=-1), "positive integer"),
        (lambda: vj.fixed_point(_M, _Z, k=1.5), "positive integer"),
        (lambda: vj.step_map(_M, _Z, k=0), "positive integer"),
        (lambda: vj.continue_fixed_point(_M, _Z, vj.CompassGait(psi=float("nan"))), "finite"),
        (lambda: vj.continue_fixed_point(_M, _Z, vj.CompassGait(mH=float("nan"))), "finite"),
        (lambda: vj.continue_fixed_point(_M, _Z[:2], vj.CompassGait(psi=0.06)), "z_start"),
        (lambda: vj.continue_fixed_point(_M, _Z, _M, k=0), "positive integer"),
        (lambda: vj.bifurcation_diagram([0.05], _Z[None], num_record=0), "num_record"),
        (lambda: vj.bifurcation_diagram([0.05], _Z[None], num_record=1), "num_record"),
        (lambda: vj.bifurcation_diagram([0.05], _Z[None], num_transient=-1), "num_transient"),
        (lambda: vj.bifurcation_diagram([0.05, 0.06], _Z[None]), "one gait per slope"),
        (lambda: vj.basin_slice(_M, _Z, shape=(2, 2), num_steps=0), "num_steps"),
        (lambda: vj.recover(_M, _X[None], _X, num_steps=0), "num_steps"),
        (lambda: vj.recover(_M, _X[None], _X, max_period=0), "max_period"),
        (lambda: vj.recover(_M, _X, _X), "shape (batch, 4)"),
        (lambda: vj.recover(_M, _X[None], _X * float("nan")), "x_star must be finite"),
        (lambda: vj.max_push(_M, _X, 0.73, [], [0.0]), "at least one phase"),
        (lambda: vj.max_push(_M, _X, 0.73, [float("nan")], [0.0]), "finite"),
        (lambda: vj.max_push(_M, _X, 0.73, [0.1], [0.0], p_max=0.0), "search interval"),
        (lambda: vj.max_push(_M, _X, 0.73, [0.1], [0.0], iterations=0), "iterations"),
        (lambda: vj.max_floor_step(_M, _X, h_max=0.0), "search interval"),
        (lambda: vj.max_floor_step(_M, _X, h_max=-0.01), "search interval"),
        (lambda: vj.max_floor_step(_M, _X, iterations=0), "iterations"),
        (lambda: vj.flip_slope(_M, _Z, step=0.0), "step must be positive"),
        (lambda: vj.flip_slope(_M, _Z, step=float("nan")), "step must be positive"),
        (lambda: vj.contraction(_M, _Z, scale=0.0), "scale"),
        (lambda: vj.contraction(_M, _Z, scale=float("nan")), "scale"),
        (lambda: vj.sweep(_M, [[0.05, 0.06]]), "one-dimensional"),
    ],
)
def test_library_arguments_refused_in_one_line(call, message):
    """Wrong shapes and arguments: a one-line ValueError naming what is expected, before
    any tracing (no deep JAX error, no NaN or plausible number computed from them)."""
    with pytest.raises(ValueError, match=re.escape(message)) as err:
        call()
    assert "\n" not in str(err.value)


NOT_NUMBERS = [
    ["gait", "--slope-deg", "0_3"],  # Python's literal syntax: 3 degrees
    ["simulate", "--steps", "1_0"],  # 10 steps
    ["gait", "--slope-deg", "\uff13"],  # a full-width 3
    ["simulate", "--steps", "\u0661\u0660"],  # Arabic-Indic 10
    ["gait", "--slope-deg", "\u00a03"],  # a no-break space before it
    ["gait", "--slope-deg", "0x3"],
    ["gait", "--slope-deg", "1.2.3"],
    ["gait", "--slope-deg", "3,5"],
    ["contraction", "--steps", "1e1"],  # an integer flag: digits only
    ["contraction", "--steps", "10.0"],
    ["basin", "--grid", "2_0", "20"],
    ["simulate", "--x0", "0.2", "-0.3", "-1_0", "0"],
    ["push", "--directions-deg", "9_0"],
    ["sweep", "--slope-deg", "1:2:0_5"],
    ["bifurcation", "--slope-deg", "\uff12:3:0.5"],
    ["stabilize", "--q", "1,1_0,1"],
    ["stabilize", "--r", "1e0_0"],
    ["atlas", "--mass-ratio", "1,\uff12", "--length-ratio", "1"],
    ["atlas", "--mass-ratio", "1", "--length-ratio", "0_5:1:0.5"],
    ["design", "--objective", "speed", "--vary", "a", "--bounds", "a=0_1:0.9"],
]


@pytest.mark.parametrize("argv", NOT_NUMBERS, ids=[" ".join(a) for a in NOT_NUMBERS])
def test_numbers_a_person_would_not_type_are_refused(capsys, argv):
    """Python reads `0_3` as 3, `1_0` as 10 and any Unicode digit as a digit; the command
    line reads what a person types (ASCII digits, one point, an exponent) and refuses the
    rest, in every place a number is read: flag types, nargs values, START:STOP:STEP,
    comma lists, --bounds."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"vhcjax {argv[0]}: error:"), err
    assert "Traceback" not in err


@pytest.mark.parametrize("text", ["3", "3.", "3.0", "+3", " 3", "3\t", "3e0", "3E0", ".3e1"])
def test_numbers_as_typed_are_read(text):
    assert build_parser().parse_args(["gait", "--slope-deg", text]).slope_deg == 3.0


LONG = "x" * 10_000
LONG_VALUES = [
    ["gait", "--slope-deg", LONG],
    ["gait", "--slope-deg", "1" * 10_000],
    ["simulate", "--steps", "9" * 10_000],
    ["simulate", "--x0", "0.2", LONG, "0", "0"],
    ["sweep", "--slope-deg", "1:2:" + LONG],
    ["stabilize", "--q", "1,1," + LONG],
    ["atlas", "--mass-ratio", LONG, "--length-ratio", "1"],
    ["gait", "--family", LONG],
    ["gait", "--family", "x " * 5_000],
    ["basin", "--axes", "q1," + LONG],
    ["design", "--objective", "speed", "--vary", LONG],
    ["gait", "--no-such-flag", LONG],
    ["simulate", "--animate", LONG + ".mp4"],
]


@pytest.mark.parametrize("argv", LONG_VALUES, ids=[" ".join(a)[:40] for a in LONG_VALUES])
def test_a_long_bad_value_is_echoed_as_a_short_prefix(capsys, argv):
    """A 10,000-character bad value: the one-line error shows its first characters and
    its length, not the whole value."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and len(err) < 400, err[:500]
    assert "characters)" in err, err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--mass-hip", "40"], "--mass-ratio"),
        (["atlas", "--mass-ratio", "2", "--length-ratio", "1", "--mass-hip", "10"], "--mass-ratio"),
        (["basin", "--box", "0.1", "0.1", "0.1"], "give --volume-samples"),
        (["basin", "--volume-samples", "0", "--box", "0.1", "0.1", "0.1"], "give --volume-samples"),
        (["gait", "--slope-deg", "3", "--slope-deg", "4"], "--slope-deg is given twice"),
        (["simulate", "--steps", "3", "--steps=4"], "--steps is given twice"),
        (["sweep", "--slope-deg", "1:2:1", "--slope", "3"], "--slope-deg is given twice"),
        (["basin", "--grid", "5", "5", "--grid", "6", "6"], "--grid is given twice"),
        (["stabilize", "--q", "1,1,1", "--q", "2,2,2"], "--q is given twice"),
    ],
)
def test_a_flag_the_command_would_not_use_is_refused(capsys, argv, message):
    """Flags are never ignored: one the command does not use (atlas's hip mass comes
    from --mass-ratio; --box only shapes --volume-samples) or the first of a flag given
    twice is refused in one line, before any work."""
    t0 = time.perf_counter()
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err, err
    assert time.perf_counter() - t0 < 15.0
    atlas = _subparsers()["atlas"].format_help()
    assert "--mass-hip" not in atlas and "--mass-leg" in atlas


# What a person reads: characters a number is made of, and look-alikes Python also reads
ALPHABET = "0123456789.eE+-_ \t,x" + "\uff13\u0663\u00a0" + "infaINF"
SETTINGS = {"deadline": None, "derandomize": True, "max_examples": 400}


def _as_a_person_reads(text):
    """The number in `text` as a person reads it, `"large"` if beyond every float, or
    `None`: a reader written apart from `read_number` (character by character, exact
    arithmetic): an optional sign, ASCII digits with at most one point (a digit on at
    least one side), an optional exponent of ASCII digits; spaces or tabs around."""
    from fractions import Fraction

    s = text.strip(" \t")
    sign = -1 if s[:1] == "-" else 1
    s = s[1:] if s[:1] in ("-", "+") else s
    mantissa, exponent = s, "0"
    for mark in "eE":
        if mark in s:
            mantissa, _, exponent = s.partition(mark)
            break
    whole, point, fraction = mantissa.partition(".")
    if exponent[:1] in ("-", "+"):
        exp_sign, exponent = (-1 if exponent[0] == "-" else 1), exponent[1:]
    else:
        exp_sign = 1
    ascii_digits = set("0123456789")
    if not (set(whole + fraction + exponent) <= ascii_digits) or not (whole + fraction):
        return None
    if not exponent or "." in fraction:
        return None
    digits = (whole + fraction).lstrip("0")
    if not digits:
        return 0.0
    power = exp_sign * int(exponent) - len(fraction)
    if power + len(digits) > 400:
        return "large"
    if power + len(digits) < -400:
        return 0.0
    value = Fraction(int(digits)) * Fraction(10) ** power
    try:
        return sign * float(value)
    except OverflowError:
        return "large"


@given(st.text(ALPHABET, max_size=14))
@settings(**SETTINGS)
def test_what_a_flag_accepts_is_what_a_person_reads(text):
    """Property: a numeric flag accepts a string only if a person reads a number in it,
    and then means that number; `1_0`, full-width digits, no-break spaces, `inf`/`nan`
    and beyond-float values are refused."""
    from vhcjax.cli._common import read_number

    expected = _as_a_person_reads(text)
    try:
        got = read_number(text)
    except ValueError as e:
        got = None
        assert "\n" not in str(e)
    if expected is None or expected == "large":
        assert got is None, (text, got)
    else:
        assert got == expected, (text, got, expected)


@given(st.text(ALPHABET, max_size=10))
@settings(**SETTINGS)
def test_what_an_integer_flag_accepts_is_what_a_person_reads(text):
    from vhcjax.cli._common import read_number

    s = text.strip(" \t")
    body = s[1:] if s[:1] in ("-", "+") else s
    person = int(s) if body and set(body) <= set("0123456789") else None
    try:
        got = read_number(text, int)
    except ValueError:
        got = None
    assert got == person, (text, got)


@given(
    st.floats(allow_nan=False, allow_infinity=False),
    st.sampled_from(["{!r}", "{:.3e}", "{:.17g}", "{:+.6f}", "{:E}"]),
)
@settings(**SETTINGS)
def test_numbers_written_as_people_write_them_are_read_exactly(x, fmt):
    """Property: every number printed as people print them (Python's repr, fixed and
    scientific notation) is accepted, with the value printed (refused as too large where
    the printing rounded it past the largest float); also in a comma list and as
    START:STOP:STEP."""
    from vhcjax.cli._common import read_number, read_numbers

    text = fmt.format(x)
    if not math.isfinite(float(text)):  # rounded past the largest float by the format
        with pytest.raises(ValueError, match="too large"):
            read_number(text)
        return
    assert read_number(text) == float(text)
    assert read_numbers(f"{text},{text}", "--q") == [float(text)] * 2
    if abs(float(text)) < 1e300:
        assert parse_range(f"{text}:{text}:1", "--x") == [float(text)]
