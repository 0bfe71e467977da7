"""Every wait says what it is: `--help` and bad arguments answer without JAX, a program
that takes long to compile or load is named on stderr (`--quiet` silences it), and a
progress bar's elapsed time moves while nothing finishes."""

import io
import math
import os
import re
import subprocess
import sys
import threading
import time
import tomllib
from argparse import _SubParsersAction

import pytest

import vhcjax as vj
from vhcjax import _programs
from vhcjax.cli import _common, build_parser

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC = os.path.join(ROOT, "src")

#: Runs the console command's entry point (as `pyproject.toml` names it) with the
#: arguments that follow, and prints on stderr, last, which of JAX, numpy and the
#: libraries on them the process imported.
ENTRY_POINT = r"""
import atexit, importlib, sys
module, _, name = sys.argv[1].partition(":")
sys.argv = ["vhcjax"] + sys.argv[2:]
heavy = ("jax", "jaxlib", "numpy", "equinox", "diffrax", "matplotlib")
atexit.register(lambda: print(
    "imported:", sorted({m.split(".")[0] for m in sys.modules}.intersection(heavy)),
    file=sys.stderr))
sys.exit(getattr(importlib.import_module(module), name)())
"""


def _entry_point():
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as fh:
        return tomllib.load(fh)["project"]["scripts"]["vhcjax"]


