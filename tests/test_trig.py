"""`vhcjax.trig`: sin/cos computed once per evaluation, against numpy, and their
derivatives.

Two independent computations for every claim: values against numpy's `sin`/`cos`;
derivatives of every order against the analytic ones and against central differences;
the compass-gait vector field built on them against the same field built on `jnp.sin`.
"""

import math
import re

import jax
import jax.numpy as jnp
import numpy as np

import vhcjax as vj
from vhcjax import trig
from vhcjax.gait import _problem1

RNG = np.random.default_rng(7)


def test_each_angle_evaluated_once_per_field_evaluation():
    """XLA copies cheap elementwise ops into every fused kernel that reads them; `trig`
    marks its results so that they are computed once. Counted in the optimised HLO of the
    compass-gait `phi''` field, of its forward-mode Jacobian and of its second
    derivative: two angles, so 2 `sin` and 2 `cos` (16 each with plain `jnp.sin`)."""

    model = vj.CompassGait()
    y, E0, th = jnp.array([-0.25, 0.5, 0.0]), jnp.array(1.0), jnp.array(0.2)

    def field(m, th, y, E0):
        return _problem1._phi_field(th, y, (m, E0, 1.0))

    def jac(m, th, y, E0):
        return jax.jacfwd(lambda yy: field(m, th, yy, E0))(y)

    def hess(m, th, y, E0):
        return jax.jacfwd(lambda yy: jac(m, th, yy, E0))(y)

    for fn in (field, jac, hess):
        hlo = jax.jit(fn).lower(model, th, y, E0).compile().as_text()
        ops = re.findall(r"\b(sine|cosine)\(", hlo)
        assert (ops.count("sine"), ops.count("cosine")) == (2, 2), (fn.__name__, ops)


def _ulp_error(got, want):
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))


def test_values_within_one_ulp_of_numpy():
    """XLA's `sin`/`cos` against numpy's, jitted or not, up to |x| = 1e6."""
    x = RNG.uniform(-1e6, 1e6, 100_000)
    x[:1000] = RNG.uniform(-4.0, 4.0, 1000)
    for s, c in (trig.sin_cos(x), jax.jit(trig.sin_cos)(x)):
        assert _ulp_error(np.asarray(s), np.sin(x)).max() <= 1.0
        assert _ulp_error(np.asarray(c), np.cos(x)).max() <= 1.0


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
