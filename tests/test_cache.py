"""The persistent compilation cache: on by default, per vhcjax and JAX version, `off` honoured."""

import os
import subprocess
import sys

import jax

import vhcjax as vj
from vhcjax import _cache


def test_default_directory_from_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("VHCJAX_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    d = vj.default_cache_dir()
    assert d.startswith(str(tmp_path / "xdg" / "vhcjax"))
    assert jax.__version__ in os.path.basename(d)
    monkeypatch.setenv("VHCJAX_CACHE_DIR", str(tmp_path / "mine"))
    assert vj.default_cache_dir().startswith(str(tmp_path / "mine"))
    monkeypatch.setenv("VHCJAX_CACHE_DIR", "off")
    assert vj.default_cache_dir() is None
    assert vj.enable_compilation_cache() is None


def test_another_version_reads_another_directory(monkeypatch):
    monkeypatch.delenv("VHCJAX_CACHE_DIR", raising=False)
    here = vj.default_cache_dir()
    monkeypatch.setattr(_cache, "_version", lambda: "999.0")
    assert vj.default_cache_dir() != here


SCRIPT = """
import jax, jax.numpy as jnp
import vhcjax as vj
print(jax.config.jax_compilation_cache_dir or "")
sim = vj.simulate(vj.CompassGait(), jnp.array([0.2187, -0.3375, -1.0924, -0.3774]), 2)
print(int(sim.num_successful))
"""


def _run(env):
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


def test_cache_on_by_default_and_off_writes_nothing(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "VHCJAX_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "on")
    directory, steps = _run(env)
    assert directory.startswith(str(tmp_path / "on" / "vhcjax")) and steps == "2"
    assert len(os.listdir(directory)) > 0  # the simulation's program was stored
    env["XDG_CACHE_HOME"] = str(tmp_path / "off")
    env["VHCJAX_CACHE_DIR"] = "off"
    out = _run(env)
    assert out == ["2"]  # no directory printed
    assert not (tmp_path / "off").exists()


_USER_SETTINGS = """
import jax
jax.config.update("jax_compilation_cache_dir", {directory!r})
jax.config.update("jax_persistent_cache_min_compile_time_secs", 5.0)
before = jax.config.values["jax_persistent_cache_min_entry_size_bytes"]
import vhcjax
v = jax.config.values
print(v["jax_compilation_cache_dir"], v["jax_persistent_cache_min_compile_time_secs"],
      v["jax_persistent_cache_min_entry_size_bytes"] == before, v["jax_enable_x64"])
"""


def test_import_keeps_the_users_own_cache_settings(tmp_path):
    """A cache directory and threshold the user gave JAX before importing vhcjax stay as
    they were; float64 is the one setting vhcjax changes then."""
    script = _USER_SETTINGS.format(directory=str(tmp_path / "mine"))
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == [str(tmp_path / "mine"), "5.0", "True", "True"]
