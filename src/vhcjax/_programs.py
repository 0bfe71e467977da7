"""Programs kept across processes: `stored_jit`, `eqx.filter_jit` that skips tracing in a
later process.

JAX's persistent compilation cache (`vhcjax._cache`) spares a later process the XLA
compile, but not the tracing of the Python code into a program, which for an ODE solve
with events under `vmap` and `jacfwd` takes seconds. A function wrapped with `stored_jit`
is exported (`jax.export`) the first time it runs on concrete arrays, and the serialized
program is kept in the cache directory; a later process with the same vhcjax source, JAX
version, platform, static arguments and input shapes loads it and runs it, compiled
code included from the compilation cache, without running the Python again.

A walker model of a class defined outside vhcjax and the libraries it pins (a model
class from a notebook, which could change under the same name) is keyed by its dynamics
instead: the jaxprs of the model methods the algorithms call (`_model_fingerprint`).
Calls under a transformation (`jit`, `vmap`, `grad`: tracers among the arguments),
arguments spread over several devices, arguments of other types defined outside those
libraries, a walker with a public method the fingerprint does not cover, static
arguments that print differently in every process (a lambda), or the cache turned
off (`VHCJAX_CACHE_DIR=off`, or `VHCJAX_PROGRAMS=off` for these programs alone) take the
plain `eqx.filter_jit` path. So do all calls of a process whose vhcjax source files
changed after it imported vhcjax (an edited checkout, a reloaded module): the key holds
the hash of the sources taken at import. So does a program that cannot be exported (one holding a
host callback, e.g. a `throw=True` check): that is remembered, and it is traced the
usual way.

On the CPU, every program here is compiled with `compiler_options()`.

Within `notes_to(write)` (the command line, unless `--quiet`), a program that takes more
than about 2 s to trace, compile or load is named by a note (`preparing`): it is then
compiled before it runs (`lower().compile()`, which fills the caches that its call finds),
so that the note tells a compile from a long run. Without a receiver nothing changes.
"""

import contextlib
import functools
import hashlib
import inspect
import math
import os
import pickle
import re
import tempfile
import threading
import typing
import warnings
from collections.abc import Callable

import equinox as eqx
import jax
import jax.core
import numpy as np

from ._host import tracing

_F = typing.TypeVar("_F", bound=Callable)
_SUFFIX = ".program"
_memo = {}  # path of a stored program -> its `_Program`, or None for the plain path
_lock = threading.RLock()  # reentrant: an export may call another stored function
_source_hash = None


def _hash_sources():
    """A hash of the vhcjax source files as they are on disk now."""
    h = hashlib.sha256()
    root = os.path.dirname(os.path.abspath(__file__))
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        for name in sorted(filenames):
            if name.endswith(".py"):
                path = os.path.join(dirpath, name)
                h.update(os.path.relpath(path, root).encode())
                with open(path, "rb") as fh:
                    h.update(fh.read())
    return h.hexdigest()


def _source():
    """The hash of the vhcjax sources that this process runs, taken when vhcjax is
    imported (`vhcjax/__init__.py` calls this last): a changed source file never loads
    an old program."""
    global _source_hash
    if _source_hash is None:
        _source_hash = _hash_sources()
    return _source_hash


#: Seconds that tracing, compiling or loading a program may take before a note says so
#: (`preparing`); the environment variable `VHCJAX_NOTE_AFTER` sets another.
NOTE_AFTER = 2.0
_receivers = []  # the `notes_to` blocks open now: (write, notes written), innermost last


@contextlib.contextmanager
def notes_to(write):
    """Within this block, from any thread, a program that takes more than `NOTE_AFTER`
    seconds to trace, compile or load is named by `write(text)`, one line each
    (`preparing`). For the command line: the library alone prints nothing."""
    entry = (write, set())
    _receivers.append(entry)
    try:
        yield
    finally:
        _receivers.remove(entry)


