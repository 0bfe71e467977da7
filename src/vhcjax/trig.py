"""Sine and cosine for model kinematics, each evaluated once per call.

Why this module exists: XLA counts `sin` and `cos` as cheap and copies them into every
fused kernel that reads them. In the autodiff-derived compass-gait `phi''` field each
angle's `sin` and `cos` were evaluated 8 times (16 `sin`, 16 `cos` in the optimised HLO
for two angles; 32 each in its Jacobian), and on a CPU each is a scalar libm call.
`sin_cos` marks its results so that XLA computes each angle's pair once per evaluation
(2 `sin`, 2 `cos`; tested), and its derivative reuses the same pair (a `jax.custom_jvp`).
`python benchmarks/bench_simulate.py --trig plain` measures what this buys against plain
`jnp.sin`/`jnp.cos`.

Derivatives are exact (sin' = cos, cos' = -sin) to any order, forward and reverse. Use
these functions in a model's `points`/energies where `jnp.sin`/`jnp.cos` would go:

    from vhcjax import trig
    hip = l * jnp.stack([-trig.sin(q[0]), trig.cos(q[0])])
"""

import jax
import jax.numpy as jnp


def _once(values, x):
    """`values` (functions of `x`), each evaluated once per call in compiled code.

    A floating-point division counts as expensive for XLA and is never copied into the
    kernels that read it, so dividing by a 1 that XLA cannot fold (`1 + 0 x`: `0 x` is
    not 0 for infinite or NaN `x`) makes each value a kernel output, computed once and
    read by the others. Exact: `v / 1 == v`.
    """
    one = 1.0 + 0.0 * x
    return tuple(v / one for v in values)


@jax.custom_jvp
def _sin_cos(x):
    return _once((jnp.sin(x), jnp.cos(x)), x)


@_sin_cos.defjvp
def _sin_cos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = _sin_cos(x)
    return (s, c), (c * dx, -s * dx)


def sin_cos(x):
    """`(sin x, cos x)` elementwise, in float64, each computed once per call."""
    return _sin_cos(jnp.asarray(x, dtype=float))


def sin(x):
    """$\\sin x$, elementwise (float64)."""
    return sin_cos(x)[0]


def cos(x):
    """$\\cos x$, elementwise (float64)."""
    return sin_cos(x)[1]
