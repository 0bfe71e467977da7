"""`vhcjax.trig`: polynomial sin/cos against numpy (libm), and their derivatives.

The polynomials are active inside `trig.polynomial()` (the library turns it on around its
multi-step simulations); the fixture below turns it on for every test here.

Two independent computations for every claim: values against numpy's `sin`/`cos`;
derivatives of every order against the analytic ones and against central differences;
the compass-gait vector field built on them against the same field built on `jnp.sin`.
"""

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax import trig
from vhcjax.gait import _problem1

RNG = np.random.default_rng(7)


@pytest.fixture(autouse=True)
def _polynomial():
    with trig.polynomial():
        yield


def test_switch_selects_the_evaluation():
    x = jnp.array([0.3])
    # fresh lambdas: JAX caches traces per function, and the switch acts at trace time
    prims = str(jax.make_jaxpr(lambda v: trig.sin(v))(x))
    assert "vhcjax_sin_cos[polynomial=True]" in prims
    assert " sin" not in jax.jit(lambda v: trig.sin(v)).lower(x).as_text()
    with trig.polynomial(False):
        native = str(jax.make_jaxpr(lambda v: trig.sin(v))(x))
        assert "stablehlo.sine" in jax.jit(lambda v: trig.sin(v)).lower(x).as_text()
    assert "vhcjax_sin_cos[polynomial=False]" in native


@pytest.mark.parametrize("polynomial", [False, True])
def test_each_angle_evaluated_once_per_field_evaluation(polynomial):
    """XLA copies cheap elementwise ops into every fused kernel that reads them; `trig`
    marks its results so that they are computed once. Counted in the optimised HLO of the
    compass-gait `phi''` field and of its forward-mode Jacobian: two angles, so 2 `sin`
    and 2 `cos` with libm (16 each before), and the polynomial's Cody-Waite rounding
    (`round-nearest-even`) twice, once per angle."""

    model = vj.CompassGait()
    y, E0, th = jnp.array([-0.25, 0.5, 0.0]), jnp.array(1.0), jnp.array(0.2)

    def field(m, th, y, E0):
        return _problem1._phi_field(th, y, (m, E0, 1.0))

    def jac(m, th, y, E0):
        return jax.jacfwd(lambda yy: field(m, th, yy, E0))(y)

    with trig.polynomial(polynomial):
        for fn in (field, jac):
            hlo = jax.jit(fn).lower(model, th, y, E0).compile().as_text()
            ops = re.findall(r"\b(sine|cosine|round-nearest-even)\(", hlo)
            if polynomial:
                assert ops.count("round-nearest-even") == 2, ops
                assert "sine" not in ops
            else:
                assert (ops.count("sine"), ops.count("cosine")) == (2, 2), ops


def test_simulation_uses_the_polynomials():
    model = vj.CompassGait()
    x0 = jnp.array([0.2186688, -0.32338856, -1.09238359, -0.37737395])
    with trig.polynomial(False):  # the library turns it on by itself around the swing solve
        jaxpr = str(jax.make_jaxpr(lambda x: vj.simulate(model, x, 1).steps.period)(x0))
    assert "vhcjax_sin_cos[polynomial=True]" in jaxpr
    # ... but not in single steps and their Jacobians (compile time of large graphs)
    with trig.polynomial(False):
        jac = str(jax.make_jaxpr(jax.jacfwd(lambda x: vj.step(model, x, throw=False).x_plus))(x0))
    assert "polynomial=False" in jac and "polynomial=True" not in jac


def _ulp_error(got, want):
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))


@pytest.mark.parametrize("radius", [1.0, 100.0, 1e6])
def test_within_one_ulp_of_libm(radius):
    x = RNG.uniform(-radius, radius, 200_000)
    s, c = jax.jit(trig.sin_cos)(x)
    assert _ulp_error(np.asarray(s), np.sin(x)).max() <= 1.0
    assert _ulp_error(np.asarray(c), np.cos(x)).max() <= 1.0


