"""Region of attraction of a gait: 2-D slices of post-impact perturbations, the largest
perturbation that still converges along each axis, and a Monte-Carlo estimate of the basin
volume in the full section.

Perturbations are taken in section coordinates (compass gait: $z = (q_1, \\dot q_1,
\\dot q_2)$ with $q_2 = -q_1 - 2\\psi$), so every initial state is a genuine post-impact
state on the impact surface. Each point is simulated step by step
(`vhcjax.robustness.recover`) and labelled converged (with steps to converge), fell (with
the failure code), other cycle or undecided. Batches run in chunks of at most `chunk`
points (bounded memory; a chunk stops as soon as all its members are decided).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import MAX_DISPATCH, host_workers, padded_map
from .._chunks import ChunkStore, column, fingerprint
from .._host import host_only
from .._programs import stored_jit
from .._results import result_codes
from ..hybrid import FAST_CONFIG, in_walker_units, section_rates
from ._bisection import bisect_threshold
from ._gait_check import require_gait
from ._recovery import CONVERGED, recover_padded, step_capacity

BASIN_CONFIG = FAST_CONFIG
"""Swing integration used for basin maps: Tsit5, rtol = atol = 1e-8 (`FAST_CONFIG`)."""


def _recover_chunk(model, z, z_star, num_steps, tol, config):
    """The fate of each point: the summary only (not the per-step distances)."""
    capacity = step_capacity(num_steps)
    return _recover_summary(model, z, z_star, np.int64(num_steps), capacity, tol, config)


@stored_jit
def _recover_summary(model, z, z_star, count, capacity, tol, config):
    x0 = jax.vmap(model.section_to_state)(z)
    x_star = model.section_to_state(z_star)
    rec = recover_padded(model, x0, x_star, count, capacity, tol=tol, config=config)
    return {
        "label": rec.label,
        "steps": rec.steps,
        "period": rec.period,
        "result": result_codes(rec.result),
        "z_final": jax.vmap(model.state_to_section)(rec.x_final),
    }


def classify_section_points(
    model,
    z_star,
    z,
    *,
    num_steps=50,
    tol=1e-4,
    chunk=1024,
    config=BASIN_CONFIG,
    progress=None,
    mesh=None,
    checkpoint=None,
    chunk_points=4096,
):
    """Classify section points `z` (shape `(N, 2n-1)`) by their fate.

    The points run in chunks of at most `chunk` (`_batching.padded_map`: padded to a
    power of two and a multiple of the device count, split over the devices of `mesh`,
    default this process's devices, so the same call uses every GPU of a machine, and
    each process its share after `jax.distributed.initialize()`; on a CPU one chunk per
    core at a time, of at most `_batching.MAX_DISPATCH` points).
    `progress` optionally wraps the list of chunks (a progress bar).

    `checkpoint`: a folder, or `None`. Given one, the points run in parts of
    `chunk_points`, each written to the folder as a CSV file when it finishes (a row per
    point: its index, start and final section coordinates, label, steps, period, result
    code); the same call again reads the finished parts and computes only the rest. A
    folder written for other inputs raises `ValueError`.

    **Returns:** dict of numpy arrays: `label`, `steps`, `period`, `result` (integer
    `RESULTS` codes), `z_final`.
    """
    if checkpoint is not None:
        return _classify_in_chunks(
            model,
            z_star,
            z,
            num_steps,
            tol,
            chunk,
            config,
            progress,
            mesh,
            checkpoint,
            chunk_points,
        )
    z_star = jnp.asarray(z_star, float)
    if host_workers(mesh) > 1:
        # Chunks run concurrently on a CPU, and two concurrent dispatches of this program
        # with 1,024 members each deadlock XLA's CPU runtime (every thread idle).
        chunk = min(chunk, MAX_DISPATCH)
    rec = padded_map(
        lambda part: _recover_chunk(model, part, z_star, num_steps, tol, config),
        np.asarray(z, dtype=float),
        max_chunk=chunk,
        mesh=mesh,
        stage="basin",
        progress=progress,
    )
    return {k: np.asarray(v) for k, v in jax.device_get(rec).items()}


def _classify_in_chunks(
    model, z_star, z, num_steps, tol, chunk, config, progress, mesh, checkpoint, chunk_points
):
    """`classify_section_points` in parts of `chunk_points`, each read from the
    checkpoint folder if it holds it complete, else computed and written there."""
    if not (isinstance(chunk_points, int) and chunk_points >= 1):
        raise ValueError(f"chunk_points must be a positive integer, got {chunk_points!r}")
    z = np.asarray(z, dtype=float)
    z_star = np.asarray(z_star, dtype=float)
    n, k = z.shape
    store = ChunkStore(
        checkpoint,
        dict(
            kind="vhcjax.basin",
            model=type(model).__name__,
            inputs=fingerprint((model, config)),
            points_digest=fingerprint((z_star, z), rounded=True),
            points=n,
            num_steps=int(num_steps),
            tol=float(tol),
            chunk_points=chunk_points,
        ),
    )
    start = [f"z{i}" for i in range(k)]
    final = [f"z_final{i}" for i in range(k)]

    def keys(i, j):
        return [dict(index=float(m)) for m in range(i, j)]

    def compute(i, j):
        out = classify_section_points(
            model,
            z_star,
            z[i:j],
            num_steps=num_steps,
            tol=tol,
            chunk=chunk,
            config=config,
            mesh=mesh,
        )
        ints = {c: out[c].astype(int) for c in ("label", "steps", "result")}
        return [
            dict(
                index=i + m,
                **dict(zip(start, map(float, z[i + m]), strict=True)),
                period=float(out["period"][m]),
                **{c: int(v[m]) for c, v in ints.items()},
                **dict(zip(final, map(float, out["z_final"][m]), strict=True)),
            )
            for m in range(j - i)
        ]

    columns = ["index", *start, "label", "steps", "period", "result", *final]
    rows = store.rows(n, chunk_points, "points", columns, keys, compute, progress)
    return {
        "label": column(rows, "label", int),
        "steps": column(rows, "steps", int),
        "period": column(rows, "period"),
        "result": column(rows, "result", int),
        "z_final": np.stack([column(rows, c) for c in final], axis=-1),
    }


class BasinSlice(eqx.Module):
    """A 2-D slice of the basin of attraction (numpy arrays).

    - `axes`: the two perturbed section coordinates (indices into `z`).
    - `offsets_x`, `offsets_y`: perturbations along `axes[0]` and `axes[1]` (grid lines).
    - `z_star`: the gait.
    - `label`: shape `(len(offsets_y), len(offsets_x))`, `vhcjax.CONVERGED`, ... per point.
    - `steps`: steps to converge (-1 if it did not); for fallers, the step they fell on.
    - `result`: integer `RESULTS` code per point (the failure for fallers).
    - `area`: area of the converging set in the slice (product of the axes' units).
    - `fraction`: fraction of the slice's points that converge.
    - `max_converging`: dict `{"+x", "-x", "+y", "-y"}` -> the largest offset along the
      grid line through the gait up to which every grid point converges.
    - `num_steps`, `tol`: the classification settings.
    """

    axes: tuple[int, int] = eqx.field(static=True)
    offsets_x: np.ndarray
    offsets_y: np.ndarray
    z_star: np.ndarray
    label: np.ndarray
    steps: np.ndarray
    result: np.ndarray
    area: float
    fraction: float
    max_converging: dict
    num_steps: int = eqx.field(static=True)
    tol: float = eqx.field(static=True)


def _reach(ok_line, offsets, sign):
    """Largest |offset| on one side of 0 up to which every grid point converges."""
    idx = np.where(sign * offsets >= 0)[0]
    idx = idx[np.argsort(np.abs(offsets[idx]))]
    best = 0.0
    for i in idx:
        if not ok_line[i]:
            break
        best = abs(offsets[i])
    return best


@host_only("vmap `recover`")
def basin_slice(
    model,
    z_star,
    *,
    axes=(0, 1),
    half_widths=None,
    shape=(200, 200),
    num_steps=50,
    tol=1e-4,
    chunk=1024,
    config=BASIN_CONFIG,
    progress=None,
    mesh=None,
    checkpoint=None,
):
    """Classify a `shape = (nx, ny)` grid of perturbations of `z_star` along two section
    coordinates (`axes`), the others nominal.

    **Arguments:**

    - `model`, `z_star`: the walker and its gait (section coordinates).
    - `axes`: the two perturbed coordinates, e.g. `(0, 1)` for $(q_1, \\dot q_1)$.
    - `half_widths`: the grid spans `z_star[axes[i]] +- half_widths[i]` (rad, rad/s).
      Default: 0.1 rad on an angle and 0.4 rad/s on a rate for the thesis walker, in the
      same proportion to another walker's time unit (`vhcjax.in_walker_units`). Grids with an
      odd number of points contain the gait itself (one point: the gait's coordinate).
    - `shape`: grid points along each axis (200 x 200 by default).
    - `num_steps`: steps simulated per point (at most).
    - `tol`: converged when the post-impact state is within `tol` ($\\infty$-norm) of the
      gait.
    - `chunk`: batch size of one compiled call.
    - `config`: swing integration (default `BASIN_CONFIG`, tolerances 1e-8).
    - `progress`: optional wrapper of an iterable (progress bar over chunks).
    - `checkpoint`: a folder, or `None`: the points are written there in parts of 4,096
      as they finish (CSV files), and the same call again computes only the missing
      parts; a folder written for other inputs raises `ValueError`.

    **Returns:** a `BasinSlice`. A `z_star` that one step does not return to
    (`GAIT_TOL`) raises a `ValueError`.
    """
    z_star = np.asarray(z_star, dtype=float)
    nx, ny = shape
    if len(set(axes)) != 2 or not all(0 <= a < z_star.shape[0] for a in axes):
        raise ValueError(f"basin_slice: axes must be two distinct section coordinates, got {axes}")
    if half_widths is None:
        default = in_walker_units(model, np.where(section_rates(model), 0.4, 0.1), "section")
        half_widths = tuple(float(np.asarray(default)[a]) for a in axes)
    hw = np.asarray(half_widths, float)
    if hw.shape != (2,) or not (np.isfinite(hw).all() and (hw > 0).all()):
        raise ValueError(
            f"basin_slice: half_widths must be two finite positive numbers, got {half_widths}"
        )
    if int(nx) < 1 or int(ny) < 1:
        raise ValueError(f"basin_slice: shape must be two positive integers, got {shape}")
    if int(num_steps) < 1:
        raise ValueError(f"basin_slice: num_steps must be at least 1, got {num_steps}")
    require_gait(model, z_star, "basin_slice")
    ox = np.linspace(-hw[0], hw[0], nx) if nx > 1 else np.zeros(1)
    oy = np.linspace(-hw[1], hw[1], ny) if ny > 1 else np.zeros(1)
    gx, gy = np.meshgrid(ox, oy)  # (ny, nx)
    z = np.repeat(z_star[None], gx.size, 0)
    z[:, axes[0]] += gx.ravel()
    z[:, axes[1]] += gy.ravel()
    out = classify_section_points(
        model,
        z_star,
        z,
        num_steps=num_steps,
        tol=tol,
        chunk=chunk,
        config=config,
        progress=progress,
        mesh=mesh,
        checkpoint=checkpoint,
    )
    label = out["label"].reshape(ny, nx)
    conv = label == CONVERGED
    cell = (ox[1] - ox[0]) * (oy[1] - oy[0]) if nx > 1 and ny > 1 else 0.0
    iy0, ix0 = int(np.argmin(np.abs(oy))), int(np.argmin(np.abs(ox)))
    reach = {
        "+x": _reach(conv[iy0, :], ox, +1),
        "-x": _reach(conv[iy0, :], ox, -1),
        "+y": _reach(conv[:, ix0], oy, +1),
        "-y": _reach(conv[:, ix0], oy, -1),
    }
    return BasinSlice(
        axes=tuple(axes),
        offsets_x=ox,
        offsets_y=oy,
        z_star=z_star,
        label=label,
        steps=out["steps"].reshape(ny, nx),
        result=out["result"].reshape(ny, nx),
        area=float(conv.sum() * cell),
        fraction=float(conv.mean()),
        max_converging=reach,
        num_steps=num_steps,
        tol=tol,
    )


@host_only("vmap `recover`")
def max_converging_perturbation(
    model,
    z_star,
    directions,
    r_max,
    *,
    iterations=16,
    num_steps=50,
    tol=1e-4,
    scan=16,
    config=BASIN_CONFIG,
    progress=None,
):
    """Largest perturbation $r$ along each unit direction (rows of `directions`, section coordinates)
    for which $z^* + r d$ still converges to the gait, by batched bisection on
    $[0, r_{max}]$.

    **Returns:** a `vhcjax.Threshold` (per direction: `lo` converges, `hi` does not).
    """
    z_star = jnp.asarray(z_star, dtype=float)
    d = jnp.asarray(directions, dtype=float)

    def survives(r):
        z = z_star[None] + r[:, None] * d
        rec = _recover_chunk(model, z, z_star, num_steps, tol, config)
        return rec["label"] == CONVERGED

    return bisect_threshold(
        survives,
        np.zeros(d.shape[0]),
        np.broadcast_to(r_max, d.shape[0]),
        iterations=iterations,
        scan=scan,
        progress=progress,
    )


def axis_directions(n):
    """The $2n$ unit vectors $\\pm e_i$ of an n-dimensional section, as rows
    ($+e_0, -e_0, +e_1, -e_1, \\dots$)."""
    eye = np.eye(n)
    return np.stack([s * eye[i] for i in range(n) for s in (1.0, -1.0)])


def wilson_interval(successes, n, confidence=0.95):
    """Wilson score interval for a binomial proportion."""
    from statistics import NormalDist

    if n == 0:
        return (0.0, 1.0)
    zq = NormalDist().inv_cdf(0.5 + confidence / 2)
    p = successes / n
    denom = 1 + zq**2 / n
    centre = (p + zq**2 / (2 * n)) / denom
    half = zq * math.sqrt(p * (1 - p) / n + zq**2 / (4 * n**2)) / denom
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return (lo, hi)


class BasinVolume(eqx.Module):
    """Monte-Carlo estimate of the basin's volume fraction in a box of the section.

    - `fraction`: converging fraction of the uniform samples.
    - `interval`: Wilson score interval at `confidence`.
    - `volume`: `fraction` times the box volume; `volume_interval` likewise.
    - `half_widths`: the box is `z_star +- half_widths`.
    - `num_samples`, `counts`: samples drawn and how many of each label.
    """

    fraction: float
    interval: tuple
    volume: float
    volume_interval: tuple
    half_widths: np.ndarray
    num_samples: int
    counts: dict
    confidence: float


@host_only("vmap `recover`")
def basin_volume(
    model,
    z_star,
    half_widths,
    *,
    num_samples=4096,
    key=None,
    num_steps=50,
    tol=1e-4,
    chunk=1024,
    config=BASIN_CONFIG,
    confidence=0.95,
    progress=None,
    mesh=None,
    checkpoint=None,
):
    """Monte-Carlo estimate (uniform samples) of the fraction of the box
    `z_star +- half_widths` in the full section that converges to the gait, with a Wilson
    confidence interval. `checkpoint`: a folder where the samples are written in parts as
    they finish, from which the same call resumes (as in `basin_slice`), or `None`.

    **Returns:** a `BasinVolume`. A `z_star` that one step does not return to
    (`GAIT_TOL`) raises a `ValueError`.
    """
    from ._recovery import LABEL_NAMES

    z_star = np.asarray(z_star, dtype=float)
    hw = np.asarray(half_widths, dtype=float)
    if hw.shape != z_star.shape or not (np.isfinite(hw).all() and (hw > 0).all()):
        raise ValueError(
            f"basin_volume: half_widths must be {z_star.shape[0]} finite positive numbers (one "
            f"per section coordinate), got {half_widths}"
        )
    if int(num_samples) < 1:
        raise ValueError(f"basin_volume: num_samples must be >= 1, got {num_samples}")
    require_gait(model, z_star, "basin_volume")
    key = jax.random.PRNGKey(0) if key is None else key
    u = np.asarray(jax.random.uniform(key, (num_samples, z_star.shape[0]), minval=-1, maxval=1))
    z = z_star[None] + u * hw[None]
    out = classify_section_points(
        model,
        z_star,
        z,
        num_steps=num_steps,
        tol=tol,
        chunk=chunk,
        config=config,
        progress=progress,
        mesh=mesh,
        checkpoint=checkpoint,
    )
    k = int(np.sum(out["label"] == CONVERGED))
    lo, hi = wilson_interval(k, num_samples, confidence)
    box = float(np.prod(2 * hw))
    counts = {name: int(np.sum(out["label"] == i)) for i, name in enumerate(LABEL_NAMES)}
    return BasinVolume(
        k / num_samples,
        (lo, hi),
        k / num_samples * box,
        (lo * box, hi * box),
        hw,
        num_samples,
        counts,
        confidence,
    )
