"""Sine and cosine for model kinematics: evaluated once per call, libm or polynomials.

Why this module exists: XLA counts `sin` and `cos` as cheap and copies them into every
fused kernel that reads them. In the autodiff-derived compass-gait `phi''` field each
angle's `sin` and `cos` were evaluated 8 times (16 `sin`, 16 `cos` in the optimised HLO
for two angles; 32 each in its Jacobian), and on CPU each is a scalar libm call: ~40 % of
the batched gait-search run time (measured with `perf`). `sin_cos` is one JAX primitive
whose results are marked expensive for XLA (see `_once`), so each angle's pair is
computed once per evaluation (2 `sin`, 2 `cos`; tested); the gait searches ran 2x
faster and the simulation 1.5x.

Two evaluations, chosen when a function is traced:

- libm (XLA's own `sin`/`cos`), the default;
- polynomials (`with trig.polynomial():`): fdlibm's algorithm (Cody-Waite reduction by
  pi/2 and the minimax kernels `__kernel_sin`/`__kernel_cos`) written as plain
  arithmetic, which vectorizes. The library turns them on around its multi-step
  simulations; in the large graphs of the searches and Jacobians they cost ~1 s more
  compile time and run no faster. (GPUs have fast native ones; the polynomials cost no
  more there.)

Accuracy of the polynomials: within 1 ulp of the correctly rounded value for
|x| <= 1e6 (checked against numpy on random points in the tests); for larger |x| the
absolute error stays below ulp(x), the uncertainty of the argument itself (tested to
1e10). `inf` and `nan` give `nan`, as `jnp.sin` does.

Derivatives are exact (sin' = cos, cos' = -sin) to any order; derivatives of any order
add one equation each, not a re-traced function. Use them in a model's
`points`/energies where `jnp.sin`/`jnp.cos` would go:

    from vhcjax import trig
    hip = l * jnp.stack([-trig.sin(q[0]), trig.cos(q[0])])
"""

import contextlib
import contextvars

import jax
import jax.numpy as jnp
from jax.core import ShapedArray
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
    (n,) = _once((jnp.round(x * _INV_PIO2),), x)  # shared by the sin and cos kernels
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


def _once(values, x):
    """`values` (functions of `x`), each evaluated once per call in compiled code.

    XLA counts `sin`, `cos` and the polynomial arithmetic as cheap and copies them into
    every fused kernel that reads them: in the compass-gait `phi''` field each angle's
    `sin` was evaluated 8 times (16 `sin` and 16 `cos` for two angles in the optimised
    HLO). A floating-point division counts as expensive and is never copied, so dividing
    by a 1 that XLA cannot fold (`1 + 0 x`: `0 x` is not 0 for infinite or NaN `x`) makes
    each value a kernel output, computed once and read by the others (2 `sin`, 2 `cos`).
    Exact: `v / 1 == v`.
    """
    one = 1.0 + 0.0 * x
    return tuple(v / one for v in values)


def _sin_cos_poly(x):
    return _once(_sin_cos_impl(x), x)


def _sin_cos_libm(x):
    return _once((jnp.sin(x), jnp.cos(x)), x)


_LOWERINGS = {
    True: mlir.lower_fun(_sin_cos_poly, multiple_results=True),
    False: mlir.lower_fun(_sin_cos_libm, multiple_results=True),
}


# One primitive for the pair: a single equation in a jaxpr however deep the derivatives
# go (a `custom_jvp` re-traced the polynomials at every derivative order: 5x the tracing
# time of the compass-gait simulation), lowered to the polynomials or to libm.
sin_cos_p = Primitive("vhcjax_sin_cos")
sin_cos_p.multiple_results = True
_IMPLS = {True: jax.jit(_sin_cos_poly), False: jax.jit(_sin_cos_libm)}
sin_cos_p.def_impl(lambda x, *, polynomial: _IMPLS[polynomial](x))  # eager == jitted
sin_cos_p.def_abstract_eval(lambda x, **_: (ShapedArray(x.shape, x.dtype),) * 2)
mlir.register_lowering(sin_cos_p, lambda ctx, x, *, polynomial: _LOWERINGS[polynomial](ctx, x))


def _sin_cos_jvp(primals, tangents, *, polynomial):
    (x,), (dx,) = primals, tangents
    s, c = sin_cos_p.bind(x, polynomial=polynomial)
    if type(dx) is ad.Zero:
        zero = ad.Zero(jax.typeof(s).to_tangent_aval())
        return (s, c), (zero, zero)
    return (s, c), (c * dx, -s * dx)


def _sin_cos_batch(args, dims, *, polynomial):
    (x,), (d,) = args, dims
    return sin_cos_p.bind(x, polynomial=polynomial), (d, d)


ad.primitive_jvps[sin_cos_p] = _sin_cos_jvp
batching.primitive_batchers[sin_cos_p] = _sin_cos_batch


_POLYNOMIAL = contextvars.ContextVar("vhcjax_trig_polynomial", default=False)


@contextlib.contextmanager
def polynomial(enabled=True):
    """Within this block, functions *traced* evaluate `sin`/`cos` by the polynomials;
    outside it they lower to XLA's own `sin`/`cos`.

    The library turns it on where vector fields are evaluated millions of times: the
    multi-step simulations (`simulate`, `simulate_batch`, `recover`, hence basins,
    bifurcation diagrams, pushes and floor steps). Elsewhere (single steps, Jacobians of
    the step map, the gait searches, the transverse linearization) graphs are large, and
    ~50 instructions per call cost compile time (~1 s more for a gait search, which ran
    no faster).
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
    return tuple(sin_cos_p.bind(x, polynomial=_POLYNOMIAL.get()))


def sin(x):
    """$\\sin x$, elementwise (float64, within 1 ulp for $|x| \\le 10^6$)."""
    return sin_cos(x)[0]


def cos(x):
    """$\\cos x$, elementwise (float64, within 1 ulp for $|x| \\le 10^6$)."""
    return sin_cos(x)[1]