@pytest.mark.parametrize("radius", [1e8, 1e10])
def test_large_arguments_error_below_ulp_of_argument(radius):
    x = RNG.uniform(-radius, radius, 100_000)
    for s, c in (trig.sin_cos(x), jax.jit(trig.sin_cos)(x)):
        assert np.all(np.abs(np.asarray(s) - np.sin(x)) <= np.spacing(np.abs(x)))
        assert np.all(np.abs(np.asarray(c) - np.cos(x)) <= np.spacing(np.abs(x)))


def test_special_values_and_dtypes():
    x = jnp.array([np.inf, -np.inf, np.nan, 0.0, np.pi / 2, np.pi])
    s, c = trig.sin(x), trig.cos(x)
    assert np.all(np.isnan(s[:3])) and np.all(np.isnan(c[:3]))
    np.testing.assert_allclose(s[3:], np.sin(np.asarray(x[3:])), atol=1e-16)
    np.testing.assert_allclose(c[3:], np.cos(np.asarray(x[3:])), atol=1e-16)
    assert trig.sin(3).dtype == jnp.float64 and trig.cos(np.float32(1)).dtype == jnp.float64
    assert trig.sin(jnp.ones((2, 3))).shape == (2, 3)


def test_derivatives_all_orders():
    x = 0.7
    d1 = jax.grad(trig.sin)
    d2 = jax.grad(d1)
    d3 = jax.grad(d2)
    assert abs(d1(x) - math.cos(x)) < 1e-16
    assert abs(d2(x) + math.sin(x)) < 1e-16
    assert abs(d3(x) + math.cos(x)) < 1e-16
    assert abs(jax.grad(trig.cos)(x) + math.sin(x)) < 1e-16
    # central differences of the function itself (independent of the jvp rule)
    h = 1e-6
    fd = (np.asarray(trig.sin(x + h)) - np.asarray(trig.sin(x - h))) / (2 * h)
    assert abs(fd - d1(x)) < 1e-9
    # forward, reverse and batched derivatives agree
    v = jnp.array([0.3, -1.2, 2.5])
    f = lambda v: trig.sin(v) * trig.cos(2 * v)  # noqa: E731
    np.testing.assert_allclose(jax.jacfwd(f)(v), jax.jacrev(f)(v), atol=1e-15)
    np.testing.assert_allclose(
        jax.vmap(jax.grad(lambda s: f(s)))(v),
        jax.vmap(jax.grad(lambda s: jnp.sin(s) * jnp.cos(2 * s)))(v),
        atol=1e-15,
    )


def test_compass_gait_field_unchanged():
    """The vector field and impact map on `trig` equal those on `jnp.sin`/`jnp.cos`."""

    class LibmCompassGait(vj.CompassGait):
        def points(self, q):
            q1, q2 = q[0], q[1]
            hip = self.l * jnp.stack([-jnp.sin(q1), jnp.cos(q1)])
            down2 = jnp.stack([jnp.sin(q2), -jnp.cos(q2)])
            return {
                "stance_foot": jnp.zeros(2, hip.dtype),
                "stance_mass": self.b * jnp.stack([-jnp.sin(q1), jnp.cos(q1)]),
                "hip": hip,
                "swing_mass": hip + self.a * down2,
                "swing_foot": hip + self.l * down2,
            }

    psi = math.radians(3.0)
    ours, libm = vj.CompassGait(psi=psi), LibmCompassGait(psi=psi)
    xs = RNG.normal(size=(50, 4))
    f1 = jax.vmap(lambda x: ours.vector_field(0.0, x))(xs)
    f2 = jax.vmap(lambda x: libm.vector_field(0.0, x))(xs)
    np.testing.assert_allclose(f1, f2, rtol=1e-13, atol=1e-13)
    i1 = jax.vmap(lambda x: ours.impact(x)[0])(xs)
    i2 = jax.vmap(lambda x: libm.impact(x)[0])(xs)
    np.testing.assert_allclose(i1, i2, rtol=1e-12, atol=1e-12)
