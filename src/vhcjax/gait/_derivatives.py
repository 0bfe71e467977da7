"""Exact parameter derivatives of a found gait (implicit function theorem, `vhcjax.solvers.implicit_outputs`).

A `Gait` from `find_gait`/`find_gaits` is a function of the model parameters through
the solution $z^*$ of the search's residual: Problem 1's $(\\phi(c) - g, \\phi'(c) - h/d)$
(thesis 5.20) in $z = (a, b)$, or Problem 2's $P(z) - z$ on the post-impact section. The
search runs on `jax.lax.stop_gradient(model)`; `with_derivatives` then gives the gait's
states, period, energy, step length, speed and energy loss the tangents
$\\mathrm d o = (\\partial_z o\\,\\mathrm dz^*/\\mathrm dp + \\partial_p o)\\,\\mathrm dp$.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.core import Tracer

from .._results import RESULTS
from ..hybrid import DEFAULT_CONFIG, step_unchecked
from ..solvers import implicit_outputs
from ._gait import VHC_CONFIG, _derived
from ._problem1 import _vhc_eval

_FIELDS = ("x_plus", "x_minus", "T", "E0", "step_length", "speed", "energy_loss")


def _outputs(model, x_plus, x_minus, T, E0):
    L, v, loss = _derived(model, x_plus, x_minus, T)
    return {
        "x_plus": x_plus,
        "x_minus": x_minus,
        "T": T,
        "E0": E0,
        "step_length": L,
        "speed": v,
        "energy_loss": loss,
    }


def _vhc_fn(z, model, sign):
    """Problem 1: residual (5.20) in $z = (a, b)$ and the gait it defines."""
    r, bd = _vhc_eval(model, z, sign, VHC_CONFIG)
    return r, _outputs(model, bd.x_plus, bd.x_minus, bd.T, bd.E0)


def _shooting_fn(z, model, sign):
    """Problem 2: $P(z) - z$ on the post-impact section and the gait through $z$."""
    del sign
    x_plus = model.section_to_state(z)
    sr = step_unchecked(model, x_plus, DEFAULT_CONFIG)
    r = model.state_to_section(sr.x_plus) - z
    r = jnp.where(sr.result == RESULTS.successful, r, 1e3 * jnp.ones_like(r))
    return r, _outputs(model, x_plus, sr.x_minus, sr.period, model.energy(x_plus))


def _unknowns(model, gait, method):
    if method == "vhc":
        return jnp.stack([gait.x_plus[0], gait.x_plus[model.n_dof]])
    return model.state_to_section(gait.x_plus)


def _attach_one(model, gait, method, sign):
    fn = _vhc_fn if method == "vhc" else _shooting_fn
    values = {k: getattr(gait, k) for k in _FIELDS}
    ok = gait.result == RESULTS.successful
    _, out = implicit_outputs(fn, _unknowns(model, gait, method), model, values, ok, (sign,))
    n = model.n_dof
    xp, xm = out["x_plus"], out["x_minus"]
    fields = dict(
        out, a=xp[0], b=xp[n], e=xp[1], f=xp[n + 1], c=xm[0], d=xm[n], g=xm[1], h=xm[n + 1]
    )
    return dataclasses.replace(gait, **fields)


def _traced(tree):
    return any(isinstance(x, Tracer) for x in jax.tree_util.tree_leaves(tree))


def with_derivatives(model, gait, method, sign):
    """`gait` (found on `jax.lax.stop_gradient(model)`, batched or not) with implicit
    derivatives with respect to the inexact leaves of `model` attached; values unchanged.
    Outside any JAX transformation of `model` (no tracer among its leaves) nothing can be
    differentiated and `gait` is returned as it is. A batched model has a leading batch
    axis on its batched leaves (as `find_gaits` takes it); failed members get zero
    derivatives and keep their code."""
    if not _traced(model):
        return gait
    sign = jnp.asarray(sign, float)
    if jnp.ndim(gait.a) == 0:
        return _attach_one(model, gait, method, sign)
    axes = jax.tree_util.tree_map(
        lambda x: 0 if (eqx.is_array(x) and jnp.ndim(x) > 0) else None, model
    )
    B = jnp.shape(gait.a)[0]
    model = jax.tree_util.tree_map(
        lambda x: (
            jnp.broadcast_to(x, (B,) + jnp.shape(x)[1:])
            if (eqx.is_array(x) and jnp.ndim(x) > 0)
            else x
        ),
        model,
    )
    return eqx.filter_vmap(lambda m, g: _attach_one(m, g, method, sign), in_axes=(axes, 0))(
        model, gait
    )
