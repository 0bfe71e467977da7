"""Stability: section independence, growth/decay rates in direct simulation, period
doubling, period-2 gaits, the bifurcation runs and the CLI."""

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _text import assert_plain_text

import vhcjax
from vhcjax import CompassGait, stability as S

PSI3 = math.radians(3.0)


@pytest.fixture(scope="module")
def gaits3():
    """The stable and the unstable gait at 3 degrees (Newton from rounded seeds)."""
    m = CompassGait().with_slope(PSI3)
    out = {}
    for fam, seed in (("stable", (0.2187, -1.092, -0.377)), ("unstable", (0.2047, -1.211, -0.712))):
        fp = vhcjax.fixed_point(m, jnp.asarray(seed), 1, config=vhcjax.DEFAULT_CONFIG)
        assert fp.result == vhcjax.RESULTS.successful
        J = np.asarray(vhcjax.poincare_jacobian(m, fp.z, 1, vhcjax.DEFAULT_CONFIG))
        out[fam] = (np.asarray(fp.z), J)
    return m, out


@pytest.mark.parametrize("family", ["stable", "unstable"])
def test_multipliers_do_not_depend_on_the_section(gaits3, family):
    """Post-impact section vs the mid-swing section q1 = 0 (its own event machinery)."""
    m, g = gaits3
    z, J = g[family]
    ev_mid, w, ok = S.midswing_multipliers(m, jnp.asarray(z))
    assert bool(ok)
    assert abs(float(w[0]) - float(z[0])) > 1e-3  # really another section
    ev_post = np.linalg.eigvals(J)
    for lam in np.asarray(ev_mid):
        assert np.min(np.abs(ev_post - lam)) < 1e-6


def _deviations(m, z, dz, num_steps):
    sim = vhcjax.simulate(
        m, m.section_to_state(jnp.asarray(z + dz)), num_steps, config=vhcjax.DEFAULT_CONFIG
    )
    assert sim.result == vhcjax.RESULTS.successful
    zk = np.asarray(jnp.stack([m.state_to_section(x) for x in sim.steps.x_plus]))
    return np.concatenate([dz[None], zk - z[None]], axis=0)


def test_unstable_gait_perturbation_grows_at_the_largest_multiplier(gaits3):
    """A perturbation in a generic direction aligns with the unstable direction and then
    grows by |lambda_1| per step in direct simulation (within 5 %)."""
    m, g = gaits3
    z, J = g["unstable"]
    lam = np.max(np.abs(np.linalg.eigvals(J)))
    d = _deviations(m, z, 1e-9 * np.array([1.0, -1.0, 1.0]), 8)
    norms = np.linalg.norm(d, axis=1)
    ratios = norms[1:] / norms[:-1]
    assert norms[-1] < 1e-3  # still in the linear regime
    np.testing.assert_allclose(ratios[3:], lam, rtol=0.05)


def test_stable_gait_perturbation_decays_at_the_largest_multiplier(gaits3):
    """The dominant multipliers of the stable gait are a complex pair: in the real
    invariant plane of the pair (basis Re v, Im v) a perturbation rotates and shrinks by
    exactly |lambda_1| per step; measured in direct simulation (within 5 %)."""
    m, g = gaits3
    z, J = g["stable"]
    ev, V = np.linalg.eig(J)
    i = int(np.argmax(np.abs(ev)))
    W = np.stack([V[:, i].real, V[:, i].imag, V[:, np.argmin(np.abs(ev))].real], axis=1)
    d = _deviations(m, z, 1e-5 * (W[:, 0] + 0.3 * W[:, 1]), 10)
    c = np.linalg.solve(W, d.T).T[:, :2]
    r = np.linalg.norm(c, axis=1)
    np.testing.assert_allclose(r[1:] / r[:-1], np.abs(ev[i]), rtol=0.05)
    # and it turns by arg(lambda_1) per step in that plane (110 deg here)
    cos = np.sum(c[1:] * c[:-1], axis=1) / (r[1:] * r[:-1])
    np.testing.assert_allclose(np.arccos(cos), abs(np.angle(ev[i])), rtol=0.05)
    assert np.linalg.norm(d[-1]) < 1e-2 * np.linalg.norm(d[0])  # it does decay


