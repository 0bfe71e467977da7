"""Outputs of the command line: written through symbolic links, to pipes, devices and
descriptors as they are (no temporary file and rename there), checked before the work
without ever blocking, in a format that can be written here; a write that fails (disk
full, file too large, permission lost midway) is one line naming the file, exit 1.

Most tests stop before any computation (the pre-checks) or call the writer alone; the
end-to-end ones run `vhcjax simulate` for a step or two.
"""

import errno
import json
import os
import stat
import subprocess
import sys
import threading
import time

import pytest

from vhcjax import _io
from vhcjax._io import WriteError, atomic_open, output_target
from vhcjax.cli import _common, main
from vhcjax.cli._common import CLIError, check_figure_file, check_output_file, second_figure

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")


def _read_pipe(r, into):
    """Read the pipe `r` to its end in a thread (a writer to it then never blocks)."""

    def run():
        with os.fdopen(r, "rb") as fh:
            into.append(fh.read())

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_a_link_is_written_through_and_kept(tmp_path):
    """A symbolic link (one, a chain, or one whose file is not there yet) stays a link;
    the file it points to gets the output and keeps its permissions; nothing else is
    left in either folder."""
    (tmp_path / "data").mkdir()
    target = tmp_path / "data" / "table.csv"
    target.write_text("stale")
    os.chmod(target, 0o640)
    (tmp_path / "link.csv").symlink_to(target)
    (tmp_path / "chain.csv").symlink_to(tmp_path / "link.csv")
    (tmp_path / "dangling.png").symlink_to(tmp_path / "data" / "new.png")
    for name in ("link.csv", "chain.csv"):
        with atomic_open(str(tmp_path / name)) as fh:
            fh.write(f"fresh through {name}")
        assert (tmp_path / name).is_symlink()
        assert target.read_text() == f"fresh through {name}"
        assert stat.S_IMODE(target.stat().st_mode) == 0o640
    with atomic_open(str(tmp_path / "dangling.png"), "wb") as fh:
        fh.write(b"png")
    assert (tmp_path / "dangling.png").is_symlink()
    assert (tmp_path / "data" / "new.png").read_bytes() == b"png"
    assert sorted(os.listdir(tmp_path)) == ["chain.csv", "dangling.png", "data", "link.csv"]
    assert sorted(os.listdir(tmp_path / "data")) == ["new.png", "table.csv"]


def test_pipes_devices_and_descriptors_are_written_directly(tmp_path):
    """A named pipe, `/dev/null`, and a descriptor of this process (`/dev/fd/N`, which
    bash's `>(...)` passes; `/proc/self/fd/N`) are written as they are: no temporary
    file beside them, no rename (there was `/dev/fd/63.partial`)."""
    fifo = str(tmp_path / "table.csv")
    os.mkfifo(fifo)
    assert output_target(fifo) == ("direct", fifo, None)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()), daemon=True)
    reader.start()
    with atomic_open(fifo) as fh:
        fh.write("through a named pipe")
    reader.join(10)
    assert got == [b"through a named pipe"]
    assert output_target("/dev/null") == ("direct", "/dev/null", None)
    with atomic_open("/dev/null") as fh:
        fh.write("nothing")
    for template in ("/dev/fd/{}", "/proc/self/fd/{}"):
        r, w = os.pipe()
        got = []
        reader = _read_pipe(r, got)
        path = template.format(w)
        assert output_target(path) == ("descriptor", path, w)
        with atomic_open(path, "wb") as fh:
            fh.write(b"through a descriptor")
        os.close(w)  # ours; the writer closed its own duplicate
        reader.join(10)
        assert got == [b"through a descriptor"]
    assert output_target("/dev/stdout").fd == 1
    assert sorted(os.listdir(tmp_path)) == ["table.csv"]


