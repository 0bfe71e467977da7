"""Slope sweeps: a family of gaits over many slopes by continuation."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp

from .._results import RESULTS
from ._continuation import _run_continuation
from ._continuation import _unknowns
from ._continuation import continue_to_model
from ._dispatch import _check
from ._dispatch import _relabel
from ._gait import Gait
from ._gait import _REFERENCE_PSI
from ._gait import family_sign
from ._problem1 import _with_psi


# ---------------------------------------------------------------------------------------
# Sweeps in the slope
# ---------------------------------------------------------------------------------------
class Sweep(eqx.Module):
    """A gait family along a vector of slopes.

    - `psi`: the slopes (rad), as given.
    - `gaits`: a batched `Gait`, one per slope (failed members carry their code).
    - `tangent`: $dz^*/d\\psi$ at each slope where the gait was found (for fold detection).
    """

    psi: jax.Array
    gaits: Gait
    tangent: jax.Array

    @property
    def ok(self):
        return self.gaits.result == RESULTS.successful

    def ends(self):
        """Where the family stops existing or stops being found, as a list of dicts
        `{"slope_deg", "last_slope_deg", "result", "reason"}` (host side)."""
        import numpy as np

        from .._results import result_names

        ok = np.asarray(self.ok)
        names = result_names(self.gaits.result)
        names = [names] if isinstance(names, str) else names
        deg = np.degrees(np.asarray(self.psi))
        tan = np.abs(np.asarray(self.tangent)).max(axis=-1) if ok.any() else None
        out = []
        for i in range(len(ok)):
            if ok[i]:
                continue
            prev = i - 1 if i > 0 and ok[i - 1] else (i + 1 if i + 1 < len(ok) and ok[i + 1] else None)
            if prev is None:
                continue
            reason = {
                "no_real_root": "the energy quadratic (5.13) has no real root for d",
                "singular_phi_ode": "the phi'' ODE becomes singular along the arc",
                "infeasible_uphill": "the solution turned into an uphill (negative-time) one",
            }.get(names[i], names[i])
            if names[i] == "not_converged" and tan is not None and tan[prev] > 50:
                reason = f"fold: |dz*/dpsi| = {tan[prev]:.3g} at the last gait found"
            out.append(
                {"slope_deg": float(deg[i]), "last_slope_deg": float(deg[prev]),
                 "result": names[i], "reason": reason}
            )
        return out


def sweep(model, slopes, family="stable", method="vhc"):
    """The `family` gait along the slopes `slopes` (rad) by continuation.

    Starts at the slope closest to 3 degrees (reached from the reference gait by
    homotopy in the model parameters, so no guess is needed), then follows the family
    up and down the slope vector with a tangent predictor ($dz^*/d\\psi$ by implicit
    differentiation), each direction one jitted loop. Slopes where the family is not
    found keep their failure code; the next slope is predicted from the last success,
    so an isolated failure does not end the sweep. `Sweep.ends()` says where and why
    the family ends. Give the slopes in order (increasing or decreasing).

    **Returns:** a `Sweep` (`tangent` is $dz^*/d\\psi$).
    """
    import numpy as np

    _check(family, method)
    psi = np.asarray(slopes, dtype=float).reshape(-1)
    k = int(np.argmin(np.abs(psi - _REFERENCE_PSI)))
    sign = family_sign(family)
    anchor_model = _with_psi(model, psi[k])
    anchor = continue_to_model(anchor_model, family, method)
    z0 = _unknowns(anchor, method)
    # Slope path psi = psi_k * e^s: s = log(psi / psi_k).
    end = _with_psi(model, psi[k] * math.e)
    up, t_up = _run_continuation(anchor_model, end, np.log(psi[k:] / psi[k]), z0, sign, method)
    parts, tans = [up], [t_up]
    if k > 0:
        down, t_down = _run_continuation(
            anchor_model, end, np.log(psi[k::-1] / psi[k]), z0, sign, method
        )
        rev = jax.tree_util.tree_map(lambda x: x[1:][::-1], down)
        parts, tans = [rev, up], [t_down[1:][::-1], t_up]
    gaits = jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs), *parts)
    # d/dpsi = (d/ds) / psi on this path.
    tangent = jnp.concatenate(tans) / jnp.asarray(psi)[:, None]
    return Sweep(jnp.asarray(psi), _relabel(gaits, family), tangent)