@pytest.fixture(scope="module")
def flip():
    """The period-doubling slope of the stable family."""
    m = CompassGait()
    lo, hi = math.radians(4.25), math.radians(4.5)
    fp = vhcjax.fixed_point(
        m.with_slope(lo), jnp.asarray((0.2275, -1.14, -0.20)), 1, config=vhcjax.DEFAULT_CONFIG
    )
    assert fp.result == vhcjax.RESULTS.successful
    return S.period_doubling_slope(lo, hi, np.asarray(fp.z), model=m)


@pytest.mark.slow
def test_period_doubling_slope_located_to_1e_4_degrees(flip):
    assert flip.bracket[1] - flip.bracket[0] < math.radians(1e-4)
    # a multiplier is -1 there (autodiff Jacobian of the step map)
    assert np.min(np.abs(flip.multipliers + 1.0)) < 1e-4
    # and, independently, central finite differences of the step map bracket it:
    # det(I + J_fd) changes sign across psi +- 1e-4 deg
    m = CompassGait()
    signs = []
    for dpsi in (-1e-4, 1e-4):
        p = flip.psi + math.radians(dpsi)
        fp = vhcjax.fixed_point(
            m.with_slope(p), jnp.asarray(flip.z), 1, config=vhcjax.DEFAULT_CONFIG
        )
        Jfd = S.finite_difference_jacobian(m.with_slope(p), fp.z, 1, 1e-5, vhcjax.DEFAULT_CONFIG)
        signs.append(np.sign(np.linalg.det(np.eye(3) + np.asarray(Jfd))))
    assert signs[0] * signs[1] < 0


@pytest.mark.slow
def test_period_two_gait_is_a_fixed_point_of_two_simulator_steps(flip):
    m = CompassGait()
    psi = flip.psi + math.radians(0.2)
    br = S.period2_branch(m, flip, [psi])
    assert br is not None and len(br["psi"]) == 1
    z = br["z"][0]
    mm = m.with_slope(psi)
    sim = vhcjax.simulate(mm, mm.section_to_state(jnp.asarray(z)), 2, config=vhcjax.DEFAULT_CONFIG)
    assert sim.result == vhcjax.RESULTS.successful
    z1 = np.asarray(mm.state_to_section(sim.steps.x_plus[0]))
    z2 = np.asarray(mm.state_to_section(sim.steps.x_plus[1]))
    np.testing.assert_allclose(z2, z, atol=1e-9)
    assert np.max(np.abs(z1 - z)) > 1e-3  # not the period-1 gait
    T = np.asarray(sim.steps.period)
    assert abs(T[0] - T[1]) > 1e-3  # a long and a short step
    # just past the flip the period-2 gait is stable
    assert br["stable"][0]


@pytest.mark.parametrize(
    "argv",
    [
        ["bifurcation", "--slope-deg", "5:1:0.1"],
        ["bifurcation", "--slope-deg", "1:2"],
        ["bifurcation", "--slope-deg", "0:2:0.5"],
        ["bifurcation", "--slope-deg", "1:2:0.5", "--record", "1"],
        ["bifurcation", "--slope-deg", "1:2:0.5", "--mass-hip", "-1"],
        ["bifurcation", "--slope-deg", "0.01:29:0.0003", "--record", "10000"],
        ["multipliers", "--slope-deg", "45"],
    ],
)
def test_cli_bad_input_is_one_line_error(argv, capsys):
    from vhcjax.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0]
    if "--record" in argv and "10000" in argv:  # refused for its size, not its range
        assert "recorded periods" in err[0]


