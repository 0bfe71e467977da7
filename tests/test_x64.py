"""float64 turned off after import is caught at the call, in one line, with the fix
(before any solve: it used to end in a wrong result code after the whole search)."""

import jax
import jax.numpy as jnp
import pytest

import vhcjax as vj


@pytest.mark.parametrize(
    "call",
    [
        lambda m: vj.find_gait(m, "stable"),
        lambda m: vj.simulate(m, jnp.array([0.2187, -0.3234, -1.0924, -0.3774]), 3),
        lambda m: vj.fixed_point(m, jnp.array([0.2187, -1.0924, -0.3774])),
    ],
    ids=["find_gait", "simulate", "fixed_point"],
)
def test_float64_off_is_refused_at_the_call(call):
    model = vj.CompassGait()
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError) as info:
            call(model)
    finally:
        jax.config.update("jax_enable_x64", True)
    message = str(info.value)
    assert "float64" in message and "jax_enable_x64" in message and "\n" not in message
