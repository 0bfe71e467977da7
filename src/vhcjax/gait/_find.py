"""`find_gait` and `find_gaits`: the gait search as users call it, one gait or a batch."""

import math
import warnings

import equinox as eqx
import jax
import jax.core
import jax.numpy as jnp
import numpy as np

from .._batching import bucket_size, device_multiple, dispatch_size, host_workers, padded_map
from .._programs import stored_jit
from .._results import RESULTS
from ..solvers import detach
from ._continuation import _HOMOTOPY_STEPS, _continue, _seed, _unknowns, continue_to_model
from ._derivatives import with_derivatives
from ._dispatch import _check, _relabel, _search, reference_model
from ._gait import _NOISY_RESIDUAL, family_sign
from ._problem1 import _FAR, _with_psi


def find_gait(model, family="stable", method="vhc", guess=None, *, solver="newton", throw=True):
    """Find the periodic gait of `family` on `model`.

    **Arguments:**

    - `model`: a `CompassGait` (any masses, lengths, gravity, slope).
    - `family`: `"stable"` or `"unstable"` (the root of the energy quadratic, 7.3/7.8).
    - `method`: `"vhc"` (Problem 1) or `"shooting"` (Problem 2).
    - `guess`: $(a_0, b_0)$ (or $(a_0, b_0, f_0)$ for shooting). `None`: continue the
      known default-model gait to `model` (homotopy in the parameters).
    - `solver`: VHC only: `"newton"` (default), `"lm"`, `"optimistix"` or `"optax"`.
    - `throw`: raise if no gait was found (a `ValueError` at once for a non-finite
      guess or an invalid model; with `throw=False` that gait is coded `bad_input`).

    Differentiable (`jax.grad`, `jax.jacfwd`, ...) with respect to every model parameter:
    exact derivatives by the implicit function theorem at the gait, never through the
    search (`vhcjax.solvers.implicit_outputs`).

    **Returns:** a `Gait`.
    """
    _check(family, method)
    _check_model(model)
    batched = [jnp.shape(x) for x in jax.tree_util.tree_leaves(model) if jnp.ndim(x) > 0]
    if batched:
        raise ValueError(
            f"find_gait takes one model (0-d parameters), got parameters of shapes "
            f"{sorted(set(batched))}; find_gaits searches a batch"
        )
    if throw and not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model)):
        if not bool(_valid(model)):  # one line now, not a runtime error later
            raise ValueError(
                "the model has a non-positive or non-finite parameter (masses, lengths, "
                "gravity, slope); with throw=False the gait is coded bad_input"
            )
    params, model = model, detach(model)  # the search itself is never differentiated
    if guess is None:
        gait = continue_to_model(model, family, method)
    else:
        guess = detach(jnp.asarray(guess, dtype=float))
        _check_guess_shape(guess.shape, (), "guess")
        if throw and not isinstance(guess, jax.core.Tracer):
            values = np.asarray(guess)
            if not np.all(np.isfinite(values)):  # one line now, not a runtime error later
                raise ValueError(f"guess must be finite, got {values.tolist()}")
        gait = _search_one_jit(model, guess, family_sign(family), method, solver)
        gait = _relabel(gait, family)
    gait = _clean_failed(gait, guess)
    gait = with_derivatives(params, gait, method, family_sign(family))
    if throw:
        err = gait.result != RESULTS.successful
        gait = eqx.tree_at(lambda g: g.a, gait, gait.result.error_if(gait.a, err))
    return gait


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


_search_one_jit = stored_jit(_search)


#: `model.validate()` as one small program (not a dozen eager operations).
_valid = eqx.filter_jit(lambda model: model.validate())


