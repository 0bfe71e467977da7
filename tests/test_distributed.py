"""Several processes on JAX's distributed runtime (localhost, CPU devices, Gloo): the
same results as one process, each process computing half of every batch, outputs
written by process 0 only."""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))


def _free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _run(tmp_path, name, *job):
    env = dict(os.environ, VHCJAX_HOST_WORKERS="1")
    env.pop("XLA_FLAGS", None)
    cmd = [sys.executable, os.path.join(HERE, "_processes.py"), str(tmp_path / f"{name}.npz")]
    cmd += [str(tmp_path / f"ck-{name}"), *job]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE)


def test_two_processes_give_the_one_process_results_with_half_the_work_each(tmp_path):
    port = str(_free_port())
    procs = [_run(tmp_path, f"p{i}", port, "2", str(i)) for i in range(2)]
    procs.append(_run(tmp_path, "one"))
    # nothing on the processes' own standard output (the collective library's note on
    # its connections goes to standard error)
    assert [p.communicate(timeout=900)[0] for p in procs] == [b"", b"", b""]
    assert [p.returncode for p in procs] == [0, 0, 0]
    one, p0, p1 = (np.load(tmp_path / f"{n}.npz") for n in ("one", "p0", "p1"))
    assert int(one["status"]) == int(p0["status"]) == int(p1["status"]) == 0
    # the command's output: from process 0 only, equal to the one-process output
    assert str(p1["printed"]) == ""
    atlas_one, atlas_two = json.loads(str(one["printed"])), json.loads(str(p0["printed"]))
    cells_one, cells_two = atlas_one.pop("cells"), atlas_two.pop("cells")
    assert atlas_one == atlas_two and len(cells_one) == len(cells_two) == 2
    for a, b in zip(cells_one, cells_two, strict=True):
        assert a.keys() == b.keys() and a.get("reason") == b.get("reason")
        np.testing.assert_allclose(
            [a["flip_slope_deg"], *a["stable_range_deg"], a["spectral_radius"]],
            [b["flip_slope_deg"], *b["stable_range_deg"], b["spectral_radius"]],
            rtol=0,
            atol=1e-12,
        )
    # the checkpoint: written once, by process 0, into the folder it was given
    assert sorted(os.listdir(tmp_path / "ck-p0")) == sorted(os.listdir(tmp_path / "ck-one"))
    assert sorted(os.listdir(tmp_path / "ck-p1")) == []
    # the sweep in Python: every process holds the whole, equal to one process's
    assert one["sweep_ok"].all()
    for p in (p0, p1):
        np.testing.assert_array_equal(p["sweep_ok"], one["sweep_ok"])
        for k in ("sweep_x", "sweep_a"):
            np.testing.assert_allclose(p[k], one[k], rtol=0, atol=1e-12)
    # half of the batch members each (a batch smaller than the process count runs on
    # both, and each share is padded alike)
    n_one, n0, n1 = int(one["members"]), int(p0["members"]), int(p1["members"])
    assert n0 == n1
    assert abs(n0 / n_one - 0.5) < 0.1, (n_one, n0, n1)


@pytest.mark.parametrize(
    "options, words",
    [
        (["--coordinator", "localhost:1"], "together"),
        (["--num-processes", "2", "--process-id", "0"], "together"),
        (["--coordinator", "localhost:1", "--num-processes", "2", "--process-id", "2"], "below"),
        (["--num-processes", "0"], "must be in [1,"),
        (["--process-id", "-1"], "--process-id"),
    ],
)
def test_process_options_without_a_launcher_are_checked_in_one_line(options, words, capsys):
    from vhcjax.cli import main

    assert main(["gait", "--slope-deg", "3", *options]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
