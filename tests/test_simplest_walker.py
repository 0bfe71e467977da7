"""The simplest walking model (Garcia, Chatterjee, Ruina and Coleman 1998).

vhcjax's `SimplestWalker` against an independent scipy computation written in the paper's
variables (`_simplest_reference`): the limit equations and impact, both period-1 families
and their multipliers, the small-slope law, the period-doubling cascade, the compass gait
with light feet, a scaled walker, and every number of docs/simplest_walker.md.
"""

import functools
import math
import pathlib

import _simplest_reference as ref
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax.hybrid import fixed_point, jacobian

PAGE = pathlib.Path(__file__).resolve().parent.parent / "docs" / "simplest_walker.md"
FAMILIES = {"stable": "long", "unstable": "short"}  # vhcjax's names, the reference's
SLOPES = (0.001, 0.005, 0.009, 0.0145)  # gaits compared with the reference (rad)
SMALL = (1e-5, 1e-4, 1e-3)  # the small-slope law (rad)

# ---- the numbers of docs/simplest_walker.md (printed by docs/simplest_walker.py) ---------
#: theta*, theta'*, phi'*, step period at 0.009 rad
GAITS_0009 = {
    "stable": ("0.20031090", "-0.19983247", "-0.01582300", "3.882464"),
    "unstable": ("0.19393737", "-0.20386693", "-0.01514426", "3.096106"),
}
#: the multipliers at 0.009 rad: long period (real part, imaginary part, modulus), short
MULTIPLIERS_0009 = {
    "stable": ("-0.190100", "0.557599", "0.589113"),
    "unstable": ("4.003864", "0.459590"),
}
#: tau_0, C and D of the small-slope law
SMALL_SLOPE_LAW = {
    "stable": ("3.812092", "0.970956", "-0.186"),
    "unstable": (None, "0.943976", "-0.266"),
}
FLIPS = ("0.01508844", "0.01766937", "0.01816012")  # period 1 to 2, 2 to 4, 4 to 8 (rad)
FLIP_RATIO = "5.26"
#: The period-2 and period-4 gaits at their flips (vhcjax, z = (q1, dq1, dq2) at
#: 0.0176693749 and 0.0181601196 rad): seeds of the reference's check.
CASCADE_SEEDS = {
    2: (0.0176693749, (0.2401521307, -0.2486652545, -0.2163327629)),
    4: (0.0181601196, (0.2424788748, -0.2512573646, -0.2178862317)),
}
CHAOTIC = ("0.0183", "0.0190")  # no period up to 32; still walking at the second
FALL = ("0.0192", "26")  # falls, after this many steps (from the first start)
LONG_RUN = (400, 64)  # steps of the long simulations: transient, recorded
START = 1e-4  # the first start: the gait with dq2 + START


def _digits(text):
    """Half a unit in the last printed digit of `text`."""
    return 0.5 * 10.0 ** -len(text.split(".")[1]) if "." in text else 0.5


def _close_to_page(value, text, slack=1e-12):
    assert abs(value - float(text)) <= _digits(text) + slack, (value, text)


# ---- helpers -----------------------------------------------------------------------------
def garcia(model, z):
    """The paper's $(\\theta, \\dot\\theta, \\dot\\phi)$ of a section point `z` of `model`."""
    q1, dq1, dq2 = np.asarray(z, float)
    ts = float(model.time_scale)
    return np.array([q1 + float(model.psi), dq1 * ts, (dq1 - dq2) * ts])


def section(gamma, g):
    """Section point $(q_1, \\dot q_1, \\dot q_2)$ of the paper's $(\\theta, \\dot\\theta,
    \\dot\\phi)$ (unit time scale)."""
    return np.array([g[0] - gamma, g[1], g[1] - g[2]])


def multipliers(model, z):
    ev = np.linalg.eigvals(np.asarray(jacobian(model, jnp.asarray(z))))
    return ev[np.argsort(-np.abs(ev))]


def spectral_distance(a, b):
    """Largest distance from an eigenvalue of either spectrum to the nearest of the other."""
    d = np.abs(np.asarray(a)[:, None] - np.asarray(b)[None, :])
    return max(d.min(axis=0).max(), d.min(axis=1).max())


def successful(fp):
    return vj.result_names(fp.result) == "successful"


