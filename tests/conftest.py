import os

# Stored programs are on, as a user has them: the test processes and the commands they
# start load what another one traced (`vhcjax._programs`) from the compilation cache.
# Commands run in the tests print no note of a slow compile (`vhcjax._programs.preparing`):
# their stderr is what they say; `test_cli_waits.py` turns the notes on.
os.environ.setdefault("VHCJAX_NOTE_AFTER", "inf")

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


#: Test files and notebooks that compile the same programs run in one worker process, so
#: each program is traced and compiled once; every other file is a group of its own (as
#: `--dist loadfile`). Groups start longest first, so that no worker idles at the end.
_GROUPS = {
    "test_design.py": "design",
    "test_cli_design.py": "design",
    "07_design.py": "design",
    "test_control.py": "control",
    "test_cli_stabilize.py": "control",
    "06_stabilization.py": "control",
    "test_sweep.py": "sweep",
    "test_cli_gait.py": "sweep",
    "02_gait_search.py": "sweep",
    "03_stability.py": "test_stability.py",
    "04_robustness.py": "test_robustness_push.py",
    "05_new_model.py": "test_vhc_n.py",
    "01_quickstart.py": "test_cli_simulate.py",
}
_LONGEST_FIRST = (
    "design",
    "control",
    "test_kneed_control.py",
    "sweep",
    "test_stability.py",
    "test_reproduce.py",
    "test_kneed_walker.py",
    "test_robustness_push.py",
    "test_implicit.py",
)


def _group(nodeid):
    """The group of a test id: its notebook's or its file's."""
    path, _, rest = nodeid.partition("::")
    name = path.rsplit("/", 1)[-1]
    if name == "test_notebooks.py" and "[" in rest:
        name = rest[rest.index("[") + 1 : rest.rindex("]")]
    return _GROUPS.get(name, name)


def pytest_collection_modifyitems(config, items):
    def rank(item):
        g = _group(item.nodeid)
        return _LONGEST_FIRST.index(g) if g in _LONGEST_FIRST else len(_LONGEST_FIRST)

    items.sort(key=rank)  # stable: each file keeps its order


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist: absent without it
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadfile` with the groups above as its units of work (another `--dist`
    keeps xdist's own scheduler)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            return _group(nodeid)

    return GroupScheduling(config, log)
