"""Newton searches of a gait: one member (`damped_newton`) or a batch in one loop
(`damped_newton_batch`), with the same residual and finish written for one member."""

import equinox as eqx

from .._programs import stored_jit
from ..solvers import damped_newton, damped_newton_batch
from ._gait import _CHORD_BELOW


@stored_jit
def _evaluate_batch(evaluate, config, axes, model, X, T, family):
    """`evaluate(model, x, family, config, tol) -> (residual, aux)` on a batch."""
    member = lambda m, x, t: evaluate(m, x, family, config, t)  # noqa: E731
    return eqx.filter_vmap(member, in_axes=(axes, 0, 0))(model, X, T)


def _newton_search(evaluate, config, family, finish, model, x0, axes, chord, chart=None, **newton):
    """`damped_newton` on one member (`axes=None`) or `damped_newton_batch` on a batch
    (`model` batched along `axes`, `x0`: `(B, n)`) of `evaluate(model, x, family, config, tol)`;
    `finish(model, x, r, aux, iterations, error) -> Gait` is written for one member
    (`error`: Newton's estimate of the error of `x`). `chart = (to_y(model, x),
    from_y(model, y, x), use_y(model, y, r))`: `damped_newton`'s chart, written for one member."""
    newton["chord_below"] = _CHORD_BELOW if chord else None
    if axes is None:

        def member(x, tol):
            return evaluate(model, x, family, config, tol)

        if chart is not None:
            to_y, from_y, use_y = chart
            newton["chart"] = (
                lambda x: to_y(model, x),
                lambda y, x: from_y(model, y, x),
                lambda y, r: use_y(model, y, r),
            )
        return finish(model, *damped_newton(member, x0, **newton))
    fn = lambda X, T: _evaluate_batch(evaluate, config, axes, model, X, T, family)  # noqa: E731
    if chart is not None:
        to_y, from_y, use_y = chart
        newton["chart"] = (
            lambda X: eqx.filter_vmap(to_y, in_axes=(axes, 0))(model, X),
            lambda Y, X: eqx.filter_vmap(from_y, in_axes=(axes, 0, 0))(model, Y, X),
            lambda Y, R: eqx.filter_vmap(use_y, in_axes=(axes, 0, 0))(model, Y, R),
        )
    out = damped_newton_batch(fn, x0, **newton)
    return eqx.filter_vmap(finish, in_axes=(axes, 0, 0, 0, 0, 0))(model, *out)


def _each_member(search, model, guess, axes, family, **kwargs):
    """`search` on every member of a batch by `vmap` (the solvers without a batch loop)."""
    return eqx.filter_vmap(lambda m, g: search(m, g, family, **kwargs), in_axes=(axes, 0))(
        model, guess
    )
