"""Flip-slope derivatives against finite differences of located flips; a design re-solved
from scratch, its projected gradient, and a brute-force grid; atlas cells against
`period_doubling_slope` and the mass/length/time scaling invariance."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax.parameters._design import min_norm_element, with_parameters


def _stable_z(model):
    return np.asarray(vj.find_gait(model, method="shooting").z)


def test_flip_slope_derivative_vs_located_flips():
    """The flip slope and its reverse-mode derivative in the hip mass, as `design` takes
    them (`jax.value_and_grad` through `find_gait` and `flip_slope`), against central
    differences of flips located by `flip_slopes` and the bisection on det(I + J)."""
    m0 = vj.CompassGait()
    z0 = _stable_z(m0)
    res = vj.design("flip-slope", ["mass-hip"], model=m0, steps=1)
    d = res.initial["gradient"]["mass-hip"]

    # Richardson-extrapolated central differences of flips located by `flip_slopes`
    def located(mH):
        m = eqx.tree_at(lambda m: m.mH, m0, jnp.asarray(mH))
        return float(vj.flip_slopes(m, z0[None], float(m0.psi)).psi[0])

    def central(h):
        return (located(10.0 + h) - located(10.0 - h)) / (2 * h)

    fd = (4 * central(0.01) - central(0.02)) / 3
    assert abs(d - fd) < 1e-6 * abs(fd), (d, fd)
    # the located flip is the one of the existing bisection on det(I + J)
    pd = vj.period_doubling_slope(math.radians(4.0), math.radians(4.8), z0, model=m0, tol=1e-12)
    assert abs(res.initial["value"] - pd.psi) < 1e-10  # rad
    assert res.history[-1]["value"] > res.initial["value"]  # maximised


def test_design_spectral_radius():
    m0 = vj.CompassGait()
    bounds = {"mass-hip": (6.0, 20.0)}
    res = vj.design(
        "spectral-radius", ["mass-hip"], model=m0, bounds=bounds, steps=25, learning_rate=0.1
    )
    assert res.result in ("successful", "max_iterations", "no_descent")
    assert res.optimum["value"] < res.initial["value"]
    values = [h["value"] for h in res.history]
    assert all(b <= a for a, b in zip(values, values[1:]))  # never worse than the last
    # re-solved from scratch (continuation from Table 1, no guess) gives the same value
    best = res.model
    g = vj.find_gait(best, method="shooting")
    rho = float(vj.gait_spectrum(best, g).spectral_radius)
    assert abs(rho - res.optimum["value"]) < 1e-9
    # projected gradient ~ 0 (relative to the gradient's scale at the start)
    scale = abs(res.initial["gradient"]["mass-hip"]) * 14.0
    assert res.projected_gradient < 2e-2 * scale, (res.projected_gradient, scale)
    # brute force: a batched grid over the same interval finds nothing better
    grid = np.linspace(6.0, 20.0, 57)
    zs = np.tile(np.asarray(g.z), (len(grid), 1))
    model = with_parameters(m0, ["mass-hip"], [jnp.asarray(grid)])
    gs = vj.find_gaits(model, jnp.asarray(zs), method="shooting")
    ok = np.asarray(gs.result == vj.RESULTS.successful)
    rhos = np.asarray(vj.gait_spectrum(model, gs).spectral_radius)[ok]
    assert ok.sum() > 40
    assert rhos.min() > res.optimum["value"] - 1e-4, (rhos.min(), res.optimum["value"])


def test_min_norm_element_against_every_support():
    """Wolfe's method against the smallest affine minimum-norm point over every subset
    of rows that lies in its hull (duplicates and badly scaled columns included)."""
    import itertools

    def brute(G):
        best = G[np.argmin((G * G).sum(1))]
        for r in range(2, len(G) + 1):
            for S in itertools.combinations(range(len(G)), r):
                Q = G[list(S)] @ G[list(S)].T
                K = np.block([[Q, np.ones((r, 1))], [np.ones((1, r)), np.zeros((1, 1))]])
                lam = np.linalg.lstsq(K, np.r_[np.zeros(r), 1.0], rcond=None)[0][:r]
                if lam.min() >= -1e-12 and abs(lam.sum() - 1.0) < 1e-9:
                    d = lam @ G[list(S)]
                    best = d if d @ d < best @ best else best
        return best

    rng = np.random.default_rng(1)
    for trial in range(120):
        k, n = rng.integers(1, 5), rng.integers(1, 9)
        G = rng.normal(size=(n, k)) + rng.normal(size=k) * rng.uniform(0, 3)
        if trial % 3 == 0:
            G = np.vstack([G, G[:2]])
        if trial % 5 == 0:
            G[:, 0] *= 1e3
        d, ref = min_norm_element(G), brute(G)
        assert abs(np.linalg.norm(d) - np.linalg.norm(ref)) < 1e-9 * max(1.0, np.abs(G).max())
    # two gradients on either side of a kink: the shortest combination runs along it
    d = min_norm_element(np.array([[1.0, 1.0], [-1.0, 1.0]]))
    assert np.allclose(d, [0.0, 1.0])
    # a far larger gradient (next to a square-root kink) does not stop the search early
    G = np.array([[1.0, 1.0], [-1.0, 1.0], [0.3, -1.0], [1e8, 1e8]])
    assert np.linalg.norm(min_norm_element(G)) < 1e-9


def test_design_spectral_radius_along_a_kink():
    """Over (mH, b) the minimum lies where a complex pair of multipliers meets the real
    axis: Adam stalls there, gradient sampling goes on along the kink to the minimum
    (here on the bound mH = 30 kg), which batched grids confirm."""
    m0 = vj.CompassGait()
    bounds = {"mass-hip": (5.0, 30.0), "b": (0.3, 0.7)}
    res = vj.design("spectral-radius", ["mass-hip", "b"], model=m0, bounds=bounds, steps=40)
    assert res.result == "successful", res.result
    assert res.sampling_radius is not None  # the kink was met
    assert res.stationarity < 1e-4 * abs(res.initial["gradient"]["b"]) * 0.4
    values = [h["value"] for h in res.history]
    assert all(b <= a for a, b in zip(values, values[1:]))
    # re-solved from scratch gives the reported value
    g = vj.find_gait(res.model, method="shooting")
    assert abs(float(vj.gait_spectrum(res.model, g).spectral_radius) - res.optimum["value"]) < 1e-9
    # a grid over the whole box, and a fine one around the optimum, find nothing better
    # (64 members each: the batched programs of `test_design_spectral_radius`)
    z, opt = np.asarray(g.z), res.optimum["params"]
    for mh, b in (
        (np.linspace(5.0, 30.0, 8), np.linspace(0.3, 0.7, 8)),
        (
            np.clip(opt["mass-hip"] + np.linspace(-1.0, 1.0, 4), 5.0, 30.0),
            opt["b"] + np.linspace(-3e-3, 3e-3, 16),
        ),
    ):
        H, Bb = np.meshgrid(mh, b, indexing="ij")
        model = vj.CompassGait(mH=jnp.asarray(H.ravel()), b=jnp.asarray(Bb.ravel()))
        gs = vj.find_gaits(model, jnp.asarray(np.tile(z, (H.size, 1))), method="shooting")
        ok = np.asarray(gs.result == vj.RESULTS.successful)
        rho = np.asarray(vj.gait_spectrum(model, gs).spectral_radius)[ok]
        assert ok.sum() > 0.5 * H.size
        assert rho.min() > res.optimum["value"] - 1e-6, (rho.min(), res.optimum["value"])


def test_atlas_against_bifurcation_and_scaling(monkeypatch):
    mu, beta = np.array([1.5, 2.0]), np.array([0.9, 1.0])
    at = vj.atlas(mu, beta, slope=math.radians(3.0))
    assert np.isfinite(at.flip_slope).all()
    # cells against the existing bisection on det(I + J) for the same model
    from vhcjax.parameters._atlas import grid_model

    for i, j in ((0, 0), (1, 1)):
        m = grid_model(mu[i], beta[j], psi=math.radians(3.0))
        z = _stable_z(m)
        f = at.flip_slope[i, j]
        pd = vj.period_doubling_slope(
            math.radians(3.0), f + math.radians(0.2), z, model=m, tol=1e-12
        )
        assert abs(math.degrees(f - pd.psi)) < 1e-4
        gm = vj.gait_spectrum(m, vj.find_gait(m, method="shooting", guess=z))
        assert abs(float(gm.spectral_radius) - at.spectral_radius[i, j]) < 1e-8
        lo, hi = at.stable_range[i, j]
        assert lo <= math.radians(3.0) < hi and abs(hi - f) < 1e-12
    # Table 1 is mu = 2, beta = 1: its flip is the thesis model's
    pd = vj.period_doubling_slope(
        math.radians(4.0), math.radians(4.8), _stable_z(vj.CompassGait()), tol=1e-12
    )
    assert abs(math.degrees(at.flip_slope[1, 1] - pd.psi)) < 1e-4
    # scaling invariance: other leg mass, leg length and gravity, same dimensionless walker;
    # solved as a large batch is (only the cells still scanning or refining, in subsets
    # padded to a multiple of `_SUBSET`)
    import vhcjax.parameters._flip as flip

    monkeypatch.setattr(flip, "_SUBSET", 2)
    scaled = vj.atlas(mu, beta, slope=math.radians(3.0), mass_leg=2.0, leg_length=1.7, gravity=3.7)
    np.testing.assert_allclose(np.degrees(scaled.flip_slope), np.degrees(at.flip_slope), atol=1e-6)
    np.testing.assert_allclose(scaled.spectral_radius, at.spectral_radius, atol=1e-8)


def test_atlas_reports_no_flip_for_a_gait_already_past_one():
    """mu = 2, beta = 0.05: at the scan start (1 deg) the gait continued from Table 1
    already has a real multiplier below -1, so no flip lies ahead; the atlas says so
    instead of bracketing a sign change that is not there."""
    at = vj.atlas([2.0], [0.05])
    assert np.isnan(at.flip_slope[0, 0]) and np.isnan(at.stable_range[0, 0]).all()
    assert "multiplier below -1" in at.reason[0] and "past a flip" in at.reason[0]
    # independently: the stable-family gait there, by shooting, and its Poincare multipliers
    from vhcjax.parameters._atlas import grid_model

    m = grid_model(2.0, 0.05, psi=math.radians(1.0))
    g = vj.find_gait(m, "stable", "shooting")
    ev = np.asarray(vj.gait_multipliers(m, g, transverse=False).poincare)
    assert ev.real.min() < -1 and abs(ev.imag).max() < 1e-12


def test_atlas_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    """An atlas with a checkpoint folder, stopped after its first chunk, resumes:
    the same call again computes only the missing chunks, and its result equals an
    uninterrupted run's to the last bit and the one-batch atlas's to 1e-12; a chunk file
    cut short is computed again."""
    import vhcjax.parameters._atlas as atlas_module

    mu, beta = np.array([1.5, 2.0, 2.5]), np.array([1.0])
    kw = dict(slope=math.radians(3.0), psi_start=math.radians(3.0), step=math.radians(1.0))
    whole = vj.atlas(mu, beta, **kw)
    real, computed, allowed = atlas_module._atlas, [], [1]  # chunks before the stop

    class Stopped(Exception):  # a Ctrl-C or a killed job, as far as the folder can tell
        pass

    def counted(mu, *args, **kwargs):
        if len(computed) == allowed[0]:
            raise Stopped
        computed.append(mu.tolist())
        return real(mu, *args, **kwargs)

    monkeypatch.setattr(atlas_module, "_atlas", counted)
    run = lambda folder: vj.atlas(mu, beta, checkpoint=folder, chunk_cells=1, **kw)
    ck = tmp_path / "ck"
    with pytest.raises(Stopped):
        run(ck)
    assert sorted(p.name for p in ck.iterdir()) == ["cells-000000-000001.csv", "manifest.json"]
    allowed[0] = 99
    computed.clear()
    resumed = run(ck)
    assert computed == [[2.0], [2.5]]
    computed.clear()
    fresh = run(tmp_path / "fresh")
    assert computed == [[1.5], [2.0], [2.5]]
    for name in ("flip_slope", "stable_range", "spectral_radius"):
        np.testing.assert_array_equal(getattr(resumed, name), getattr(fresh, name))
        np.testing.assert_allclose(getattr(resumed, name), getattr(whole, name), rtol=0, atol=1e-12)
    assert resumed.reason == fresh.reason == whole.reason
    assert np.isfinite(resumed.spectral_radius).all()
    # a chunk file cut short (a copy interrupted, say) is detected and computed again
    cut = ck / "cells-000001-000002.csv"
    cut.write_text(cut.read_text()[:-20])
    computed.clear()
    again = run(ck)
    assert computed == [[2.0]]
    np.testing.assert_array_equal(again.flip_slope, fresh.flip_slope)
