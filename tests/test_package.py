"""Package basics: version, float64 on import, typed, public names."""

import importlib.metadata
import pathlib

import jax
import jax.numpy as jnp

import vhcjax as vj


def test_version_matches_metadata():
    assert vj.__version__ == importlib.metadata.version("vhcjax")
    assert vj.__version__.count(".") >= 1


def test_float64_enabled_on_import():
    assert jax.config.jax_enable_x64
    assert jnp.asarray(1.0).dtype == jnp.float64


def test_py_typed_shipped():
    assert (pathlib.Path(vj.__file__).parent / "py.typed").is_file()
    files = importlib.metadata.files("vhcjax") or []
    names = {pathlib.PurePath(str(f)).name for f in files}
    # Editable installs list a .pth instead of the sources; a wheel lists py.typed.
    assert "py.typed" in names or any(n.endswith(".pth") for n in names)


def test_public_names():
    for name in (
        "CompassGait",
        "WalkerModel",
        "simulate",
        "step",
        "Simulation",
        "StepResult",
        "SolverConfig",
        "DEFAULT_CONFIG",
        "FAST_CONFIG",
        "RESULTS",
        "result_names",
        "mass_matrix",
        "coriolis_matrix",
        "gravity_vector",
        "acceleration",
        "augmented_impact",
        "enable_compilation_cache",
        "clear_caches",
    ):
        assert hasattr(vj, name), name
    for name in ("plot_states", "plot_phase_portrait", "plot_step_periods", "animate"):
        assert hasattr(vj.plotting, name), name


def test_cli_lists_simulate():
    from vhcjax import cli

    assert "simulate" in cli.build_parser().format_help()
