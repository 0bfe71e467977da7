"""`find_gait` and `find_gaits`: the gait search as users call it, one gait or a batch."""

import dataclasses
import math

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np

from .._batching import bucket_size, device_multiple, dispatch_size, host_workers, padded_map
from .._programs import stored_jit
from .._results import RESULTS, result_codes
from ..hybrid import check_section_shape
from ..solvers import detach
from ._continuation import (
    _HOMOTOPY_STEPS,
    _continue,
    _finite_gait_in_units,
    _homotopy_steps,
    _seed,
    _unknowns,
    continue_to_model,
)
from ._derivatives import with_derivatives
from ._dispatch import _check, _relabel, _search, vhc_applies
from ._gait import (
    _NOISY_RESIDUAL,
    FAMILIES,
    _make_gait,
    family_sign,
    gait_in_units,
    section_in_units,
)
from ._problem1 import _FAR


def find_gait(model, family="stable", method="auto", guess=None, *, solver="newton", throw=True):
    """Find the periodic gait of `family` on `model`: the one gait finder of vhcjax.

    **Arguments:**

    - `model`: any walker model (`CompassGait` with any masses, lengths, gravity and
      slope, a leg mass at the foot included; `KneedWalker`, `PendulumWalker`,
      `SimplestWalker`, your own `WalkerModel`).
    - `family`: `"stable"` or `"unstable"` (for the compass gait the root of the energy
      quadratic, 7.3/7.8; a model with one known family has `"stable"` alone).
    - `method`: `"auto"` (default): the VHC search (Problem 1) where it applies (the
      compass gait), and shooting (Problem 2) wherever it fails, for any reason; so "no
      gait" is said only when neither finds one. `"vhc"` or `"shooting"`: that method
      alone (the VHC search is for the compass gait only).
    - `guess`: compass gait: $(a_0, b_0)$ (or $(a_0, b_0, f_0)$); other models: a section
      point. `None`: continue the model's `reference_gait` to `model` (a homotopy in the
      parameters).
    - `solver`: VHC only: `"newton"` (default), `"lm"`, `"optimistix"` or `"optax"`.
    - `throw`: raise if no gait was found (a `ValueError` at once for a non-finite
      guess or an invalid model; with `throw=False` that gait is coded `bad_input`).
      Under `jax.jit` or `jax.vmap` nothing is raised: read `result` (per member).

    The search runs in the walker's own units (`WalkerModel.in_own_units`: masses,
    lengths and gravity relative to their sums), so a walker and its scaled copy give
    the same angles, and tolerances hold in any units. `Gait.found_by` says which method
    found the gait.

    Differentiable (`jax.grad`, `jax.jacfwd`, ...) with respect to every model parameter:
    exact derivatives by the implicit function theorem at the gait, never through the
    search. Under `jax.jit`, `jax.vmap` or
    `jax.grad` without a guess, the continuation runs on the host (a `pure_callback`,
    one member at a time under `vmap`) and the traced search starts from its gait.

    **Returns:** a `Gait`.
    """
    _check(family, method)
    _check_model(model, method)
    batched = [jnp.shape(x) for x in jax.tree_util.tree_leaves(model) if jnp.ndim(x) > 0]
    if batched:
        raise ValueError(
            f"find_gait takes one model (0-d parameters), got parameters of shapes "
            f"{sorted(set(batched))}; find_gaits searches a batch"
        )
    if throw and not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model)):
        if not bool(_valid(model)):  # one line now, not a runtime error later
            raise ValueError(
                "the model has a parameter out of its range (non-finite, or a mass, length "
                "or gravity not positive, or a slope outside (0, 30) deg); with throw=False "
                "the gait is coded bad_input"
            )
    params, model = model, detach(model)  # the search itself is never differentiated
    if guess is None and any(
        isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model)
    ):
        guess = _found_on_host(model, family, method, solver)
    if guess is not None:
        guess = detach(jnp.asarray(guess, dtype=float))
        if throw and not isinstance(guess, jax.core.Tracer):
            values = np.asarray(guess)
            if not np.all(np.isfinite(values)):  # one line now, not a runtime error later
                raise ValueError(f"guess must be finite, got {values.tolist()}")
    if vhc_applies(model):
        if guess is not None:
            _check_guess_shape(guess.shape, (), "guess")
        methods = ("vhc", "shooting") if method == "auto" else (method,)
        gait = _compass_gait(model, family, methods[0], guess, solver)
        for m in methods[1:]:
            code = result_codes(gait.result)
            done = (
                result_codes(RESULTS.successful),
                result_codes(RESULTS.bad_input),
            )  # nothing to retry
            if not isinstance(code, jax.core.Tracer) and code in done:
                break
            gait = _prefer(gait, _compass_gait(model, family, m, guess, solver))
    else:
        gait = _shooting_gait_of(model, family, guess)
    gait = dataclasses.replace(gait, method=method)  # the label of the call, not the data
    gait = _clean_failed(gait, guess)
    gait = with_derivatives(params, gait, _derivative_method(gait), family_sign(family))
    if throw and not isinstance(result_codes(gait.result), jax.core.Tracer):
        # outside `jit`/`vmap` only: inside, each member keeps its own code, so that one
        # failure does not sink a batch
        err = gait.result != RESULTS.successful
        gait = eqx.tree_at(lambda g: g.a, gait, gait.result.error_if(gait.a, err))
    return gait


