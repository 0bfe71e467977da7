"""Stored programs (`vhcjax._programs`): a later process loads the traced program instead of
tracing again, with the same numbers; anything that could go stale takes the plain path."""

import json
import os
import pickle
import re
import subprocess
import sys
import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax import _programs
from vhcjax.hybrid import _poincare
from vhcjax.solvers import diffeqsolve

SCRIPT = """
import json, logging, math, sys
import numpy as np
import vhcjax as vj
from vhcjax import _programs
logging.basicConfig(stream=sys.stderr)
logging.getLogger("jax._src.compiler").setLevel(logging.DEBUG)
m = vj.CompassGait(psi=math.radians(3.0))
z = np.array([0.2187, -1.0924, -0.3774])
sim = vj.simulate(m, m.section_to_state(z), 3)
ev = vj.poincare_multipliers(m, z)
gaits = []
if sys.argv[1:] == ["search"]:  # both searches (VHC, shooting) from a guess
    for method in ("vhc", "shooting"):
        g = vj.find_gait(vj.CompassGait(), "stable", method, guess=(0.2, -1.0))
        gaits.append([float(g.a), float(g.b), float(g.T)])
print(json.dumps({"x": np.asarray(sim.steps.x_plus).tolist(),
                  "p": [[complex(v).real, complex(v).imag] for v in np.asarray(ev)],
                  "gaits": gaits, "stats": _programs.stats}))
"""


def _run(env, *args):
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.splitlines()[-1]), out.stderr


def test_a_second_process_loads_the_programs_and_gets_the_same_numbers(tmp_path):
    """The simulation, the multipliers and both gait searches are stored, traced
    (`programs/`) and compiled (none holds a host callback); a second process loads them
    all (nothing traced, JAX reports a compilation-cache hit for each search) and gets the
    same numbers, which are those of the plain path."""
    cache = tmp_path / "cache"
    env = dict(os.environ, VHCJAX_CACHE_DIR=str(cache), VHCJAX_PROGRAMS="on")
    first, _ = _run(env, "search")
    assert first["stats"]["exported"] >= 4 and first["stats"]["loaded"] == 0
    (versioned,) = cache.iterdir()  # vhcjax-<version>-jax-<version>
    stored = sorted(p.name for p in versioned.iterdir())
    assert sum(name.startswith("jit__search-") for name in stored) == 2, stored
    traced = sorted(p.name for p in (versioned / "programs").iterdir())
    assert sum(name.startswith("search-") for name in traced) == 2, traced
    second, log = _run(env, "search")
    # nothing traced again: the simulation, the multipliers and the searches come from disk
    assert second["stats"]["exported"] == 0 and second["stats"]["loaded"] >= 4
    assert log.count("Persistent compilation cache hit for 'jit__search'") == 2
    assert second == dict(first, stats=second["stats"])
    # and they are the numbers of the plain path (a third process without stored programs)
    plain, _ = _run(dict(env, VHCJAX_PROGRAMS="off"))
    assert plain["stats"] == {"exported": 0, "loaded": 0, "unexportable": 0}
    np.testing.assert_allclose(plain["x"], first["x"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(plain["p"], first["p"], rtol=0, atol=1e-10)
    np.testing.assert_allclose(first["gaits"][0], first["gaits"][1], rtol=1e-9)  # VHC = shooting


USER_SCRIPT = """
import json, sys
import jax.numpy as jnp, numpy as np
sys.path.insert(0, sys.argv[1])
import vhcjax as vj
from vhcjax import _programs
from _user_model import TRACES, RodWalker
m = RodWalker(psi=0.03)
fp = vj.fixed_point(m, jnp.array([0.2, -1.0, -0.2]))
ev = vj.poincare_multipliers(m, fp.z)
print(json.dumps({"z": np.asarray(fp.z).tolist(), "ev": np.abs(np.asarray(ev)).tolist(),
                  "traces": TRACES[0], "stats": _programs.stats}))
"""


def test_a_second_process_loads_a_users_walker(tmp_path):
    """The programs of a user's own walker (a class in the user's module) are stored too:
    a second process traces none of its dynamics again and gets the same numbers."""
    env = dict(os.environ, VHCJAX_CACHE_DIR=str(tmp_path / "cache"), VHCJAX_PROGRAMS="on")
    tests = os.path.dirname(os.path.abspath(__file__))
    runs = []
    for _ in range(2):
        out = subprocess.run(
            [sys.executable, "-c", USER_SCRIPT, tests],
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append(json.loads(out.stdout.splitlines()[-1]))
    first, second = runs
    assert first["stats"]["exported"] >= 2 and first["stats"]["loaded"] == 0
    assert second["stats"]["exported"] == 0 and second["stats"]["loaded"] >= 2
    # the fingerprint traces each method once, abstractly; the solves are not traced
    assert second["traces"] < first["traces"]
    assert second["z"] == first["z"] and second["ev"] == first["ev"]


@pytest.fixture
def store(tmp_path, monkeypatch):
    """A private program directory for this test, nothing loaded yet."""
    monkeypatch.setattr(_programs, "program_directory", lambda: str(tmp_path / "programs"))
    monkeypatch.setattr(_programs, "_memo", {})
    return tmp_path / "programs"


def _counts(monkeypatch):
    counts = {"exported": 0, "loaded": 0, "unexportable": 0}
    monkeypatch.setattr(_programs, "stats", counts)
    return counts


@_programs.stored_jit
def _double_map(model, z, config):
    return vj.step_map(model, z, config=config), 2 * z


def test_a_new_source_misses(store, monkeypatch):
    counts = _counts(monkeypatch)
    model, z = vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774])
    for fn in (vj.step_map,):
        a = fn(model, z)
        assert counts["exported"] == 1 and len(os.listdir(store)) == 1
        # the same function in a process that imported an edited library: another key,
        # a new export
        monkeypatch.setattr(_programs, "_source_hash", "changed source")
        monkeypatch.setattr(_programs, "_hash_sources", lambda: "changed source")
        b = fn(model, z)
        assert counts["exported"] == 2 and len(os.listdir(store)) == 2
        np.testing.assert_array_equal(np.asarray(a.z_next), np.asarray(b.z_next))


def test_sources_edited_after_import_take_the_plain_path(store, monkeypatch):
    """A process runs the code it imported: once the files on disk differ from it, a
    program traced now would be stored under the key of the edited files (and a later
    process would run the old code), and a program stored under the key of the imported
    ones may come from other code. Neither is stored nor loaded."""
    counts = _counts(monkeypatch)
    model, z = vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774])
    on_disk = _programs._hash_sources
    monkeypatch.setattr(_programs, "_hash_sources", lambda: "edited since import")
    a = vj.step_map(model, z)
    assert counts == {"exported": 0, "loaded": 0, "unexportable": 0}
    assert not os.path.exists(store) or os.listdir(store) == []
    monkeypatch.setattr(_programs, "_hash_sources", on_disk)
    _programs._memo.clear()
    b = vj.step_map(model, z)  # sources as imported: stored as usual
    assert counts["exported"] == 1 and len(os.listdir(store)) == 1
    np.testing.assert_array_equal(np.asarray(a.z_next), np.asarray(b.z_next))


