"""Period doubling: the slope where a multiplier of the period-k gait crosses $-1$
(secant/bisection on $\\det(I + J)$, which changes sign there), and the period-2 branch
born there."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._results import RESULTS
from ..hybrid import DEFAULT_CONFIG, fixed_point, step_map
from ..hybrid._poincare import _jacobian as jacobian  # forward mode, as its callers need
from ..hybrid._simulate import section_units
from ..models import CompassGait  # the default model (thesis Table 1) where none is given
from ._multipliers import _sort


def _flip_function(model, psi, z0, config, k=1):
    fp = fixed_point(model.with_slope(psi), jnp.asarray(z0), k, config=config)
    J = jacobian(model.with_slope(psi), fp.z, k, config)
    return float(jnp.linalg.det(jnp.eye(J.shape[0]) + J)), np.asarray(fp.z), fp.result


class PeriodDoubling(eqx.Module):
    """A flip (period-doubling) bifurcation, as `period_doubling_slope` locates it.

    - `psi`: the slope of the flip (rad).
    - `z`: the period-`k` gait there (post-impact section coordinates).
    - `multipliers`: its Poincare multipliers at `psi` (one of them is $-1$).
    - `bracket`: the last slope bracket `(lo, hi)` (rad).
    - `iterations`: regula falsi iterations taken.
    """

    psi: float
    z: np.ndarray
    multipliers: np.ndarray
    bracket: tuple
    iterations: int


@host_only("`flip_slope`")
def period_doubling_slope(
    psi_lo,
    psi_hi,
    z_lo,
    *,
    model=None,
    k=1,
    tol=math.radians(1e-5),
    config=DEFAULT_CONFIG,
    max_iter=60,
):
    """Slope in `[psi_lo, psi_hi]` where a multiplier of the period-`k` gait crosses $-1$.

    $f(\\psi) = \\det(I + J(\\psi))$ ($J$ the Jacobian of $P^k$ at the fixed point) is
    smooth and changes sign where a real multiplier crosses $-1$; the root is found by
    bisection safeguarded regula falsi (Illinois) to `tol` (default 1e-5 degrees),
    continuing the fixed point from `z_lo` (a gait at `psi_lo`).
    """
    model = CompassGait() if model is None else model
    fa, za, ra = _flip_function(model, psi_lo, z_lo, config, k)
    fb, zb, rb = _flip_function(model, psi_hi, za, config, k)
    if ra != RESULTS.successful or rb != RESULTS.successful:
        raise ValueError("period_doubling_slope: no period-k gait at the bracket ends")
    if not fa * fb < 0:
        raise ValueError(f"no sign change of det(I+J) in [{psi_lo}, {psi_hi}]: {fa}, {fb}")
    a, b = psi_lo, psi_hi
    side = 0
    it = 0
    while b - a > tol and it < max_iter:
        c = (a * fb - b * fa) / (fb - fa)
        if not (a < c < b) or it % 3 == 2:
            c = 0.5 * (a + b)
        zc_guess = za + (zb - za) * (c - a) / (b - a)
        fc, zc, res = _flip_function(model, c, zc_guess, config, k)
        if fc * fb < 0:
            a, fa, za = b, fb, zb
            b, fb, zb = c, fc, zc
            side = 0
        else:
            b, fb, zb = c, fc, zc
            if side == 1:
                fa *= 0.5
            side = 1
        if a > b:
            a, b, fa, fb, za, zb = b, a, fb, fa, zb, za
        it += 1
    psi = 0.5 * (a + b)
    _, z, _ = _flip_function(model, psi, za, config, k)
    J = jacobian(model.with_slope(psi), jnp.asarray(z), k, config)
    ev = np.asarray(_sort(jnp.linalg.eigvals(J)))
    return PeriodDoubling(psi, z, ev, (a, b), it)


@host_only("`period_k_orbit` with k=2")
def period2_branch(model, pd, psis, config=DEFAULT_CONFIG, amplitudes=(3e-3, 1e-2, 3e-2)):
    """Continue the period-2 gait born at the flip `pd` (a `PeriodDoubling`) over the
    slopes `psis` (rad, increasing, all past the flip).

    The first solve starts from the period-1 gait at the flip displaced along the flip
    eigenvector (several trial amplitudes; a solution that is the period-1 gait again is
    rejected), then secant continuation. Stops where Newton fails or the orbit collapses.
    **Returns:** dict with `psi` (m,), `z` (m, 3), `periods` (m, 2), `max_abs` (m,) and
    `stable` (m,) from the multipliers of $P^2$, and `flip_psi`: the slope where a
    multiplier of $P^2$ crosses $-1$ (period 2 -> 4), located to 1e-5 degrees, or None.
    """
    psis = np.asarray(psis, float)
    if len(psis) == 0:
        return None
    J = jacobian(model.with_slope(pd.psi), jnp.asarray(pd.z), 1, config)
    ev, V = np.linalg.eig(np.asarray(J))
    # the flip eigenvector, normalised in the walker's own units (rates times T)
    unit = np.asarray(section_units(model))
    v = np.real(V[:, np.argmin(np.abs(ev + 1))]) / unit
    v = unit * v / np.linalg.norm(v)
    out_psi, out_z, out_T, out_mx = [], [], [], []
    zs = []
    for i, p in enumerate(psis):
        m = model.with_slope(p)
        if i == 0:
            trials = [pd.z + s * v for s in amplitudes]
        else:
            trials = [
                zs[-1]
                if len(zs) == 1
                else zs[-1] + (zs[-1] - zs[-2]) * (p - out_psi[-1]) / (out_psi[-1] - out_psi[-2])
            ]
        found = None
        for guess in trials:
            fp = fixed_point(m, jnp.asarray(guess), 2, config=config)
            if fp.result != RESULTS.successful:
                continue
            z1 = np.asarray(step_map(m, fp.z, 1, config).z_next)
            if np.max(np.abs(z1 - np.asarray(fp.z)) / unit) > 1e-6:
                found = fp
                break
        if found is None:
            break
        zs.append(np.asarray(found.z))
        Jk = jacobian(m, found.z, 2, config)
        out_psi.append(p)
        out_z.append(zs[-1])
        out_T.append(np.asarray(found.periods))
        out_mx.append(float(np.max(np.abs(np.linalg.eigvals(np.asarray(Jk))))))
    if not out_psi:
        return None
    mx = np.asarray(out_mx)
    stable = mx < 1.0
    flip = None
    idx = np.where(stable[:-1] & ~stable[1:])[0]
    if len(idx):
        i = int(idx[0])
        try:
            flip = period_doubling_slope(
                out_psi[i], out_psi[i + 1], out_z[i], model=model, k=2, config=config
            ).psi
        except ValueError:
            flip = None
    return {
        "psi": np.asarray(out_psi),
        "z": np.stack(out_z),
        "periods": np.stack(out_T),
        "max_abs": mx,
        "stable": stable,
        "flip_psi": flip,
    }