def _found_on_host(model, family, method, solver):
    """The section point of the gait that `find_gait` finds on the values of a traced
    `model` (under `jit`, `vmap`, `grad`), by a host callback: the continuation from the
    model's reference gait chooses its steps on the host. The traced search then starts
    from it, so the result, its code and its derivatives are those of a search from a
    guess. A failed host search hands back its last point, and the traced search codes it."""
    dynamic, static = eqx.partition(model, eqx.is_array)
    x = jax.ShapeDtypeStruct((2 * model.n_dof,), jnp.float64)
    shape = jax.eval_shape(model.state_to_section, x).shape

    def host(values):
        m = eqx.combine(jax.tree_util.tree_map(jnp.asarray, values), static)
        gait = find_gait(m, family, method, solver=solver, throw=False)
        return np.asarray(m.state_to_section(gait.x_plus), dtype=np.float64)

    return jax.pure_callback(
        host, jax.ShapeDtypeStruct(shape, jnp.float64), dynamic, vmap_method="sequential"
    )


def _derivative_method(gait):
    """The residual whose implicit derivatives are attached: Problem 1's where every
    member was found by the VHC search, else Problem 2's (both vanish at the gait)."""
    if gait.method != "auto":
        return gait.method
    by = gait.shooting
    return "vhc" if not isinstance(by, jax.core.Tracer) and not np.any(by) else "shooting"


def _prefer(first, second):
    """`first` where it succeeded, else `second` (per member; traced results too), except
    where `second` failed too and `first` found a solution that is no walking gait
    (`infeasible_uphill`, `other_cycle`, `bad_impact`, `other_root`: a finding, not a failure of its
    assumptions). The method label becomes `"auto"` where the two differ."""
    finding = (
        (first.result == RESULTS.infeasible_uphill)
        | (first.result == RESULTS.other_cycle)
        | (first.result == RESULTS.bad_impact)
        | (first.result == RESULTS.other_root)
    )
    ok = (first.result == RESULTS.successful) | (finding & (second.result != RESULTS.successful))
    if first.method != second.method:
        first = dataclasses.replace(first, method="auto")
        second = dataclasses.replace(second, method="auto")
    return _select(ok, first, second)


@eqx.filter_jit
def _select(ok, first, second):
    def pick(a, b):
        if not eqx.is_array(a):
            return a
        k = ok.reshape(ok.shape + (1,) * (jnp.ndim(a) - ok.ndim))
        return jnp.where(k, a, b)

    return jax.tree_util.tree_map(pick, first, second)


def _compass_gait(model, family, method, guess, solver):
    """One method's search for the compass gait, in the walker's own units."""
    if guess is None:
        return continue_to_model(model, family, method)
    own = model.in_own_units()
    ts = model.scales()["time"]
    g = guess * jnp.concatenate([jnp.ones(1), jnp.full(guess.shape[0] - 1, ts)])
    if method == "vhc":  # (a0, b0): a section point's dq2 is for shooting
        g = g[:2]
    found = _relabel(_search(own, g, family_sign(family), method, solver), family)
    return _finite_gait_in_units(found, model)


