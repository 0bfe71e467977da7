"""Multipliers in the commands' output: JSON fields (`gait`, `bifurcation`) and the
stability columns of the `sweep` CSV."""

import math
from typing import Any

#: Stability columns of the `sweep` CSV: the transverse-linearization multipliers by
#: modulus (empty unless asked for and trusted), the verdict from the Poincare-map
#: Jacobian, why the transverse ones are empty, and the Poincare multipliers by modulus.
CSV_COLUMNS = [
    "mult1_re",
    "mult1_im",
    "mult2_re",
    "mult2_im",
    "mult3_re",
    "mult3_im",
    "max_abs_multiplier",
    "stable",
    "transverse_result",
    "pmult1_re",
    "pmult1_im",
    "pmult2_re",
    "pmult2_im",
    "pmult3_re",
    "pmult3_im",
]


def _pairs(ev):
    return [[float(e.real), float(e.imag)] for e in ev]


def stability_json(gm, index=None) -> dict[str, Any]:
    """JSON fields from a (possibly batched, then `index`) `GaitMultipliers`:
    `multipliers` (transverse linearization, a list of `[re, im]`, or `null` where it
    was not asked for or its assumptions fail, with `multipliers_reason`),
    `multipliers_poincare`, `max_abs_multiplier` and `stable` (from the Poincare
    multipliers), `stability_method`, `transverse_result` and `transverse_disagreement`
    (relative; `null` if not computed, not finite, or not used for a reason other than
    the disagreement itself)."""
    from .._results import result_names
    from ..stability import transverse_note

    gm = _host(gm, index)
    note = transverse_note(gm)
    out: dict[str, Any] = {"multipliers": None if note else _pairs(gm.transverse)}
    if note:
        out["multipliers_reason"] = note
    # multipliers not used for a reason other than their disagreement: theirs says nothing
    code = result_names(gm.transverse_result)
    unused = note is not None and code != "methods_disagree"
    dis = None if gm.disagreement is None or unused else float(gm.disagreement)
    out.update(
        {
            "multipliers_poincare": _pairs(gm.poincare),
            "max_abs_multiplier": float(gm.max_abs),
            "stable": bool(gm.stable),
            "stability_method": "poincare_jacobian",
            "transverse_result": code,
            "transverse_disagreement": dis if dis is not None and math.isfinite(dis) else None,
        }
    )
    return out


def _host(gm, index):
    """Member `index` of a batched `GaitMultipliers` (or all of it), as numpy."""
    import jax

    gm = jax.device_get(gm)
    return gm if index is None else jax.tree_util.tree_map(lambda x: x[index], gm)


def add_stability_columns(model, gaits, psis, rows, transverse=False):
    """Fill the `CSV_COLUMNS` of sweep rows (dicts) from one batched `family_multipliers`
    call over a batched `Gait` (`transverse`: the transverse linearization too, several
    times slower); rows whose gait failed get empty values."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .._results import RESULTS, result_names
    from ..stability import family_multipliers

    z = jax.vmap(model.state_to_section)(jnp.asarray(gaits.x_plus))
    gm = _host(family_multipliers(model, jnp.asarray(psis, float), z, transverse=transverse), None)
    codes = result_names(gm.transverse_result)
    gait_ok = np.asarray(gm.result == RESULTS.successful)
    for i, row in enumerate(rows):
        if not (gait_ok[i] and row.get("result") == "successful"):
            row.update(dict.fromkeys(CSV_COLUMNS, ""))
            continue
        trusted = codes[i] == "successful"
        vals = []
        for e in gm.transverse[i] if trusted else [None] * len(gm.poincare[i]):
            vals += ["", ""] if e is None else [float(e.real), float(e.imag)]
        vals += [float(gm.max_abs[i]), bool(gm.stable[i]), codes[i]]
        for e in gm.poincare[i]:
            vals += [float(e.real), float(e.imag)]
        row.update(dict(zip(CSV_COLUMNS, vals)))