def _check_model(model):
    """A one-line `ValueError` for a model the gait searches do not cover."""
    from ..models import CompassGait

    if not isinstance(model, CompassGait):
        raise ValueError(
            f"find_gait and find_gaits search gaits of a CompassGait, got "
            f"{type(model).__name__}; for another model use vhcjax.fixed_point (shooting on "
            "its step map)"
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
def _search_single(model, guesses, sign, method, solver, chord, far):
    """`_search` on a batch of one member, unbatched inside."""
    one = jax.tree_util.tree_map(
        lambda x: x[0] if (eqx.is_array(x) and jnp.ndim(x) > 0) else x, model
    )
    gait = _search(one, guesses[0], sign, method, solver, chord, far=far)
    return jax.tree_util.tree_map(lambda x: x[None], gait)


def _from_reference(model, sign, method, num=_HOMOTOPY_STEPS):
    s_buf = jnp.linspace(0.0, 1.0, num)
    gaits = _continue(reference_model(), model, s_buf, num, _seed(sign, method), sign, method)
    return jax.tree_util.tree_map(lambda x: x[-1], gaits)


@stored_jit
def _from_reference_batch(model, sign, method, num, axes):
    return eqx.filter_vmap(lambda m: _from_reference(m, sign, method, num), in_axes=(axes,))(model)


def find_gaits(
    model,
    guesses=None,
    family="stable",
    method="vhc",
    *,
    psi=None,
    solver="newton",
    mesh=None,
    chord=None,
    far=None,
    vectorise=None,
):
    """Batched `find_gait` over guesses, slopes and model parameters; never raises.

    **Arguments:**

    - `model`: a `CompassGait`; any parameter may be an array with a leading batch axis.
    - `guesses`: `(B, 2)` (or `(B, 3)` for shooting) seeds, or `None` for continuation
      from the reference gait (per member).
    - `family`, `method`, `solver`: as in `find_gait`.
    - `psi`: optional `(B,)` slopes (rad), replacing `model.psi`.
    - `mesh`: a `jax.sharding.Mesh` with a `"batch"` axis; default: all local devices.
    - `chord`: with `guesses`, finish Newton with chord steps (see `vhc_search`).
      `None` (default): where a device holds 64 or more members.
    - `far`: VHC, with `guesses`: see `vhc_search` (`None`: its default; `math.inf`
      for guesses predicted next to a gait, as `sweep` makes them).
    - `vectorise`: ignored (every batch is one vectorised Newton loop); kept so that
      existing calls still run.

    With `solver="newton"` one Newton loop iterates every member of a batch, each member
    stopping at its own convergence (`damped_newton_batch`); other solvers run by `vmap`.
    Batches are padded (with copies of the first member) to a power of two, rounded up to
    a multiple of the device count, so that nearby sizes share one compiled program
    (`_batching.padded_map`); larger batches run in chunks of 128 per device,
    concurrently from one host thread per CPU core (`_batching.host_workers`; XLA runs
    each program on one core). Each chunk is split over the devices of `mesh`.
    A different split changes the results by rounding only, with the same result codes.

    Differentiable like `find_gait`; a failed member has zero derivatives.

    **Returns:** a `Gait` with a leading batch axis; check `result` per member.
    """
    _check(family, method)
    _check_model(model)
    if vectorise is not None:
        warnings.warn(
            "find_gaits(vectorise=...) is ignored: every batch is one vectorised Newton loop",
            DeprecationWarning,
            stacklevel=2,
        )
    if psi is not None:
        model = _with_psi(model, jnp.asarray(psi, dtype=float))
    params, model = model, detach(model)  # the search itself is never differentiated
    if guesses is not None:
        guesses = detach(guesses)
    gaits = _find_gaits(model, guesses, family, method, solver, mesh, chord, far)
    return with_derivatives(params, gaits, method, family_sign(family))


def _find_gaits(model, guesses, family, method, solver, mesh, chord, far=None):
    far = _FAR if far is None else far
    if not (isinstance(far, float) and math.isinf(far)):  # `inf`: no chart (see vhc_search)
        far = np.asarray(far, float)  # an argument, not a constant
    sizes = [
        jnp.shape(x)[0]
        for x in jax.tree_util.tree_leaves(model)
        if eqx.is_array(x) and jnp.ndim(x) > 0
    ]
    if guesses is not None:
        guesses = jnp.atleast_2d(jnp.asarray(guesses, dtype=float))
        _check_guess_shape(guesses.shape, ("B",), "guesses")
        sizes.append(guesses.shape[0])
    if not sizes:
        raise ValueError("find_gaits needs a batch: guesses, psi or batched model parameters")
    B = max(sizes)
    if B == 0 or any(size not in (1, B) for size in sizes):
        raise ValueError(
            f"find_gaits: the batched inputs (guesses, psi, model parameters) must have one "
            f"length >= 1 (or 1), got lengths {sorted(set(sizes))}"
        )
    sign = family_sign(family)
    if B == 1 and guesses is not None:  # one member: no batching to trace or run
        gaits = _search_single(model, guesses, sign, method, solver, bool(chord), far)
        return _clean_failed(_relabel(gaits, family), guesses, B)
    # one member (a homotopy, no guess) runs alone: a padded batch would repeat its work
    chunk = 1 if B == 1 else _chunk_size(B, host_workers(mesh), mesh)
    if chord is None:  # members per device of one dispatch (every chunk: one program)
        chord = dispatch_size(B, chunk, mesh) // device_multiple(mesh) >= _CHORD_MIN_MEMBERS
    # the batched parameters, each with B rows; the rest is shared by every member
    batched, shared = eqx.partition(model, lambda x: eqx.is_array(x) and jnp.ndim(x) > 0)
    batched = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:]), batched
    )

    def search(params, g):
        m = eqx.combine(params, shared)
        axes = _batched_axes(m)
        if g is None:
            return _from_reference_batch(m, sign, method, _HOMOTOPY_STEPS, axes)
        return _search_batch(m, g, sign, method, solver, axes, bool(chord), far)

    gaits = padded_map(search, batched, guesses, max_chunk=chunk, mesh=mesh, stage="gait search")
    gaits = _relabel(gaits, family)
    concrete = not isinstance(gaits.result._value, jax.core.Tracer)  # not under `jit`
    if chord and guesses is not None and concrete:
        gaits = _redo_without_chord(gaits, batched, shared, family, method, solver, mesh, far)
    return _clean_failed(gaits, guesses, B)


def _redo_without_chord(gaits, batched, shared, family, method, solver, mesh, far):
    """Members a chord finish left `not_converged` with a residual below 1e-8 are solved
    again, with Newton steps, from where they stopped: a residual that rounds above
    `SUCCESS_TOL` needs Newton's error estimate to be accepted, and the
    chord steps' Jacobian is too old to give one. (Host-side: not under `jit`.)"""
    code = np.asarray(gaits.result._value)
    redo = np.flatnonzero(
        (code == RESULTS.not_converged._value) & (np.asarray(gaits.residual) < _NOISY_RESIDUAL)
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