def _shooting_gait_of(model, family, guess):
    """A model without a VHC search: shooting, from `guess` (a section point) or by
    continuation from the model's `reference_gait` (`continue_fixed_point`), in the
    walker's own units."""
    from ..hybrid import continue_fixed_point, fixed_point

    if family not in model_families(model):
        raise ValueError(
            f"{type(model).__name__} has the gait families {model_families(model)}, got {family!r}"
        )
    own = model.in_own_units()
    ts = model.scales()["time"]
    if guess is None:
        ref, z_ref = model.reference_gait(family)
        fp, _ = continue_fixed_point(
            ref.in_own_units(), section_in_units(ref, z_ref, ref.scales()["time"]), own
        )
    else:
        check_section_shape(model, guess, "guess")
        fp = fixed_point(own, section_in_units(model, guess, ts))
    return _finite_gait_in_units(_fixed_point_gait(own, fp, family), model)


def model_families(model):
    """The gait families `model` knows a reference gait of (`reference_gait`)."""
    out = []
    for family in FAMILIES:
        try:
            model.reference_gait(family)
        except ValueError:
            continue
        except NotImplementedError:
            return list(FAMILIES)  # no reference: any label, a guess is needed
        out.append(family)
    return out


@stored_jit  # top level after a shooting search: kept on disk, and named while it compiles
def _fixed_point_gait(model, fp, family):
    """The `Gait` of a fixed point of the step map (`vhcjax.fixed_point`)."""
    from ..hybrid import step_unchecked

    sr = step_unchecked(model, fp.x0)
    return _make_gait(
        model,
        fp.x0,
        sr.x_minus,
        fp.periods[0],
        model.energy(fp.x0),
        fp.iterations,
        fp.residual,
        fp.result,
        family,
        "shooting",
        sr.result != RESULTS.bad_impact,
    )


# ---------------------------------------------------------------------------------------
# Batches
# ---------------------------------------------------------------------------------------
#: Largest number of members per device in one dispatch: larger batches run in chunks of
#: this size, all compiled as one program (see `_batching.MAX_DISPATCH`).
_MAX_CHUNK = 128
#: Guessed batches with at least this many members per device finish with chord steps.
_CHORD_MIN_MEMBERS = 64
#: Batches of at most this many members per host worker are not split over workers: the
#: run is short next to its compilation, and splitting would compile a second size.
_MIN_SPLIT = 8


#: `model.validate()` as one small program (not a dozen eager operations).
_valid = eqx.filter_jit(lambda model: model.validate())


def _check_model(model, method="auto"):
    """A one-line `ValueError` for a model or method the gait searches do not cover."""
    from ..mechanics import WalkerModel

    if not isinstance(model, WalkerModel):
        raise ValueError(f"model must be a walker model, got {type(model).__name__}")
    if method == "vhc" and not vhc_applies(model):
        raise ValueError(
            f"the VHC search (Problem 1) is written for the two-DOF compass gait, not "
            f"{type(model).__name__}: use method='auto' or 'shooting'"
        )


def _check_guess_shape(shape, batch, name):
    """A guess is $(a_0, b_0)$ or $(a_0, b_0, f_0)$ (with a leading batch axis for
    `find_gaits`): any other shape is a `ValueError` naming the shapes expected."""
    if len(shape) != len(batch) + 1 or shape[-1] not in (2, 3):
        want = " or ".join(str((*batch, k)).replace("'", "") for k in (2, 3))
        raise ValueError(f"{name} must have shape {want}: (a0, b0) or (a0, b0, f0); got {shape}")