@pytest.mark.slow
def test_cli_bifurcation_json_and_files(tmp_path, capsys):
    """End to end on six slopes (the batch size of test_transverse: compiled once): a
    period-1 pattern at 3 degrees whose step period is the Newton gait's."""
    from vhcjax.cli import main

    csv, png = tmp_path / "b.csv", tmp_path / "b.png"
    assert (
        main(
            [
                "bifurcation",
                "--slope-deg",
                "2.75:3.0:0.05",
                "--transient",
                "40",
                "--record",
                "8",
                "--json",
                "--csv",
                str(csv),
                "--png",
                str(png),
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["period_doubling_slopes_deg"] == [] and out["num_fell"] == 0
    assert out["num_aperiodic"] == 0 and "warning" not in captured.err
    assert (
        out["first_fall_slope_deg"] is None
        and "no walker fell" in out["first_fall_slope_deg_reason"]
    )
    rows = csv.read_text().splitlines()
    assert rows[0].startswith("slope_deg,result,pattern,period_1")
    assert len(rows) == 7
    r3 = rows[6].split(",")
    assert r3[1] == "successful" and r3[2] == "1"
    # the simulated step period (FAST_CONFIG, after 40 steps) is the Newton gait's period
    fp = vhcjax.fixed_point(
        CompassGait().with_slope(PSI3),
        jnp.asarray((0.2187, -1.092, -0.377)),
        1,
        config=vhcjax.DEFAULT_CONFIG,
    )
    assert abs(float(r3[3]) - float(fp.periods[0])) < 1e-6
    assert png.stat().st_size > 10_000
    # the same summary in words (the programs are compiled: a second run is cheap)
    argv = ["bifurcation", "--slope-deg", "2.75:3.0:0.05", "--transient", "40", "--record", "8"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert_plain_text(text)
    assert "period doubling (a multiplier crossing -1): none in the slopes given" in text
    assert "simulated 6 of 6 slopes (2.75 to 3 deg)" in text and "fell at 0 slopes" in text
    # with a checkpoint folder: the same JSON, and again from the folder alone
    ck = tmp_path / "ck"
    for _ in range(2):
        assert main([*argv, "--json", "--checkpoint", str(ck)]) == 0
        assert json.loads(capsys.readouterr().out) == out
    assert sorted(p.name for p in ck.iterdir()) == [
        "manifest.json",
        "slopes-000000000-000000006.csv",
    ]
    # another record length there: refused in one line
    assert main([*argv[:-1], "9", "--checkpoint", str(ck)]) == 2
    err = capsys.readouterr().err.strip()
    assert "other settings (num_record)" in err and "\n" not in err


@pytest.mark.slow
def test_a_bifurcation_diagram_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    """Six slopes in parts of two, stopped after the first part: the same call again
    computes only the other two parts, and the diagram equals the one-batch diagram."""
    import vhcjax.stability._bifurcation as bif

    psis = np.radians(np.arange(2.75, 3.01, 0.05))
    zs = np.asarray(vhcjax.sweep(CompassGait(), psis).gaits.z)
    kw = dict(num_transient=40, num_record=8)
    whole = bif.bifurcation_diagram(psis, zs, **kw)
    real, calls, allowed = bif.padded_map, [], [1]

    class Stopped(Exception):
        pass

    def counted(fn, ps, *args, **kwargs):
        if len(calls) == allowed[0]:
            raise Stopped
        calls.append(len(ps))
        return real(fn, ps, *args, **kwargs)

    monkeypatch.setattr(bif, "padded_map", counted)
    run = lambda: bif.bifurcation_diagram(  # noqa: E731
        psis, zs, checkpoint=tmp_path / "ck", chunk_slopes=2, **kw
    )
    with pytest.raises(Stopped):
        run()
    allowed[0] = 99
    calls.clear()
    resumed = run()
    assert calls == [2, 2]
    for name in ("periods", "fell", "result", "period_pattern"):
        np.testing.assert_array_equal(getattr(resumed, name), getattr(whole, name))


@pytest.mark.slow
def test_cli_bifurcation_simulates_only_where_there_is_a_gait(tmp_path, capsys, monkeypatch):
    """A slope without a period-1 gait (a stand-in: the search's result replaced by
    `not_converged` at 3 degrees) is not simulated: its CSV row gives the search's result
    and no pattern, it counts neither as a fall nor in the diagram, the JSON names it
    and says why the period doublings may be incomplete, and the command exits 1 with
    one line saying so (an incomplete answer)."""
    import equinox as eqx

    from vhcjax._results import results_from_codes
    from vhcjax.cli import main

    real = S.period1_family

    def missing_at_3(psis, family="stable", **kwargs):
        fam = real(psis, family, **kwargs)
        at3 = jnp.abs(jnp.asarray(psis) - PSI3) < 1e-9
        codes = jnp.where(
            at3, vhcjax.result_codes(vhcjax.RESULTS.not_converged), vhcjax.result_codes(fam.result)
        )
        return eqx.tree_at(lambda f: f.result, fam, results_from_codes(codes))

    monkeypatch.setattr(vhcjax.stability, "period1_family", missing_at_3)
    csv = tmp_path / "b.csv"
    argv = ["bifurcation", "--slope-deg", "2.75:3.0:0.05", "--transient", "40", "--record", "8"]
    assert main(argv + ["--json", "--csv", str(csv)]) == 1
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["num_no_gait"] == 1 and out["num_fell"] == 0 and out["num_slopes"] == 6
    assert out["no_gait_slopes_deg"] == [3.0]
    assert "3 deg" in out["period_doubling_slopes_deg_reason"]
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "incomplete: no period-1 gait found at 1 of 6 slopes (3 deg" in err[0]
    rows = csv.read_text().splitlines()
    assert rows[6] == "3,not_converged," + "," * 8
    assert rows[5].split(",")[1:3] == ["successful", "1"]


@pytest.mark.slow
def test_period_four_gait_at_five_degrees():
    """Thesis 7.4: a four-step gait at 5 degrees. Newton on P^4 from a rounded seed: its
    minimal period is 4, the simulator returns to it after 4 steps, and its P^4
    multipliers (autodiff = central differences) are inside the unit circle."""
    m5 = CompassGait().with_slope(math.radians(5.0))
    o = S.period_k_orbit(m5, np.array([0.2178, -1.1614, -0.1080]), 4)
    assert o.result == vhcjax.RESULTS.successful and o.minimal_period == 4
    for a in o.multipliers:
        assert np.min(np.abs(o.multipliers_fd - a)) < 1e-6
    assert np.max(np.abs(o.multipliers)) < 1.0
    sim = vhcjax.simulate(
        m5, m5.section_to_state(jnp.asarray(o.z)), 4, config=vhcjax.DEFAULT_CONFIG
    )
    np.testing.assert_allclose(m5.state_to_section(sim.steps.x_plus[-1]), o.z, atol=1e-9)
    assert len(np.unique(np.round(np.asarray(sim.steps.period), 4))) == 4


def test_period1_family_is_the_poincare_fixed_point_at_every_slope(gaits3):
    """The family over slopes (the slope sweep, VHC) against an independent Newton solve
    of P(z) = z (optimistix) at each slope, and the 3-degree gaits of `gaits3`; for a
    model far from Table 1 (mH = 1 kg) the VHC search ends (singular phi'' ODE) before
    4.5 degrees, where the gait is found by shooting."""
    _, ref = gaits3
    for family in ("stable", "unstable"):
        psis = np.radians([2.0, 3.0, 4.0])
        fam = vhcjax.period1_family(psis, family)
        assert vhcjax.result_names(fam.result) == ["successful"] * 3
        np.testing.assert_allclose(np.asarray(fam.z)[1], ref[family][0], atol=1e-10)
        for p, z, T in zip(psis, np.asarray(fam.z), np.asarray(fam.periods)):
            fp = vhcjax.fixed_point(
                CompassGait().with_slope(p),
                jnp.asarray(z) + 1e-4,
                1,
                config=vhcjax.DEFAULT_CONFIG,
            )
            assert fp.result == vhcjax.RESULTS.successful
            np.testing.assert_allclose(np.asarray(fp.z), z, atol=1e-10)
            assert abs(float(fp.periods[0]) - T) < 1e-10
    light = CompassGait(mH=1.0)
    vhc = vhcjax.sweep(light, np.radians([3.5, 4.5]), "stable", "vhc", tangents=False)
    assert vhcjax.result_names(vhc.gaits.result) == ["successful", "singular_phi_ode"]
    fam = vhcjax.period1_family(np.radians([3.5, 4.5]), "stable", model=light)
    assert vhcjax.result_names(fam.result) == ["successful"] * 2
    for p, z in zip(np.radians([3.5, 4.5]), np.asarray(fam.z)):
        out = vhcjax.step_map(light.with_slope(p), jnp.asarray(z))
        assert float(jnp.max(jnp.abs(out.z_next - z))) < vhcjax.gait.SUCCESS_TOL
    with pytest.raises(TypeError, match="compass-gait"):
        vhcjax.period1_family([PSI3], model=vhcjax.KneedWalker())
    # a slope that is not finite and positive is coded, the others solved
    fam = vhcjax.period1_family(np.radians([3.0, -1.0, np.nan]), "stable")
    assert vhcjax.result_names(fam.result) == ["successful", "bad_input", "bad_input"]
    np.testing.assert_allclose(np.asarray(fam.z)[0], ref["stable"][0], atol=1e-10)
    assert np.isfinite(np.asarray(fam.z)).all() and np.isfinite(np.asarray(fam.periods)).all()


def test_multipliers_only_of_a_gait_of_a_valid_model(gaits3):
    m, g = gaits3
    z = g["stable"][0]
    out = vhcjax.gait_multipliers(m, z + 0.02)  # one step moves it: not a gait
    assert vhcjax.result_names(out.result) == "not_a_gait" and not bool(out.stable)
    assert vhcjax.result_names(vhcjax.gait_multipliers(m, z).result) == "successful"
    bad = vhcjax.gait_multipliers(CompassGait(mH=-1.0), z, transverse=False)
    assert vhcjax.result_names(bad.result) == "bad_input" and not bool(bad.stable)
    with pytest.raises(ValueError, match="3 section coordinates"):
        vhcjax.gait_multipliers(m, m.section_to_state(jnp.asarray(z)))
    # a result holding the gait (a `Gait`, a fixed point) is taken at its section point
    fp = vhcjax.fixed_point(m, jnp.asarray(z), 1, config=vhcjax.DEFAULT_CONFIG)
    np.testing.assert_allclose(
        np.asarray(vhcjax.gait_multipliers(m, fp).poincare),
        np.asarray(vhcjax.gait_multipliers(m, fp.z).poincare),
        atol=0,
    )


def test_one_gait_multipliers_equal_the_batched_family_member(gaits3):
    """`gait_multipliers` (one unbatched program) and `family_multipliers` (vmapped over
    a batch) are two compilations of the same computation: equal to rounding, numpy
    leaves on concrete inputs; a batch of points is refused with the shape expected."""
    m, g = gaits3
    zs = np.stack([g["stable"][0], g["unstable"][0]])
    batch = S.family_multipliers(m, np.full(2, PSI3), zs, transverse=False)
    for i in range(2):
        one = vhcjax.gait_multipliers(m, zs[i], transverse=False)
        assert isinstance(one.poincare, np.ndarray)
        np.testing.assert_allclose(one.poincare, batch.poincare[i], rtol=1e-10, atol=1e-12)
        assert bool(one.stable) == bool(batch.stable[i]) == (i == 0)
    # under a transformation (traced inputs) the same numbers, as traced values
    traced = jax.vmap(lambda z: vhcjax.gait_multipliers(m, z, transverse=False).max_abs)(zs)
    np.testing.assert_allclose(np.asarray(traced), batch.max_abs, rtol=1e-10)
    with pytest.raises(ValueError, match="3 section coordinates.*got shape \\(2, 3\\)"):
        vhcjax.gait_multipliers(m, zs)


def test_library_inputs_refused_with_the_shape_or_range_expected():
    m = CompassGait()
    for guess in ([0.2, -1.0, 0.1, 0.2, 0.3], [0.2]):
        with pytest.raises(ValueError, match=r"\(2,\) or \(3,\)"):
            vhcjax.find_gait(m, guess=guess, throw=False)
    with pytest.raises(ValueError, match=r"\(B, 2\) or \(B, 3\)"):
        vhcjax.find_gaits(m, np.zeros((3, 5)))
    for mu, beta in (([-1.0, 2.0], [1.0]), ([2.0], [np.nan])):
        with pytest.raises(ValueError, match="finite positive"):
            vhcjax.atlas(mu, beta)
    with pytest.raises(ValueError, match="outside the bounds"):
        # default bounds in proportion to the walker's mass: a hip of 0.5 kg on 10.5 kg
        # is below the thesis walker's 1 kg on 20 kg
        vhcjax.design("speed", ["mass-hip"], model=CompassGait(mH=0.5))
    with pytest.raises(ValueError, match="non-positive"):
        vhcjax.design("speed", ["mass-hip"], model=CompassGait(mH=-1.0))


def test_bifurcation_aperiodic_warning_names_the_slopes():
    """Slopes with no detected period are named in one warning, with the transient steps
    that did not settle them (a chaotic walk or an unsettled one: the command cannot tell)."""
    from vhcjax.cli._bifurcation import _aperiodic_message

    slopes = [4.4, 4.45, 4.5, 4.55]
    msg = _aperiodic_message(slopes, np.array([False, True, False, True]), 20, 64)
    assert "2 of 4 slopes (4.45 to 4.55 deg)" in msg and "after 20 transient steps" in msg
    one = _aperiodic_message(slopes, np.array([False, False, True, False]), 300, 64)
    assert "1 of 4 slopes (4.5 deg)" in one and "\n" not in one
    assert "no period of 1, 2, 4, 8, 16 or 32 steps" in one
    assert "no period of 1, 2 or 4 steps" in _aperiodic_message(slopes, ~np.zeros(4, bool), 9, 8)
    assert "no period of 1 step:" in _aperiodic_message(slopes, ~np.zeros(4, bool), 9, 2)
