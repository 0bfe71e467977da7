"""`vhcjax._compile.filter_jit`: XLA options on top-level calls, plain `eqx.filter_jit`
when nested, same results either way."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import vhcjax  # noqa: F401  (float64)
from vhcjax import _compile
def _f(x, scale):
    return jnp.sin(x) * scale + jnp.cumsum(x**2)


def test_options_on_cpu_and_opt_out(monkeypatch):
    opts = _compile.compiler_options()
    background = _compile.compiler_options(background=True)
    if jax.default_backend() == "cpu":
        # Either this XLA knows the options (they are used) or the probe turned them off.
        assert opts in (None, _compile.CPU_COMPILER_OPTIONS)
        both = {**_compile.CPU_COMPILER_OPTIONS, **_compile.CPU_BACKGROUND_OPTIONS}
        assert background in (opts, both)
    monkeypatch.setenv("VHCJAX_XLA_OPTIONS", "0")
    assert _compile._choose() == (None, None)


def test_top_level_nested_and_vmapped_calls_agree_with_eqx_filter_jit():
    f = _compile.filter_jit(_f)
    x = jnp.linspace(0.0, 1.0, 7)
    ref = eqx.filter_jit(_f)(x, 2.0)
    np.testing.assert_allclose(f(x, 2.0), ref, rtol=1e-15, atol=1e-15)
    # Inside another jit (only a top-level jit takes compile options) and under vmap.
    nested = jax.jit(lambda y: f(y, 2.0))(x)
    np.testing.assert_allclose(nested, ref, rtol=1e-15, atol=1e-15)
    batched = jax.vmap(lambda y: f(y, 2.0))(jnp.stack([x, x]))
    np.testing.assert_allclose(batched, jnp.stack([ref, ref]), rtol=1e-15, atol=1e-15)
    assert f.lower(x, 2.0).compile() is not None


def test_decorator_form_keeps_jit_keywords():
    @_compile.filter_jit(donate="none")
    def g(x):
        return 2.0 * x

    np.testing.assert_array_equal(g(jnp.arange(3.0)), jnp.array([0.0, 2.0, 4.0]))