def _chunk_size(B, workers, mesh):
    """Members per dispatch: at most `_MAX_CHUNK` per device; with several host workers
    (CPU cores, `_batching.host_workers`) a batch of more than `_MIN_SPLIT` per worker is
    split into one bucket-sized chunk per worker, so that all cores work."""
    k = device_multiple(mesh)
    chunk = _MAX_CHUNK * k
    if workers > 1 and B > _MIN_SPLIT * workers:
        chunk = min(chunk, bucket_size(-(-B // (workers * k))) * k)
    return chunk


def _batched_axes(model):
    return jax.tree_util.tree_map(
        lambda x: 0 if (eqx.is_array(x) and jnp.ndim(x) > 0) else None, model
    )


@stored_jit
def _search_batch(model, guesses, sign, method, solver, axes, chord, far):
    return _search(model, guesses, sign, method, solver, chord, axes, far)


@stored_jit
def _search_single(model, guess, sign, method, solver, chord, far):
    """`_search` of one member (`model` unbatched), as a batch of one."""
    gait = _search(model, guess, sign, method, solver, chord, far=far)
    return jax.tree_util.tree_map(lambda x: x[None], gait)


def _from_reference(model, sign, method, num=_HOMOTOPY_STEPS):
    """The continuation of `continue_to_model` in `num` steps (`model` in its own units)."""
    s_buf = jnp.linspace(0.0, 1.0, num)
    start, z0 = _seed(model, sign, method)
    gaits = _continue(start, model, s_buf, num, z0, sign, method)
    return jax.tree_util.tree_map(lambda x: x[-1], gaits)


@stored_jit
def _from_reference_batch(model, sign, method, num, axes):
    return eqx.filter_vmap(lambda m: _from_reference(m, sign, method, num), in_axes=(axes,))(model)


def find_gaits(
    model,
    guesses=None,
    family="stable",
    method="auto",
    *,
    psi=None,
    solver="newton",
    mesh=None,
    chord=None,
    far=None,
):
    """Batched `find_gait` over guesses, slopes and model parameters; never raises.

    **Arguments:**

    - `model`: any walker model; any parameter may be an array with a leading batch
      axis.
    - `guesses`: `(B, 2)` (or `(B, 3)`) seeds of the compass gait, `(B, 2n - 1)` section
      points of another model, or `None` for continuation from the model's reference
      gait (per member).
    - `family`, `method`, `solver`: as in `find_gait` (`"auto"`: the VHC search, then
      shooting for the members it missed).
    - `psi`: optional `(B,)` slopes (rad), replacing the model's slope (`with_slope`).
    - `mesh`: a `jax.sharding.Mesh` with a `"batch"` axis; default: all local devices.
    - `chord`: with `guesses`, finish Newton with chord steps (see `vhc_search`).
      `None` (default): where a device holds 64 or more members.
    - `far`: VHC, with `guesses`: see `vhc_search` (`None`: its default; `math.inf`
      for guesses predicted next to a gait, as `sweep` makes them).

    With `solver="newton"` one Newton loop iterates every member of a batch, each member
    stopping at its own convergence; other solvers run by `vmap`.
    Batches are padded (with copies of the first member) to a power of two, rounded up to
    a multiple of the device count, so that nearby sizes share one compiled program;
    larger batches run in chunks of 128 per device, concurrently from one host thread
    per CPU core (XLA runs each program on one core). Each chunk is split over the
    devices of `mesh`. A different split changes the results by rounding only, with the
    same result codes. The searches run in each walker's own units (as `find_gait`).

    Differentiable like `find_gait`; a failed member has zero derivatives.

    **Returns:** a `Gait` with a leading batch axis; check `result` per member and
    `found_by` for the method that found it.
    """
    _check(family, method)
    _check_model(model, method)
    if psi is not None:
        model = model.with_slope(psi)
    params, model = model, detach(model)  # the search itself is never differentiated
    if guesses is not None:
        guesses = detach(jnp.atleast_2d(jnp.asarray(guesses, dtype=float)))
    if vhc_applies(model):
        gaits = _find_in_units(model, guesses, family, method, solver, mesh, chord, far)
    else:
        gaits = _shooting_gaits_of(model, guesses, family, method)
    return with_derivatives(params, gaits, _derivative_method(gaits), family_sign(family))


def _batch_size(model, guesses):
    sizes = [
        jnp.shape(x)[0]
        for x in jax.tree_util.tree_leaves(model)
        if eqx.is_array(x) and jnp.ndim(x) > 0
    ]
    if guesses is not None:
        sizes.append(guesses.shape[0])
    if not sizes:
        raise ValueError("find_gaits needs a batch: guesses, psi or batched model parameters")
    B = max(sizes)
    if B == 0 or any(size not in (1, B) for size in sizes):
        raise ValueError(
            f"find_gaits: the batched inputs (guesses, psi, model parameters) must have one "
            f"length >= 1 (or 1), got lengths {sorted(set(sizes))}"
        )
    return B


def _members(model, B, idx=None):
    """`model` with every batched leaf broadcast to `B` rows (and taken at `idx`)."""

    def take(x):
        if not (eqx.is_array(x) and jnp.ndim(x) > 0):
            return x
        x = jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:])
        return x if idx is None else x[idx]

    return jax.tree_util.tree_map(take, model)


@eqx.filter_jit
def _gaits_in_units(gaits, model):
    B = jnp.shape(gaits.a)[0]
    model = _members(model, B)
    return eqx.filter_vmap(gait_in_units, in_axes=(0, _batched_axes(model)))(gaits, model)


def _find_in_units(model, guesses, family, method, solver, mesh, chord, far):
    """The compass-gait batch in the walkers' own units; with `"auto"`, shooting for the
    members the VHC search missed (every member under `jit`)."""
    B = _batch_size(model, guesses)
    own = model.in_own_units()
    if guesses is not None:
        _check_guess_shape(guesses.shape, ("B",), "guesses")
        ts = jnp.broadcast_to(model.scales()["time"], (B,))
        k = guesses.shape[1]
        guesses = guesses * jnp.concatenate(
            [jnp.ones((B, 1)), jnp.broadcast_to(ts[:, None], (B, k - 1))], axis=1
        )
    first = "vhc" if method == "auto" else method
    gaits = _find_gaits(own, guesses, family, first, solver, mesh, chord, far)
    if method == "auto":
        code = result_codes(gaits.result)
        if isinstance(code, jax.core.Tracer):
            redo = _find_gaits(own, guesses, family, "shooting", solver, mesh, chord, far)
            gaits = _prefer(gaits, redo)
        else:
            code = np.asarray(code)  # bad input is no failure of the VHC search
            idx = np.flatnonzero(
                (code != result_codes(RESULTS.successful))
                & (code != result_codes(RESULTS.bad_input))
            )
            if idx.size:
                sub = _members(own, B, idx)  # a shared model stays shared
                g = None if guesses is None else guesses[idx]
                again = _find_gaits(sub, g, family, "shooting", solver, mesh, chord, far)
                again = jax.tree_util.tree_map(lambda x: x[: idx.size], again)
                gaits = dataclasses.replace(gaits, method="auto")
                missed = jax.tree_util.tree_map(lambda x: x[idx], gaits)
                again = _prefer(missed, dataclasses.replace(again, method="auto"))
                gaits = jax.tree_util.tree_map(
                    lambda a, b: jnp.asarray(a).at[idx].set(b) if eqx.is_array(a) else a,
                    gaits,
                    again,
                )
    gaits = dataclasses.replace(gaits, method=method)  # the label of the call
    return _clean_failed(_gaits_in_units(gaits, model), None, B)


def _shooting_gaits_of(model, guesses, family, method):
    """A batch of a model without a VHC search: `vmap` of the shooting search from
    `guesses`, or `find_gait` (continuation) member by member."""
    B = _batch_size(model, guesses)
    if guesses is None:
        gaits = [find_gait(_members(model, B, i), family, method, throw=False) for i in range(B)]
        return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *gaits)
    model = _members(model, B)
    check_section_shape(model, guesses[0], "guesses[i]")
    gaits = _shooting_batch(model, guesses, family, _batched_axes(model))
    return dataclasses.replace(gaits, method=method)