@functools.cache
def vhcjax_family(name):
    """`{slope: (model, z, period)}` for `SLOPES` and `SMALL`: `fixed_point` from
    `reference_gait`, then `continue_fixed_point` from slope to slope (up to 0.0145, down
    to 1e-5)."""
    model, z0 = vj.SimplestWalker().reference_gait(name)
    fp = fixed_point(model, z0)
    assert successful(fp)
    out = {float(model.psi): (model, fp.z, float(fp.periods[0]))}
    for chain in ((0.0145,), (0.005, 0.001, 1e-4, 1e-5)):
        m, step = model, fp
        for psi in chain:
            step, m = vj.continue_fixed_point(m, step.z, m.with_slope(psi))
            assert successful(step) and float(m.psi) == psi, (name, psi)
            out[psi] = (m, step.z, float(step.periods[0]))
    return out


@functools.cache
def reference_gait(name, gamma):
    return ref.gait(gamma, FAMILIES[name])


@functools.cache
def reference_long_gait(gamma):
    """The long-period gait at `gamma` >= 0.0145, continued in the reference."""
    z = reference_gait("stable", 0.0145)["z"]
    for g in (0.0165, 0.0183, 0.0190, 0.0192):
        if g <= gamma:
            z = ref.fixed_point(g, z)[0]
    return ref.fixed_point(gamma, z)[0]


def detect_period(taus, tol=1e-5):
    for k in (1, 2, 4, 8, 16, 32):
        if np.max(np.abs(taus[k:] - taus[:-k])) < tol:
            return k
    return 0


# ---- the model -----------------------------------------------------------------------------
def test_parameters_and_reference_gaits():
    w = vj.SimplestWalker()
    assert bool(w.validate())
    for bad in (dict(M=-1.0), dict(l=0.0), dict(g=-9.81), dict(psi=0.0), dict(psi=0.6)):
        assert not bool(vj.SimplestWalker(**bad).validate()), bad
    assert float(w.with_slope(0.004).psi) == 0.004 and float(w.with_slope(0.004).M) == 1.0
    with pytest.raises(NotImplementedError, match="generalized forces"):
        w.acceleration(jnp.zeros(2), jnp.zeros(2), jnp.ones(2))
    with pytest.raises(ValueError, match="family"):
        w.reference_gait("fast")
    for name in FAMILIES:
        # the literals are the reference's gaits at 0.009 rad
        model, z = w.reference_gait(name)
        assert float(model.psi) == 0.009
        g = reference_gait(name, 0.009)
        assert np.max(np.abs(garcia(model, z) - g["z"])) < 1e-12
        # a dimensional walker: the same angles, rates scaled by sqrt(g/l)
        big, zb = vj.SimplestWalker(M=3.0, l=2.0, g=9.81).reference_gait(name)
        assert float(big.g) == 9.81 and float(big.psi) == 0.009
        np.testing.assert_allclose(garcia(big, zb), garcia(model, z), rtol=1e-15, atol=1e-15)


@eqx.filter_jit
def _dynamics(model, x):
    """`(acceleration, x_plus, impulse, physical)` of `model` at the states `x` (batch)."""
    n = model.n_dof

    def one(x):
        return model.acceleration(x[:n], x[n:]), *model.impact(x)

    return jax.vmap(one)(x)


def test_limit_equations_and_impact():
    """The limit equations and impact map are the paper's (the reference), and the limit
    of the generic, energy-derived compass gait with its leg masses at the feet."""
    rng = np.random.default_rng(0)
    psi = 0.009
    q1 = rng.uniform(-0.35, -0.05, 6)
    x = np.stack([q1, -q1 - 2 * psi, rng.uniform(-0.4, -0.1, 6), rng.uniform(-0.4, 0.4, 6)], 1)
    w = vj.SimplestWalker(psi=psi)
    ddq, x_plus, impulse, physical = map(np.asarray, _dynamics(w, jnp.asarray(x)))
    # the compass gait with feet of 1e-8 of the hip's mass (its validate is not called):
    # it differs by O(1e-8), and its impact map, a solve with that mass on the diagonal,
    # loses about as many digits to rounding
    light = vj.CompassGait(m1=1e-8, m2=1e-8, mH=1.0, a=1.0, b=0.0, g=1.0, psi=psi)
    ddq_cg, x_plus_cg, impulse_cg, _ = map(np.asarray, _dynamics(light, jnp.asarray(x)))
    np.testing.assert_allclose(ddq, ddq_cg, rtol=0, atol=5e-8)
    np.testing.assert_allclose(x_plus, x_plus_cg, rtol=0, atol=5e-8)
    np.testing.assert_allclose(impulse, impulse_cg, rtol=0, atol=5e-8)
    assert physical.all()
    for xi, a, xp in zip(x, ddq, x_plus):
        # in the paper's variables: theta = q1 + psi, phi = q1 - q2
        y = [xi[0] + psi, xi[0] - xi[1], xi[2], xi[2] - xi[3]]
        rhs = ref.rhs(0.0, y, psi)
        np.testing.assert_allclose([a[0], a[0] - a[1]], rhs[2:], rtol=1e-13, atol=1e-15)
        y_plus = ref.heel_strike(y)
        np.testing.assert_allclose(
            [xp[0] + psi, xp[0] - xp[1], xp[2], xp[2] - xp[3]], y_plus, rtol=1e-12, atol=1e-15
        )


