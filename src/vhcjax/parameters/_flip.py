"""The first period-doubling (flip) slope of the stable period-1 gait, batched over models,
and its exact derivative with respect to the model parameters.

$F(\\psi, p) = \\det(I + J(z^*(\\psi, p), \\psi, p))$ ($J$ the step-map Jacobian at the
gait) changes sign where a real multiplier crosses $-1$ (as in
`vhcjax.period_doubling_slope`). The slopes are scanned upward from a start slope with
the gaits continued from one slope to the next (one batched `find_gaits` per slope, all
models at once), the first sign change is bracketed, then refined by a batched
Illinois regula falsi. At the root, $\\mathrm d\\psi_f/\\mathrm dp = -\\partial_p F /
\\partial_\\psi F$ (implicit function theorem), with the total derivatives of $F$ through
the implicit gait derivatives (`find_gait`) and the forward-over-forward Jacobian.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._batching import padded_map
from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS
from ..gait import find_gait, find_gaits
from ..hybrid import DEFAULT_CONFIG
from ..hybrid._poincare import _jacobian as jacobian  # forward mode, as its callers need
from ..solvers import detach
from ..stability import gait_spectrum


@stored_jit
def _det_and_radius(model, zs):
    """$\\det(I + J)$ and the spectral radius at the section points `zs` (batched with the
    model's leading axis where it has one)."""
    axes = jax.tree_util.tree_map(
        lambda x: 0 if (eqx.is_array(x) and jnp.ndim(x) > 0) else None, model
    )

    def one(m, z):
        J = jacobian(m, z, 1, DEFAULT_CONFIG)
        return jnp.linalg.det(jnp.eye(J.shape[0]) + J), jnp.max(jnp.abs(jnp.linalg.eigvals(J)))

    return eqx.filter_vmap(one, in_axes=(axes, 0))(model, zs)


def _broadcast(model, B, every=False):
    """Array leaves with a leading axis broadcast to `B` members (`every`: scalars too)."""
    return jax.tree_util.tree_map(
        lambda x: (
            jnp.broadcast_to(x, (B,) + jnp.shape(x)[min(1, jnp.ndim(x)) :])
            if (eqx.is_array(x) and (every or jnp.ndim(x) > 0))
            else x
        ),
        model,
    )


#: A batch of more than this many models is solved only at the members that still need
#: it (the others have bracketed their flip, converged or lost their gait), padded to a
#: multiple of this size by repeating one of them: every such subset runs the compiled
#: programs of the full batch.
_SUBSET = 256


def _members(mask):
    """Indices of the batch to solve: all of a small batch; in a large one the members
    in `mask`, padded to a multiple of `_SUBSET`."""
    B = mask.size
    if B <= _SUBSET:
        return np.arange(B)
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return idx
    n = -(-idx.size // _SUBSET) * _SUBSET
    return np.concatenate([idx, np.full(n - idx.size, idx[0])])


def _take(model, idx):
    """The members `idx` of a batch of models (every array leaf with a leading axis)."""
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x)[idx] if (eqx.is_array(x) and jnp.ndim(x) > 0) else x, model
    )


def _det_and_radius_batch(model, zs):
    """`_det_and_radius` of a batch, in chunks of the library's padded sizes
    (`padded_map`), every parameter broadcast to the batch: which parameters vary does not
    make another program."""
    n = np.shape(zs)[0]
    return padded_map(_det_and_radius, _broadcast(model, n, every=True), jnp.asarray(zs))


