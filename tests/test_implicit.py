"""Exact parameter derivatives of gaits (implicit function theorem) against Richardson-
extrapolated central differences of re-solved gaits, forward against reverse mode, the
eigenvalue-perturbation derivatives of the multipliers, and zero derivatives of failed
members."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax.solvers import eigenvalues, implicit_outputs

NAMES = ("m1", "m2", "mH", "a", "b", "g", "psi")
TABLE1 = np.array([5.0, 5.0, 10.0, 0.5, 0.5, 9.81, np.radians(3.0)])
# A random model near Table 1 (fixed seed): every parameter changed by up to 15 %.
RANDOM = TABLE1 * (1 + 0.15 * np.random.default_rng(7).uniform(-1, 1, 7))


def model_of(p):
    return vj.CompassGait(**{k: p[i] for i, k in enumerate(NAMES)})


_SEEDS = {}


def seed(method):
    if method not in _SEEDS:
        g = vj.find_gait(vj.CompassGait(), method=method)
        _SEEDS[method] = np.asarray(g.z if method == "shooting" else jnp.stack([g.a, g.b]))
    return _SEEDS[method]


def outputs(p, method):
    g = vj.find_gait(model_of(p), method=method, guess=seed(method))
    return jnp.concatenate([g.z, jnp.stack([g.T, g.step_length, g.speed, g.energy_loss, g.E0])])


def richardson(f, p, rel=2e-3):
    """Central differences with steps h and h/2, Richardson-extrapolated (error O(h^4))."""
    cols = []
    for i in range(len(p)):
        h = rel * abs(p[i])

        def d(h):
            e = np.zeros(len(p))
            e[i] = h
            return (np.asarray(f(p + e)) - np.asarray(f(p - e))) / (2 * h)

        cols.append((4 * d(h / 2) - d(h)) / 3)
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("method", ["vhc", "shooting"])
def test_gait_derivatives_vs_richardson(method):
    f = lambda p: outputs(p, method)
    for p in (TABLE1, RANDOM):
        J = np.asarray(jax.jacfwd(f)(jnp.asarray(p)))
        fd = richardson(f, p)
        scale = np.maximum(np.abs(fd), 1e-3 * np.abs(fd).max())
        assert np.max(np.abs(J - fd) / scale) < 1e-6, np.max(np.abs(J - fd) / scale)


def test_forward_and_reverse_agree_and_batch():
    f = lambda p: outputs(p, "vhc")
    p = jnp.asarray(RANDOM)
    Jf = np.asarray(jax.jacfwd(f)(p))
    Jr = np.asarray(jax.jacrev(f)(p))
    np.testing.assert_allclose(Jr, Jf, rtol=1e-10, atol=1e-12 * np.abs(Jf).max())
    # jax.grad of a scalar through the batched search (slopes and masses batched)
    psis = jnp.radians(jnp.array([2.5, 3.0, 3.5]))

    def total_speed(mH):
        gs = vj.find_gaits(vj.CompassGait(mH=mH), jnp.tile(seed("vhc"), (3, 1)), psi=psis)
        return jnp.sum(gs.speed), gs

    (v, gs), dv = jax.value_and_grad(total_speed, has_aux=True)(10.0)
    assert (gs.result == vj.RESULTS.successful).all()
    each = [
        float(
            jax.grad(lambda m: outputs(jnp.asarray(TABLE1).at[2].set(m).at[6].set(s), "vhc")[5])(
                10.0
            )
        )
        for s in psis
    ]
    np.testing.assert_allclose(float(dv), sum(each), rtol=1e-9)


def test_failed_member_has_zero_derivative_and_keeps_code():
    psis = jnp.radians(jnp.array([3.0, 30.0]))  # no gait at 30 degrees from this seed

    def speeds(mH):
        gs = vj.find_gaits(vj.CompassGait(mH=mH), jnp.tile(seed("vhc"), (2, 1)), psi=psis)
        return gs.speed, gs.result

    (v, codes), (dv, _) = jax.jvp(speeds, (10.0,), (1.0,))
    ok = np.asarray(codes == vj.RESULTS.successful)
    assert ok[0] and not ok[1]
    assert float(dv[1]) == 0.0 and float(dv[0]) != 0.0
    assert np.isfinite(np.asarray(dv)).all()


def test_multiplier_derivatives_vs_richardson():
    """Eigenvalue perturbation (complex pair included) and the spectral radius, through
    `find_gait` and `gait_spectrum`, against re-solved gaits; forward against reverse."""

    def spec(p):
        m = model_of(p)
        g = vj.find_gait(m, method="shooting", guess=seed("shooting"))
        lam = vj.gait_spectrum(m, g).multipliers
        # the pair as (Re, |Im|) of its member with Im > 0, then the real multiplier
        pair = jnp.where(jnp.imag(lam[0]) > 0, lam[0], lam[1])
        return jnp.stack([jnp.real(pair), jnp.imag(pair), jnp.real(lam[2]), jnp.abs(lam[0])])

    p = jnp.asarray(TABLE1)
    J = np.asarray(jax.jacfwd(spec)(p))
    fd = richardson(spec, TABLE1)
    scale = np.maximum(np.abs(fd), 1e-3 * np.abs(fd).max())
    assert np.max(np.abs(J - fd) / scale) < 1e-6, np.max(np.abs(J - fd) / scale)
    rho = lambda p: spec(p)[3]
    np.testing.assert_allclose(
        np.asarray(jax.grad(rho)(p)), J[3], rtol=1e-10, atol=1e-12 * np.abs(J[3]).max()
    )


def test_implicit_outputs_generic():
    """The mechanism on an equation with a known solution: r(z, p) = z^3 + p z - 1."""

    def fn(z, p):
        return z**3 + p * z - 1.0, {"z2": z**2}

    def solve(p):
        z = jnp.array([0.5])
        for _ in range(60):
            z = z - (z**3 + p * z - 1) / (3 * z**2 + p)
        return z

    def out(p):
        z = solve(jax.lax.stop_gradient(p))
        zz, o = implicit_outputs(fn, z, p, {"z2": z**2})
        return jnp.concatenate([zz, o["z2"]])

    p = 2.0
    z = float(solve(p)[0])
    dz = -z / (3 * z**2 + p)  # implicit differentiation by hand
    np.testing.assert_allclose(np.asarray(jax.jacfwd(out)(p)), [dz, 2 * z * dz], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(jax.jacrev(out)(p)), [dz, 2 * z * dz], rtol=1e-12)
    # eigenvalue perturbation on a rotation-like matrix (complex pair)
    A = jnp.array([[0.2, -0.9, 0.1], [0.8, 0.1, 0.0], [0.05, 0.0, -0.4]])
    dA = jnp.array([[0.3, 0.1, 0.0], [-0.2, 0.5, 0.1], [0.0, 0.2, 0.1]])
    _, dl = jax.jvp(eigenvalues, (A,), (dA,))
    h = 1e-6
    lp, lm = np.linalg.eigvals(np.asarray(A + h * dA)), np.linalg.eigvals(np.asarray(A - h * dA))
    lp, lm = (
        lp[np.argsort(-np.abs(lp) - 1e-9 * np.imag(lp))],
        lm[np.argsort(-np.abs(lm) - 1e-9 * np.imag(lm))],
    )
    lam = np.asarray(eigenvalues(A))
    for i in range(3):
        jp = np.argmin(np.abs(lp - lam[i]))
        jm = np.argmin(np.abs(lm - lam[i]))
        assert abs((lp[jp] - lm[jm]) / (2 * h) - complex(dl[i])) < 1e-7
