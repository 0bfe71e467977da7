"""One process of a multi-process job (JAX's distributed runtime on localhost), for
`test_distributed.py`: `vhcjax atlas` with a checkpoint folder, then a sweep in Python;
writes what the command printed, the sweep's gaits and the number of batch members this
process computed to an `.npz` file.

    python _processes.py OUT CHECKPOINT [PORT NUM_PROCESSES PROCESS_ID]

Without the last three it runs alone (the reference)."""

import contextlib
import io
import sys

import numpy as np

from vhcjax import _batching
from vhcjax.cli import main

out, checkpoint, *job = sys.argv[1:]
members = [0]
_in_chunks = _batching.in_chunks


def counted(fn, n, *args, **kwargs):
    members[0] += n
    return _in_chunks(fn, n, *args, **kwargs)


_batching.in_chunks = counted
options = []
if job:
    port, num, pid = job
    options = ["--coordinator", f"localhost:{port}", "--num-processes", num, "--process-id", pid]
printed = io.StringIO()
with contextlib.redirect_stdout(printed):
    status = main(
        ["atlas", "--mass-ratio", "1.5,2.5", "--length-ratio", "1", "--slope-deg", "3"]
        + ["--scan-start-deg", "3", "--scan-step-deg", "1", "--json", "--quiet"]
        + ["--checkpoint", checkpoint]
        + options
    )
# the distributed runtime, if any, is up: the library splits its batches too
import vhcjax as vj  # noqa: E402

sw = vj.sweep(vj.CompassGait(), np.radians(np.linspace(2.0, 5.0, 16)), tangents=False)
np.savez(
    out,
    status=status,
    printed=printed.getvalue(),
    sweep_x=np.asarray(sw.gaits.x_plus),
    sweep_a=np.asarray(sw.gaits.a),
    sweep_ok=np.asarray(sw.ok),
    members=members[0],
)
