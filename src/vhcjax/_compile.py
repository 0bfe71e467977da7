"""How vhcjax's jitted entry points are compiled: `filter_jit`, `eqx.filter_jit` with
XLA options chosen for the graphs of this library.

On the CPU backend XLA lowers every fusion through its MLIR "fusion emitters" by default.
The graphs here are large and deeply nested (Newton over an adaptive ODE solve carrying
forward-mode tangents, events inside), and for them XLA's older LLVM IR emitters compile
markedly faster and run as fast or faster (measured on the batched VHC search: XLA
compile 4.4 s -> 2.6 s, 265 -> 300 gaits/s; run `benchmarks/bench_gait_search.py` with
`VHCJAX_XLA_OPTIONS=0` to compare). Results agree to rounding (the test suite runs with
the options on).

The options are used where the backend is CPU and the installed XLA knows them (probed
once, on the first compile); elsewhere, or with the environment variable
`VHCJAX_XLA_OPTIONS=0`, `filter_jit` is plain `eqx.filter_jit`.
"""

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import equinox as eqx
import jax

#: XLA compile options for the CPU backend (fields of XLA's `DebugOptions`).
CPU_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}

#: Added for a program that `compile_pair` compiles in the background while this thread
#: traces the other: its LLVM code generation on one thread, leaving the other cores to
#: the tracing and to the other program's compile. Measured (batched gait searches,
#: B = 256, fresh processes; six runs with it, three without): compile 5.1-5.4 s instead
#: of 5.4-5.8 s (VHC), 6.2-6.5 s instead of 6.7-7.2 s (shooting), in the same order.
CPU_BACKGROUND_OPTIONS = {"xla_cpu_parallel_codegen_split_count": 1}

_chosen = []


def compiler_options(background=False):
    """The options `filter_jit` passes to `jax.jit` in this process (`None`: XLA defaults);
    `background`: for a program compiled beside other work (`compile_pair`)."""
    if not _chosen:
        _chosen.append(_choose())
    return _chosen[0][1 if background else 0]


def _choose():
    if os.environ.get("VHCJAX_XLA_OPTIONS", "1") == "0" or jax.default_backend() != "cpu":
        return None, None
    chosen = []
    for options in (CPU_COMPILER_OPTIONS, {**CPU_COMPILER_OPTIONS, **CPU_BACKGROUND_OPTIONS}):
        try:  # an XLA that does not know an option rejects it (a Python error, not a crash)
            jax.jit(lambda x: x + 1, compiler_options=options).lower(1.0).compile()
            chosen.append(dict(options))
        except Exception:  # noqa: BLE001
            chosen.append(chosen[0] if chosen else None)
    return tuple(chosen)


def top_level():
    """True outside any JAX transformation (only a top-level `jax.jit` takes options)."""
    try:
        from jax._src.core import trace_state_clean
    except ImportError:  # pragma: no cover - a JAX without it: no options when nested
        return True
    return trace_state_clean()


class _Jit:
    """`eqx.filter_jit(fun, compiler_options=compiler_options())`, built on first use (so
    that importing vhcjax does not start a JAX backend). Inside another transformation
    (a nested call) it is plain `eqx.filter_jit`: the enclosing jit's options apply."""

    def __init__(self, fun, kwargs):
        self._fun, self._kwargs, self._jitted = fun, kwargs, None
        self._plain = eqx.filter_jit(fun, **kwargs)
        functools.update_wrapper(self, fun)

    def _get(self):
        if not top_level():
            return self._plain
        if self._jitted is None:
            options = compiler_options()
            self._jitted = (
                self._plain if options is None
                else eqx.filter_jit(self._fun, compiler_options=options, **self._kwargs)
            )
        return self._jitted

    def __call__(self, *args, **kwargs):
        return self._get()(*args, **kwargs)

    def lower(self, *args, **kwargs):
        return self._get().lower(*args, **kwargs)


def filter_jit(fun=None, **kwargs):
    """`eqx.filter_jit` with vhcjax's compile options; usable as `@filter_jit` too."""
    if fun is None:
        return lambda f: _Jit(f, kwargs)
    return _Jit(fun, kwargs)


_pairs = {}
_pairs_lock = threading.Lock()


