"""A parameter atlas of the compass gait: over a grid of mass ratio $\\mu = m_H/m$ and
length ratio $\\beta = b/a$, the first period-doubling slope of the stable period-1 gait,
the slope range where it is stable, and its spectral radius at a given slope
(in the spirit of Goswami, Thuilot and Espiau, 1998).

The dimensionless gait depends on $\\mu$ and $\\beta$ alone: the leg mass $m$, leg
length $l = a + b$ and gravity $g$ only scale mass, length and time. All cells are
solved at once: one batched `find_gaits` per slope of the scan, then a batched
refinement of every flip (`flip_slopes`).
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._batching import report
from .._chunks import ChunkStore
from .._host import host_only
from .._results import RESULTS
from ..gait import find_gaits
from ..models import CompassGait  # the atlas is over the compass gait's mass and length ratios
from ._flip import _det_and_radius_batch, flip_slopes


def grid_model(
    mass_ratio, length_ratio, *, mass_leg=5.0, leg_length=1.0, gravity=9.81, psi=math.radians(3.0)
):
    """`CompassGait` with $m_1 = m_2 = $ `mass_leg`, $m_H = \\mu m$, $a = l/(1 + \\beta)$,
    $b = l\\beta/(1 + \\beta)$ (arrays broadcast: a batch of models)."""
    mu = jnp.asarray(mass_ratio, float)
    beta = jnp.asarray(length_ratio, float)
    a = leg_length / (1.0 + beta)
    shape = jnp.broadcast_shapes(mu.shape, beta.shape)
    full = lambda v: jnp.broadcast_to(jnp.asarray(v, float), shape)
    return CompassGait(
        m1=full(mass_leg),
        m2=full(mass_leg),
        mH=full(mu * mass_leg),
        a=full(a),
        b=full(beta * a),
        g=full(gravity),
        psi=full(psi),
    )


def seed_gaits(model, method="auto"):
    """Stable gaits (section points, `(B, 3)`, NaN where none was found) of a batch of
    models: `find_gaits` without guesses (each member continued from the reference gait,
    the VHC search and, with `method="auto"`, shooting where it fails)."""
    g = find_gaits(model, None, "stable", method)
    good = np.asarray(g.result == RESULTS.successful)
    return np.where(good[:, None], np.asarray(g.z), np.nan)


class Atlas(eqx.Module):
    """The atlas over `mass_ratio` x `length_ratio` (numpy; arrays indexed `[i_mu, j_beta]`).

    - `flip_slope`: first period-doubling slope (rad), NaN where none was found.
    - `stable_range`: `(..., 2)` lowest and highest scanned slope (rad) with a stable
      period-1 gait, the upper end refined (to the flip, or to where the spectral radius
      reaches 1 between scan slopes: then the last stable scan slope).
    - `spectral_radius`: at `slope` (NaN where no gait or no slope given).
    - `reason`: per cell, why the flip is missing (`""` where found).
    - `slope`, `psi_start`, `psi_max`, `step`: the settings (rad).
    """

    mass_ratio: np.ndarray
    length_ratio: np.ndarray
    flip_slope: np.ndarray
    stable_range: np.ndarray
    spectral_radius: np.ndarray
    reason: list = eqx.field(static=True)
    slope: float | None = eqx.field(static=True)
    psi_start: float = eqx.field(static=True)
    psi_max: float = eqx.field(static=True)
    step: float = eqx.field(static=True)


@host_only("vmap `find_gait` and `flip_slope` over models")
def atlas(
    mass_ratio,
    length_ratio,
    *,
    slope=None,
    mass_leg=5.0,
    leg_length=1.0,
    gravity=9.81,
    psi_start=math.radians(1.0),
    psi_max=math.radians(12.0),
    step=math.radians(0.5),
    tol=1e-10,
    method="auto",
    checkpoint=None,
    chunk_cells=256,
) -> Atlas:
    """The atlas of the stable compass gait over a grid of $\\mu$ and $\\beta$.

    **Arguments:**

    - `mass_ratio`, `length_ratio`: 1-d arrays ($\\mu = m_H/m$, $\\beta = b/a$).
    - `slope`: where to report the spectral radius (rad), or `None`.
    - `mass_leg` (kg), `leg_length` (m), `gravity` (m/s^2): the scales (they do not
      change the slopes or the spectral radius).
    - `psi_start`, `psi_max`, `step`: the slope scan (rad); `tol`: of the flip slopes
      (rad). The gaits at `psi_start` are continued from the default model's (by
      `find_gaits` with `method`, without guesses).
    - `checkpoint`: a folder, or `None`. Given one, the grid is computed in chunks of
      whole rows of `mass_ratio` (about `chunk_cells` cells each), each written to the
      folder as a CSV file when it finishes; the same call again (after Ctrl-C or a
      killed job, say) reads the finished chunks and computes only the rest. A folder
      written with other arguments raises `ValueError`.

    **Returns:** an `Atlas`.
    """
    mu = np.atleast_1d(np.asarray(mass_ratio, float))
    beta = np.atleast_1d(np.asarray(length_ratio, float))
    for name, v in (("mass_ratio", mu), ("length_ratio", beta)):
        if v.ndim != 1 or v.size == 0 or not (np.isfinite(v).all() and (v > 0).all()):
            raise ValueError(
                f"atlas: {name} must be a non-empty 1-d array of finite positive numbers"
            )
    for name, v in (
        ("mass_leg", mass_leg),
        ("leg_length", leg_length),
        ("gravity", gravity),
        ("psi_start", psi_start),
        ("step", step),
    ):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"atlas: {name} must be finite and positive, got {v!r}")
    if not (math.isfinite(psi_max) and psi_max > psi_start):
        raise ValueError(f"atlas: psi_max must be finite and above psi_start, got {psi_max!r}")
    if slope is not None and not (math.isfinite(slope) and slope > 0):
        raise ValueError(f"atlas: slope must be finite and positive (rad), got {slope!r}")
    if not (isinstance(chunk_cells, int) and chunk_cells >= 1):
        raise ValueError(f"atlas: chunk_cells must be a positive integer, got {chunk_cells!r}")
    settings = dict(
        slope=slope,
        mass_leg=mass_leg,
        leg_length=leg_length,
        gravity=gravity,
        psi_start=psi_start,
        psi_max=psi_max,
        step=step,
        tol=tol,
        method=method,
    )
    if checkpoint is not None:
        return _atlas_in_chunks(mu, beta, checkpoint, chunk_cells, settings)
    return _atlas(mu, beta, **settings)


def _atlas(
    mu, beta, *, slope, mass_leg, leg_length, gravity, psi_start, psi_max, step, tol, method
):
    """`atlas` of checked arguments, in one batch."""
    MU, BETA = np.meshgrid(mu, beta, indexing="ij")
    model = grid_model(
        MU.ravel(),
        BETA.ravel(),
        mass_leg=mass_leg,
        leg_length=leg_length,
        gravity=gravity,
        psi=psi_start,
    )
    N = MU.size
    z0 = seed_gaits(model, method)
    ok = np.asarray(np.isfinite(z0).all(axis=1), dtype=bool)
    scan = flip_slopes(model, z0, psi_start, psi_max=psi_max, step=step, tol=tol)
    reason = [
        r if ok[i] else "no stable gait at the start of the scan" for i, r in enumerate(scan.reason)
    ]
    rho = np.full(N, np.nan)
    if slope is not None and ok.any():
        # continue each cell's start gait to `slope` in steps of at most `step`
        n = max(1, int(math.ceil(abs(slope - psi_start) / step)))
        z = np.where(ok[:, None], z0, np.nan_to_num(z0[ok][0]))
        alive = ok.copy()
        for s in np.linspace(psi_start, slope, n + 1)[1:]:
            g = find_gaits(model, jnp.asarray(z), method="shooting", psi=np.full(N, s))
            good = np.asarray(g.result == RESULTS.successful)
            alive &= good
            z = np.where(good[:, None], np.asarray(g.z), z)
        _, r = _det_and_radius_batch(model.with_slope(np.full(N, slope)), z)
        rho = np.where(alive, np.asarray(r), np.nan)
    shape = MU.shape
    return Atlas(
        mu,
        beta,
        scan.psi.reshape(shape),
        scan.stable_range.reshape(shape + (2,)),
        rho.reshape(shape),
        reason,
        None if slope is None else float(slope),
        float(psi_start),
        float(psi_max),
        float(step),
    )


#: The columns of an atlas chunk file (slopes in rad; `reason` empty where a flip was found).
CHUNK_COLUMNS = [
    "mass_ratio",
    "length_ratio",
    "flip_slope",
    "stable_lo",
    "stable_hi",
    "spectral_radius",
    "reason",
]


def _atlas_in_chunks(mu, beta, checkpoint, chunk_cells, settings):
    """`atlas` over chunks of whole mass-ratio rows, each read from the checkpoint folder
    if it holds it complete, else computed and written there."""
    store = ChunkStore(
        checkpoint,
        dict(
            kind="vhcjax.atlas",
            mass_ratio=mu.tolist(),
            length_ratio=beta.tolist(),
            chunk_cells=chunk_cells,
            **settings,
        ),
    )
    rows = max(1, chunk_cells // beta.size)
    cells = []
    bounds = list(range(0, mu.size, rows))
    for k, i0 in enumerate(bounds):
        i1 = min(mu.size, i0 + rows)
        name = f"cells-{i0:06d}-{i1:06d}.csv"
        keys = [dict(mass_ratio=m, length_ratio=b) for m in mu[i0:i1] for b in beta]
        part = store.load(name, CHUNK_COLUMNS, keys)
        if part is None:
            at = _atlas(mu[i0:i1], beta, **settings)
            part = [
                dict(
                    key,
                    flip_slope=f,
                    stable_lo=lo,
                    stable_hi=hi,
                    spectral_radius=r,
                    reason=why,
                )
                for key, f, (lo, hi), r, why in zip(
                    keys,
                    at.flip_slope.ravel(),
                    at.stable_range.reshape(-1, 2),
                    at.spectral_radius.ravel(),
                    at.reason,
                    strict=True,
                )
            ]
            store.save(name, CHUNK_COLUMNS, part)  # floats in `repr`: read back exactly
        cells += part
        report("atlas chunks", k + 1, len(bounds))
    col = lambda c: np.array([float(x[c]) for x in cells]).reshape(mu.size, beta.size)
    return Atlas(
        mu,
        beta,
        col("flip_slope"),
        np.stack([col("stable_lo"), col("stable_hi")], axis=-1),
        col("spectral_radius"),
        [x["reason"] for x in cells],
        None if settings["slope"] is None else float(settings["slope"]),
        float(settings["psi_start"]),
        float(settings["psi_max"]),
        float(settings["step"]),
    )


def atlas_json(at):
    """The atlas as a JSON-ready dict (`null` with a reason where a value is missing)."""
    cells = []
    for i, m in enumerate(at.mass_ratio):
        for j, b in enumerate(at.length_ratio):
            k = i * len(at.length_ratio) + j
            f = at.flip_slope[i, j]
            lo, hi = at.stable_range[i, j]
            r = at.spectral_radius[i, j]
            cell = {
                "mass_ratio": float(m),
                "length_ratio": float(b),
                "flip_slope_deg": float(math.degrees(f)) if np.isfinite(f) else None,
                "stable_range_deg": (
                    [float(math.degrees(lo)), float(math.degrees(hi))]
                    if np.isfinite(lo) and np.isfinite(hi)
                    else None
                ),
                "spectral_radius": float(r) if np.isfinite(r) else None,
            }
            if not np.isfinite(f):
                cell["reason"] = at.reason[k]
            if at.slope is not None and not np.isfinite(r):
                cell["spectral_radius_reason"] = "no period-1 gait found at the slope"
            if at.slope is None:
                cell["spectral_radius_reason"] = "no slope given for the spectral radius"
            cells.append(cell)
    return {
        "mass_ratio": [float(m) for m in at.mass_ratio],
        "length_ratio": [float(b) for b in at.length_ratio],
        "cells": cells,
    }
