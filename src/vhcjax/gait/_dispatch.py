"""One search by method name; which methods apply to a model."""

from .._programs import stored_jit
from ._gait import FAMILIES, METHODS
from ._problem1 import vhc_search
from ._shooting import shooting_search


@stored_jit
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


def vhc_applies(model):
    """Whether the VHC search (Problem 1) is written for `model`: the two-DOF compass
    gait (its subclasses with more degrees of freedom are searched by shooting)."""
    from ..models import CompassGait

    return isinstance(model, CompassGait) and model.n_dof == 2
