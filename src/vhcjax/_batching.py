"""Batches: one padding rule, chunks run from host threads, spread over devices.

Batched entry points (`simulate_batch`, `family_multipliers`, the sweep tangents, basins)
call `padded_map(fn, *args)`, where `fn` is a jitted, vmapped computation. The batch is
cut into chunks of one padded size (a power of two, at most `MAX_DISPATCH`), each placed
with a `NamedSharding` over a 1-D mesh axis `"batch"` so that XLA's SPMD partitioner
splits it over the devices, with no host round trip inside loops; on a CPU several chunks
run at once from host threads (`host_workers`). `find_gaits` pads its batches by the same
rule, with a chunk size of its own (`max_chunk`).

Several processes (`jax.distributed.initialize()` on each, every one running the same
program): `padded_map` computes this process's share of the batch on its own devices and
gathers the shares (`vhcjax._distributed`); meshes span the local devices.
"""

import contextlib
import contextvars
import os
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from . import _distributed
from ._host import tracing


def bucket_size(n, minimum=8):
    """Padded size of a batch of `n`: the smallest power of two that is at least `n` and
    `minimum`. Batches padded to these few sizes share compiled programs (tracing and
    compiling cost far more than running the padding members)."""
    return max(minimum, 1 << (int(n) - 1).bit_length())


def default_mesh(devices=None):
    """A 1-D mesh with axis `"batch"` over `devices` (default: this process's devices)."""
    devices = jax.local_devices() if devices is None else devices
    return Mesh(np.asarray(devices), ("batch",))


def shard_batch(tree, mesh=None):
    """Place the leaves of `tree` (common leading batch axis) split over the `"batch"` axis
    of `mesh` (default: all local devices), so that a jitted, vmapped computation on them
    runs partitioned across the devices (XLA SPMD), replicated inputs staying whole.

    A no-op with one device. The batch size must be a multiple of the number of devices
    (callers pad their chunks); otherwise the leaves are left where they are.
    """
    mesh = default_mesh() if mesh is None else mesh
    n_dev = mesh.devices.size
    leaves = jax.tree_util.tree_leaves(tree)
    if n_dev == 1 or not leaves or leaves[0].shape[0] % n_dev:
        return tree
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return jax.tree_util.tree_map(lambda x: jax.device_put(jnp.asarray(x), sharding), tree)


def device_multiple(mesh=None):
    """Number of devices a batch should be a multiple of (1 on a single device)."""
    return (default_mesh() if mesh is None else mesh).devices.size


