"""Slope sweeps: a family of gaits over many slopes.

A coarse continuation over a few anchor slopes predicts the gait at every slope by
Hermite interpolation of the anchors' gaits (slopes from finite differences); the batched
Newton search (`find_gaits`) then solves the whole slope vector at once, and slopes it
misses are retried from their nearest solved neighbour.
"""

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp

from .._batching import padded_map
from .._host import host_only
from .._programs import stored_jit
from .._results import RESULTS, result_codes
from ._continuation import _on_curve, _run_continuation, _tangent, _unknowns, continue_to_model
from ._dispatch import _check, _relabel, vhc_applies
from ._find import _gaits_in_units, _prefer, find_gaits
from ._gait import Gait, family_sign
from ._problem1 import quadratic_coefficients


# ---------------------------------------------------------------------------------------
# Sweeps in the slope
# ---------------------------------------------------------------------------------------
class Sweep(eqx.Module):
    """A gait family along a vector of slopes.

    - `psi`: the slopes (rad), as given.
    - `gaits`: a batched `Gait`, one per slope (failed members carry their code).
    - `tangent`: $dz^*/d\\psi$ at each slope where the gait was found (zero elsewhere), or
      `None` when the sweep was asked not to compute it (`tangents=False`).
    - `edge_tangent`: $\\max_k |dz^*_k/d\\psi|$ at each found slope next to a missed one,
      in the walker's own units (rates times its time unit; zero elsewhere): a large
      value there means a fold; `None` (a `Sweep` built by
      hand, e.g. to plot gaits): no fold is reported.
    """

    psi: jax.Array
    gaits: Gait
    tangent: jax.Array | None = None
    edge_tangent: jax.Array | None = None

    @property
    def ok(self):
        """Where the gait was found."""
        return self.gaits.result == RESULTS.successful

    def ends(self):
        """Where the family stops existing or stops being found, as a list of dicts
        `{"slope_deg", "last_slope_deg", "result", "reason", "isolated"}` (host side),
        in the order of the slopes given. `isolated`: a missed slope between two found
        ones (by slope), a search failure rather than an end (its `reason` says so)."""
        import numpy as np

        from .._results import result_names

        ok = np.asarray(self.ok)
        names = result_names(self.gaits.result)
        names = [names] if isinstance(names, str) else names
        deg = np.degrees(np.asarray(self.psi))
        if self.edge_tangent is not None:
            tan = np.asarray(self.edge_tangent)
        elif self.tangent is not None:
            tan = np.abs(np.asarray(self.tangent)).max(axis=-1)
        else:  # built by hand without tangents: no fold is reported
            tan = np.zeros(len(ok))
        # neighbours by slope (the slopes may come in any order)
        by_slope = np.argsort(deg, kind="stable")
        rank = np.empty_like(by_slope)
        rank[by_slope] = np.arange(len(ok))
        ok_by_slope = ok[by_slope]
        out = []
        for i in range(len(ok)):
            if ok[i]:
                continue
            prev = (
                i - 1 if i > 0 and ok[i - 1] else (i + 1 if i + 1 < len(ok) and ok[i + 1] else None)
            )
            if prev is None:
                continue
            reason = {
                # a gait always has a real root ((2Ad + B)^2 = B^2 - 4AC): a search failure
                "no_real_root": (
                    "no gait found: the search left the region where the energy quadratic "
                    "(5.13) has real roots"
                ),
                "other_root": (
                    "the gait reaches a double root of the energy quadratic (5.13) and "
                    f"goes on as a gait of the other family ({_other_family(self.gaits.family)!r})"
                ),
                "singular_phi_ode": "the phi'' ODE becomes singular along the arc",
                "infeasible_uphill": "the solution turned into an uphill (negative-time) one",
                "other_cycle": (
                    "the search found a gait of the other family "
                    f"({_other_family(self.gaits.family)!r}) here"
                ),
            }.get(names[i], names[i])
            if names[i] == "not_converged" and tan[prev] > _FOLD_TANGENT:
                reason = f"fold: |dz*/dpsi| = {tan[prev]:.3g} at the last gait found"
            r = rank[i]
            isolated = 0 < r < len(ok) - 1 and bool(ok_by_slope[r - 1] and ok_by_slope[r + 1])
            if isolated:  # whatever the code claims, the family goes on
                reason = f"{names[i]}: a search failure; the family is found on both sides"
            out.append(
                {
                    "slope_deg": float(deg[i]),
                    "last_slope_deg": float(deg[prev]),
                    "result": names[i],
                    "reason": reason,
                    "isolated": isolated,
                }
            )
        return out