@eqx.filter_jit
def _shooting_batch(model, guesses, family, axes):
    from ..hybrid import fixed_point

    def one(m, z):
        own = m.in_own_units()
        fp = fixed_point(own, section_in_units(m, z, m.scales()["time"]))
        return gait_in_units(_fixed_point_gait(own, fp, family), m)

    return eqx.filter_vmap(one, in_axes=(axes, 0))(model, guesses)


def _find_gaits(model, guesses, family, method, solver, mesh, chord, far=None):
    far = _FAR if far is None else far
    if not (isinstance(far, float) and math.isinf(far)):  # `inf`: no chart (see vhc_search)
        far = np.asarray(far, float)  # an argument, not a constant
    B = _batch_size(model, guesses)
    sign = family_sign(family)
    if B == 1 and guesses is not None:  # one member: no batching to trace or run
        # the member, unbatched here: a model given with batched parameters and one with
        # scalar ones run one program
        one = jax.tree_util.tree_map(
            lambda x: x[0] if (eqx.is_array(x) and jnp.ndim(x) > 0) else x, model
        )
        gaits = _search_single(one, guesses[0], sign, method, solver, bool(chord), far)
        return _clean_failed(_relabel(gaits, family), guesses, B)
    # one member (a homotopy, no guess) runs alone: a padded batch would repeat its work
    chunk = 1 if B == 1 else _chunk_size(B, host_workers(mesh), mesh)
    if chord is None:  # members per device of one dispatch (every chunk: one program)
        chord = dispatch_size(B, chunk, mesh) // device_multiple(mesh) >= _CHORD_MIN_MEMBERS
    num = _HOMOTOPY_STEPS  # homotopy steps without guesses: as many as the farthest member
    if guesses is None and not any(
        isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model)
    ):  # needs (a power of two: few programs), as `continue_to_model` takes for each one
        num = bucket_size(_homotopy_steps(_seed(model, sign, method)[0], model), _HOMOTOPY_STEPS)
    # every parameter with B rows, varied or not: a study of the slope and one of the hip
    # mass run one program (its key would name which parameters vary)
    batched, shared = eqx.partition(model, eqx.is_array)
    batched = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:]), batched
    )

    def search(params, g):
        m = eqx.combine(params, shared)
        axes = _batched_axes(m)
        if g is None:
            return _from_reference_batch(m, sign, method, num, axes)
        return _search_batch(m, g, sign, method, solver, axes, bool(chord), far)

    gaits = padded_map(search, batched, guesses, max_chunk=chunk, mesh=mesh, stage="gait search")
    gaits = _relabel(gaits, family)
    concrete = not isinstance(result_codes(gaits.result), jax.core.Tracer)  # not under `jit`
    if chord and guesses is not None and concrete:
        gaits = _redo_without_chord(gaits, batched, shared, family, method, solver, mesh, far)
    return _clean_failed(gaits, guesses, B)


