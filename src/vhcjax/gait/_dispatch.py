"""One search by method name, and the reference gait that seeds continuation."""

import jax.numpy as jnp

from ._gait import _REFERENCE_AB, _REFERENCE_PSI, FAMILIES, METHODS
from ._problem1 import vhc_search
from ._shooting import shooting_search


def _search(model, guess, sign, method, solver="newton", chord=False, axes=None, far=None):
    """`far`: VHC only (see `vhc_search`); `None`: its default."""
    if method == "vhc":
        kw = {} if far is None else {"far": far}
        return vhc_search(model, guess, sign, solver=solver, chord=chord, axes=axes, **kw)
    if method == "shooting":
        return shooting_search(
            model,
            guess,
            sign,
            solver="optimistix" if solver == "optimistix" else "newton",
            chord=chord,
            axes=axes,
        )
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def _relabel(gait, family):
    import dataclasses

    return dataclasses.replace(gait, family=family)


def _check(family, method):
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def reference_model(like=None):
    """The default model (thesis Table 1) at 3 degrees, where `reference_guess` holds."""
    from ..models import CompassGait

    return CompassGait(psi=_REFERENCE_PSI)


def reference_guess(family="stable"):
    """$(a, b)$ of the `family` gait of the default model at 3 degrees (a seed)."""
    return jnp.asarray(_REFERENCE_AB[family])
