import jax
import pytest

import vhcjax  # noqa: F401  (enables float64)


def pytest_configure(config):
    assert jax.config.jax_enable_x64, "vhcjax must enable float64 on import"


@pytest.fixture(scope="session")
def model():
    return vhcjax.CompassGait()
