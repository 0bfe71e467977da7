"""Exact derivatives of solutions of nonlinear equations, by the implicit function theorem.

A search (Newton, continuation, bisection) finds $z^*$ with $r(z^*, p) = 0$; its
iterations are never differentiated. Instead the converged values get a `jax.custom_jvp`
whose tangent is
$$\\mathrm d z^* = -\\big(\\partial_z r\\big)^{-1}\\,\\partial_p r\\;\\mathrm dp,$$
and an output $o(z, p)$ gets $\\mathrm d o = (\\partial_z o\\,\\mathrm dz^*/\\mathrm dp +
\\partial_p o)\\,\\mathrm dp$. All partial derivatives come from one forward-mode Jacobian
(`jax.jacfwd`, through diffrax's `ForwardMode` events); the tangent is then a matrix
times $\\mathrm dp$, which JAX can transpose, so `jax.grad`/`jax.jacrev` work as well as
`jax.jvp`/`jax.jacfwd`, although the residual itself contains `while_loop`s that reverse
mode cannot differentiate.

`linearised` wraps any function the same way without a residual (its own Jacobian);
`eigenvalues` gives the eigenvalue perturbation formula
$\\mathrm d\\lambda_i = w_i^H\\,\\mathrm dJ\\,v_i / (w_i^H v_i)$ (simple eigenvalues,
complex pairs included).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from .._programs import stored_jit


def _inexact(x):
    if isinstance(x, float):  # a Python float primal (e.g. `jax.grad(f)(5.0)`)
        return True
    if not eqx.is_array(x) or x.dtype == jax.dtypes.float0:
        return False
    return jnp.issubdtype(x.dtype, jnp.inexact)


def detach(tree):
    """`jax.lax.stop_gradient(tree)` with float leaves as float64 arrays: what a search
    runs on, so that it is never differentiated, and so that a float primal (which
    `jax.grad(f)(5.0)` and `jax.jacfwd` hand over) does not become a compile-time
    constant of a jitted search."""
    tree = jax.lax.stop_gradient(tree)
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, float) if isinstance(x, float) else x, tree
    )


def _as_arrays(tree):
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x) if _inexact(x) else x, tree)


def _flat(tree):
    """The inexact leaves of `tree`, concatenated into one float vector."""
    leaves = [jnp.ravel(x) for x in jax.tree_util.tree_leaves(tree) if _inexact(x)]
    if not leaves:
        return jnp.zeros(0)
    return jnp.concatenate([jnp.asarray(x, float) for x in leaves])


def _unflat(vector, like):
    """`like` with its inexact leaves replaced from `vector` (inverse of `_flat`)."""
    leaves, treedef = jax.tree_util.tree_flatten(like)
    out, i = [], 0
    for x in leaves:
        if _inexact(x):
            size = int(np.prod(jnp.shape(x)))
            out.append(jnp.reshape(vector[i : i + size], jnp.shape(x)).astype(jnp.result_type(x)))
            i += size
        else:
            out.append(x)
    return jax.tree_util.tree_unflatten(treedef, out)


def _tangents(flat_tangent, like):
    """Tangents of the leaves of `like`: from `flat_tangent` for the inexact ones, float0
    zeros for the others (integer codes, booleans)."""
    leaves, treedef = jax.tree_util.tree_flatten(like)
    out, i = [], 0
    for x in leaves:
        if _inexact(x):
            size = int(np.prod(jnp.shape(x)))
            out.append(
                jnp.reshape(flat_tangent[..., i : i + size], jnp.shape(x)).astype(
                    jnp.result_type(x)
                )
            )
            i += size
        else:
            out.append(np.zeros(jnp.shape(x), dtype=jax.dtypes.float0))
    return jax.tree_util.tree_unflatten(treedef, out)


# One compile cache whether called under `jax.grad` or `jax.jacfwd`.
@stored_jit
def _sensitivity(fn, z, params, ok, args, static):
    """$S = \\partial_p o - \\partial_z o\\,(\\partial_z r)^{-1}\\partial_p r$ at $(z, p)$ for
    `fn(z, params, *args) -> (r, o)`, zero where not `ok` or not finite."""
    n = z.shape[0]
    p0 = _flat(params)

    def F(u):
        r, o = fn(u[:n], _unflat(u[n:], params), *args, *static)
        return jnp.concatenate([jnp.ravel(r), _flat(o)])

    Jac = jax.jacfwd(F)(jnp.concatenate([z, p0]))
    Rz, Rp = Jac[:n, :n], Jac[:n, n:]
    Oz, Op = Jac[n:, :n], Jac[n:, n:]
    dzdp = -jnp.linalg.solve(Rz, Rp)
    S = jnp.concatenate([dzdp, Op + Oz @ dzdp])
    good = jnp.asarray(ok) & jnp.all(jnp.isfinite(S))
    return jnp.where(good, S, 0.0)


def implicit_outputs(fn, z, params, values, ok=True, args=(), static=()):
    r"""Attach implicit-function-theorem derivatives to the outputs of a solved equation.

    **Arguments:**

    - `fn`: `fn(z, params, *args, *static) -> (r, o)`, the residual $r(z, p)$ (shape of `z`) and
      the outputs $o(z, p)$ (a pytree); a module-level function (it keys a compile cache).
    - `z`: the converged solution $z^*$ (its own tangent is ignored: pass the value of a
      search run on `jax.lax.stop_gradient(params)`).
    - `params`: a pytree; the derivatives are taken with respect to its inexact leaves.
    - `values`: the outputs at $z^*$ as the search computed them (returned unchanged).
    - `ok`: where False (a failed search), every derivative is zero.
    - `args`: further arguments of `fn` (arrays), not differentiated.
    - `static`: further hashable arguments of `fn` (settings).

    **Returns:** `(z, values)` with tangents $\mathrm dz^* = -(\partial_z r)^{-1}
    \partial_p r\,\mathrm dp$ and $\mathrm do = (\partial_z o\,\mathrm dz^*/\mathrm dp +
    \partial_p o)\,\mathrm dp$ (zero where not `ok`, or where $\partial_z r$ is singular).
    """
    z = jax.lax.stop_gradient(jnp.asarray(z, float))
    values = jax.lax.stop_gradient(values)

    @jax.custom_jvp
    def attach(params, z, values, ok, args):
        return z, values

    @attach.defjvp
    def attach_jvp(primals, tangents):
        params, z, values, ok, args = primals
        dp = _flat(tangents[0])
        params = _as_arrays(params)  # a Python float would be static to the jit below
        S = _sensitivity(fn, z, params, ok, args, static)
        dout = S @ dp
        n = z.shape[0]
        return (z, values), (dout[:n], _tangents(dout[n:], values))

    return attach(params, z, values, ok, args)


def linearised(fn, *static):
    """`fn(*args, *static)` (a pytree function of pytrees) with a JVP given by its
    forward-mode Jacobian (`jax.jacfwd`) times the tangent of the inexact leaves of
    `args`: transposable, so reverse mode works through `fn` even where it contains
    `while_loop`s (diffrax, root finders). The Jacobian is taken with respect to the
    leaves that carry a tangent only (the slope under `jax.grad` of a function of the
    slope, not a feedback law's gain table). `static`: hashable arguments (settings), not
    differentiated. Integer outputs get float0 tangents. `fn` should be a module-level
    function (it keys a compile cache). Leaves of `args` that are not arrays (a Python
    integer in a user's feedback law, say) pass through as constants."""

    def wrapped(*args):
        arrays, rest = eqx.partition(_as_arrays(args), eqx.is_array)

        @jax.custom_jvp
        def call(arrays):
            return _apply(fn, eqx.combine(arrays, rest), static)

        def call_jvp(primals, tangents):
            moves = jax.tree_util.tree_map(lambda t: not _is_zero(t), tangents[0], is_leaf=_is_zero)
            moving, fixed = eqx.partition(primals[0], moves)
            out, J = _jacobian(fn, moving, eqx.combine(fixed, rest), static)
            dmoving = eqx.filter(tangents[0], moves, is_leaf=_is_zero)
            return out, _tangents(J @ _flat(dmoving), out)

        call.defjvp(call_jvp, symbolic_zeros=True)
        return call(arrays)

    return wrapped


def _is_zero(t):
    return isinstance(t, SymbolicZero)


@stored_jit
def _apply(fn, args, static):
    return fn(*args, *static)


@stored_jit
def _jacobian(fn, moving, fixed, static):
    """The outputs of `fn` and their Jacobian with respect to the inexact leaves of
    `moving` (the arguments are `moving` combined with `fixed`)."""

    def flat_and_out(v):  # one trace of `fn`: the outputs ride along as the auxiliary
        out = fn(*eqx.combine(_unflat(v, moving), fixed), *static)
        return _flat(out), out

    J, out = jax.jacfwd(flat_and_out, has_aux=True)(_flat(moving))
    return out, J


def _sorted_eig(J):
    lam, V = jnp.linalg.eig(J)
    order = jnp.argsort(-jnp.abs(lam))
    return lam[order], V[:, order]


@jax.custom_jvp
def eigenvalues(J):
    r"""Eigenvalues of a real square matrix sorted by modulus (descending), complex,
    with the derivative of a simple eigenvalue
    $\mathrm d\lambda_i = (V^{-1}\,\mathrm dJ\,V)_{ii}$ (eigenvalue perturbation; the rows
    of $V^{-1}$ are the left eigenvectors normalised by $w_i^H v_i = 1$). Complex
    conjugate pairs are included; repeated eigenvalues have no derivative. `eig` runs on
    the CPU (JAX implements non-symmetric `eig` there only)."""
    return _sorted_eig(J)[0]


@eigenvalues.defjvp
def _eigenvalues_jvp(primals, tangents):
    (J,), (dJ,) = primals, tangents
    lam, V = _sorted_eig(J)
    W = jnp.linalg.inv(V)
    dlam = jnp.einsum("ij,jk,ki->i", W, dJ.astype(V.dtype), V)
    return lam, dlam


def spectral_radius(lam):
    """$\\max_i |\\lambda_i|$ of `eigenvalues` output (sorted: the first)."""
    return jnp.abs(lam[..., 0])