#: Largest slope step (rad) between anchors of the coarse continuation.
ANCHOR_STEP = math.radians(0.25)
#: Rounds of retries of the slopes the batched search missed.
_RETRIES = 4
#: $|dz^*/d\psi|$ above which a missed slope next to a found one is reported as a fold.
_FOLD_TANGENT = 50.0


#: Below this slope (1 degree) the anchors go down geometrically, in steps of at most
#: `_ANCHOR_REL` of the slope (and at most the anchor step), as the gaits change ever
#: faster toward zero slope.
_ANCHOR_KNEE = math.radians(1.0)
_ANCHOR_REL = 0.1
#: Smallest slope a sweep solves (rad): the gaits shrink to nothing at zero slope.
MIN_SLOPE = 1e-6


def _anchor_grid(start, stop, step):
    """Slopes from `start` to `stop` (either direction) in equal steps of at most `step`;
    downward below `_ANCHOR_KNEE`, geometric steps of at most `_ANCHOR_REL` times the
    slope and at most `step`."""
    import numpy as np

    knee = stop if stop >= start else max(stop, min(start, _ANCHOR_KNEE))
    n = max(1, int(np.ceil(abs(knee - start) / step - 1e-9)))
    grid = np.linspace(start, knee, n + 1)
    if stop < knee:
        m = max(np.log(knee / stop) / np.log1p(_ANCHOR_REL), (knee - stop) / step)
        m = max(1, int(np.ceil(m - 1e-9)))
        grid = np.concatenate([grid, np.geomspace(knee, stop, m + 1)[1:]])
    return grid


def _anchor_slopes(pa, za):
    """$dz^*/d\\psi$ at the sorted anchors `pa` by finite differences of their gaits
    `za` (second order, one-sided at the ends; zero for a single anchor): the anchors are
    close, and the predictions they make only start Newton."""
    import numpy as np

    if len(pa) < 2:
        return np.zeros_like(za)
    return np.gradient(za, pa, axis=0, edge_order=2 if len(pa) > 2 else 1)


def _hermite(ps, pa, za, ta):
    """Cubic Hermite interpolation of the anchors' gaits `za` and slopes `ta` (with respect
    to psi) at the sorted slopes `ps`; outside the anchors, the tangent line of the
    nearest one."""
    import numpy as np

    j = np.clip(np.searchsorted(pa, ps) - 1, 0, len(pa) - 2) if len(pa) > 1 else None
    if j is None:
        return za[0] + ta[0] * (ps - pa[0])[:, None]
    h = (pa[j + 1] - pa[j])[:, None]
    t = ((ps - pa[j])[:, None]) / h
    z = (
        (2 * t**3 - 3 * t**2 + 1) * za[j]
        + (t**3 - 2 * t**2 + t) * h * ta[j]
        + (-2 * t**3 + 3 * t**2) * za[j + 1]
        + (t**3 - t**2) * h * ta[j + 1]
    )
    below, above = ps < pa[0], ps > pa[-1]
    z[below] = za[0] + ta[0] * (ps[below] - pa[0])[:, None]
    z[above] = za[-1] + ta[-1] * (ps[above] - pa[-1])[:, None]
    return z


@stored_jit
def _tangents_padded(model, psis, zs, sign, method):
    def one(p, z):
        return _tangent(lambda q: model.with_slope(q), p, z, sign, method)

    return jax.vmap(one)(psis, zs)


def _tangents(model, psis, zs, sign, method):
    r"""$dz^*/d\psi$ at every slope (implicit differentiation, batched like `find_gaits`)."""
    import numpy as np

    return np.asarray(
        padded_map(
            lambda p, z: _tangents_padded(model, p, z, sign, method),
            np.asarray(psis, float),
            np.asarray(zs, float),
            stage="tangents",
        )
    )


