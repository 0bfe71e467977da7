"""The generic phi'' ODE and the Problem-1 algebra against the thesis closed forms."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax import gait as G
from vhcjax.gait import _vhc as _vhc


def thesis_f0(p, E0, theta, phi, Dphi):
    """Appendix C.3, `function Dx = f0(theta, x, E0)`, copied term by term."""
    p1, p2, p3, p4, p5 = (p[k] for k in ("p1", "p2", "p3", "p4", "p5"))
    cos, sin = np.cos, np.sin
    return (
        -1.0
        / (-p1 * p3 + cos(-theta + phi) ** 2 * p2**2)
        * (
            -cos(-theta + phi) * p2**2 * sin(-theta + phi) * Dphi
            + p3 * sin(-theta + phi) * p2 * Dphi**3
            - cos(-theta + phi) * p2**2 * sin(-theta + phi) * Dphi**2
            + p1 * sin(-theta + phi) * p2
        )
        - 1.0
        / (-p1 * p3 + cos(-theta + phi) ** 2 * p2**2)
        / (E0 - cos(theta) * p4 - p5 + cos(phi) * p5 + p4)
        * (
            -sin(theta) * p4 * p3 * Dphi
            + sin(theta) * p4 * p2 * cos(-theta + phi)
            + sin(phi) * p5 * cos(-theta + phi) * p2 * Dphi
            - sin(phi) * p5 * p1
        )
        * (p1 + p3 * Dphi**2 - 2.0 * p2 * cos(-theta + phi) * Dphi)
        / 2.0
    )


MODELS = [
    vj.CompassGait(),
    vj.CompassGait(m1=3.0, m2=4.0, mH=12.0, a=0.4, b=0.7, g=9.0, psi=math.radians(4.5)),
]


@pytest.mark.parametrize("model", MODELS)
def test_phi_ode_equals_thesis_f0(model):
    rng = np.random.default_rng(0)
    p = {k: float(v) for k, v in model.parameters().items()}
    f = jax.jit(
        lambda E0, th, ph, dph: _vhc.phi_second_derivative(model, E0, th, ph[None], dph[None])[0][0]
    )
    for _ in range(50):
        theta, phi = rng.uniform(-0.5, 0.5, 2)
        dphi = rng.uniform(-3.0, 3.0)
        E0 = rng.uniform(5.0, 15.0)
        got = float(f(E0, theta, jnp.asarray(phi), jnp.asarray(dphi)))
        want = thesis_f0(p, E0, theta, phi, dphi)
        assert abs(got - want) <= 1e-12 * max(1.0, abs(want)), (got, want)


def _thesis_fh(p, psi, a, b, d):
    """Thesis (5.9)."""
    c = np.cos(2 * a + 2 * psi)
    f = (p["p7"] * c * b - p["p9"] * d) / p["p8"]
    h = (
        (p["p7"] ** 2 * c**2 - p["p6"] * p["p8"]) * b
        + (p["p8"] * p["p10"] - p["p7"] * p["p9"]) * c * d
    ) / (p["p8"] * p["p11"])
    return f, h


def _thesis_abc(p, psi, a, b):
    """Appendix C.3 `solving_E0_for_d` (A2, B2, C2), identical to (5.14)."""
    p1, p2, p3, p4, p5, p6, p7, p8, p9, p10, p11 = (p[f"p{i}"] for i in range(1, 12))
    c = np.cos(2 * a + 2 * psi)
    A = (
        (p8 * p10 - p9 * p7) ** 2 / p8**2 / p11**2 * c**2 * p3 / 2
        - p9**2 / p8**2 * p3 / 2
        + p1 / 2
        - (p8 * p10 - p9 * p7) / p8 / p11 * c**2 * p2
    )
    B = (
        -p9 / p8 * c * p2 * b
        - (p7**2 / p8 / p11 * c**2 - p6 / p11) * b * c * p2
        + (p7**2 / p8 / p11 * c**2 - p6 / p11) * b * (p8 * p10 - p9 * p7) / p8 / p11 * c * p3
        + b * p7 * c * p9 / p8**2 * p3
    )
    C = (
        -p1 * b**2 / 2
        - np.cos(a) * p4
        + (p7**2 / p8 / p11 * c**2 - p6 / p11) ** 2 * b**2 * p3 / 2
        - np.cos(a) * p5
        + b**2 * p7 * c**2 / p8 * p2
        + np.cos(a + 2 * psi) * p4
        + np.cos(a + 2 * psi) * p5
        - b**2 * p7**2 * c**2 / p8**2 * p3 / 2
    )
    return A, B, C


@pytest.mark.parametrize("model", MODELS)
def test_impact_relations_and_energy_quadratic_match_thesis(model):
    """f, h from the autodiff impact map == (5.9); A, B, C from three energy evaluations ==
    (5.14); the selector-2 root is the stable one, the selector-1 root the unstable one."""
    rng = np.random.default_rng(1)
    p = {k: float(v) for k, v in model.parameters().items()}
    psi = float(model.psi)
    fh = jax.jit(lambda a, b, d: G.velocity_relations(model, a, b, d))
    abc = jax.jit(lambda a, b: G.quadratic_coefficients(model, a, b))
    roots = jax.jit(lambda a, b: [G.solve_for_d(model, a, b, f) for f in ("stable", "unstable")])
    for _ in range(20):
        a, b, d = rng.uniform(0.1, 0.3), rng.uniform(-1.5, -0.8), rng.uniform(-2.0, -1.0)
        f, h = fh(a, b, d)
        f_t, h_t = _thesis_fh(p, psi, a, b, d)
        np.testing.assert_allclose([float(f), float(h)], [f_t, h_t], rtol=1e-12, atol=1e-12)
        got = np.array([float(v) for v in abc(a, b)])
        want = np.array(_thesis_abc(p, psi, a, b))
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-11 * np.abs(want).max())
        A, B, C = want
        disc = B**2 - 4 * A * C
        if disc >= 0:
            for (d_got, real), s in zip(roots(a, b), (-1, 1)):
                assert bool(real)
                np.testing.assert_allclose(
                    float(d_got), (-B + s * math.sqrt(disc)) / (2 * A), rtol=1e-10
                )


def test_energy_restoring_weight_gives_conserved_energy(model):
    """Along the thesis stable gait's constraint, d/dt of the reduced energy (5.10) equals
    mu . (equations of motion) with mu = Phi' (4.24): zero on solutions."""
    rng = np.random.default_rng(2)

    @jax.jit
    def check(theta, phi, dphi, ddphi, dth, ddth):
        al, be, ga = _vhc.reduced_coefficients(
            model, theta, jnp.array([phi]), jnp.array([dphi]), jnp.array([ddphi])
        )
        eom = al * ddth + be * dth**2 + ga
        mu = jnp.array([1.0, dphi])

        def E(t):
            th = theta + dth * t + 0.5 * ddth * t**2
            ph = phi + dphi * (th - theta) + 0.5 * ddphi * (th - theta) ** 2
            dph = dphi + ddphi * (th - theta)
            return _vhc.reduced_energy(model, th, dth + ddth * t, jnp.array([ph]), jnp.array([dph]))

        return jax.grad(E)(0.0), (mu @ eom) * dth

    for _ in range(5):
        theta, phi = rng.uniform(-0.3, 0.3, 2)
        dphi, ddphi, dth, ddth = rng.normal(size=4)
        dE, want = check(theta, phi, dphi, ddphi, dth, ddth)
        np.testing.assert_allclose(float(dE), float(want), rtol=1e-10, atol=1e-12)
