"""Bifurcation diagrams in the style of Goswami et al. (1998): long batched simulations
from the period-1 gaits, the step periods of the last steps against slope, falls marked;
the step-period pattern (1, 2, 4, ... steps) read from them."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import MAX_DISPATCH, host_workers, padded_map
from .._chunks import ChunkStore, column, fingerprint
from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS, result_codes
from ..hybrid import FAST_CONFIG, simulate
from ..models import CompassGait  # the default model (thesis Table 1) where none is given


class BifurcationDiagram(eqx.Module):
    """Long simulations over slopes.

    - `psi` (B,): slopes (rad).
    - `periods` (B, num_record): step periods of the last `num_record` steps (NaN-free;
      zero after a fall).
    - `fell` (B,): the walker did not complete all steps.
    - `result` (B,): first failure code per slope.
    - `period_pattern` (B,): how often the recorded step periods repeat (to `period_tol`
      of the walker's time unit):
      1, 2, 4, ... steps per repetition, 0 if aperiodic (chaotic or not settled), -1 where it fell.
    """

    psi: np.ndarray
    periods: np.ndarray
    fell: np.ndarray
    result: np.ndarray
    period_pattern: np.ndarray


@stored_jit
def _long_runs(model, psis, x0s, num_steps, num_record, config):
    def one(p, x0):
        sim = simulate(model.with_slope(p), x0, num_steps, config=config)
        return sim.steps.period[-num_record:], sim.result

    return jax.vmap(one)(psis, x0s)


@host_only("vmap `simulate`")
def bifurcation_diagram(
    psis,
    zs,
    *,
    model=None,
    num_transient=300,
    num_record=64,
    perturbation=3e-5,
    period_tol=3e-5,
    config=FAST_CONFIG,
    chunk=None,
    mesh=None,
    checkpoint=None,
    chunk_slopes=256,
):
    """Simulate from the period-1 gaits `zs` at slopes `psis` (rad) for
    `num_transient + num_record` steps (batched with `vmap`) and keep the step periods
    of the last `num_record`.

    The start is the gait plus `perturbation` on $\\dot q_2$, in the walker's rate unit
    $1/T$ ($T$ = `model.time_scale`; the default is about 1e-4 rad/s for the thesis
    walker), so that unstable period-1 gaits (past the flip) leave towards the attractor.
    The period pattern compares step periods to `period_tol` $T$ (about 1e-5 s for the
    thesis walker): both are unit-free, so a rescaled walker gives the same diagram. Default tolerance: `FAST_CONFIG`
    (rtol = atol = 1e-8). `chunk`: largest batch of one call (default: 256 when the
    chunks run one per CPU core at a time, else the whole batch). The chunks are padded
    to a power of two (nearby sizes share one compiled program) and split over the devices
    of `mesh` (default: this process's devices).

    `checkpoint`: a folder, or `None`. Given one, the slopes run in parts of
    `chunk_slopes`, each written to the folder as a CSV file when it finishes (a row per
    slope: slope, result code, the recorded step periods); the same call again reads the
    finished parts and computes only the rest. A folder written for other inputs raises
    `ValueError`.
    """
    model = CompassGait() if model is None else model
    psis = np.asarray(psis, float).reshape(-1)
    zs = np.asarray(zs, float)
    if zs.ndim != 2 or len(zs) != len(psis):
        raise ValueError(
            f"bifurcation_diagram: one gait per slope: zs must have shape ({len(psis)}, n), "
            f"got {zs.shape}"
        )
    if int(num_transient) < 0 or int(num_record) < 2:  # one period shows no pattern
        raise ValueError(
            "bifurcation_diagram: num_transient must be at least 0 and num_record at least 2, "
            f"got {num_transient}, {num_record}"
        )
    x0s = np.stack(
        [np.asarray(model.with_slope(p).section_to_state(jnp.asarray(z))) for p, z in zip(psis, zs)]
    )
    time_unit = float(model.time_scale)
    x0s[:, -1] += perturbation / time_unit
    steps = num_transient + num_record

    def run(i, j):
        p, r = padded_map(
            lambda ps, xs: _long_runs(model, ps, xs, steps, num_record, config),
            psis[i:j],
            x0s[i:j],
            # chunks of up to 256 run one per CPU core; a GPU takes the whole batch at once
            max_chunk=chunk or (MAX_DISPATCH if host_workers(mesh) > 1 else j - i),
            mesh=mesh,
            stage="simulation",
        )
        return np.asarray(p), np.asarray(result_codes(r))

    if checkpoint is None:
        periods, codes = run(0, len(psis))
    else:
        if not (isinstance(chunk_slopes, int) and chunk_slopes >= 1):
            raise ValueError(f"chunk_slopes must be a positive integer, got {chunk_slopes!r}")
        store = ChunkStore(
            checkpoint,
            dict(
                kind="vhcjax.bifurcation",
                model=type(model).__name__,
                inputs=fingerprint((model, config)),
                gaits_digest=fingerprint(zs, rounded=True),
                slopes=len(psis),
                num_transient=int(num_transient),
                num_record=int(num_record),
                perturbation=float(perturbation),
                chunk_slopes=chunk_slopes,
            ),
        )
        recorded = [f"period{k}" for k in range(num_record)]

        def compute(i, j):
            p, c = run(i, j)
            return [
                dict(psi=psis[m], result=int(c[m - i]), **dict(zip(recorded, map(float, p[m - i]))))
                for m in range(i, j)
            ]

        rows = store.rows(
            len(psis),
            chunk_slopes,
            "slopes",
            ["psi", "result", *recorded],
            lambda i, j: [dict(psi=psis[m]) for m in range(i, j)],
            compute,
        )
        periods = np.stack([column(rows, c) for c in recorded], axis=-1)
        codes = column(rows, "result", int)
    fell = codes != int(result_codes(RESULTS.successful))
    tol = period_tol * time_unit
    nd = np.array([-1 if f else detect_period(pp, tol) for pp, f in zip(periods, fell)])
    return BifurcationDiagram(psis, periods, fell, codes, nd)


#: The periods (in steps) that `detect_period` looks for.
PERIOD_CANDIDATES = (1, 2, 4, 8, 16, 32)


def detect_period(periods, tol=1e-5, candidates=PERIOD_CANDIDATES):
    """Smallest p in `candidates` with `periods[i + p] == periods[i]` (within `tol` s)
    for all recorded i; 0 if none (aperiodic, e.g. chaotic, or not settled)."""
    periods = np.asarray(periods)
    for p in candidates:
        if p < len(periods) and np.max(np.abs(periods[p:] - periods[:-p])) < tol:
            return p
    return 0


def period_doubling_slopes_from_diagram(diagram):
    """Slopes (rad) where the detected step-period pattern (`detect_period`) first reaches
    2, 4, 8, ... (midpoints between neighbouring slopes), from a `BifurcationDiagram`: a
    simulation-only estimate of the cascade, as coarse as the slope grid."""
    per = np.asarray(diagram.period_pattern)
    out = []
    target = 2
    for i in range(1, len(per)):
        if per[i] >= target and 0 < per[i - 1] < target:
            out.append(0.5 * (diagram.psi[i - 1] + diagram.psi[i]))
            target *= 2
    return out
