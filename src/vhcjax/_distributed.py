"""Several processes (JAX's distributed runtime): every batch split between them.

After `jax.distributed.initialize()` on every process of a job (SLURM's `srun`, Open
MPI's `mpirun`, or explicit coordinator, process count and process index), every process
runs the same program. Each batched computation of the library (`_batching.padded_map`:
gait searches, tangents, multipliers, simulations, basins) computes only this process's
contiguous share of the members on its own devices, and the shares are then gathered
(`jax.experimental.multihost_utils.process_allgather`, over the runtime's collectives:
Gloo on CPUs), so that every process holds the whole result and the host-side logic
around it (continuations, retries, scans, bisections) goes on identically everywhere.
With one process nothing changes.
"""

import os

import jax
import numpy as np


def process_count():
    """How many processes run this program (1 without the distributed runtime)."""
    return jax.process_count()


def is_main():
    """Whether this is the process that prints and writes outputs (process 0)."""
    return jax.process_index() == 0


def share(n):
    """This process's members `[i, j)` of a batch of `n` and the share size `s` (the
    largest share: process `p` holds `[p s, min((p + 1) s, n))`)."""
    s = -(-n // jax.process_count())
    i = min(n, jax.process_index() * s)
    return i, min(n, i + s), s


def gather(tree, n, size, to_host):
    """The results of all processes' shares (`tree`: this process's, padded to `size`
    members) as one batch of `n`, on every process."""
    from jax.experimental import multihost_utils

    out = multihost_utils.process_allgather(jax.device_get(tree), tiled=False)

    def cut(x):
        x = np.asarray(x)
        x = x.reshape((x.shape[0] * x.shape[1],) + x.shape[2:])[:n]
        return x if to_host else jax.numpy.asarray(x)

    return jax.tree_util.tree_map(cut, out)


def agree(flag):
    """Whether `flag` holds on every process (a host-side decision all of them must make
    alike, e.g. that a checkpoint chunk can be read everywhere)."""
    if jax.process_count() == 1:
        return bool(flag)
    from jax.experimental import multihost_utils

    flags = multihost_utils.process_allgather(np.asarray(bool(flag)))
    return bool(np.all(flags))


#: Environment variables by which a launcher says that a job has several processes.
#: (SLURM's count of the job step's tasks: a batch script itself is a step of one task,
#: so only a command started by `srun` counts.) JAX's `jax.distributed.initialize`
#: detects both launchers.
LAUNCHERS = {"SLURM_STEP_NUM_TASKS": "SLURM", "OMPI_COMM_WORLD_SIZE": "Open MPI"}


def launched_processes():
    """The number of processes a launcher started this job with (1 if none did)."""
    for var in LAUNCHERS:
        v = os.environ.get(var, "").strip()
        if v.isdigit() and int(v) > 1:
            return int(v)
    return 1


def initialize(coordinator=None, num_processes=None, process_id=None):
    """Join a multi-process job: `jax.distributed.initialize` with the coordinator
    (`"host:port"`), the process count and this process's index, or with what the
    launcher says (SLURM, Open MPI, ...) for those not given. Call it before any other
    JAX work. Does nothing for a job of one process."""
    given = (coordinator, num_processes, process_id)
    if all(v is None for v in given) and launched_processes() == 1:
        return
    if num_processes is not None and not (isinstance(num_processes, int) and num_processes >= 1):
        raise ValueError(f"num_processes must be a positive integer, got {num_processes!r}")
    if process_id is not None and num_processes is not None:
        if not (isinstance(process_id, int) and 0 <= process_id < num_processes):
            raise ValueError(f"process_id must be in 0..{num_processes - 1}, got {process_id!r}")
    if num_processes == 1 or jax.distributed.is_initialized():
        return
    jax.distributed.initialize(
        coordinator_address=coordinator, num_processes=num_processes, process_id=process_id
    )
    connect()


#: The fewest CPU cores of any process of the job (`connect`), or `None` before.
COMMON: dict[str, int | None] = {"cores": None}


def local_cores():
    """The CPU cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def common_cores():
    """The fewest CPU cores of any process of the job (this process's alone without the
    distributed runtime): every process then cuts its batches alike, and makes the same
    decisions and collective calls."""
    if jax.process_count() == 1 or COMMON["cores"] is None:
        return local_cores() or 1
    return COMMON["cores"]


def connect():
    """Open the connections between the processes now, with the collective library's
    note on them ("[Gloo] Rank 0 is connected to 1 peer ranks...", which it prints to
    standard output) sent to standard error, so that standard output holds only what a
    command prints (its JSON, say); and agree on the core count (`common_cores`)."""
    import sys

    from jax.experimental import multihost_utils

    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        cores = multihost_utils.process_allgather(np.asarray(local_cores() or 1))
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    COMMON["cores"] = int(np.min(cores))


def split_is_worth(n):
    """Whether a batch of `n` members is split between the processes: when each gets at
    least one (a smaller batch is computed by every process alike)."""
    return jax.process_count() > 1 and n >= jax.process_count()
