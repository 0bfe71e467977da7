"""Host-side functions: the public functions that run Python loops, numpy or files over
compiled programs (sweeps, bisections, scans, optimisers) and so cannot be part of a
`jit`, `vmap` or derivative trace. Under one they raise a single `TypeError` that names
the function and the traceable function to use instead, before any work starts."""

import functools

import jax
import jax.core


def tracing(tree=()):
    """Whether a call is being traced: a tracer among the leaves of `tree`, or a call
    inside another program (`jit`, `vmap`, a derivative), where even an array made of
    constants is a tracer."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree)) or (
        isinstance(jax.numpy.zeros(()), jax.core.Tracer)
    )


def host_only(instead):
    """Decorator for a host-side public function; `instead` is what to use under a
    transformation (a phrase such as "vmap `find_gait`")."""

    def wrap(fn):
        @functools.wraps(fn)
        def host_function(*args, **kwargs):
            if tracing((args, kwargs)):
                raise TypeError(
                    f"{fn.__name__} runs on the host (concrete inputs, numpy results) and "
                    f"cannot be traced by jit, vmap or a derivative; use {instead} there"
                )
            return fn(*args, **kwargs)

        return host_function

    return wrap