def test_swing_energy_and_impact_momentum():
    """Along a simulated walk: the swing conserves the hip's energy; heel strike conserves
    the hip's angular momentum about the landing foot, its impulse pushes along the new
    stance leg, and the kinetic energy lost is that of the hip's velocity along that leg."""
    model, z, _ = vhcjax_family("stable")[0.009]
    x0 = model.section_to_state(jnp.asarray(z) + jnp.array([0.0, 0.0, 0.01]))
    sim = vj.simulate(model, x0, 4)
    assert vj.result_names(sim.result) == "successful"
    steps = sim.steps
    starts = np.concatenate([np.asarray(x0)[None], np.asarray(steps.x_plus[:-1])])
    for x_start, xm, xp, p in zip(starts, steps.x_minus, steps.x_plus, steps.impulse):
        xm, xp, p = np.asarray(xm), np.asarray(xp), np.asarray(p)
        assert abs(float(model.energy(jnp.asarray(xm)) - model.energy(jnp.asarray(x_start)))) < 1e-9
        q, dq = jnp.asarray(xm[:2]), jnp.asarray(xm[2:])
        pts = {k: np.asarray(v) for k, v in model.points(q).items()}
        r = pts["hip"] - pts["swing_foot"]  # from the landing foot to the hip
        u = r / np.linalg.norm(r)
        v_minus = np.asarray(jax.jvp(lambda q: model.points(q)["hip"], (q,), (dq,))[1])
        v_plus = v_minus + p / float(model.M)
        cross = lambda a, b: a[0] * b[1] - a[1] * b[0]  # noqa: E731
        assert abs(cross(r, v_plus) - cross(r, v_minus)) < 1e-14
        assert abs(cross(u, p)) < 1e-13 * np.linalg.norm(p) and np.dot(u, p) > 0
        # kinetic: the potential energy is measured from the stance foot, which changes
        kinetic = lambda x: float(model.kinetic_energy(jnp.asarray(x[:2]), jnp.asarray(x[2:])))  # noqa: E731
        loss = kinetic(xm) - kinetic(xp)
        assert abs(loss - 0.5 * float(model.M) * np.dot(v_minus, u) ** 2) < 1e-14


# ---- gaits against the reference ---------------------------------------------------------------
@pytest.mark.parametrize("psi", SLOPES)
@pytest.mark.parametrize("name", list(FAMILIES))
def test_gaits_match_reference(name, psi):
    model, z, period = vhcjax_family(name)[psi]
    g = reference_gait(name, psi)
    assert np.max(np.abs(garcia(model, z) - g["z"])) < 1e-9
    assert abs(period - g["tau"]) < 1e-8
    ev = multipliers(model, z)
    assert spectral_distance(ev, g["multipliers"]) < 1e-7
    assert abs(ev[2]) < 1e-10  # exactly 0: the state after impact ignores dq2 before it
    assert (np.abs(ev[0]) < 1) == (name == "stable")


def test_published_values():
    """Loose checks against the paper: the long-period gait at 0.009 rad against the
    values quoted from it to 5 digits (theta* = 0.20031, theta'* = -0.19983), and the
    abstract's stability range, 0 < gamma < 0.015 rad. phi'* follows from the heel-strike
    map alone, (1 - cos 2 theta*) theta'* = -0.01582: a phi'* of about -0.02 would not
    belong to this gait."""
    model, z, _ = vhcjax_family("stable")[0.009]
    theta, dtheta, dphi = garcia(model, z)
    assert abs(theta - 0.20031) < 1e-5 and abs(dtheta + 0.19983) < 1e-5
    assert abs(dphi - (1 - math.cos(2 * theta)) * dtheta) < 1e-12
    assert abs(dphi + 0.01582) < 1e-5
    assert round(float(FLIPS[0]), 3) == 0.015  # the flip, checked in test_first_flip_two_ways


