"""`report_progress`: a callback told of every finished chunk of a batched computation,
in order, on the calling thread; the results are those of a run without it."""

import threading

import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax._batching import in_chunks


@pytest.mark.parametrize("workers", [1, 2])
def test_chunks_reported_in_order_on_the_calling_thread(workers):
    calls, threads = [], set()

    def fn(i, j):
        return jnp.arange(i, j) ** 2

    def on_chunk(stage, done, total):
        calls.append((stage, done, total))
        threads.add(threading.get_ident())

    with vj.report_progress(on_chunk):
        out = in_chunks(fn, 10, 3, workers, stage="squares")
    assert calls == [("squares", k, 4) for k in (1, 2, 3, 4)]
    assert threads == {threading.get_ident()}
    np.testing.assert_array_equal(np.asarray(out), np.arange(10) ** 2)
    # outside the block nothing is reported
    in_chunks(fn, 10, 3, workers, stage="squares")
    assert len(calls) == 4
