"""The period-1 gaits of a compass-gait model over a range of slopes (the slope sweep)."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._host import host_only
from .._results import RESULTS, result_codes, results_from_codes
from ..models import CompassGait  # the default model (thesis Table 1) where none is given


class Family(eqx.Module):
    """Period-1 gaits along a slope range: `psi` (rad), `z` (B, 2n-1), `periods` (B,),
    `result` (per slope)."""

    psi: jax.Array
    z: jax.Array
    periods: jax.Array
    result: RESULTS


@host_only("vmap `find_gait`")
def period1_family(
    psis,
    family="stable",
    *,
    model=None,
    method="auto",
    coarse_step=math.radians(0.1),
):
    """Period-1 gaits of a compass-gait model at the slopes `psis` (rad).

    The slope sweep of the gait search (`vhcjax.sweep`): the gait at 3 degrees by homotopy
    from the reference model, a continuation over anchor slopes at most `coarse_step`
    apart, then one batched Newton solve at every slope, missed slopes retried from
    their neighbours. `method="auto"` (default) solves thesis Problem 1 and, at the
    slopes where that fails for any reason, the fixed point of the Poincare map (thesis
    Problem 2); `"vhc"` and `"shooting"` use one of them throughout.

    The sweep needs no seed and solves every gait to 1e-12. A slope that is not finite
    and positive (at least 1e-6 rad) gets the code `bad_input`;
    another model than a compass gait raises `TypeError`.

    **Returns:** a `Family`; `z` holds the section coordinates $(q_1, \\dot q_1,
    \\dot q_2)$ after impact, `periods` the step periods, `result` the code per slope.
    """
    from ..gait import MIN_SLOPE, sweep

    model = CompassGait() if model is None else model
    if not isinstance(model, CompassGait):
        raise TypeError(
            "period1_family follows compass-gait families; for another model solve each "
            "slope with vhcjax.fixed_point (it works under jax.vmap)"
        )
    psis = np.atleast_1d(np.asarray(psis, float))
    # a slope that is not finite and positive (downhill), or below the sweep's smallest,
    # is `bad_input`; the rest is solved
    valid = np.isfinite(psis) & (psis >= MIN_SLOPE)
    z = np.zeros((len(psis), 2 * model.n_dof - 1))
    periods = np.zeros(len(psis))
    codes = np.full(len(psis), int(result_codes(RESULTS.bad_input)), dtype=np.int32)
    if valid.any():  # `"auto"`: the VHC search, shooting where it fails
        g = sweep(model, psis[valid], family, method, anchor_step=coarse_step, tangents=False)
        z[valid] = np.asarray(g.gaits.z)
        periods[valid] = np.asarray(g.gaits.T)
        codes[valid] = np.asarray(result_codes(g.gaits.result))
    result = results_from_codes(codes)
    return Family(jnp.asarray(psis), jnp.asarray(z), jnp.asarray(periods), result)