@host_only("`find_gaits` (one guess per slope) or vmap `find_gait`")
def sweep(model, slopes, family="stable", method="auto", *, anchor_step=ANCHOR_STEP, tangents=True):
    r"""The `family` gait at every slope of `slopes` (rad).

    1. The gait of `model` at 3 degrees, from the reference gait by homotopy in the
       model parameters (no guess needed).
    2. A continuation (secant predictor) from there to both ends of the slope range,
       over anchor slopes at most `anchor_step` apart.
    3. Every slope at once by the batched Newton search (`find_gaits`), from the cubic
       Hermite interpolation of the anchors' gaits, with $dz^*/d\psi$ from finite
       differences between anchors.
    4. Slopes the batch missed are retried from their nearest solved slope (its gait and
       tangent), a few rounds.
    5. Missed slopes where the family passes through a double root of (5.13) and goes
       on as a gait of the other family are coded `other_root`.

    The slopes may come in any order. `Sweep.ends()` says where and why the family ends.
    `method="auto"` (default) sweeps with the VHC search and then sweeps by shooting the
    slopes where it failed (not those where it found a gait of the other family, which
    shooting finds too; `Gait.found_by` says which found each gait). The sweep runs in
    the walker's own units (`WalkerModel.in_own_units`).

    **Returns:** a `Sweep` (`tangent` is $dz^*/d\psi$, zero where no gait was found;
    `tangents=False` leaves it out, computing it only where a retry or a fold test needs
    it, which saves about a third of the time of a large sweep).
    """
    import numpy as np

    _check(family, method)
    if not vhc_applies(model):
        raise ValueError(
            f"sweep follows gait families of the compass gait, not {type(model).__name__}: "
            "use find_gaits with psi=..."
        )
    psi = np.asarray(slopes, dtype=float)
    if psi.ndim > 1:
        raise ValueError(f"sweep: slopes must be one-dimensional, got shape {psi.shape}")
    psi = psi.reshape(-1)
    if psi.size == 0:
        raise ValueError("sweep needs at least one slope")
    if not np.all(np.isfinite(psi)) or np.any(psi <= 0):
        raise ValueError("sweep: slopes must be finite and positive (rad)")
    if np.any(psi < MIN_SLOPE):
        raise ValueError(f"sweep: slopes below {MIN_SLOPE:g} rad are not solved")
    own = model.in_own_units()
    first = "vhc" if method == "auto" else method
    gaits, tangent, edge_tangent = _sweep(own, psi, family, first, anchor_step, tangents)
    if method == "auto":
        # Where the VHC search found the gait and it is one of the other family, shooting
        # would find the same gait: it searches the slopes where the VHC search failed.
        found = _on_curve(gaits.result) | (gaits.result == RESULTS.other_root)
        miss = np.flatnonzero(~np.array(found))
        if miss.size:
            g2, t2, e2 = _sweep(own, psi[miss], family, "shooting", anchor_step, tangents)
            gaits = dataclasses.replace(gaits, method="auto")
            missed = jax.tree_util.tree_map(lambda x: x[miss], gaits)
            g2 = _prefer(missed, dataclasses.replace(g2, method="auto"))
            gaits = _put_members(gaits, miss, g2)
            if tangent is not None and t2 is not None:
                tangent = tangent.at[miss].set(t2[:, :2])  # (da/dpsi, db/dpsi)
            edge_tangent = edge_tangent.at[miss].set(e2)
    gaits = dataclasses.replace(gaits, method=method)  # the label of the call
    # back to the model's units: velocities and their tangents over the time unit
    ts = float(model.scales()["time"])
    gaits = _gaits_in_units(gaits, model.with_slope(jnp.asarray(psi)))
    if tangent is not None:
        tangent = tangent.at[:, 1:].divide(ts)
    return Sweep(jnp.asarray(psi), gaits, tangent, edge_tangent)


def _put_members(gaits, idx, values):
    """`gaits` with the members at `idx` replaced by `values` (host side)."""
    import numpy as np

    def put(a, b):
        if not eqx.is_array(a):
            return a
        a = np.array(a)
        a[idx] = np.asarray(b)
        return jnp.asarray(a)

    return jax.tree_util.tree_map(put, gaits, values)