def _evaluate(
    model, psi, zs, mask, solver="newton"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gaits at slopes `psi` (B,) from guesses `zs` (B, 3) of the members in `mask`:
    section points, ok, F, rho (the other members of a large batch: their guess, False,
    NaN, NaN; see `_SUBSET`)."""
    B = zs.shape[0]
    z_out, ok_out = zs.copy(), np.zeros(B, bool)
    F_out, rho_out = np.full(B, np.nan), np.full(B, np.nan)
    idx = _members(mask)
    if idx.size == 0:
        return z_out, ok_out, F_out, rho_out
    sub = _take(model, idx)
    gaits = find_gaits(sub, jnp.asarray(zs[idx]), method="shooting", psi=psi[idx], solver=solver)
    ok = np.asarray(gaits.result == RESULTS.successful)
    z = np.asarray(gaits.z)
    F, rho = _det_and_radius_batch(sub.with_slope(psi[idx]), z)
    z_out[idx], ok_out[idx] = z, ok
    F_out[idx] = np.where(ok, np.asarray(F), np.nan)
    rho_out[idx] = np.where(ok, np.asarray(rho), np.nan)
    return z_out, ok_out, F_out, rho_out


class FlipScan(eqx.Module):
    """Result of `flip_slopes` (numpy, one entry per model of the batch).

    - `psi`: the flip slope (rad), NaN where none was found in the scanned range (or
      the gait at the start already has a multiplier below -1: past a flip).
    - `z`: the period-1 gait there (section point).
    - `stable_range`: `(B, 2)`, the lowest and highest slope (rad) of the scan where the
      period-1 gait was found and stable (the upper end refined to the flip slope, or to
      the slope where the spectral radius reaches 1), NaN where it never was.
    - `found`: whether a flip was bracketed and refined.
    - `reason`: why not, per model (`""` where found).
    """

    psi: np.ndarray
    z: np.ndarray
    stable_range: np.ndarray
    found: np.ndarray
    reason: list = eqx.field(static=True)


@host_only("`flip_slope`")
def flip_slopes(
    model,
    z_start,
    psi_start,
    *,
    psi_max=math.radians(12.0),
    step=math.radians(0.25),
    tol=1e-12,
    max_iter=60,
) -> FlipScan:
    """First flip slope of the stable period-1 gait for each model of a batch.

    **Arguments:**

    - `model`: a `CompassGait`, leaves batched along a leading axis (or scalars).
    - `z_start`: `(B, 3)` section points of the stable gait at `psi_start` (from
      `find_gaits(..., method="shooting")`); rows that are NaN are skipped.
    - `psi_start`: the start slope (rad), below the flip slope.
    - `psi_max`, `step`: the scan (rad).
    - `tol`, `max_iter`: of the refinement (rad).

    **Returns:** a `FlipScan`.
    """
    if not (math.isfinite(step) and step > 0 and math.isfinite(psi_max)):
        raise ValueError(
            f"flip slope scan: step must be positive and psi_max finite, got {step}, {psi_max}"
        )
    model = detach(model)
    z_start = np.asarray(z_start, float)
    B = z_start.shape[0]
    model = _broadcast(model, B)
    alive = np.asarray(np.isfinite(z_start).all(axis=1), dtype=bool)
    z = np.where(alive[:, None], z_start, np.nan_to_num(z_start[alive][0]) if alive.any() else 0.0)
    slopes = np.arange(psi_start, psi_max + 0.5 * step, step)
    lo = np.full(B, np.nan)
    hi = np.full(B, np.nan)
    bracket = np.zeros(B, bool)
    a = np.full(B, np.nan)
    fa = np.full(B, np.nan)
    za = z.copy()
    b = np.full(B, np.nan)
    fb = np.full(B, np.nan)
    zb = z.copy()
    ra = np.full(B, np.nan)
    rb = np.full(B, np.nan)
    reason = ["" for _ in range(B)]
    for psi in slopes:
        todo = alive & ~bracket
        if not todo.any():
            break
        zs, ok, F, rho = _evaluate(model, np.full(B, psi), z, todo)
        stable = ok & (rho < 1)
        lo = np.where(todo & stable & np.isnan(lo), psi, lo)
        # det(I + J) < 0 already at the start: a real multiplier below -1, no flip ahead
        past = todo & ok & (F < 0) & np.isnan(a)  # no slope kept yet: the first one
        for i in np.nonzero(past)[0]:
            reason[i] = (
                f"the gait at the start of the scan ({math.degrees(psi):.3f} deg) already has "
                "a multiplier below -1 (det(I + J) < 0): past a flip"
            )
        alive &= ~past
        todo &= ~past
        cross = todo & ok & (F < 0) & (fa > 0)
        # the first sign change of F: bracket [previous slope, this slope]
        b = np.where(cross, psi, b)
        fb = np.where(cross, F, fb)
        zb = np.where(cross[:, None], zs, zb)
        rb = np.where(cross, rho, rb)
        bracket |= cross
        lost = todo & ~ok & ~cross
        for i in np.nonzero(lost)[0]:
            reason[i] = f"the period-1 gait was lost at {math.degrees(psi):.3f} deg before a flip"
        alive &= ~lost
        keep = todo & ok & ~cross
        a = np.where(keep, psi, a)
        fa = np.where(keep, F, fa)
        za = np.where(keep[:, None], zs, za)
        ra = np.where(keep, rho, ra)
        hi = np.where(keep & stable, psi, hi)
        z = np.where(keep[:, None], zs, z)  # continuation: the next slope starts here
    a_bracket = a.copy()
    for i in np.nonzero(alive & ~bracket)[0]:
        if not reason[i]:
            reason[i] = f"no flip below {math.degrees(psi_max):.3f} deg"
    # batched Illinois regula falsi on the brackets
    it = 0
    side = np.zeros(B, int)
    active = bracket.copy()
    while active.any() and it < max_iter:
        c = np.where(active, (a * fb - b * fa) / (fb - fa), a)
        bad = ~((np.minimum(a, b) < c) & (c < np.maximum(a, b))) | (it % 4 == 3)
        c = np.where(active & bad, 0.5 * (a + b), c)
        w = np.clip((c - a) / np.where(b != a, b - a, 1.0), 0, 1)[:, None]
        zc_guess = np.where(active[:, None], za + (zb - za) * w, za)
        # Plain Newton (optimistix) here: the guesses are already very close, closer
        # than the loose first integration of the damped search resolves.
        zc, ok, Fc, _ = _evaluate(model, np.where(active, c, a), zc_guess, active, "optimistix")
        failed = active & ~ok
        for i in np.nonzero(failed)[0]:
            reason[i] = "the refinement lost the gait inside the bracket"
        active &= ~failed
        bracket &= ~failed
        same = active & (Fc * fb > 0)  # root between a and c
        other = active & ~same
        # other: root between c and b -> a <- b
        a = np.where(other, b, a)
        fa = np.where(other, fb, fa)
        za = np.where(other[:, None], zb, za)
        fa = np.where(same & (side == 1), 0.5 * fa, fa)
        side = np.where(other, 0, np.where(same, 1, side))
        b = np.where(active, c, b)
        fb = np.where(active, Fc, fb)
        zb = np.where(active[:, None], zc, zb)
        active &= np.abs(b - a) > tol
        it += 1
    psi_f = np.where(bracket, b, np.nan)
    # stable up to the flip where the last scanned slope before it was stable
    hi = np.where(bracket & (hi == a_bracket), psi_f, hi)
    rng = np.stack([lo, np.where(np.isfinite(lo), hi, np.nan)], axis=1)
    zf = np.where(bracket[:, None], zb, np.nan)
    return FlipScan(psi_f, zf, rng, bracket, reason)


def _flip_function(model, psi, z):
    """$F(\\psi, p) = \\det(I + J)$ at the gait found from `z` (differentiable)."""
    m = model.with_slope(psi)
    g = find_gait(m, method="shooting", guess=z, throw=False)
    J = gait_spectrum(m, g).jacobian
    return jnp.linalg.det(jnp.eye(J.shape[0]) + J)


def flip_slope(model, z_start, *, psi_max=math.radians(12.0), step=math.radians(0.25)):
    """The first flip slope (rad) of the stable gait of one `model`, starting from its
    gait `z_start` (section point) at `model.psi`; differentiable with respect to the
    model parameters (`jax.grad`, `jax.jvp`, ...) by the implicit function theorem on
    $\\det(I + J) = 0$. Locating it runs on the host (not under `jit`). NaN where no flip
    was found below `psi_max`, or where the gait at `model.psi` is already past one
    (`flip_slopes` says why)."""
    params = model
    m = detach(model)
    scan = flip_slopes(
        m, np.asarray(detach(z_start), float)[None], float(m.psi), psi_max=psi_max, step=step
    )
    psi_f, z_f = float(scan.psi[0]), scan.z[0]
    return _attach_flip(params, jnp.asarray(psi_f), jnp.asarray(z_f))


@jax.custom_jvp
def _attach_flip(model, psi_f, z_f):
    return psi_f


@_attach_flip.defjvp
def _attach_flip_jvp(primals, tangents):
    model, psi_f, z_f = primals
    dmodel = tangents[0]
    # dF = F_psi dpsi + F_p . dp = 0 on the flip curve
    F_psi = jax.jvp(lambda s: _flip_function(model, s, z_f), (psi_f,), (jnp.ones_like(psi_f),))[1]
    dmodel = eqx.tree_at(lambda m: m.psi, dmodel, jnp.zeros_like(psi_f))
    F_p = jax.jvp(lambda m: _flip_function(m, psi_f, z_f), (model,), (dmodel,))[1]
    dpsi = jnp.where(jnp.isfinite(psi_f), -F_p / F_psi, 0.0)
    return psi_f, dpsi