def test_page_gaits_at_0009():
    """The page's table, from the reference."""
    for name in FAMILIES:
        g = reference_gait(name, 0.009)
        for value, text in zip([*g["z"], g["tau"]], GAITS_0009[name]):
            _close_to_page(value, text)
        ev = g["multipliers"]
        if name == "stable":
            re, im, mod = MULTIPLIERS_0009[name]
            _close_to_page(ev[0].real, re)
            _close_to_page(abs(ev[0].imag), im)
            _close_to_page(abs(ev[0]), mod)
        else:
            for e, text in zip(ev[:2].real, MULTIPLIERS_0009[name]):
                _close_to_page(e, text)
        assert abs(ev[2]) < 1e-8  # central differences


# ---- the small-slope law ---------------------------------------------------------------------
def _fit(slopes, theta, c):
    u = np.asarray(slopes) ** (2 / 3)
    return float(
        np.sum(u * (np.asarray(theta) / np.asarray(slopes) ** (1 / 3) - c)) / np.sum(u * u)
    )


@pytest.mark.parametrize("name", list(FAMILIES))
def test_small_slope_law(name):
    """theta* / gamma^(1/3) tends to the derived C, with a gamma^(2/3) correction D fitted
    at 1e-5, 1e-4, 1e-3 rad: vhcjax and the reference give the same D, the page's."""
    tau0, c_text, d_text = SMALL_SLOPE_LAW[name]
    c = ref.coefficient(FAMILIES[name])
    _close_to_page(c, c_text)
    if tau0 is not None:
        _close_to_page(2 * ref.long_period_half(), tau0)
    theta = [garcia(*vhcjax_family(name)[psi][:2])[0] for psi in SMALL]
    theta_ref = [reference_gait(name, psi)["z"][0] for psi in SMALL]
    # near a multiplier of 1 (the long-period gait at 1e-5 rad: 0.968) shooting is less exact
    np.testing.assert_allclose(theta, theta_ref, rtol=0, atol=5e-9)
    d, d_ref = _fit(SMALL, theta, c), _fit(SMALL, theta_ref, c)
    assert abs(d - d_ref) < 1e-4
    _close_to_page(d, d_text)
    _close_to_page(d_ref, d_text)
    for psi, th in zip(SMALL, theta):
        # the leading term alone is off by about D gamma
        assert abs(th - c * psi ** (1 / 3) - d * psi) < 0.02 * abs(d) * psi


# ---- period doubling and where walking stops ------------------------------------------------------
def test_first_flip_two_ways():
    """The long-period gait's multiplier crosses -1: vhcjax `period_doubling_slope`
    (regula falsi on det(I + J), autodiff Jacobians) and the reference's bisection on the
    multiplier (central differences) agree to 1e-9 rad."""
    lo, hi = 0.01508, 0.0151
    model, z, _ = vhcjax_family("stable")[0.0145]
    fp, _ = vj.continue_fixed_point(model, z, model.with_slope(lo))
    assert successful(fp)
    pd = vj.period_doubling_slope(lo, hi, np.asarray(fp.z), model=vj.SimplestWalker(), tol=1e-11)
    z_ref = ref.fixed_point(lo, reference_gait("stable", 0.0145)["z"])[0]
    psi_ref = ref.flip_slope(lo, hi, z_ref, tol=1e-11)
    assert abs(pd.psi - psi_ref) < 1e-9, (pd.psi, psi_ref)
    assert abs(np.min(pd.multipliers.real) + 1) < 1e-6
    _close_to_page(pd.psi, FLIPS[0])
    _close_to_page(psi_ref, FLIPS[0])