def note_after():
    """`NOTE_AFTER`, or the seconds that `VHCJAX_NOTE_AFTER` gives (`inf`: no notes)."""
    text = os.environ.get("VHCJAX_NOTE_AFTER", "").strip()
    if not text:
        return NOTE_AFTER
    try:
        seconds = float(text)
    except ValueError:
        raise ValueError(f"VHCJAX_NOTE_AFTER must be a number of seconds, got {text!r}") from None
    if math.isnan(seconds) or seconds < 0:
        raise ValueError(f"VHCJAX_NOTE_AFTER must be 0 or more seconds, got {text!r}")
    return seconds


def _listening():
    """Whether a note would be written (`notes_to` open, a finite `note_after()`)."""
    return bool(_receivers) and math.isfinite(note_after())


@contextlib.contextmanager
def preparing(what, again=None):
    """A block that traces, compiles or loads a program. If it takes more than
    `note_after()` seconds, a watcher thread writes the note `what` to the innermost
    `notes_to` receiver while the block still runs, or `again` (default `what`) if that
    receiver has had `what` already. Nothing without a receiver."""
    delay = note_after()
    if not _receivers or not math.isfinite(delay):
        yield
        return
    write, written = _receivers[-1]
    done = threading.Event()

    def watch():
        if not done.wait(delay):
            text = what if what not in written else (again or what)
            written.add(what)
            write(text)

    watcher = threading.Thread(target=watch, name="vhcjax-note", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        watcher.join()


def _cache_note(loading):
    """The note (`preparing`) of a program loaded from the cache or compiled anew, and
    that of a later one."""
    directory = jax.config.values["jax_compilation_cache_dir"]
    if loading:
        return f"loading compiled programs from {directory}", "loading another compiled program"
    if directory and program_directory() is not None:
        how = f"first run only; later runs load the programs from {directory}"
    elif directory:
        how = "stored programs are off (VHCJAX_PROGRAMS=off): every run traces them"
    else:
        how = "the compilation cache is off: every run compiles them"
    return f"compiling ({how})", "compiling another program"


#: What this process did: programs `exported` (traced and stored), `loaded` (from disk),
#: `unexportable` (taking the plain path).
stats = {"exported": 0, "loaded": 0, "unexportable": 0}


#: XLA options of the programs on the CPU: XLA's older fusion code generator compiles
#: these programs (ODE solves in Newton loops) faster than the default one and runs them
#: as fast; `benchmarks/bench_cli.py --compiler-options` times first runs of commands
#: with and without it (it clears this dict), and "A persistent compilation cache" in
#: `docs/design.md` says more.
_CPU_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
_options = None


def compiler_options():
    """The XLA options vhcjax compiles its programs with: `_CPU_OPTIONS` where the
    default backend is the CPU and its XLA knows them (checked once, on a one-line
    program), else none (a version of XLA without that option compiles as usual)."""
    global _options
    if _options is None:
        options = {}
        if jax.default_backend() == "cpu":
            try:
                check = jax.jit(lambda x: x + 1, compiler_options=_CPU_OPTIONS)
                check.lower(np.float64(0.0)).compile()
                options = dict(_CPU_OPTIONS)
            except jax.errors.JaxRuntimeError:  # "No such compile option"
                pass
        _options = options
    return _options


def program_directory():
    """Where stored programs go: `programs/` in the compilation cache directory; `None`
    if that cache is off, or stored programs are (`VHCJAX_PROGRAMS=off`)."""
    directory = jax.config.values["jax_compilation_cache_dir"]
    if not directory or os.environ.get("VHCJAX_PROGRAMS", "").strip().lower() == "off":
        return None
    return os.path.join(directory, "programs")


#: Packages whose types may appear in the arguments of a stored program: their code is
#: pinned by the source hash and the JAX version of the key. A type from anywhere else (a
#: model class defined in a notebook, say) could change without the key changing.
_PINNED = (
    "vhcjax",
    "builtins",
    "numpy",
    "jax",
    "jaxlib",
    "equinox",
    "diffrax",
    "optimistix",
    "lineax",
)


#: The walker-model methods a stored program may call, with their arguments built from
#: the model (`q`, `dq`: coordinates and rates; `x`: a state; `z`: a section point; `v`:
#: a velocity in the plane; `f`: generalized forces). The program of a model class
#: defined outside `_PINNED` (a user's own) is stored under the jaxprs of these methods.
_MODEL_METHODS = {
    "kinetic_energy": "q dq",
    "kinetic_energy+base": "q dq v",
    "potential_energy": "q",
    "contact_point": "q",
    "guard": "q",
    "strike_gate": "q",
    "fallen": "q",
    "relabel": "q dq",
    "section_to_state": "z",
    "state_to_section": "x",
    "energy": "x",
    "impact": "x",
    "vector_field": "t x",
    "acceleration": "q dq",
    "acceleration+force": "q dq f",
    "mass_matrix": "q",
    "coriolis_matrix": "q dq",
    "gravity_vector": "q",
    "validate": "",
    "scales": "",
    "in_own_units": "",
    "with_slope": "t",
    "slope_normal": "property",
    "time_scale": "property",
}
_fingerprints = {}  # (class, structure, shapes) -> fingerprint of a model, or None


def _model_fingerprint(model):
    """Text that changes whenever the dynamics of `model`'s class could: its name, its
    class attributes, and the jaxprs (constants included) of `_MODEL_METHODS`; `None`
    where it cannot be taken (a public method outside `_MODEL_METHODS`, which the
    algorithms might call, a multi-domain model, or a class attribute without a stable
    text): such a model takes the plain path."""
    from .hybrid import MultiDomainModel
    from .mechanics import WalkerModel

    if not isinstance(model, WalkerModel) or isinstance(model, MultiDomainModel):
        return None
    leaves, tree = jax.tree_util.tree_flatten(model)
    shapes = [(np.shape(x), str(getattr(x, "dtype", type(x).__name__))) for x in leaves]
    memo = (type(model), str(tree), repr(shapes))
    if memo not in _fingerprints:
        try:
            _fingerprints[memo] = _take_fingerprint(model)
        except Exception:  # a model that cannot be traced abstractly: the plain path
            _fingerprints[memo] = None
    return _fingerprints[memo]


def _take_fingerprint(model):
    import dataclasses

    fields = {f.name for f in dataclasses.fields(model)}
    parts = [f"{type(model).__module__}.{type(model).__qualname__}"]
    for cls in type(model).__mro__:
        if cls.__module__.split(".")[0] in _PINNED:
            continue
        for name, value in sorted(cls.__dict__.items()):
            if name.startswith("_") or name in fields or name in _MODEL_METHODS:
                continue  # private helpers reach the algorithms only through the methods
            if callable(value) or isinstance(value, (property, staticmethod, classmethod)):
                return None
            text = repr(value)
            if " at 0x" in text:
                return None
            parts.append(f"{cls.__qualname__}.{name}={text}")
    n = model.n_dof
    q = jax.numpy.zeros(n)
    x = jax.numpy.zeros(2 * n)
    z = jax.eval_shape(model.state_to_section, x)
    args = {
        "q": q,
        "dq": q,
        "x": x,
        "z": jax.numpy.zeros(z.shape, z.dtype),
        "v": jax.numpy.zeros(2),
        "f": q,
        "t": jax.numpy.zeros(()),
    }
    for key, spec in _MODEL_METHODS.items():
        name = key.split("+")[0]
        if spec == "property":
            fn = lambda m, name=name: getattr(m, name)  # noqa: E731
            inputs = ()
        else:
            fn = lambda m, *a, name=name: getattr(m, name)(*a)  # noqa: E731
            inputs = tuple(args[a] for a in spec.split())
        try:
            closed = jax.make_jaxpr(fn)(model, *inputs)
        except Exception as err:  # e.g. a method the class does not offer
            parts.append(f"{key}: {type(err).__name__}")
            continue
        consts = hashlib.sha256()
        for c in closed.consts:
            c = np.asarray(c)
            consts.update(f"{c.shape}{c.dtype}".encode() + c.tobytes())
        parts.append(f"{key}: {closed} {consts.hexdigest()}")
    return "\n".join(parts)


def _foreign(tree):
    """`""` where every node and leaf type of `tree` comes from a `_PINNED` package; the
    fingerprints of the models among them that do not (`_model_fingerprint`); `None`
    where another type does not, or a fingerprint cannot be taken."""
    foreign = []

    def visit(x):
        if type(x).__module__.split(".")[0] not in _PINNED:
            foreign.append(x)
        return False  # descend into every node

    jax.tree_util.tree_flatten(tree, is_leaf=visit)
    texts = []
    for node in foreign:
        text = _model_fingerprint(node)
        if text is None:
            return None
        texts.append(text)
    return "\0".join(texts)


def _named(x):
    """A module-level function of a `_PINNED` package as its name (stable across
    processes); anything else as it is."""
    qualname = getattr(x, "__qualname__", "")
    module = getattr(x, "__module__", None) or ""
    if (
        callable(x)
        and module.split(".")[0] in _PINNED
        and "<locals>" not in qualname
        and not getattr(x, "__closure__", None)
    ):
        return f"<function {module}.{qualname}>"
    return x


def _call_text(fn, args, in_tree, static, leaves):
    """What a program is stored for, as text: the sources, JAX, the platform, `fn`, the
    arguments' structure, static values, shapes and dtypes; `None` where a stored program
    could go stale: an argument of a type from outside `_PINNED`, or static arguments
    without a stable text (a function, printed with its address)."""
    text = repr(jax.tree_util.tree_map(_named, static))
    if " at 0x" in text:
        return None
    foreign = _foreign(args)
    if foreign is None:
        return None
    parts = [
        _source(),
        jax.__version__,
        jax.default_backend(),
        str(jax.config.read("jax_enable_x64")),
        f"{fn.__module__}.{fn.__qualname__}",
        str(in_tree),
        text,
        repr([(x.shape, str(x.dtype)) for x in leaves]),
        foreign,
    ]
    return "\0".join(parts)


def _file_name(fn, call):
    """The file name of the program stored for the call `call` (`_call_text`)."""
    digest = hashlib.sha256(call.encode()).hexdigest()[:40]
    return f"{fn.__name__.strip('_')}-{digest}{_SUFFIX}"


def _key(fn, args, in_tree, static, leaves):
    """The file name of a program, or `None` where a stored program could go stale (see
    `_call_text`)."""
    call = _call_text(fn, args, in_tree, static, leaves)
    return None if call is None else _file_name(fn, call)


def _skeleton(tree):
    """`tree` with every array replaced by a 0-d placeholder: pickled, it restores the
    tree structure in another process (a pickled `PyTreeDef` of an equinox module does
    not)."""
    return jax.tree_util.tree_map(lambda x: np.zeros((), x.dtype), tree)


class _Program:
    """A loaded or freshly exported program: flat array inputs to the output pytree."""

    def __init__(self, exported, out_skeleton, out_static):
        def run(*leaves):
            return exported.call(*leaves)

        run.__name__ = exported.fun_name.removeprefix("jit_")  # "jit_<fn>" in JAX's logs
        self._call = jax.jit(run, compiler_options=compiler_options())
        self._out_tree = jax.tree_util.tree_structure(out_skeleton)
        self._out_static = out_static

    def _placed(self, leaves):
        # One signature for every call: weak types and uncommitted arrays would each make
        # the wrapper compile again (the program itself wants plain dtypes on one device).
        device = next(
            (next(iter(x.sharding.device_set)) for x in leaves if getattr(x, "committed", False)),
            jax.local_devices()[0],
        )
        return [jax.device_put(_plain(x), device) for x in leaves]

    def compile(self, leaves):
        """Compile (or load from the compilation cache) the program for `leaves` now,
        without running it: its calls then find it compiled."""
        self._call.lower(*self._placed(leaves)).compile()

    def __call__(self, leaves):
        out = self._call(*self._placed(leaves))
        return eqx.combine(jax.tree_util.tree_unflatten(self._out_tree, out), self._out_static)


def _plain(x):
    """`x` without a weak type (on the host if it had one: no operation to dispatch)."""
    return np.asarray(x) if getattr(x, "weak_type", False) or not isinstance(x, jax.Array) else x


#: LAPACK kernels that `jax.export` does not promise to keep across JAX versions. A
#: stored program is only ever loaded by the JAX version that wrote it (see `_key`).
_UNCHECKED_TARGETS = (
    "lapack_sormqr_ffi",
    "lapack_dormqr_ffi",
    "lapack_cunmqr_ffi",
    "lapack_zunmqr_ffi",
)


def _export_with(flat, specs, targets):
    checks = [jax.export.DisabledSafetyCheck.custom_call(t) for t in targets]
    return jax.export.export(jax.jit(flat), disabled_checks=checks)(*specs)


def _export(fn, in_tree, static, leaves, call):
    """Trace `fn` once into an exported program, and the pickled record that restores it
    (with `call`, the `_call_text` it is stored for, checked when it is loaded)."""
    shapes = {}

    def flat(*xs):  # named after `fn` below: the exported program keeps the name
        args, kwargs = eqx.combine(jax.tree_util.tree_unflatten(in_tree, xs), static)
        out_dyn, out_static = eqx.partition(fn(*args, **kwargs), eqx.is_array)
        shapes["out"] = (out_dyn, out_static)
        return jax.tree_util.tree_leaves(out_dyn)

    flat.__name__ = fn.__name__
    specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
    targets = list(_UNCHECKED_TARGETS)
    try:
        exported = _export_with(flat, specs, targets)
    except ValueError as err:  # another kernel without a cross-version guarantee: allow it
        more = re.findall(r"custom_call @(\w+)\(", str(err))
        if not more:
            raise
        exported = _export_with(flat, specs, targets + more)
    out_dyn, out_static = shapes["out"]
    record = {
        "call": call,
        "exported": bytes(exported.serialize()),
        "skeleton": _skeleton(out_dyn),
        "static": out_static,
    }
    return _Program(exported, record["skeleton"], out_static), record


class _Mismatch(Exception):
    """A stored program that is not the one its call expects."""


def _avals(xs):
    return [(tuple(x.shape), np.dtype(x.dtype)) for x in xs]


def _load(fn, path, call, leaves):
    """The program of `fn` stored at `path` for the call `call` (`_call_text`) with array
    arguments `leaves`, or `None` for a function remembered as not exportable. Raises
    `_Mismatch` for a file stored for another call (its `call` differs, e.g. a file
    copied over another) or one that contradicts itself: a program whose inputs are
    not `leaves`' shapes and dtypes, whose outputs are not its output skeleton's, or
    which is not `fn`'s."""
    with open(path, "rb") as fh:
        record = pickle.load(fh)
    if not isinstance(record, dict) or record.get("call") != call:
        raise _Mismatch("stored for another call")
    if record["exported"] is None:  # not exportable: the plain path
        return None
    exported = jax.export.deserialize(bytearray(record["exported"]))
    skeleton = jax.tree_util.tree_leaves(record["skeleton"])
    if exported.fun_name.removeprefix("jit_") != fn.__name__:
        raise _Mismatch(f"the program of {exported.fun_name}, not of {fn.__name__}")
    if _avals(exported.in_avals) != _avals(leaves):
        raise _Mismatch("its inputs are not the call's")
    out = _avals(exported.out_avals)
    if [d for _, d in out] != [d for _, d in _avals(skeleton)]:
        raise _Mismatch("its outputs are not its output structure's")
    return _Program(exported, record["skeleton"], record["static"])


_warned: set[str] = set()  # program directories already warned about


def _warn_mismatch(path, why):
    """Warn once per process and folder: a stored program was not the one expected."""
    folder = os.path.dirname(path)
    if folder in _warned:
        return
    _warned.add(folder)
    warnings.warn(
        f"the cache folder {folder} holds a damaged or wrong program "
        f"({os.path.basename(path)}: {why}): traced again and stored anew; deleting the "
        "folder clears every stored program",
        RuntimeWarning,
        stacklevel=4,
    )


def _store(path, record):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            pickle.dump(record, fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)  # atomic: a concurrent reader sees all or nothing
    except BaseException:
        os.unlink(tmp)
        raise


def _spread(leaves):
    """Whether an argument is spread over several devices (not a stored program's
    single-device signature)."""
    for x in leaves:
        sharding = getattr(x, "sharding", None)
        if sharding is not None and len(sharding.device_set) > 1:
            return True
    return False


class X64Error(RuntimeError):
    """JAX's float64 mode is off: vhcjax's solves to 1e-12 need it."""


def require_x64():
    """Raise `X64Error` (one line, with the fix) if JAX's float64 mode is off: vhcjax
    turns it on when imported, so it was turned off later in the process. Every stored
    program checks this when called."""
    if not jax.config.read("jax_enable_x64"):  # a direct read (`values` copies them all)
        raise X64Error(
            "vhcjax needs float64, but JAX's float64 mode was turned off after vhcjax was "
            "imported: call jax.config.update('jax_enable_x64', True) before using vhcjax"
        )


@typing.overload
def stored_jit(fn: _F) -> _F: ...
@typing.overload
def stored_jit(fn: None = None, *, arrays: tuple[str, ...] = ()) -> Callable[[_F], _F]: ...
def stored_jit(fn: typing.Any = None, *, arrays: tuple[str, ...] = ()) -> typing.Any:
    """`eqx.filter_jit(fn)` whose programs are also kept on disk (see the module docstring).

    `fn` takes pytrees of arrays and static values (as with `filter_jit`) and returns a
    pytree whose non-array leaves depend only on the static arguments. The arguments
    named in `arrays` (times, impulses: numbers that change from gait to gait) are made
    float64 arrays when given as Python numbers, so that another value does not compile
    another program, as a static one would.
    """
    if fn is None:
        return functools.partial(stored_jit, arrays=arrays)
    if arrays:
        return _as_arrays(stored_jit(fn), fn, arrays)
    if "<locals>" in fn.__qualname__ or getattr(fn, "__closure__", None):
        # A closure's captured values are not arguments: they cannot enter the key.
        raise TypeError(f"stored_jit needs a module-level function, not {fn.__qualname__}")
    nested = eqx.filter_jit(fn)  # traced into another program, compiled as part of it
    top = []  # on its own: the `filter_jit` with `compiler_options()`, made at first use

    compiled = set()  # `_signature`s compiled under a note (`preparing`)

    def run_plain(traced, args, kwargs):
        if traced:
            return nested(*args, **kwargs)
        if not top:
            options = compiler_options()  # passed on to `jax.jit` (untyped in equinox)
            top.append(eqx.filter_jit(fn, compiler_options=options))  # pyright: ignore[reportCallIssue]
        if _listening():
            signature = _signature(args, kwargs)
            if signature is not None and signature not in compiled:
                with _lock:
                    if signature not in compiled:
                        with preparing(*_cache_note(loading=False)):
                            top[0].lower(*args, **kwargs).compile()
                        compiled.add(signature)
        return top[0](*args, **kwargs)

    def plain(*args, **kwargs):
        return run_plain(tracing((args, kwargs)), args, kwargs)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        require_x64()
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, in_tree = jax.tree_util.tree_flatten(dynamic)
        traced = tracing(leaves)
        directory = program_directory()
        if traced or directory is None or _spread(leaves):
            return run_plain(traced, args, kwargs)
        call_text = _call_text(fn, (args, kwargs), in_tree, static, leaves)
        if call_text is None:
            return run_plain(traced, args, kwargs)
        path = os.path.join(directory, _file_name(fn, call_text))
        program = _memo.get(path, False)
        if program is False:
            with _lock:
                program = _memo.get(path, False)
                if program is False:
                    with preparing(*_cache_note(loading=os.path.exists(path))):
                        program = _obtain(fn, path, in_tree, static, leaves, call_text)
                        if program is not None and _listening():
                            program.compile(leaves)
                    _memo[path] = program
        if program is None:
            return run_plain(traced, args, kwargs)
        return program(leaves)

    call.plain = plain  # pyright: ignore[reportAttributeAccessIssue]  (the filter_jit path)
    return call


def _as_arrays(call, fn, names):
    """`call` with the arguments of `fn` named in `names` made float64 arrays where they
    are Python numbers (`stored_jit(arrays=...)`)."""
    signature = inspect.signature(fn)
    missing = set(names) - set(signature.parameters)
    if missing:
        raise TypeError(f"stored_jit: {fn.__qualname__} has no argument {sorted(missing)}")

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        for name in names:
            value = bound.arguments.get(name)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                bound.arguments[name] = np.float64(value)
        return call(*bound.args, **bound.kwargs)

    wrapped.plain = call.plain  # pyright: ignore[reportAttributeAccessIssue]
    return wrapped


def _signature(args, kwargs):
    """What a plain call's program depends on (structure, static values, shapes, dtypes,
    placement), hashable; `None` where a static value is not."""
    dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
    leaves, in_tree = jax.tree_util.tree_flatten(dynamic)
    avals = tuple(
        (x.shape, str(x.dtype), getattr(x, "weak_type", False), getattr(x, "sharding", None))
        for x in leaves
    )
    signature = (in_tree, jax.tree_util.tree_structure(static), avals)
    signature += tuple(jax.tree_util.tree_leaves(static))
    try:
        hash(signature)
    except TypeError:
        return None
    return signature


def _obtain(fn, path, in_tree, static, leaves, call):
    """The program stored at `path` for `call` (`_call_text`), else a new export stored
    there; `None` if `fn` cannot be exported, or if the source files changed since
    vhcjax was imported (its calls then take the plain path): the code this process
    runs is then not the code that the key names, and a program traced from it must not
    be stored under that key, nor one stored there be run in its place. A stored file
    that cannot be read or is not the program of `call` (`_load`) is replaced by a new
    export, with a warning naming the cache folder."""
    if _hash_sources() != _source():
        return None
    if os.path.exists(path):
        try:
            program = _load(fn, path, call, leaves)
            stats["loaded" if program is not None else "unexportable"] += 1
            return program
        except ImportError:  # no deserializer (flatbuffers) installed: nothing to load
            return None
        except Exception as err:  # damaged, or another call's program: export again
            why = str(err) if isinstance(err, _Mismatch) else f"unreadable: {type(err).__name__}"
            _warn_mismatch(path, why)
    try:
        program, record = _export(fn, in_tree, static, leaves, call)
        stats["exported"] += 1
    except ImportError:  # no serializer (flatbuffers) installed: nothing to remember
        return None
    except Exception:  # e.g. a host callback, which jax.export cannot serialize
        program, record = None, {"call": call, "exported": None}  # no export next time
        stats["unexportable"] += 1
    try:
        _store(path, record)
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        pass  # not storable (read-only cache, unpicklable static output): used in-process
    return program