def _walker_class(height):
    """A user's walker (defined outside the library) whose swing foot strikes the ground
    `height` above the compass gait's guard: the same class text for the same `height`."""

    class MyWalker(vj.CompassGait):
        def guard(self, q):
            return super().guard(q) + height

    return MyWalker


def test_a_users_walker_is_stored_under_its_dynamics(store, monkeypatch):
    """A walker class from outside the library is stored under the jaxprs of its methods:
    the same dynamics (a class defined again alike) load the same program; other
    dynamics under the same name, a different one."""
    counts = _counts(monkeypatch)
    z = jnp.array([0.2187, -1.0924, -0.3774])
    a = vj.step_map(_walker_class(0.0)(), z)
    assert counts == {"exported": 1, "loaded": 0, "unexportable": 0}
    _programs._memo.clear()
    b = vj.step_map(_walker_class(0.0)(), z)  # another class object, the same dynamics
    assert counts == {"exported": 1, "loaded": 1, "unexportable": 0}
    c = vj.step_map(_walker_class(1e-3)(), z)  # the same name, another guard
    assert counts == {"exported": 2, "loaded": 1, "unexportable": 0}
    plain = vj.step_map(vj.CompassGait(), z)
    np.testing.assert_array_equal(np.asarray(a.z_next), np.asarray(b.z_next))
    np.testing.assert_allclose(np.asarray(a.z_next), np.asarray(plain.z_next), rtol=0, atol=0)
    assert not np.allclose(np.asarray(c.z_next), np.asarray(a.z_next))


def test_what_cannot_be_fingerprinted_is_not_stored(store, monkeypatch):
    """A walker with a public method the algorithms might call but the fingerprint does
    not cover, and a function from outside the library, take the plain path."""
    counts = _counts(monkeypatch)

    class WithInputs(vj.CompassGait):
        def input_matrix(self, q):  # read by the control algorithms: not fingerprinted
            return jnp.ones((2, 1))

    z = jnp.array([0.2187, -1.0924, -0.3774])
    vj.step_map(WithInputs(), z)
    assert counts == {"exported": 0, "loaded": 0, "unexportable": 0}
    assert _programs._key(_double_map, ((print,), {}), None, (lambda x: x,), []) is None


