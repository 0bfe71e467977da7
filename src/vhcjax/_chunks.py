"""Results written in chunks as they finish, so that a long run that is stopped (Ctrl-C,
a killed job, a node lost) resumes from what is on disk.

A checkpoint folder holds `manifest.json` (the settings that determine the results) and
one CSV file per finished chunk (a header, then one row per result; floats written in
full precision, so a value read back is the value written; `pandas.read_csv` opens each).
Each chunk file is written under a temporary name and renamed when complete, so the
folder never holds a partial chunk under a chunk's name; a chunk file that is cut short
or altered anyway (a copy interrupted, a full disk) fails the checks of `load` and is
computed again. A folder whose manifest holds other settings is refused, not mixed.

With several processes (`vhcjax._distributed`) every process reads the folder (it must be
on a file system they all see), a chunk counts as finished only if every process could
read it, and only process 0 writes.
"""

import csv
import json
import os
import re

from ._distributed import agree, is_main
from ._io import atomic_open

MANIFEST = "manifest.json"


class CheckpointError(ValueError):
    """A checkpoint folder that cannot be used for this run (other settings, not a
    folder, unreadable manifest)."""


def fingerprint(tree, rounded=False):
    """A hex digest of a pytree (a model, a solver configuration, arrays): its structure,
    static fields included, and the values of its array leaves; for a manifest to tell
    whether a folder was written for the same inputs. `rounded`: floats to about 8
    significant digits (27 bits), for computed inputs such as gaits, which another
    process count or machine may give to other last bits."""
    import hashlib

    import jax
    import numpy as np

    leaves, treedef = jax.tree_util.tree_flatten(tree)
    # a static field's repr may hold an object's address, which changes every run
    h = hashlib.sha256(re.sub(r" at 0x[0-9a-fA-F]+", "", str(treedef)).encode())
    for x in leaves:
        a = np.asarray(x)
        if rounded and np.issubdtype(a.dtype, np.floating):
            m, e = np.frexp(a)
            a = np.ldexp(np.round(m * 2.0**27) / 2.0**27, e)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _canonical(settings):
    """`settings` as JSON would read them back (tuples as lists, floats exact)."""
    return json.loads(json.dumps(settings, allow_nan=True))


class ChunkStore:
    """The checkpoint folder `folder` of a run with `settings` (a JSON-ready dict): made
    if missing; a folder written with other settings raises `CheckpointError`."""

    def __init__(self, folder, settings):
        self.folder = os.fspath(folder)
        if os.path.exists(self.folder) and not os.path.isdir(self.folder):
            raise CheckpointError(f"checkpoint {self.folder!r} exists and is not a folder")
        try:
            os.makedirs(self.folder, exist_ok=True)
        except OSError as e:
            raise CheckpointError(f"checkpoint {self.folder!r}: {e.strerror}") from None
        settings = _canonical(settings)
        path = os.path.join(self.folder, MANIFEST)
        if os.path.exists(path):
            try:
                with open(path) as fh:
                    held = json.load(fh)
            except (OSError, ValueError) as e:
                msg = f"checkpoint {self.folder!r}: unreadable {MANIFEST} ({e})"
                raise CheckpointError(msg) from None
            if held != settings:
                changed = sorted(
                    k for k in set(held) | set(settings) if held.get(k) != settings.get(k)
                )
                raise CheckpointError(
                    f"checkpoint {self.folder!r} holds a run with other settings "
                    f"({', '.join(changed)}): give another folder, or remove it to start over"
                )
        elif is_main():
            with atomic_open(path, "w") as fh:
                json.dump(settings, fh, indent=1, allow_nan=True)

    def path(self, name):
        return os.path.join(self.folder, name)

    def load(self, name, columns, keys):
        """The rows (dicts of column -> float or str) of chunk `name`, or `None` if it is
        missing or fails a check (on any process): its header is `columns`, and it holds
        exactly one row per entry of `keys` (a list of dicts) whose key columns are those
        values."""
        rows = self._read(name, columns, keys)
        return rows if agree(rows is not None) else None

    def _read(self, name, columns, keys):
        try:
            with open(self.path(name), newline="") as fh:
                rows = list(csv.reader(fh))
        except (OSError, UnicodeDecodeError, csv.Error):
            return None
        if not rows or rows[0] != list(columns) or len(rows) != len(keys) + 1:
            return None
        out = []
        for row, key in zip(rows[1:], keys, strict=True):
            if len(row) != len(columns):
                return None
            rec = dict(zip(columns, row, strict=True))
            for k, v in key.items():
                try:
                    if float(rec[k]) != v:
                        return None
                except ValueError:
                    return None
            out.append(rec)
        return out

    def save(self, name, columns, rows):
        """Write chunk `name` (rows: dicts over `columns`; floats in full precision); only
        process 0 writes, and a failure to write stops every process."""
        error = None
        if is_main():
            try:
                with atomic_open(self.path(name), "w", newline="") as fh:
                    w = csv.writer(fh)
                    w.writerow(columns)
                    for r in rows:
                        w.writerow([_cell(r[c]) for c in columns])
            except OSError as e:
                error = e
        if not agree(error is None):
            if error is not None:
                raise error
            raise CheckpointError(f"checkpoint {self.folder!r}: process 0 could not write {name}")

    def rows(self, n, size, stem, columns, keys, compute, progress=None):
        """All `n` rows of a run, in parts of `size` rows (`[i, j)`, in order): each part
        read from the folder (`<stem>-<i>-<j>.csv`) if it holds it complete, else
        `compute(i, j)` (its rows, as dicts over `columns`) and written there. `keys(i,
        j)`: the key columns of the part's rows (see `load`); `progress` optionally wraps
        the list of parts (a progress bar)."""
        bounds = [(i, min(n, i + size)) for i in range(0, n, size)]
        out = []
        for i, j in progress(bounds) if progress is not None else bounds:
            name = f"{stem}-{i:09d}-{j:09d}.csv"
            part = self.load(name, columns, keys(i, j))
            if part is None:
                part = compute(i, j)
                self.save(name, columns, part)  # floats in `repr`: read back exactly
            out += part
        return out


def column(rows, name, kind=float):
    """Column `name` of `rows` (as read or computed) as a numpy array of `kind`."""
    import numpy as np

    return np.array([kind(float(r[name])) for r in rows])


def _cell(v):
    """A CSV field: a float (numpy's too) in full precision (`repr`), anything else as is."""
    return repr(float(v)) if isinstance(v, float) else v