def test_checks_never_block_and_refuse_what_cannot_be_written(tmp_path):
    """The pre-checks open no pipe (a named pipe without a reader would block them) and
    leave nothing behind; a descriptor must be open for writing."""
    fifo = str(tmp_path / "figure.png")
    os.mkfifo(fifo)
    t0 = time.perf_counter()
    check_output_file(fifo, "--csv")
    check_figure_file(fifo, "--png")
    assert time.perf_counter() - t0 < 10.0
    r, w = os.pipe()
    check_figure_file(f"/dev/fd/{w}", "--png")  # no suffix: PNG, as the flag says
    with pytest.raises(CLIError, match="open for reading only"):
        check_output_file(f"/dev/fd/{r}", "--csv")
    os.close(r)
    os.close(w)
    with pytest.raises(CLIError, match="is not open"):
        check_output_file(f"/dev/fd/{w}", "--csv")
    dangling = tmp_path / "link.csv"
    dangling.symlink_to(tmp_path / "missing.csv")
    check_output_file(str(dangling), "--csv")
    assert dangling.is_symlink() and not (tmp_path / "missing.csv").exists()
    with pytest.raises(CLIError, match="does not exist"):
        (tmp_path / "away.csv").symlink_to(tmp_path / "no" / "such" / "folder.csv")
        check_output_file(str(tmp_path / "away.csv"), "--csv")
    assert sorted(os.listdir(tmp_path)) == ["away.csv", "figure.png", "link.csv"]


@pytest.fixture
def no_pgf(monkeypatch):
    """matplotlib lists `pgf` but cannot write it here (as without LaTeX), whether or
    not this machine has LaTeX."""
    monkeypatch.setitem(_common._FORMAT_PROBLEMS, "pgf", "'xelatex' not found")