def signature(tree):
    """What a program compiled for `tree` is specific to: the tree structure, the shape,
    dtype and weak type of each array, and the value of every other leaf."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    return treedef, tuple(
        (x.shape, x.dtype, x.weak_type) if isinstance(x, jax.Array) else x for x in leaves
    )


def compile_pair(key, first, second, state_shapes, args, names=("first", "second")):
    """Two programs that run one after the other, `state = first(*args)` and then
    `second(*args, state)`, compiled concurrently: XLA compiles `second` on another
    thread (it releases the interpreter lock), with its code generation on one thread
    (`CPU_BACKGROUND_OPTIONS`), while this thread traces and compiles `first`. Kept by
    `key`, which must hold everything the two programs depend on besides the arrays of
    `args` (e.g. `signature(args)`); `clear_caches` forgets them.

    XLA's time grows faster than the size of a program: two halves compile in less time
    than the whole, even one after the other, and on two cores they overlap.

    `state_shapes`: a function of `args` whose output has the shapes and dtypes of
    `first`'s, cheaper to trace than `first` (`jax.eval_shape` traces it). The batched
    gait searches: `second` (the chord loop) needs only the residual, which `first` (the
    Newton loop) traces anyway before differentiating it, so the second core compiles
    the chord loop while the Newton loop's forward mode is traced.

    `names`: of the two programs (as JAX and its disk cache show them).

    **Returns:** `(first, second)`, compiled: call them with the arrays of `args` (and the
    state), as `first(*args)` and `second(*args, state)`.
    """
    with _pairs_lock:  # one compilation per key, also when host threads ask at once
        if key not in _pairs:
            dynamic, static = eqx.partition(args, eqx.is_array)

            def with_static(fn):
                return lambda *a: fn(*eqx.combine(a[: len(args)], static), *a[len(args):])

            def jit(fn, name, background=False):
                program = with_static(fn)
                program.__name__ = program.__qualname__ = name  # names the disk-cache entry
                return jax.jit(program, compiler_options=compiler_options(background))

            state = jax.tree_util.tree_map(
                lambda o: jax.ShapeDtypeStruct(o.shape, o.dtype),
                jax.eval_shape(with_static(state_shapes), *dynamic),
            )
            lowered = jit(second, names[1], background=True).trace(*dynamic, state).lower()
            with ThreadPoolExecutor(1) as pool:
                compiling = pool.submit(lowered.compile)
                first_compiled = jit(first, names[0]).trace(*dynamic).lower().compile()
                _pairs[key] = (first_compiled, compiling.result())
        first_compiled, second_compiled = _pairs[key]

    def run_first(*a):
        return first_compiled(*eqx.filter(a, eqx.is_array))

    def run_second(*a):
        return second_compiled(*eqx.filter(a[:-1], eqx.is_array), a[-1])

    return run_first, run_second


def clear_caches():
    """`jax.clear_caches()`, and the programs vhcjax keeps itself (`compile_pair`: the
    batched gait searches), which `jax.clear_caches()` does not reach. Frees their memory;
    the next call compiles again."""
    with _pairs_lock:
        _pairs.clear()
    jax.clear_caches()


def default_cache_dir():
    """Where `enable_compilation_cache` keeps compiled programs by default:
    `$XDG_CACHE_HOME/vhcjax/xla` (`~/.cache/vhcjax/xla`)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "vhcjax", "xla")


def enable_compilation_cache(directory=None):
    """Keep compiled programs on disk (JAX's persistent compilation cache), so that a
    later process loads them instead of running XLA again. Call it before the first
    computation; it applies to every program of the process that takes XLA a second or
    more (a JAX-wide setting).

    It saves the XLA part of a compilation, not the tracing: the batched VHC search
    compiles in about 4 s instead of 8-10 s from the second process on (2-core CPU).
    Programs holding a host callback are not stored (none of the searches or multiplier
    computations holds one). The `vhcjax` command calls this when the environment
    variable `VHCJAX_CACHE_DIR` names a directory.

    **Returns:** the directory used (default: `default_cache_dir()`).
    """
    directory = os.fspath(directory) if directory else default_cache_dir()
    os.makedirs(directory, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", directory)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    return directory