def _sweep(model, psi, family, method, anchor_step, tangents):
    """`sweep` with one method, in the model's units: `(gaits, tangent, edge_tangent)`."""
    import numpy as np

    order = np.argsort(psi, kind="stable")
    ps = psi[order]
    sign = family_sign(family)
    # 1. the gait at the reference slope (3 degrees for the compass gait) for this model
    p0 = float(model.reference_gait(family)[0].psi)
    anchor_model = model.with_slope(p0)
    z0 = _unknowns(continue_to_model(anchor_model, family, method), method)

    # 2. coarse continuation from there over the slope range (path psi = p0 e^s)
    end = model.with_slope(p0 * math.e)
    pa, za, anchor_other = [], [], []
    for grid in (
        _anchor_grid(p0, max(ps[-1], p0), anchor_step),
        _anchor_grid(p0, min(ps[0], p0), anchor_step),
    ):
        g = _run_continuation(anchor_model, end, np.log(grid / p0), z0, sign, method)
        # A gait of the other family lies on the same curve of gaits, past a double root
        # of (5.13) (the continuation carries it): it predicts as well as one of this
        # family. A sequential continuation past a failure is unreliable: keep the run up
        # to it.
        ok = np.array(_on_curve(g.result))
        n_ok = len(ok) if ok.all() else int(np.argmin(ok))
        z = np.asarray(jax.vmap(lambda gg: _unknowns(gg, method))(g))
        pa += list(grid[:n_ok])
        za += list(z[:n_ok])
        anchor_other += list(np.array(g.result == RESULTS.other_cycle)[:n_ok])
    if not pa:  # not even the first anchor: nothing to predict from
        gaits = find_gaits(
            model, np.repeat(np.asarray(z0)[None], len(ps), 0), family, method, psi=jnp.asarray(ps)
        )
        tangent = np.zeros((len(ps), len(z0)))
        have = np.zeros(len(ps), bool)
    else:
        pa, uniq = np.unique(np.asarray(pa), return_index=True)
        za = np.asarray(za)[uniq]
        oa = np.asarray(anchor_other)[uniq]
        ta = _anchor_slopes(pa, za)
        # 3. every slope at once
        guesses = _hermite(ps, pa, za, ta)
        gaits = _search_predicted(model, ps, guesses, _predicted_from(ps, pa, oa), family, method)
        gaits, tangent, have = _retry(model, ps, gaits, family, method, sign, anchor_step, tangents)
        gaits, tangent, have = _other_root(model, ps, gaits, tangent, have, family, method)
    # 6. the tangents still wanted: all of them, or those next to a missed slope (a fold?)
    # in the order of the slopes or in the order given (`ends()` looks there)
    ok = np.array(gaits.result == RESULTS.successful)
    inverse = np.empty_like(order)
    inverse[order] = np.arange(len(order))
    edge = _edges(ok) | _edges(ok[inverse])[order]
    need = (ok if tangents else edge) & ~have
    if need.any():
        z = np.asarray(jax.vmap(lambda g: _unknowns(g, method))(gaits))
        tangent[need] = _tangents(model, ps[need], z[need], sign, method)
    edge_tangent = np.where(edge, np.abs(tangent).max(axis=-1), 0.0)
    gaits = jax.tree_util.tree_map(lambda x: jnp.asarray(np.asarray(x)[inverse]), gaits)
    gaits = _relabel(gaits, family)
    return (
        gaits,
        jnp.asarray(tangent[inverse]) if tangents else None,
        jnp.asarray(edge_tangent[inverse]),
    )


def _predicted_from(ps, pa, flag):
    """Slopes `ps` whose prediction (`_hermite`) comes from flagged anchors only: between
    two flagged anchors, or beyond a flagged end anchor."""
    import numpy as np

    if len(pa) == 1:
        return np.full(len(ps), bool(flag[0]))
    j = np.clip(np.searchsorted(pa, ps) - 1, 0, len(pa) - 2)
    inside = flag[j] & flag[j + 1]
    return np.where(ps < pa[0], flag[0], np.where(ps > pa[-1], flag[-1], inside))