def test_a_format_that_cannot_be_written_here_is_refused_before_work(tmp_path, capsys, no_pgf):
    cases = [
        ["sweep", "--slope-deg", "2:3:0.5", "--png"],
        ["multipliers", "--png"],
        ["bifurcation", "--slope-deg", "2:3:0.5", "--png-multipliers"],
        ["contraction", "--png"],
        ["slope-sensitivity", "--png"],
        ["stabilize", "--png"],
    ]
    for argv in cases:
        t0 = time.perf_counter()
        assert main([*argv, str(tmp_path / "figure.pgf")]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "cannot write pgf here" in err and argv[-1] in err, err
        assert time.perf_counter() - t0 < 15.0  # before any work
    assert os.listdir(tmp_path) == []


def test_the_format_probe_finds_what_matplotlib_cannot_write():
    """The probe itself: PNG and SVG are written here; a format whose writer fails (PGF
    without LaTeX) is reported with the writer's reason."""
    assert _common._format_problem("png") is None
    assert _common._format_problem("svg") is None
    import shutil

    if not (shutil.which("xelatex") or shutil.which("pdflatex") or shutil.which("lualatex")):
        assert "latex" in (_common._format_problem("pgf") or "").lower()


def test_one_naming_rule_for_a_second_figure(tmp_path, capsys):
    """A command that writes two figures from one `--png FILE` (slope-sensitivity) puts
    the second beside the first as STEM-NAME.EXT, in the same format; a pipe or device
    holds one figure, so it is refused unless the second is not written."""
    assert second_figure("out.svg", "slope", "--png") == "out-slope.svg"
    assert second_figure("run.3/out.v2.pdf", "slope", "--png") == "run.3/out.v2-slope.pdf"
    with pytest.raises(CLIError, match="takes one figure"):
        second_figure("/dev/stdout", "slope", "--png")
    (tmp_path / "out-slope.svg").mkdir()  # the second figure's place is taken
    assert main(["slope-sensitivity", "--png", str(tmp_path / "out.svg")]) == 2
    err = capsys.readouterr().err
    assert "out-slope.svg" in err and "is a directory" in err
    assert main(["slope-sensitivity", "--png", "/dev/stdout"]) == 2
    assert "takes one figure" in capsys.readouterr().err


def _simulate(tmp_path, *argv):
    return main(["simulate", "--steps", "2", "--quiet", *argv])


def test_simulate_writes_through_links_and_to_a_descriptor(tmp_path, capsys):
    """End to end: `--plots DIR` whose figures are links, and `--animate` to a pipe
    given as `/dev/fd/N` (bash's `--animate >(cat > walk.gif)`): the links stay and
    their files get the figures; the pipe gets the GIF."""
    plots = tmp_path / "plots"
    plots.mkdir()
    (tmp_path / "kept").mkdir()
    for name in ("states.png", "phase.png", "periods.png"):
        (plots / name).symlink_to(tmp_path / "kept" / name)
    r, w = os.pipe()
    got = []
    reader = _read_pipe(r, got)
    assert _simulate(tmp_path, "--json", "--plots", str(plots), "--animate", f"/dev/fd/{w}") == 0
    os.close(w)
    reader.join(30)
    assert got and got[0][:6] == b"GIF89a"
    assert json.loads(capsys.readouterr().out)["result"] == "successful"
    for name in ("states.png", "phase.png", "periods.png"):
        assert (plots / name).is_symlink()
        assert (tmp_path / "kept" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(os.listdir(plots)) == ["periods.png", "phase.png", "states.png"]


def test_a_full_disk_is_one_line_naming_the_file(tmp_path, capsys):
    """`/dev/full` behind the output's name: exit 1, one line naming the file as given,
    no "internal error", nothing partial left."""
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    gif = tmp_path / "walk.gif"
    gif.symlink_to("/dev/full")
    assert _simulate(tmp_path, "--animate", str(gif)) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"vhcjax simulate: cannot write {str(gif)!r}: No space left on device"
    assert os.listdir(tmp_path) == ["walk.gif"]


def test_permission_lost_midway_is_one_line_naming_the_file(tmp_path, monkeypatch):
    """Permission taken away between the pre-check and the rename (simulated: as root a
    folder's mode does not stop a write): `WriteError` naming the output, no partial."""
    real_replace = os.replace

    def refused(src, dst):
        raise PermissionError(errno.EACCES, "Permission denied", src, dst)

    monkeypatch.setattr(_io.os, "replace", refused)
    out = tmp_path / "table.csv"
    with pytest.raises(WriteError) as err:
        with atomic_open(str(out)) as fh:
            fh.write("rows")
    assert err.value.filename == str(out) and err.value.errno == errno.EACCES
    monkeypatch.setattr(_io.os, "replace", real_replace)
    assert os.listdir(tmp_path) == []
    # an error of another file raised inside the block is not relabelled
    with pytest.raises(FileNotFoundError) as other:
        with atomic_open(str(out)):
            open(tmp_path / "no" / "such")
    assert not isinstance(other.value, WriteError)
    assert os.listdir(tmp_path) == []


SCRIPT = """
import os, resource, sys
from vhcjax.cli import _simulate, main

real = _simulate.atomic_open

def limited(*args, **kwargs):  # `ulimit -f 8` for the output alone (not the JAX cache)
    resource.setrlimit(resource.RLIMIT_FSIZE, (8192, resource.RLIM_INFINITY))
    return real(*args, **kwargs)

_simulate.atomic_open = limited
sys.exit(main(["simulate", "--steps", "2", "--quiet", "--animate", sys.argv[1]]))
"""


def test_a_file_too_large_is_one_line_naming_the_file(tmp_path):
    """`ulimit -f` while the GIF is written: the kernel refuses the write (EFBIG; Python
    ignores SIGXFSZ): exit 1, one line naming the file, no partial file left."""
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    gif = str(tmp_path / "walk.gif")
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, gif], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip() == f"vhcjax simulate: cannot write {gif!r}: File too large"
    assert os.listdir(tmp_path) == []


class _Closed:
    """A standard output that cannot be written."""

    def __init__(self, code):
        self.code = code

    def write(self, text):
        raise OSError(self.code, os.strerror(self.code))

    def flush(self):
        pass


@pytest.mark.parametrize("code, status", [(errno.ENOSPC, 1), (errno.EPIPE, 141)])
def test_standard_output_that_cannot_be_written(monkeypatch, capsys, code, status):
    """`> /dev/full`: one line, exit 1; a closed pipe (`| head`): no line, exit 141."""
    monkeypatch.setattr(sys, "stdout", _Closed(code))
    assert main(["simulate", "--steps", "2", "--quiet", "--json"]) == status
    err = capsys.readouterr().err.strip()
    if status == 141:
        assert err == ""
    else:
        assert err == "vhcjax simulate: cannot write standard output: No space left on device"
