"""Output files that are either complete or absent, written where their name points.

A regular file (or a name not taken yet) is written to a temporary name beside it and
renamed over it at the end (`os.replace` is atomic on one file system). A symbolic link
is followed: the file it points to is replaced, the link stays. A pipe, a device
(`/dev/null`) or an open descriptor of this process (`/dev/stdout`, bash's `>(...)`,
which names `/dev/fd/N`) cannot be renamed over and is written directly. A write that
fails (disk full, file too large, permission lost midway) raises `WriteError`, which
names the output as it was given."""

import contextlib
import os
import re
import shutil
import stat
import sys
import tempfile
from typing import NamedTuple, NoReturn

#: Temporary files and folders being written now; removed by `remove_pending` (the
#: command line calls it when interrupted, so that no partial file is left behind).
PENDING: set[str] = set()

#: `{"on": True}` in a process that computes but must not write (a process other than 0
#: of a multi-process command): outputs then go to `os.devnull`.
DISCARD = {"on": False}


class WriteError(OSError):
    """Writing an output failed: an `OSError` (same `errno` and `strerror`) whose
    `filename` is the output's path as given, not a temporary name."""


#: The folder of a process's open descriptors: `/dev/fd`, `/proc/self/fd`, resolved.
_FD_FOLDER = re.compile(r"/proc/([0-9]+)(?:/task/[0-9]+)?/fd")


def descriptor(path):
    """The open descriptor of this process that `path` names (`/dev/stdout`, `/dev/fd/3`,
    `/proc/self/fd/3`), else `None`. Symbolic links are followed one at a time: the last
    one, `/proc/<pid>/fd/N`, points to the open file itself, which may have no name."""
    p = os.path.abspath(path)
    for _ in range(40):  # the kernel's limit on links in one path
        head, name = os.path.split(p)
        head = os.path.realpath(head)
        m = _FD_FOLDER.fullmatch(head)
        if m and int(m[1]) == os.getpid() and name.isascii() and name.isdigit():
            return int(name)
        full = os.path.join(head, name)
        if not os.path.islink(full):
            return None
        p = os.path.join(head, os.readlink(full))
    return None


class Target(NamedTuple):
    """How an output is written (`output_target`)."""

    how: str  # "descriptor", "direct" or "replace"
    path: str  # what is opened: the regular file itself for "replace"
    fd: int | None = None  # the descriptor, for "descriptor"


def output_target(path):
    """How `path` is written: `"descriptor"` (`fd`) for an open descriptor of this
    process; `"direct"` for an existing file that is not a regular file (a pipe, a
    device, a socket); else `"replace"`, `path` then being the regular file (existing
    or not) that `path` names once symbolic links are followed."""
    fd = descriptor(path)
    if fd is not None:
        return Target("descriptor", path, fd)
    real = os.path.realpath(path)
    try:
        mode = os.stat(real).st_mode
    except OSError:  # not there yet (or not reachable: the open says why)
        return Target("replace", real)
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return Target("replace", real)
    return Target("direct", path)


def _raise_named(err, path, *own) -> NoReturn:
    """Raise `err` as a `WriteError` naming `path` when it comes from writing `path` (no
    file name, or one of the names in `own`); any other error as it is."""
    if isinstance(err, WriteError) or (err.filename is not None and err.filename not in own):
        raise err
    raise WriteError(err.errno, err.strerror or str(err), path) from err


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
    """`open(path, mode)` for an output (see the module docstring): a regular file is
    written as `<file>.partial<suffix>` beside it (the suffix kept for writers that read
    the format from the name) and renamed to the file only when the `with` block ends
    without an exception, keeping the permissions of the file it replaces; on an
    exception the partial file is removed and the file is untouched. A pipe, a device or
    a descriptor is written directly. With `DISCARD` on, nothing is written."""
    if DISCARD["on"]:
        with open(os.devnull, mode, **kwargs) as fh:
            yield fh
        return
    how, where, fd = output_target(path)
    if fd is not None:
        for stream in (sys.stdout, sys.stderr):  # what was printed comes first
            stream.flush()
        try:
            with open(os.dup(fd), mode, **kwargs) as fh:
                yield fh
        except OSError as e:
            _raise_named(e, path)
        return
    if how == "direct":
        try:
            with open(where, mode, **kwargs) as fh:
                yield fh
        except OSError as e:
            _raise_named(e, path, where)
        return
    tmp = f"{where}.partial{os.path.splitext(path)[1]}"
    PENDING.add(tmp)
    try:
        with open(tmp, mode, **kwargs) as fh:
            yield fh
        if os.path.exists(where):
            shutil.copymode(where, tmp)
        os.replace(tmp, where)
    except OSError as e:
        _raise_named(e, path, where, tmp)
    finally:
        PENDING.discard(tmp)
        if os.path.exists(tmp):
            os.remove(tmp)


@contextlib.contextmanager
def pending_folder(parent, prefix=".partial-"):
    """A new hidden folder in `parent` for files that are not complete yet (the caller
    moves them out when they are); removed with what is left in it when the block ends,
    or by `remove_pending` after an interrupt."""
    folder = tempfile.mkdtemp(prefix=prefix, dir=parent)
    PENDING.add(folder)
    try:
        yield folder
    finally:
        PENDING.discard(folder)
        shutil.rmtree(folder, ignore_errors=True)


def remove_pending():
    """Remove every partial file and folder still being written (after an interrupt)."""
    for tmp in list(PENDING):
        if os.path.isdir(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
            continue
        try:
            os.remove(tmp)
        except OSError:
            pass