def _search_predicted(model, ps, guesses, other, family, method):
    """`find_gaits` at the slopes `ps` from the predictions `guesses`; those predicted
    from gaits of the other family (`other`) are searched as that family, whose root of
    (5.13) maps their guesses to the search's unknowns, and coded from this family's
    side (a gait of the other family: `other_cycle`)."""
    import numpy as np

    def search(idx, fam):
        return find_gaits(
            model, jnp.asarray(guesses[idx]), fam, method, psi=jnp.asarray(ps[idx]), far=math.inf
        )

    if not other.any():
        return search(slice(None), family)
    there = search(np.flatnonzero(other), _other_family(family))
    swap = jax.vmap(
        lambda r: RESULTS.where(
            r == RESULTS.successful,
            RESULTS.other_cycle,
            RESULTS.where(r == RESULTS.other_cycle, RESULTS.successful, r),
        )
    )
    there = _relabel(eqx.tree_at(lambda g: g.result, there, swap(there.result)), family)
    if other.all():
        return there
    here = search(np.flatnonzero(~other), family)
    gaits = jax.tree_util.tree_map(lambda x: x[np.zeros(len(ps), int)], here)
    gaits = _put_members(gaits, np.flatnonzero(~other), here)
    return _put_members(gaits, np.flatnonzero(other), there)


def _edges(ok):
    """Found members next to a missed one (boolean mask)."""
    import numpy as np

    return ok & ~(np.r_[ok[1:], True] & np.r_[True, ok[:-1]])


def _retry(model, ps, gaits, family, method, sign, reach, all_tangents=True):
    """4. Re-solve the missed slopes within `reach` of a solved one, from the nearest
    solved slope's gait and tangent, until a round finds nothing new. **Returns:** the
    gaits, the tangents (zero where missed or not computed) and where they were computed
    (every found slope with `all_tangents`, else only those a retry started from)."""
    import numpy as np

    unknowns = jax.vmap(lambda g: _unknowns(g, method))
    Z = np.array(unknowns(gaits))
    ok = np.array(gaits.result == RESULTS.successful)
    T = np.zeros_like(Z)
    have = ok.copy() if all_tangents else np.zeros_like(ok)
    if all_tangents and ok.any():
        T[ok] = _tangents(model, ps[ok], Z[ok], sign, method)
    for _ in range(_RETRIES):
        if ok.all() or not ok.any():
            break
        good = np.where(ok)[0]
        miss = np.where(~ok)[0]
        near = good[np.argmin(np.abs(ps[good][None, :] - ps[miss][:, None]), axis=1)]
        adjacent = np.isin(miss - 1, good) | np.isin(miss + 1, good)
        close = (np.abs(ps[miss] - ps[near]) <= 2 * reach) | adjacent
        miss, near = miss[close], near[close]
        if miss.size == 0:
            break
        todo = np.unique(near[~have[near]])
        if todo.size:
            T[todo] = _tangents(model, ps[todo], Z[todo], sign, method)
            have[todo] = True
        guess = Z[near] + T[near] * (ps[miss] - ps[near])[:, None]
        again = find_gaits(
            model, jnp.asarray(guess), family, method, psi=jnp.asarray(ps[miss]), far=math.inf
        )
        found = np.array(again.result == RESULTS.successful)
        # a landing on the other root is kept too: `_other_root` reads passages from it
        code = np.asarray(result_codes(gaits.result))
        other = np.array(again.result == RESULTS.other_cycle) & (
            code[miss] != result_codes(RESULTS.other_cycle)
        )
        if other.any():
            take, rows = miss[other], np.where(other)[0]
            gaits = jax.tree_util.tree_map(
                lambda a, b: _put(a, take, np.asarray(b)[rows]), gaits, again
            )
            Z[take] = np.asarray(unknowns(again))[rows]
        if not found.any():
            break
        take, rows = miss[found], np.where(found)[0]
        gaits = jax.tree_util.tree_map(
            lambda a, b: _put(a, take, np.asarray(b)[rows]), gaits, again
        )
        Z[take] = np.asarray(unknowns(again))[rows]
        if all_tangents:
            T[take] = _tangents(model, ps[take], Z[take], sign, method)
            have[take] = True
        ok[take] = True
    return gaits, T, have


def _other_family(family):
    return {"stable": "unstable", "unstable": "stable"}.get(family, "the other family")


#: Relative discriminant of (5.13), $(B^2 - 4AC)/B^2$, below which a found gait next to a
#: missed slope is near a double root, where its family may pass to the other root.
_DOUBLE_ROOT = 1e-4
#: Missed slopes searched for a passage to the other root beyond each such gait.
_PASSAGE_RUN = 3


