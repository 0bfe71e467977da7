import os

# The tests run the library's plain jitted functions; stored programs (a later process
# loading what an earlier one traced) are tested in `test_programs.py`, which turns them
# on. Set before vhcjax is imported: subprocesses of the tests inherit it.
os.environ.setdefault("VHCJAX_PROGRAMS", "off")

import jax  # noqa: E402
import pytest  # noqa: E402

import vhcjax  # noqa: E402, F401  (enables float64)


def pytest_configure(config):
    assert jax.config.jax_enable_x64, "vhcjax must enable float64 on import"


@pytest.fixture(scope="session")
def model():
    return vhcjax.CompassGait()


def _memory_maps():
    try:
        with open("/proc/self/maps") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux
        return 0


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Drop compiled executables when the process holds too many memory maps.

    XLA's CPU backend maps every compiled executable into memory sections of its own; a
    long test session that compiles hundreds of programs can exhaust the kernel's
    per-process map limit (vm.max_map_count, 65530 by default) and abort inside the
    compiler. Past 30,000 maps, JAX's caches are cleared between test modules (below
    that, modules share what earlier ones compiled).
    """
    yield
    if _memory_maps() > 30_000:
        vhcjax.clear_caches()