def round_to_devices(n, mesh=None):
    """`n` rounded up to a multiple of the device count of `mesh`."""
    k = device_multiple(mesh)
    return -(-n // k) * k


#: Largest batch handed to one vmapped Newton / linearization program: one dispatch of
#: 1,024 members hung inside the XLA CPU runtime (all threads idle, reproducible, not
#: cured by `--xla_cpu_multi_thread_eigen=false`); 256 runs reliably.
MAX_DISPATCH = 256


def host_workers(mesh=None):
    """How many chunks of a large batch to run at once (`in_chunks`).

    XLA's CPU runtime runs one program on one core (the loops of an ODE solve are
    sequential), so on a CPU the chunks run from a pool of threads: one per core not
    already given a device of `mesh`. One on other platforms (a GPU queues its programs).
    The environment variable `VHCJAX_HOST_WORKERS` overrides it (1: one chunk at a time).
    """
    env = os.environ.get("VHCJAX_HOST_WORKERS", "").strip()
    if env:
        if not env.isdigit() or int(env) < 1:
            raise ValueError(f"VHCJAX_HOST_WORKERS must be a positive integer, got {env!r}")
        return int(env)
    devices = (default_mesh() if mesh is None else mesh).devices.ravel()
    if any(d.platform != "cpu" for d in devices):
        return 1
    # several processes: the fewest cores of any, so that all cut their batches alike
    return max(1, _distributed.common_cores() // devices.size)


_PROGRESS = contextvars.ContextVar("vhcjax_progress", default=None)


@contextlib.contextmanager
def report_progress(callback):
    """Within this block, `callback(stage, done, total)` is called on the calling thread
    each time a chunk of a batched computation (gait search, tangents, multipliers,
    simulation, continuation) has finished: `done` of `total` chunks of `stage`.
    For progress bars; nothing is reported for a batch that runs in one chunk.
    """
    token = _PROGRESS.set(callback)
    try:
        yield
    finally:
        _PROGRESS.reset(token)


def report(stage, done, total):
    """Tell the `report_progress` callback (if any) that `done` of `total` chunks of
    `stage` have finished."""
    callback = _PROGRESS.get()
    if callback is not None:
        callback(stage, done, total)


def map_in_order(fn, items, workers=1, progress=None):
    """`[fn(x) for x in items]`, up to `workers` calls at once from a pool of host threads
    (see `host_workers`), results in the order of `items`; `progress` optionally wraps
    `items` (a progress bar that advances as the results come in)."""
    items = list(items)
    ticks = progress(items) if progress is not None else items
    workers = max(1, min(workers, len(items)))
    if workers == 1:
        return [fn(x) for x in ticks]
    with ThreadPoolExecutor(workers) as pool:
        results = pool.map(lambda x: jax.block_until_ready(fn(x)), items)
        return [r for _, r in zip(ticks, results)]


def in_chunks(fn, n, chunk, workers=1, stage="batch", progress=None, to_host=False):
    """`fn(i, j)` on the slices `[i, j)` of a batch of `n`, `chunk` at a time, results
    concatenated along the batch axis (a host loop: each call is one dispatch; numpy
    concatenation with `to_host`, for results that `fn` fetched to the host).

    With `workers > 1`, up to `workers` chunks run at once (`map_in_order`), for a CPU
    where each program runs on one core (see `host_workers`). The chunks are independent,
    so the results are the same as one at a time; JAX traces and compiles a program once
    even when several threads call it first. Finished chunks are reported to
    `report_progress` as `stage`, or to `progress` (a wrapper of the list of chunks, such
    as a progress bar, see `map_in_order`) if given.
    """
    bounds = [(i, min(i + chunk, n)) for i in range(0, n, chunk)]

    def ticks(items):  # results are collected in order: report each as it arrives
        for k, b in enumerate(items):
            if k:
                report(stage, k, len(bounds))
            yield b
        report(stage, len(bounds), len(bounds))

    if progress is None and _PROGRESS.get() is not None and len(bounds) > 1:
        progress = ticks
    parts = map_in_order(lambda b: jax.block_until_ready(fn(*b)), bounds, workers, progress)
    if len(parts) == 1:
        return parts[0]
    xp = np if to_host else jnp
    return jax.tree_util.tree_map(lambda *xs: xp.concatenate(xs), *parts)


def dispatch_size(n, max_chunk=MAX_DISPATCH, mesh=None):
    """Members per dispatch of `padded_map` for a batch of `n`: `bucket_size(n)`, at most
    `max_chunk`, rounded up to a multiple of the device count of `mesh`."""
    return round_to_devices(min(bucket_size(n), max_chunk), mesh)


def padded_map(
    fn, *args, max_chunk=MAX_DISPATCH, mesh=None, stage="batch", progress=None, to_host=False
):
    """`fn(*args)` for a batch of `n` members (the leading axis of the leaves of `args`),
    run in chunks of one padded size: the library's one padding rule.

    The size (`dispatch_size`) is the smallest power of two that holds the batch
    (`bucket_size`) or `max_chunk` if that is smaller, rounded up to a multiple of the
    device count of `mesh` (default: all local devices), so that batches of nearby sizes share one compiled program (tracing
    and compiling cost far more than running a few padding members). Each chunk is padded
    with copies of its first member (a valid input, so padding neither fails nor slows the
    chunk), split over the devices (`shard_batch`) and run, up to `host_workers` chunks
    at once (`in_chunks`, which reports each to `report_progress` as `stage`, or to
    `progress`).

    `fn` maps arrays with a leading axis of the chunk size to a pytree of arrays with the
    same leading axis (typically a jitted `vmap`).

    With several processes (`vhcjax._distributed`), each computes its contiguous share
    of the members and every process gets all of them (a traced batch, inside another
    program, is not split). Inside a trace (`jit`, `vmap`, a derivative) the batch is one
    call of `fn`: the trace is the caller's program, and host threads would leak it.

    **Returns:** the results of the `n` members, concatenated along the batch axis (numpy
    arrays with `to_host=True`: each chunk is fetched to the host and cut there).
    """
    n = jax.tree_util.tree_leaves(args)[0].shape[0]
    if tracing(args):
        return fn(*args)
    if _distributed.split_is_worth(n):
        i, j, s = _distributed.share(n)
        own = jax.tree_util.tree_map(
            lambda a: (
                np.concatenate([a[i:j], np.repeat(a[i:j][:1], s - (j - i), axis=0)])
                if j - i
                else np.repeat(a[:1], s, axis=0)
            ),
            jax.device_get(args),
        )
        # chunks sized for the share, one per core at least (the caller sized them for n)
        local = min(max_chunk, bucket_size(-(-s // host_workers(mesh))))
        out = _local_map(fn, own, s, local, mesh, stage, progress, True)
        return _distributed.gather(out, n, s, to_host)
    return _local_map(fn, args, n, max_chunk, mesh, stage, progress, to_host)


def _local_map(fn, args, n, max_chunk, mesh, stage, progress, to_host):
    """`padded_map` on this process's devices."""
    size = dispatch_size(n, max_chunk, mesh)

    def part(i, j):
        m = j - i

        def pad(a):
            if m == size == n:  # the whole batch in one chunk: nothing to cut
                return a
            # host arrays are cut and padded on the host: no small programs to compile
            xp = np if isinstance(a, np.ndarray) else jnp
            a = a[i:j] if xp is np else jnp.asarray(a[i:j])
            if m == size:
                return a
            return xp.concatenate([a, xp.repeat(a[:1], size - m, axis=0)])

        out = fn(*shard_batch(jax.tree_util.tree_map(pad, args), mesh))
        if to_host:
            out = jax.device_get(out)
        return out if m == size else jax.tree_util.tree_map(lambda x: x[:m], out)

    return in_chunks(part, n, size, host_workers(mesh), stage, progress, to_host)