@stored_jit
def _discriminant_rate_padded(model, psis, zs, ts):
    """The relative discriminant of (5.13) at gaits `zs` on slopes `psis`, and its rate
    of change along the family (direction $(1, dz^*/d\\psi)$ = `(1, ts)`)."""

    def relative(p, z):
        A, B, C = quadratic_coefficients(model.with_slope(p), z[0], z[1])
        return (B**2 - 4 * A * C) / B**2

    def one(p, z, t):
        return jax.jvp(relative, (p, z), (jnp.ones_like(p), t))

    return jax.vmap(one)(psis, zs, ts)


def _other_root(model, ps, gaits, T, have, family, method):
    """Code `other_root` the missed slopes where the family passes to the other root of
    (5.13). Along a family the discriminant $\\Delta$ can fall to zero and rise
    again: the gait goes on, continuously, as a gait of the other family, and this family
    ends there. A found gait next to a missed slope is a candidate when its relative
    $\\Delta$ is below `_DOUBLE_ROOT` and $\\sqrt{\\Delta}$ (smooth through the passage)
    extrapolated along the family reaches zero beyond it, at $\\psi_0$. Past the passage
    the sweep's search lands on the gait itself, coded `other_cycle` (its $d$ is the
    other root). A passage is shown at the first of the `_PASSAGE_RUN` missed slopes
    beyond the candidate where that gait lies closer to the candidate's tangent
    prediction than a quarter of the prediction's step, with $\\psi_0$ at most twice as
    far as that slope; the missed slopes up to there are coded with it. **Returns:** the
    gaits, and the tangents and where they were computed (as `_retry`)."""
    import numpy as np

    ok = np.array(gaits.result == RESULTS.successful)
    n = len(ok)
    runs, near = [], []  # the missed slopes beyond each found gait next to a miss
    for j in np.where(_edges(ok))[0]:
        for step in (-1, 1):
            run = []
            i = j + step
            while 0 <= i < n and not ok[i] and len(run) < _PASSAGE_RUN:
                run.append(i)
                i += step
            if run:
                runs.append(run)
                near.append(j)
    if not runs:
        return gaits, T, have
    near = np.asarray(near)
    sign = family_sign(family)
    Z = np.asarray(jax.vmap(lambda g: _unknowns(g, method))(gaits))
    todo = np.unique(near[~have[near]])
    if todo.size:
        T, have = T.copy(), have.copy()
        T[todo] = _tangents(model, ps[todo], Z[todo], sign, method)
        have[todo] = True
    rel, rate = (
        np.asarray(x)
        for x in padded_map(
            lambda p, z, t: _discriminant_rate_padded(model, p, z, t),
            ps[near],
            Z[near],
            T[near],
            stage="discriminants",
        )
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        zero = -2 * rel / rate  # where sqrt(relative discriminant) reaches zero, from psi
    beyond = np.array([np.sign(ps[r[0]] - ps[j]) for r, j in zip(runs, near)]) * zero
    candidate = (rel < _DOUBLE_ROOT) & np.isfinite(beyond) & (beyond > 0)
    runs = [r for r, c in zip(runs, candidate) if c]
    near, beyond = near[candidate], beyond[candidate]
    if not runs:
        return gaits, T, have
    miss = np.concatenate([np.asarray(r) for r in runs])
    start = np.concatenate([np.full(len(r), j) for r, j in zip(runs, near)])
    reach = np.concatenate([np.full(len(r), b) for r, b in zip(runs, beyond)])
    step = T[start] * (ps[miss] - ps[start])[:, None]
    guess = Z[start] + step
    # the gait on the other root, where the sweep's search found it
    found = np.asarray(result_codes(gaits.result))[miss] == result_codes(RESULTS.other_cycle)
    off = np.abs(Z[miss] - guess).max(-1)
    passed = (
        found & (off <= 0.25 * np.abs(step).max(-1)) & (reach <= 2 * np.abs(ps[miss] - ps[start]))
    )
    mask = np.zeros(n, bool)
    k = 0
    for run in runs:
        hit = np.where(passed[k : k + len(run)])[0]
        if hit.size:
            mask[run[: hit[0] + 1]] = True
        k += len(run)
    if not mask.any():
        return gaits, T, have
    code = jax.vmap(lambda p, r: RESULTS.where(p, RESULTS.other_root, r))(
        jnp.asarray(mask), gaits.result
    )
    return eqx.tree_at(lambda g: g.result, gaits, code), T, have


def _put(a, idx, values):
    import numpy as np

    out = np.array(a, copy=True)
    out[idx] = values
    return out