def _command(*argv, env=None, timeout=600):
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = SRC + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run(
        [sys.executable, "-c", ENTRY_POINT, _entry_point(), *argv],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize(
    "argv, status, first",
    [
        (["--help"], 0, "usage: vhcjax "),
        (["gait", "--help"], 0, "usage: vhcjax gait "),
        (["basin", "--help"], 0, "usage: vhcjax basin "),
        (["gait", "--slope-deg", "x"], 2, "vhcjax gait: error: --slope-deg: expected a number"),
        (["gait", "--bogus"], 2, "vhcjax: error: unrecognized arguments: --bogus"),
        (["nonsense"], 2, "vhcjax: error: command: invalid choice: 'nonsense'"),
    ],
    ids=["help", "gait-help", "basin-help", "bad-number", "unknown-flag", "unknown-command"],
)
def test_help_and_bad_arguments_import_no_jax(argv, status, first):
    proc = _command(*argv, timeout=120)
    assert proc.returncode == status, proc.stderr
    *said, imported = proc.stderr.strip().splitlines()
    assert imported == "imported: []", proc.stderr
    if status == 0:
        assert proc.stdout.startswith(first) and said == []
    else:  # one line
        assert proc.stdout == "" and len(said) == 1 and said[0].startswith(first), said


def test_python_m_vhcjax_runs_the_same_command():
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run(
        [sys.executable, "-m", "vhcjax", "simulate", "--slope-deg", "45"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.strip() == (
        "vhcjax simulate: error: --slope-deg must be in (0, 30) degrees, got 45"
    )


def _help_default(text):
    return float(re.search(r"\(default ([0-9.]+)\)", text)[1])


def test_parser_defaults_are_the_models_defaults():
    """The parser's defaults are literals (it imports no JAX): they are the models'."""
    compass, kneed, simplest = vj.CompassGait(), vj.KneedWalker(), vj.SimplestWalker()
    assert _common.KNEED_SLOPE_DEG == math.degrees(float(kneed.psi))
    assert _common.SIMPLEST_SLOPE_DEG == math.degrees(float(simplest.psi))
    fields = {"mass_hip": "mH", "mass_leg": "m1", "a": "a", "b": "b", "gravity": "g"}
    for dest, default in _common._COMPASS_DEFAULTS.items():
        assert default == float(getattr(compass, fields[dest])), dest
    assert float(compass.m2) == float(compass.m1)
    commands = next(a for a in build_parser()._actions if isinstance(a, _SubParsersAction))
    gait = commands.choices["gait"]
    actions = {a.dest: a for a in gait._actions}
    assert actions["slope_deg"].help.startswith("slope angle in degrees")
    assert f"{_common.KNEED_SLOPE_DEG:.6g}" in actions["slope_deg"].help
    for dest, _, field, text in _common.KNEED_FLAGS:
        assert _help_default(text) == float(getattr(kneed, field)), dest
    assert _help_default(actions["leg_length"].help) == float(simplest.l)
    model_help = actions["model"].help
    assert "--mass-hip defaults to 0.5 kg" in model_help and float(kneed.mh) == 0.5
    assert float(simplest.M) == float(simplest.g) == 1.0


def test_a_slow_block_is_noted_once_a_fast_one_never(monkeypatch):
    monkeypatch.setenv("VHCJAX_NOTE_AFTER", "0.2")
    notes = []
    with _programs.notes_to(notes.append):
        with _programs.preparing("compiling a", "another"):
            pass
        assert notes == []
        with _programs.preparing("compiling a", "another"):
            time.sleep(0.6)
        assert notes == ["compiling a"]  # written while the block ran, once
        with _programs.preparing("compiling a", "another"):
            time.sleep(0.4)
        assert notes == ["compiling a", "another"]
    with _programs.preparing("compiling b"):  # no receiver: nothing
        time.sleep(0.4)
    assert notes == ["compiling a", "another"]
    assert not [t for t in threading.enumerate() if t.name == "vhcjax-note"]


@pytest.mark.parametrize("value", ["-1", "nan", "soon"])
def test_a_bad_note_delay_is_refused(monkeypatch, value):
    monkeypatch.setenv("VHCJAX_NOTE_AFTER", value)
    with pytest.raises(ValueError, match="VHCJAX_NOTE_AFTER"):
        _programs.note_after()


def test_no_notes_in_the_tests_by_default():
    """In-process commands in the tests print no notes (`conftest.py`): their stderr is
    what the command says."""
    assert math.isinf(_programs.note_after())


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_progress_bar_ticks_while_nothing_finishes(monkeypatch):
    monkeypatch.setattr(_common, "TICK", 0.2)
    monkeypatch.setitem(_common.QUIET, "on", False)
    stderr = _Terminal()
    monkeypatch.setattr(sys, "stderr", stderr)
    bar = _common.progress(total=4, desc="basin")
    time.sleep(1.1)
    drawn = stderr.getvalue().count("0/4")
    assert drawn >= 4, stderr.getvalue()  # the first draw and a redraw every tick
    bar.update(1)
    bar.close()
    after = stderr.getvalue()
    time.sleep(0.6)
    assert stderr.getvalue() == after  # closed: no more redraws
    assert not [t for t in threading.enumerate() if t.name == "vhcjax-progress"]


def test_quiet_silences_the_bar(monkeypatch):
    monkeypatch.setitem(_common.QUIET, "on", True)
    stderr = _Terminal()
    monkeypatch.setattr(sys, "stderr", stderr)
    bar = _common.progress(total=4, desc="basin")
    bar.update(4)
    bar.close()
    assert stderr.getvalue() == ""


def test_a_fresh_cache_says_compiling_and_quiet_says_nothing(tmp_path):
    """`vhcjax simulate` through the console command's entry point, with an empty cache:
    a note that it is compiling, then, run again, one that it loads the programs (notes
    after 0 s here); `--quiet` prints none. The package set up without its `__init__`
    gets it before the command runs."""
    env = dict(os.environ, VHCJAX_CACHE_DIR=str(tmp_path / "cache"), VHCJAX_NOTE_AFTER="0")
    env.pop("VHCJAX_PROGRAMS", None)  # stored programs on, as a user has them
    argv = ["simulate", "--steps", "1", "--json"]
    first = _command(*argv, env=env)
    assert first.returncode == 0, first.stderr
    assert first.stdout.startswith('{"result": "successful"')
    *said, imported = first.stderr.strip().splitlines()
    assert "'jax'" in imported
    assert said and said[0].startswith("vhcjax simulate: compiling (first run only; later"), said
    assert all(line.startswith("vhcjax simulate: compiling") for line in said), said
    later = _command(*argv, env=env)
    said = later.stderr.strip().splitlines()[:-1]
    assert said and said[0].startswith("vhcjax simulate: loading compiled programs from"), said
    quiet = _command(*argv, "--quiet", env=env)
    assert quiet.returncode == 0 and quiet.stdout == first.stdout
    assert quiet.stderr.strip().splitlines()[:-1] == []
