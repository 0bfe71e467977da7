"""JAX's persistent compilation cache, on by default for vhcjax.

Compiling the programs of a gait search or a stability computation takes seconds; the
cache keeps the compiled programs on disk, so that a later process loads them instead of
running XLA again. vhcjax turns it on when imported, in a directory per vhcjax and JAX
version (a new version never reads an entry of an old one):

- `$VHCJAX_CACHE_DIR` if set, `off` to leave the cache off;
- else `$XDG_CACHE_HOME/vhcjax`, else `~/.cache/vhcjax`.

A cache directory the user already gave JAX (`jax_compilation_cache_dir`) is kept.
"""

import os

import jax

_ENV = "VHCJAX_CACHE_DIR"


def _version():
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vhcjax")
    except PackageNotFoundError:  # running from a source tree
        return "0.0.0"


def default_cache_dir():
    """The directory `enable_compilation_cache()` uses without an argument: `$VHCJAX_CACHE_DIR`,
    else `$XDG_CACHE_HOME/vhcjax`, else `~/.cache/vhcjax`; in it, one folder per vhcjax
    and JAX version. `None` when `VHCJAX_CACHE_DIR=off`."""
    env = os.environ.get(_ENV, "").strip()
    if env.lower() == "off":
        return None
    if env:
        base = env
    else:
        xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        base = os.path.join(xdg, "vhcjax")
    return os.path.join(base, f"vhcjax-{_version()}-jax-{jax.__version__}")


def enable_compilation_cache(directory=None):
    """Keep compiled programs on disk (JAX's persistent compilation cache). vhcjax calls
    this on import; call it to move the cache. It applies to every program of the
    process (a JAX-wide setting). Programs traced by vhcjax are kept there too
    (in `programs/`), so that a later process does not trace them again.

    **Arguments:**

    - `directory`: where to keep the programs; default `default_cache_dir()`.

    **Returns:** the directory used, or `None` if the cache is off (`VHCJAX_CACHE_DIR=off`
    and no `directory`).
    """
    directory = os.fspath(directory) if directory else default_cache_dir()
    if directory is None:
        return None
    os.makedirs(directory, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", directory)
    # Every program, however quick to compile: a later process then compiles nothing.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return directory


def enable_default_cache():
    """On import: turn the cache on unless it is off or JAX already has a directory. An
    unwritable default location leaves it off (the library still works, compiling anew)."""
    if jax.config.values["jax_compilation_cache_dir"]:
        return None
    try:
        return enable_compilation_cache()
    except OSError:
        return None


def clear_caches():
    """Drop the programs compiled or loaded in this process (`jax.clear_caches()`), freeing
    their memory; the next call compiles again (or loads from the disk cache)."""
    from . import _programs

    _programs._memo.clear()
    jax.clear_caches()