@pytest.mark.parametrize("k", [2, 4])
def test_cascade_flips(k):
    """The period-k gait's flip (the page's, from vhcjax): in the reference, its k-step
    map's multiplier is above -1 just below it and below -1 just above it."""
    psi, z = CASCADE_SEEDS[k]
    seed = garcia(vj.SimplestWalker(psi=psi), z)
    h = 1e-6
    (f_lo, z_lo), (f_hi, _) = (ref.flip_function(psi + s, seed, k) for s in (-h, h))
    assert f_lo > 0 > f_hi
    root = psi - h + 2 * h * f_lo / (f_lo - f_hi)
    assert abs(root - psi) < 1e-9
    _close_to_page(root, FLIPS[k // 2])
    # a gait of period k, not a shorter one
    assert np.max(np.abs(ref.step_map(z_lo, psi - h, k // 2) - z_lo)) > 1e-3
    if k == 4:  # the ratio of the cascade's first two intervals
        g1, g2, g3 = 0.0150884380, CASCADE_SEEDS[2][0], CASCADE_SEEDS[4][0]
        _close_to_page((g2 - g1) / (g3 - g2), FLIP_RATIO)


def test_chaotic_walking_and_falls():
    """From the long-period gait with dq2 + 1e-4 (the reference): no period up to 32 in
    the last 64 of 464 steps at 0.0183 and 0.0190 rad, still walking; a fall at 0.0192."""
    steps = sum(LONG_RUN)
    for text in CHAOTIC:
        gamma = float(text)
        z = section(gamma, reference_long_gait(gamma)) + np.array([0.0, 0.0, START])
        taus = ref.walk(gamma, garcia(vj.SimplestWalker(psi=gamma), z), steps)
        assert len(taus) == steps and detect_period(taus[-LONG_RUN[1] :]) == 0, gamma
    gamma = float(FALL[0])
    z = section(gamma, reference_long_gait(gamma)) + np.array([0.0, 0.0, START])
    taus = ref.walk(gamma, garcia(vj.SimplestWalker(psi=gamma), z), steps)
    assert abs(len(taus) - int(FALL[1])) <= 1


def test_page_has_these_numbers():
    text = PAGE.read_text()
    numbers = [
        *(t for v in GAITS_0009.values() for t in v),
        *(t for v in MULTIPLIERS_0009.values() for t in v),
        *(t for v in SMALL_SLOPE_LAW.values() for t in v if t is not None),
        *FLIPS,
        FLIP_RATIO,
        *CHAOTIC,
        *FALL,
        str(sum(LONG_RUN)),
        str(LONG_RUN[1]),
    ]
    missing = [t for t in numbers if t not in text]
    assert not missing, missing


# ---- the compass gait with light feet, and a scaled walker ------------------------------------------
@pytest.mark.parametrize("name", list(FAMILIES))
def test_light_compass_gait_converges(name):
    """`CompassGait` with its leg masses beta at the feet: its gaits approach the simplest
    walker's linearly in beta."""
    model, z, _ = vhcjax_family(name)[0.009]
    # the stance leg's mass at its foot (b = 0) where CompassGait accepts it, else just above
    b = 0.0 if bool(vj.CompassGait(b=0.0).validate()) else 1e-6
    dist = []
    for beta in (1e-2, 1e-3, 1e-4):
        cg = vj.CompassGait(m1=beta, m2=beta, mH=1.0, a=1.0 - b, b=b, g=1.0, psi=0.009)
        fp = fixed_point(cg, z)
        assert successful(fp), beta
        dist.append(float(jnp.max(jnp.abs(fp.z - z))))
    assert 0.09 < dist[1] / dist[0] < 0.11 and 0.09 < dist[2] / dist[1] < 0.11, dist
    assert dist[2] < 1e-4


@pytest.mark.parametrize("name", list(FAMILIES))
def test_scaled_walker(name):
    """A walker of 1e6 kg on legs of 1 km under gravity 1e-4 m/s^2: the same angles, its
    rates and periods scaled by sqrt(l/g) and its energy by M g l."""
    big, z0 = vj.SimplestWalker(M=1e6, l=1e3, g=1e-4).reference_gait(name)
    fp = fixed_point(big, z0)
    assert successful(fp)
    model, z, _ = vhcjax_family(name)[0.009]
    unit = fixed_point(model, z)
    ts = float(big.time_scale)
    assert np.max(np.abs(garcia(big, fp.z) - garcia(model, unit.z))) < 1e-9
    assert abs(float(fp.periods[0]) / ts - float(unit.periods[0])) < 1e-9
    assert spectral_distance(multipliers(big, fp.z), multipliers(model, unit.z)) < 1e-7
    energy = float(big.energy(big.section_to_state(fp.z))) / (1e6 * 1e3 * 1e-4)
    assert abs(energy - float(model.energy(model.section_to_state(unit.z)))) < 1e-9
