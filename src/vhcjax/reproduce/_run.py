"""`reproduce`: recompute thesis chapter 7 and the library's analyses, section by
section, and write the report."""

import os
import time
from typing import Any

from .._io import DISCARD, pending_folder
from ._report import Section, _write
from ._sections import SECTIONS, Run

# ---------------------------------------------------------------------------------------
# Sizes
# ---------------------------------------------------------------------------------------
SIZES: dict[str, dict[str, Any]] = {
    "quick": dict(
        sim_steps=24,
        dense=24,
        settle_rounds=3,
        sweep_n=8,
        sweep_range=(1.0, 6.0),
        bif_n=8,
        bif_range=(4.0, 5.4),
        bif_transient=40,
        bif_record=16,
        basin=(11, 11),
        basin_steps=30,
        basin_chunk=128,
        push_phases=4,
        push_angles=(0.0, 180.0),
        push_iterations=5,
        push_scan=4,
        pd_rounds=3,
    ),
    "full": dict(
        sim_steps=40,
        dense=60,
        settle_rounds=10,
        sweep_n=64,
        sweep_range=(0.5, 6.0),
        bif_n=64,
        bif_range=(3.5, 5.5),
        bif_transient=300,
        bif_record=64,
        basin=(101, 101),
        basin_steps=50,
        basin_chunk=1024,
        push_phases=20,
        push_angles=(0.0, 90.0, 180.0, 270.0),
        push_iterations=12,
        push_scan=8,
        pd_rounds=6,
    ),
}

#: Sections of the report (one progress-bar step each).
N_SECTIONS = len(SECTIONS)


def reproduce(out_dir, quick=False, progress=None, method="auto"):
    """Recompute thesis chapter 7 and the library's analyses; write figures,
    `report.md` and `results.json` to `out_dir`. `progress`: a tqdm-like bar (one
    `update(1)` per section). `method`: the gait search (`find_gaits`: `"auto"`, `"vhc"`
    or `"shooting"`); the report names the method that found each gait.
    **Returns:** the results dict."""
    if method not in ("auto", "vhc", "shooting"):
        raise ValueError(f"method must be 'auto', 'vhc' or 'shooting', got {method!r}")
    os.makedirs(out_dir, exist_ok=True)
    mode = "quick" if quick else "full"
    # Figures and report go to a private folder first and move into `out_dir` only when
    # every section has run: an interrupted run leaves `out_dir` as it was.
    with pending_folder(out_dir, ".reproduce-") as work:
        run = Run(work, SIZES[mode], method)
        t_start = time.perf_counter()
        sections = []
        for key, title, fn in SECTIONS:
            sec = Section(key, title)
            t0 = time.perf_counter()
            fn(run, sec)
            sec.seconds = time.perf_counter() - t0
            sections.append(sec)
            if progress is not None:
                progress.update(1)
        results = _write(work, sections, mode, time.perf_counter() - t_start)
        # the figures first, the report last: a report names only figures already there
        last = ("results.json", "report.md")
        names = sorted(set(os.listdir(work)) - set(last)) + list(last)
        if not DISCARD["on"]:  # a process other than 0 of a job writes nothing
            for name in names:
                os.replace(os.path.join(work, name), os.path.join(out_dir, name))
        return results