def _redo_without_chord(gaits, batched, shared, family, method, solver, mesh, far):
    """Members a chord finish left `not_converged` with a residual below 1e-8 are solved
    again, with Newton steps, from where they stopped: a residual that rounds above
    `SUCCESS_TOL` needs Newton's error estimate to be accepted, and the
    chord steps' Jacobian is too old to give one. (Host-side: not under `jit`.)"""
    code = np.asarray(result_codes(gaits.result))
    redo = np.flatnonzero(
        (code == result_codes(RESULTS.not_converged))
        & (np.asarray(gaits.residual) < _NOISY_RESIDUAL)
    )
    if redo.size == 0:
        return gaits
    params = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[redo], batched)
    start = np.asarray(jax.vmap(lambda g: _unknowns(g, method))(gaits))[redo]
    again = _find_gaits(
        eqx.combine(params, shared), start, family, method, solver, mesh, False, far
    )
    return jax.tree_util.tree_map(lambda a, b: jnp.asarray(a).at[redo].set(b), gaits, again)


@eqx.filter_jit  # one small program, not a dozen operations dispatched one by one
def _clean_failed(gaits, guesses, B=None):
    """Members with a non-finite guess are `bad_input`; failed members hold no NaN or inf:
    their numbers are placeholders (0 where not finite; all 0 for `bad_input`, where
    nothing was computed), the code says why. `B`: batch size (`None`: one gait,
    `guesses` one guess)."""
    if guesses is not None and B is None:
        gaits = eqx.tree_at(
            lambda g: g.result,
            gaits,
            RESULTS.where(jnp.all(jnp.isfinite(guesses)), gaits.result, RESULTS.bad_input),
        )
    elif guesses is not None:
        finite = jnp.broadcast_to(jnp.all(jnp.isfinite(guesses), axis=1), (B,))
        code = jax.vmap(lambda f, r: RESULTS.where(f, r, RESULTS.bad_input))(finite, gaits.result)
        gaits = eqx.tree_at(lambda g: g.result, gaits, code)
    failed = gaits.result != RESULTS.successful
    bad = gaits.result == RESULTS.bad_input

    def clean(x):
        if not eqx.is_inexact_array(x) or jnp.ndim(x) < failed.ndim:
            return x
        f = failed.reshape(failed.shape + (1,) * (x.ndim - failed.ndim))
        b = bad.reshape(bad.shape + (1,) * (x.ndim - bad.ndim))
        return jnp.where((f & ~jnp.isfinite(x)) | b, 0.0, x)

    return jax.tree_util.tree_map(clean, gaits)