def test_transformed_calls_take_the_plain_path(store, monkeypatch):
    counts = _counts(monkeypatch)
    model, z = vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774])
    direct = vj.step_map(model, z).z_next
    jitted = jax.jit(lambda z: vj.step_map(model, z).z_next)(z)
    batched = jax.vmap(lambda z: vj.step_map(model, z).z_next)(z[None])
    jac = jax.jacfwd(lambda z: vj.step_map(model, z).z_next)(z)
    assert counts["exported"] == 1 and len(os.listdir(store)) == 1  # the direct call only
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(direct), rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(batched[0]), np.asarray(direct), rtol=0, atol=1e-14)
    assert jac.shape == (3, 3) and np.all(np.isfinite(np.asarray(jac)))


def test_a_program_with_a_host_callback_is_remembered_as_plain(store, monkeypatch):
    counts = _counts(monkeypatch)
    model = vj.CompassGait()
    x0 = jnp.array([0.2187, -0.3375, -1.0924, -0.3774])
    res = vj.step(model, x0)  # throw=True: an error check, a host callback
    assert counts["unexportable"] == 1 and counts["exported"] == 0
    assert len(os.listdir(store)) == 1  # the marker, so no later process tries again
    with pytest.raises(Exception):  # noqa: B017  (the check raises whatever equinox raises)
        vj.step(model, jnp.array([0.2, -0.3, 50.0, 50.0]))  # the check still fires
    assert bool(res.result == vj.RESULTS.successful)


def test_closures_are_refused():
    def outer(k):
        return _programs.stored_jit(lambda x: k * x)

    with pytest.raises(TypeError, match="module-level"):
        outer(2.0)


def test_off_stores_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("VHCJAX_PROGRAMS", "off")
    assert _programs.program_directory() is None
    counts = _counts(monkeypatch)
    vj.step_map(vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774]))
    assert counts == {"exported": 0, "loaded": 0, "unexportable": 0}


def test_outputs_keep_their_types(store):
    out = vj.step_map(vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774]))
    plain = _poincare._step_map.plain(
        vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774]), 1, vj.DEFAULT_CONFIG
    )
    assert type(out) is type(plain)
    assert jax.tree_util.tree_structure(out) == jax.tree_util.tree_structure(plain)
    assert eqx.tree_equal(out, plain, rtol=0, atol=1e-14)


def test_a_call_inside_another_program_becomes_part_of_it(store, monkeypatch):
    """Constant arguments inside `jax.jit`: no stored program, no program of its own
    (whose compiler options `jax.jit` would refuse), the same numbers."""
    counts = _counts(monkeypatch)
    model, z = vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774])
    inside = jax.jit(lambda: vj.step_map(model, z).z_next)()
    assert counts == {"exported": 0, "loaded": 0, "unexportable": 0}
    alone = vj.step_map(model, z).z_next
    assert counts["exported"] == 1
    np.testing.assert_allclose(inside, alone, rtol=0, atol=1e-13)


def test_programs_compile_with_the_cpu_options():
    """On the CPU every top-level program gets `xla_cpu_use_fusion_emitters=False` (this
    XLA knows the option); a program compiled with it gives the same numbers."""
    assert jax.default_backend() == "cpu"
    assert _programs.compiler_options() == {"xla_cpu_use_fusion_emitters": False}
    model, z = vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774])
    default = jax.jit(lambda z: vj.hybrid.step_map(model, z).z_next)(z)
    np.testing.assert_allclose(
        _poincare._step_map.plain(model, z, 1, vj.DEFAULT_CONFIG).z_next, default, atol=1e-13
    )


def _warned_once(monkeypatch):
    monkeypatch.setattr(_programs, "_warned", set())


def test_a_stored_program_that_is_not_the_calls_is_traced_again(store, monkeypatch):
    """A cache whose files are valid but the wrong programs (one copied over another), or
    a program whose record contradicts itself, or bytes that are no record at all: each
    is recomputed with one warning naming the cache folder, gives the right numbers and
    types, and is stored anew (the next process loads it without a warning)."""
    counts = _counts(monkeypatch)
    model, z = vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774])
    right = vj.step_map(model, z)
    other = _double_map(model, z, vj.hybrid.FAST_CONFIG)  # another program, beside it
    (mine,) = [p for p in store.iterdir() if not p.name.startswith("double_map")]
    (theirs,) = [p for p in store.iterdir() if p.name.startswith("double_map")]
    good = mine.read_bytes()
    record = pickle.loads(good)
    wrong_program = dict(record, exported=pickle.loads(theirs.read_bytes())["exported"])
    damages = {
        "stored for another call": theirs.read_bytes(),
        "not of _step_map": pickle.dumps(wrong_program),
        "unreadable": b"not a pickled program",
    }
    for why, damaged in damages.items():
        mine.write_bytes(damaged)
        monkeypatch.setattr(_programs, "_memo", {})
        _warned_once(monkeypatch)
        exported = counts["exported"]
        with pytest.warns(RuntimeWarning, match=re.escape(str(store))) as caught:
            again = vj.step_map(model, z)
        assert len(caught) == 1 and why in str(caught[0].message), str(caught[0].message)
        assert type(again) is type(right)
        assert eqx.tree_equal(again, right, rtol=0, atol=0)
        assert counts["exported"] == exported + 1
        monkeypatch.setattr(_programs, "_memo", {})  # a later process: loads it, silently
        loaded = counts["loaded"]
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            vj.step_map(model, z)
        assert counts["loaded"] == loaded + 1
    assert isinstance(other, tuple)


