"""Shooting (thesis Problem 2): Newton on the step-to-step map of the hybrid simulation
on the post-impact section."""

import equinox as eqx
import jax.numpy as jnp

from .. import hybrid as _poincare
from .._programs import stored_jit
from .._results import RESULTS
from ..hybrid import DEFAULT_CONFIG, step_unchecked
from ._gait import _LOOSE_TOL, _RESIDUAL_CAP, _label, _make_gait, accepted
from ._newton_search import _each_member, _newton_search
from ._problem1 import _with_tolerance, on_other_root, solve_for_d, velocity_relations


# ---------------------------------------------------------------------------------------
# Shooting (Problem 2)
# ---------------------------------------------------------------------------------------
@stored_jit
def complete_guess(model, ab, family="stable"):
    """Section coordinates $(a, b, f)$ of a guess $(a, b)$: $d$ from the energy quadratic
    with the `family` root, then $f$ from the impact relations (5.9). A seed for shooting
    that uses no integration."""
    ab = jnp.asarray(ab, dtype=float)
    d, _ = solve_for_d(model, ab[0], ab[1], family)
    f, _ = velocity_relations(model, ab[0], ab[1], d)
    return jnp.stack([ab[0], ab[1], f])


def _shoot_eval(model, z, config=DEFAULT_CONFIG, tol=None):
    sr = step_unchecked(model, model.section_to_state(z), _with_tolerance(config, tol))
    r = model.state_to_section(sr.x_plus) - z
    return jnp.where(sr.result == RESULTS.successful, r, 1e3 * jnp.ones_like(r)), sr


def _shoot_member(model, z, family, config, tol):
    """`_shoot_eval` with the signature of a Newton search's member (`family` unused)."""
    del family
    return _shoot_eval(model, z, config, tol)


def shooting_search(
    model,
    guess,
    family="stable",
    *,
    solver="newton",
    rtol=1e-12,
    atol=1e-12,
    max_steps=40,
    config=DEFAULT_CONFIG,
    chord=False,
    axes=None,
):
    """Solve Problem 2, $P(z) = z$ for the step-to-step map $P$ on the post-impact section
    (`step_map`), from `guess` (pure; never raises).

    `guess` is $(a_0, b_0, f_0)$ on the post-impact section, or $(a_0, b_0)$, completed
    with $d$ the `family` root of the energy quadratic (5.13) and $f$ from the impact
    relations (5.9). `solver="newton"` uses the library's damped Newton method
    (forward-mode Jacobian through the heel-strike event, steps damped
    Levenberg-Marquardt style where a full step fails); `"optimistix"` uses
    `fixed_point` (plain `optx.Newton`). The `family` label is checked:
    a fixed point whose $d$ is the other root of (5.13) gets `RESULTS.other_cycle`.
    `chord`: as in `vhc_search` (1.6-1.8x the batched throughput). `axes`: a batch of guesses,
    as in `vhc_search`.

    **Returns:** a `Gait` (`method="shooting"`).
    """
    guess = jnp.asarray(guess, dtype=float)
    if axes is not None and solver != "newton":
        return _each_member(
            shooting_search,
            model,
            guess,
            axes,
            family,
            solver=solver,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            config=config,
        )
    z0 = _section_points(model, guess, family, axes)
    if solver == "newton":
        return _shooting_newton(
            model, z0, family, config, chord, axes, rtol=rtol, atol=atol, max_steps=max_steps
        )
    if solver != "optimistix":
        raise ValueError(f"solver must be 'newton' or 'optimistix' for shooting, got {solver!r}")
    fp = _poincare.fixed_point(
        model, z0, 1, rtol=rtol, atol=atol, max_steps=max_steps, config=config
    )
    sr = step_unchecked(model, fp.x0, config)
    return _shooting_gait(
        model,
        fp.x0,
        sr.x_minus,
        fp.periods[0],
        fp.iterations,
        fp.residual,
        fp.result,
        family,
        sr.result != RESULTS.bad_impact,
    )


def _section_points(model, guess, family, axes=None):
    """Guesses on the post-impact section: `(a, b, f)` as given, `(a, b)` completed by
    `complete_guess` (per member when `axes` gives a batch)."""
    if guess.shape[-1] == 3:
        return guess
    if axes is None:
        return complete_guess(model, guess, family)
    complete = lambda m, g: complete_guess(m, g, family)  # noqa: E731
    return eqx.filter_vmap(complete, in_axes=(axes, 0))(model, guess)


def _shooting_newton(
    model,
    z0,
    family,
    config=DEFAULT_CONFIG,
    chord=False,
    axes=None,
    rtol=1e-12,
    atol=1e-12,
    max_steps=40,
):
    """`shooting_search` with `solver="newton"` from section points `z0`."""

    def finish(model, z, r, sr, iters, error):
        res = jnp.max(jnp.abs(r))
        ok = (sr.result == RESULTS.successful) & jnp.isfinite(z).all()
        code = RESULTS.where(
            sr.result != RESULTS.successful,
            sr.result,
            RESULTS.where(ok & accepted(res, error), RESULTS.successful, RESULTS.not_converged),
        )
        return _shooting_gait(
            model,
            model.section_to_state(z),
            sr.x_minus,
            sr.period,
            iters,
            res,
            code,
            family,
            sr.result != RESULTS.bad_impact,
        )

    return _newton_search(
        _shoot_member,
        config,
        family,
        finish,
        model,
        z0,
        axes,
        chord,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        tolerances=(_LOOSE_TOL, config.rtol),
        residual_cap=_RESIDUAL_CAP,
    )


def _shooting_gait(model, x_plus, x_minus, T, iters, res, code, family, physical):
    """`physical`: the step's impact was checked (`step_unchecked` flags `RESULTS.bad_impact`)."""
    E0 = model.energy(x_plus)
    wrong = on_other_root(model, x_plus, x_minus, family)  # the root of (5.13) of its d
    code = RESULTS.where((code == RESULTS.successful) & wrong, RESULTS.other_cycle, code)
    return _make_gait(
        model, x_plus, x_minus, T, E0, iters, res, code, _label(family), "shooting", physical
    )
