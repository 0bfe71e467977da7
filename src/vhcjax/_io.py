"""Output files that are either complete or absent: write to a temporary name beside the
target, rename at the end (`os.replace` is atomic on one file system)."""

import contextlib
import os
import shutil
import tempfile

#: Temporary files and folders being written now; removed by `remove_pending` (the
#: command line calls it when interrupted, so that no partial file is left behind).
PENDING: set[str] = set()


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
    """`open(path, mode)` that writes `path + ".partial"` and renames it to `path` only when
    the `with` block ends without an exception; on an exception the partial file is
    removed and `path` is untouched."""
    tmp = f"{path}.partial"
    PENDING.add(tmp)
    try:
        with open(tmp, mode, **kwargs) as fh:
            yield fh
        os.replace(tmp, path)
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


def save_figure(fig, path, **kwargs):
    """`fig.savefig` through `atomic_open` (the format from the suffix of `path`)."""
    fmt = os.path.splitext(path)[1].lstrip(".") or None
    with atomic_open(path, "wb") as fh:
        fig.savefig(fh, format=fmt, **kwargs)


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