def test_the_command_line_warns_in_one_line_and_recomputes(store, monkeypatch, capsys):
    """`vhcjax simulate` on a cache whose programs were swapped: one warning line naming
    the cache folder, exit 0, the numbers of an intact cache."""
    from vhcjax.cli import main

    argv = ["simulate", "--steps", "2", "--json", "--quiet"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    vj.step_map(vj.CompassGait(), jnp.array([0.2187, -1.0924, -0.3774]))
    files = sorted(store.iterdir())
    contents = [p.read_bytes() for p in files]
    for p, data in zip(files, contents[1:] + contents[:1]):  # each holds the next one's
        p.write_bytes(data)
    monkeypatch.setattr(_programs, "_memo", {})
    _warned_once(monkeypatch)
    assert main(argv) == 0
    out, err = capsys.readouterr()
    assert json.loads(out) == first
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vhcjax simulate: warning: "), err
    assert str(store) in lines[0] and "traced again" in lines[0]


def test_the_dense_simulation_is_stored(store, monkeypatch):
    """`simulate(..., dense_points=N)` holds no host callback: it is exported like the
    rest, and a later load gives the same trajectory."""
    counts = _counts(monkeypatch)
    model = vj.CompassGait()
    x = model.section_to_state(jnp.array([0.2187, -1.0924, -0.3774]))
    a = vj.simulate(model, x, 2, dense_points=7)
    assert counts == {"exported": 1, "loaded": 0, "unexportable": 0}
    _programs._memo.clear()
    b = vj.simulate(model, x, 2, dense_points=7)
    assert counts == {"exported": 1, "loaded": 1, "unexportable": 0}
    np.testing.assert_array_equal(np.asarray(a.dense_x), np.asarray(b.dense_x))
    assert np.asarray(a.dense_x).shape == (2, 7, 4)


def _oscillator(solve, fn=None):
    """`y'' = -y` from (1, 0) over [0, 1], saved at `ts` by `solve`."""
    term = diffrax.ODETerm(lambda t, y, args: jnp.stack([y[1], -y[0]]))

    def run(y0, ts):
        saveat = diffrax.SaveAt(ts=ts) if fn is None else diffrax.SaveAt(ts=ts, fn=fn)
        return solve(
            term,
            diffrax.Tsit5(),
            t0=0.0,
            t1=1.0,
            dt0=None,
            y0=y0,
            stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-10),
            saveat=saveat,
            throw=False,
        )

    return run


def test_save_times_from_the_interpolant_are_storable_and_equal_diffrax():
    """`solvers.diffeqsolve` answers `SaveAt(ts=...)` from the solver's interpolant: the
    numbers of diffrax's own save times (and of the exact solution), with a `SaveAt` `fn`
    too, in a program that `jax.export` stores."""
    y0, ts = jnp.array([1.0, 0.0]), jnp.linspace(0.0, 1.0, 5)
    ours, theirs = _oscillator(diffeqsolve)(y0, ts), _oscillator(diffrax.diffeqsolve)(y0, ts)
    assert ours.ts is not None and ours.ys is not None and theirs.ys is not None
    np.testing.assert_array_equal(ours.ts, ts)
    np.testing.assert_allclose(ours.ys, theirs.ys, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ours.ys[:, 0], np.cos(ts), atol=1e-9)
    first = lambda t, y, args: y[0]  # noqa: E731
    ys = np.asarray(_oscillator(diffeqsolve, first)(y0, ts).ys)
    ref = np.asarray(_oscillator(diffrax.diffeqsolve, first)(y0, ts).ys)
    np.testing.assert_allclose(ys, ref, rtol=0, atol=1e-15)
    assert ys.shape == (5,)
    stored = jax.export.export(jax.jit(lambda y, t: _oscillator(diffeqsolve)(y, t).ys))(y0, ts)
    np.testing.assert_allclose(stored.call(y0, ts), ours.ys, rtol=0, atol=1e-15)
