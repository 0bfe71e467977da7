"""Batched bisection for survival thresholds (largest perturbation a walker survives).

`survives(magnitudes)` is a batched predicate (one magnitude per member, e.g. the size of
a push, of a floor step or of a perturbation along a ray). Every member is bisected in
parallel, so a whole table of thresholds (phases x directions) costs `iterations` batched
simulations. The bracket `[lo, hi]` is verified on return: `lo` survives, `hi` does not.
The set of surviving magnitudes need not be an interval (a walker may fall after a
medium push and survive a larger one). With `scan > 0`, each member is first evaluated at
`scan` equally spaced magnitudes and the bisection starts from the first failure of that
scan, so it finds the *first* threshold up to the scan resolution; with `scan = 0` it
returns some boundary point. A predicate may return integer labels instead of booleans
(0: survived, as `CONVERGED`); the label of the failure at `hi` is then kept, so that a
caller can tell a fall from a recovery still under way when its step budget ran out.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._host import host_only


class Threshold(eqx.Module):
    """Result of a batched bisection (numpy arrays, host side).

    - `lo`: largest magnitude found to survive (per member).
    - `hi`: smallest magnitude found to fail (per member); `inf` where `hi_max` survived.
    - `bracketed`: `lo` survives and `hi` fails (both verified by simulation).
    - `survives_max`: the member survived even `hi_max` (threshold above the search range).
    - `fails_min`: the member failed even at `lo_min` (threshold below the search range).
    - `hi_label`: the predicate's label at `hi` where it returns labels (why `hi` fails);
      -1 where it returns booleans, or where `hi_max` survived.
    """

    lo: np.ndarray
    hi: np.ndarray
    bracketed: np.ndarray
    survives_max: np.ndarray
    fails_min: np.ndarray
    hi_label: np.ndarray


def _evaluate(survives, magnitudes):
    """(survived, label) of a predicate returning booleans (label -1) or labels (0 survives)."""
    out = np.asarray(survives(jnp.asarray(magnitudes)))
    if out.dtype == bool:
        return out, np.full(out.shape, -1)
    return out == 0, out.astype(int)


@host_only("a bisection in `jax.lax` around your own test")
def bisect_threshold(survives, lo_min, hi_max, *, iterations=20, scan=0, progress=None):
    """Bisect `survives` on `[lo_min, hi_max]` for every member (host loop, batched calls).

    **Arguments:**

    - `survives`: callable, `(batch,) magnitudes -> (batch,) bool`, or `-> (batch,) int`
      labels with 0 for survival (the failing label at `hi` is then kept).
    - `lo_min`, `hi_max`: arrays (batch,) or scalars; `lo_min` is expected to survive.
    - `iterations`: number of halvings (the bracket shrinks by `2**iterations`).
    - `scan`: number of interior magnitudes evaluated first (one batched call per
      magnitude) to locate the first failure along `[lo_min, hi_max]`.
    - `progress`: optional callable `iterable -> iterable` (e.g. a tqdm bar).

    **Returns:** a `Threshold`.
    """
    lo = np.asarray(lo_min, dtype=float)
    hi = np.asarray(hi_max, dtype=float)
    lo, hi = np.broadcast_arrays(lo, hi)
    lo, hi = lo.copy(), hi.copy()
    bad = ~(np.isfinite(lo) & np.isfinite(hi) & (hi > lo))
    if bad.any():
        i = np.unravel_index(np.argmax(bad), bad.shape)
        raise ValueError(
            "the search interval of a threshold (0 to the largest magnitude tried) must be "
            f"finite and not empty, got [{lo[i]:g}, {hi[i]:g}]"
        )
    if int(iterations) < 1 or int(scan) < 0:
        raise ValueError(
            f"bisect_threshold: iterations must be at least 1 and scan at least 0, got "
            f"{iterations}, {scan}"
        )
    s_lo, _ = _evaluate(survives, lo)
    s_hi, label = _evaluate(survives, hi)
    if scan > 0:
        fracs = np.arange(1, scan + 1) / (scan + 1)
        grid = lo[None] + fracs[:, None] * (hi - lo)[None]  # (scan, batch)
        ok, labels = (np.stack(a) for a in zip(*(_evaluate(survives, g) for g in grid)))
        fail = ~ok
        first = np.where(fail.any(axis=0), fail.argmax(axis=0), scan)  # index of first fail
        cols = np.arange(lo.shape[0])
        new_hi = np.where(first < scan, grid[np.minimum(first, scan - 1), cols], hi)
        new_lo = np.where(first > 0, grid[np.maximum(first - 1, 0), cols], lo)
        use = s_lo  # only members whose lower end survives
        hi = np.where(use, new_hi, hi)
        lo = np.where(use, new_lo, lo)
        found = use & (first < scan)
        label = np.where(found, labels[np.minimum(first, scan - 1), cols], label)
        s_hi = np.where(found, False, s_hi)
    rng = range(iterations)
    for _ in progress(rng) if progress is not None else rng:
        mid = 0.5 * (lo + hi)
        s, lab = _evaluate(survives, mid)
        active = s_lo & ~s_hi
        lo = np.where(active & s, mid, lo)
        hi = np.where(active & ~s, mid, hi)
        label = np.where(active & ~s, lab, label)
    survives_max = s_hi
    fails_min = ~s_lo
    hi_out = np.where(survives_max, np.inf, hi)
    lo_out = np.where(survives_max, hi, np.where(fails_min, np.nan, lo))
    label = np.where(survives_max, -1, label)
    return Threshold(lo_out, hi_out, s_lo & ~s_hi, survives_max, fails_min, label)
