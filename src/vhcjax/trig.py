"""Sine and cosine as vectorizable float64 polynomials, for model kinematics.

Why this module exists: XLA's CPU backend evaluates float64 `sin`/`cos` by calling the
scalar C library once per element, and it recomputes them inside every fused kernel that
needs them. In the autodiff-derived compass-gait vector field (mass matrix, bias forces)
that is 44 libm calls per evaluation and ~77 % of the run time (measured with `perf`).
Written as plain arithmetic (fdlibm's algorithm: Cody-Waite reduction by pi/2 and the
minimax kernels `__kernel_sin`/`__kernel_cos`), the same functions vectorize and fuse,
and the vector field runs ~2.4x faster. (GPUs have fast native ones; the polynomials cost no more there.)

Accuracy: within 1 ulp of the correctly rounded value for |x| <= 1e6 (checked against
numpy on random points in the tests); for larger |x| the absolute error stays below
ulp(x), the uncertainty of the argument itself (tested to 1e10). `inf` and `nan` give `nan`,
as `jnp.sin` does.

Derivatives are exact (sin' = cos, cos' = -sin) to any order; `sin_cos` is one JAX
primitive, so derivatives of any order add one equation each, not a re-traced polynomial.

The polynomials are used where the library turns them on (`with trig.polynomial():`,
around its multi-step simulations); elsewhere `trig.sin` is
`jnp.sin`, since each polynomial call is ~50 XLA instructions and large graphs (Jacobians
of Jacobians) would compile ~3x slower. Use them in a model's `points`/energies where
`jnp.sin`/`jnp.cos` would go:

    from vhcjax import trig
    hip = l * jnp.stack([-trig.sin(q[0]), trig.cos(q[0])])
"""

import contextlib
import contextvars

import jax
import jax.numpy as jnp
from jax.extend.core import Primitive
from jax.interpreters import ad, batching, mlir

# fdlibm (e_rem_pio2.c, k_sin.c, k_cos.c) constants.
_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of pi/2
_PIO2_1T = 6.07710050650619224932e-11  # pi/2 - _PIO2_1
_PIO2_2 = 6.07710050630396597660e-11  # second 33 bits
_PIO2_2T = 2.02226624879595063154e-21  # pi/2 - (_PIO2_1 + _PIO2_2)
_S1, _S2, _S3, _S4, _S5, _S6 = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C1, _C2, _C3, _C4, _C5, _C6 = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)


def _reduce(x):
    """$x = n\\pi/2 + (y + y_{lo})$ with $|y| \\le \\pi/4$ (two Cody-Waite rounds)."""
    n = jnp.round(x * _INV_PIO2)
    t = x - n * _PIO2_1
    w = n * _PIO2_2
    r = t - w
    w = n * _PIO2_2T - ((t - r) - w)
    y = r - w
    return n, y, (r - y) - w


def _kernel_sin(x, y):
    z = x * x
    v = z * x
    r = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    return x - ((z * (0.5 * y - v * r) - y) - v * _S1)


def _kernel_cos(x, y):
    z = x * x
    r = z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


def _sin_cos_impl(x):
    n, y, lo = _reduce(x)
    s, c = _kernel_sin(y, lo), _kernel_cos(y, lo)
    quadrant = jnp.mod(n, 4.0)
    sin = jnp.where(quadrant == 0, s, jnp.where(quadrant == 1, c, jnp.where(quadrant == 2, -s, -c)))
    cos = jnp.where(quadrant == 0, c, jnp.where(quadrant == 1, -s, jnp.where(quadrant == 2, -c, s)))
    return sin, cos


# One primitive for the pair: a single equation in a jaxpr however deep the derivatives
# go (a `custom_jvp` re-traced the polynomials at every derivative order: 5x the tracing
# time of the compass-gait simulation), lowered to the arithmetic above.
sin_cos_p = Primitive("vhcjax_sin_cos")
sin_cos_p.multiple_results = True
sin_cos_p.def_impl(jax.jit(_sin_cos_impl))  # eager == jitted, bit for bit
sin_cos_p.def_abstract_eval(lambda x: (jax.core.ShapedArray(x.shape, x.dtype),) * 2)
mlir.register_lowering(sin_cos_p, mlir.lower_fun(_sin_cos_impl, multiple_results=True))


def _sin_cos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sin_cos_p.bind(x)
    if type(dx) is ad.Zero:
        zero = ad.Zero.from_primal_value(s)
        return (s, c), (zero, zero)
    return (s, c), (c * dx, -s * dx)


def _sin_cos_batch(args, dims):
    (x,), (d,) = args, dims
    return sin_cos_p.bind(x), (d, d)


ad.primitive_jvps[sin_cos_p] = _sin_cos_jvp
batching.primitive_batchers[sin_cos_p] = _sin_cos_batch


_POLYNOMIAL = contextvars.ContextVar("vhcjax_trig_polynomial", default=False)


@contextlib.contextmanager
def polynomial(enabled=True):
    """Within this block, functions *traced* evaluate `sin`/`cos` by the polynomials;
    outside it they lower to XLA's own `sin`/`cos` (one instruction each).

    The library turns it on where vector fields are evaluated millions of times: the
    multi-step simulations (`simulate`, `simulate_batch`, `recover`, hence basins,
    bifurcation diagrams, pushes and floor steps). Elsewhere (single steps, Jacobians of
    the step map, the VHC residual, the transverse linearization) graphs are large and
    run rarely, and ~50 instructions per call would triple XLA's compile time for nothing.
    Both paths agree to 1 ulp. The choice is made when JAX traces a function; a trace
    that JAX has cached keeps the choice it was made with.
    """
    token = _POLYNOMIAL.set(bool(enabled))
    try:
        yield
    finally:
        _POLYNOMIAL.reset(token)


def sin_cos(x):
    """`(sin x, cos x)` elementwise, in float64 (see `polynomial` for which evaluation)."""
    x = jnp.asarray(x, dtype=float)
    if _POLYNOMIAL.get():
        return tuple(sin_cos_p.bind(x))
    return jnp.sin(x), jnp.cos(x)


def sin(x):
    """$\\sin x$, elementwise (float64, within 1 ulp for $|x| \\le 10^6$)."""
    return sin_cos(x)[0]


def cos(x):
    """$\\cos x$, elementwise (float64, within 1 ulp for $|x| \\le 10^6$)."""
    return sin_cos(x)[1]
