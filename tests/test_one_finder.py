"""One gait finder: `find_gait(method="auto")` and every door that uses it find the same
gait, for unusual walkers and in any units; the VHC search's failures fall back to
shooting, whatever their reason."""

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest

import vhcjax as vj
from vhcjax.cli import main
from vhcjax.gait import _find

#: A light hip (1 kg on 5 kg legs) at 4.5 degrees: the VHC search's phi'' ODE is singular
#: along its stable gait, which shooting finds (section point, to 1e-12).
LIGHT_HIP = {"mH": 1.0, "psi": math.radians(4.5)}
LIGHT_HIP_Z = (0.134029020219, -1.024185189159, 0.386163037854)
#: The same, rounded: a guess for the searches.
LIGHT_HIP_GUESS = (0.134, -1.024, 0.386)


def _json(capsys, argv):
    code = main(argv + ["--json", "--quiet"])
    return code, json.loads(capsys.readouterr().out)


@pytest.mark.parametrize(
    "code",
    [
        "no_real_root",
        "singular_phi_ode",
        "not_converged",
        "nonfinite",
        "bad_impact",
        "other_cycle",
        "infeasible_uphill",
    ],
)
def test_auto_falls_back_to_shooting_whatever_the_vhc_failure(monkeypatch, code):
    """Wherever the VHC search ends without a gait, for any reason, `auto` returns the
    gait shooting finds (the VHC search's result is replaced here by each failure)."""
    real = _find._compass_gait

    def failing(model, family, method, guess, solver):
        gait = real(model, family, method, guess, solver)
        if method == "vhc":
            bad = vj.RESULTS.where(True, getattr(vj.RESULTS, code), gait.result)
            gait = _find.dataclasses.replace(gait, result=bad)
        return gait

    monkeypatch.setattr(_find, "_compass_gait", failing)
    m = vj.CompassGait()
    auto = vj.find_gait(m, "stable", guess=(0.2, -1.1))
    shot = vj.find_gait(m, "stable", "shooting", guess=(0.2, -1.1))
    assert auto.found_by == "shooting" and auto.method == "auto"
    np.testing.assert_array_equal(np.asarray(auto.x_plus), np.asarray(shot.x_plus))


def test_a_finding_of_the_vhc_search_is_kept_where_shooting_fails_too():
    """The thesis's uphill solution (7.17): the VHC search finds it and says what it is;
    shooting from the same seed falls, which is no better answer."""
    g = vj.find_gait(vj.CompassGait(), "stable", guess=(0.20, 1.0), throw=False)
    assert vj.result_names(g.result) == "infeasible_uphill" and g.found_by == "vhc"


def test_every_door_finds_the_gait_the_vhc_search_misses(capsys):
    """The light hip: the VHC search fails (singular phi'' ODE); `find_gait`, `find_gaits`
    and `vhcjax gait` find shooting's gait, and say that shooting found it."""
    m = vj.CompassGait(**LIGHT_HIP)
    vhc = vj.find_gait(m, "stable", "vhc", guess=LIGHT_HIP_GUESS[:2], throw=False)
    assert vj.result_names(vhc.result) == "singular_phi_ode"
    one = vj.find_gait(m, "stable", guess=LIGHT_HIP_GUESS)
    assert one.found_by == "shooting"
    np.testing.assert_allclose(np.asarray(one.z), LIGHT_HIP_Z, rtol=0, atol=1e-10)
    batch = vj.find_gaits(
        vj.CompassGait(mH=1.0),
        jnp.asarray([LIGHT_HIP_GUESS, LIGHT_HIP_GUESS]),
        psi=jnp.radians(jnp.asarray([4.5, 4.0])),  # at 4 degrees the VHC search holds
    )
    assert vj.result_names(batch.result) == ["successful"] * 2
    assert batch.found_by == ["shooting", "vhc"] and batch.method == "auto"
    np.testing.assert_allclose(np.asarray(batch.z[0]), LIGHT_HIP_Z, rtol=0, atol=1e-10)
    argv = ["gait", "--mass-hip", "1", "--slope-deg", "4.5", "--no-stability", "--guess"]
    code, rec = _json(capsys, argv + [str(v) for v in LIGHT_HIP_GUESS])
    assert code == 0 and rec["method"] == "shooting" and "method_reason" in rec
    z = [rec["params"][k] for k in ("a", "b", "f")]
    np.testing.assert_allclose(z, LIGHT_HIP_Z, rtol=0, atol=1e-10)
    # --method vhc alone: no gait, exit 1, one line that points to auto
    code = main(argv + [str(v) for v in LIGHT_HIP_GUESS[:2]] + ["--method", "vhc", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1 and "try --method auto" in err


def test_light_feet_walker_without_a_guess(capsys):
    """Garcia et al.'s walker as a compass gait (leg masses at the feet, 1e-4 of the hip's,
    b = 0): the gait continued from the thesis's walker by `find_gait` is shooting's,
    and `vhcjax gait` reports the same one."""
    kw = dict(m1=1e-4, m2=1e-4, mH=1.0, a=1.0, b=0.0, g=1.0, psi=math.radians(0.9))
    m = vj.CompassGait(**kw)
    auto = vj.find_gait(m, "unstable")
    shot = vj.find_gait(m, "unstable", "shooting", guess=np.asarray(auto.z))
    np.testing.assert_allclose(np.asarray(auto.z), np.asarray(shot.z), rtol=0, atol=1e-10)
    flags = ["--mass-hip", "1", "--mass-leg", "1e-4", "--a", "1", "--b", "0", "--gravity", "1"]
    code, rec = _json(
        capsys, ["gait", "--slope-deg", "0.9", "--family", "unstable", "--no-stability"] + flags
    )
    assert code == 0
    np.testing.assert_allclose(rec["x0"], np.asarray(auto.x_plus), rtol=0, atol=1e-12)


def test_a_walker_with_its_leg_masses_at_the_hip_is_refused_in_one_line(capsys):
    assert main(["gait", "--a", "0", "--b", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no inertia" in err


SCALINGS = [
    ("length", 1e-3),
    ("length", 1e3),
    ("mass", 1e-6),
    ("mass", 1e6),
    ("gravity", 1e-4),
    ("gravity", 1e4),
]


def _scaled(kind, k, psi=math.radians(3.0)):
    m = dict(m1=5.0, m2=5.0, mH=10.0, a=0.5, b=0.5, g=9.81)
    names = {"length": ("a", "b"), "mass": ("m1", "m2", "mH"), "gravity": ("g",)}[kind]
    for name in names:
        m[name] *= k
    return vj.CompassGait(psi=psi, **m)


@pytest.mark.parametrize("family", ["stable", "unstable"])
def test_a_scaled_walker_has_the_same_gait_in_its_own_units(family):
    """Lengths x 1e-3 and 1e3, masses x 1e-6 and 1e6, gravity x 1e-4 and 1e4: the same
    angles, velocities over the time unit sqrt(l/g), energies over m g l (to 1e-9),
    multipliers equal (to 5e-10)."""
    ref = vj.find_gait(vj.CompassGait(), family)
    mref = vj.gait_multipliers(vj.CompassGait(), ref.z, transverse=False).poincare
    for kind, k in SCALINGS:
        m = _scaled(kind, k)
        g = vj.find_gait(m, family)
        t = math.sqrt({"length": k, "mass": 1.0, "gravity": 1 / k}[kind])  # time unit ratio
        e = {"length": k, "mass": k, "gravity": k}[kind]  # energy unit ratio
        np.testing.assert_allclose(g.x_plus[:2], ref.x_plus[:2], rtol=0, atol=1e-9)
        np.testing.assert_allclose(g.x_plus[2:] * t, ref.x_plus[2:], rtol=1e-9, atol=0)
        np.testing.assert_allclose(g.T / t, ref.T, rtol=1e-9)
        np.testing.assert_allclose(g.E0 / e, ref.E0, rtol=1e-9)
        lengths = {"length": k}.get(kind, 1.0)
        np.testing.assert_allclose(g.step_length / lengths, ref.step_length, rtol=1e-9)
        # the swing runs in the walker's own units: the Jacobians agree to the gaits' own
        # agreement (the fixed points' accuracy, ~1e-11)
        mult = vj.gait_multipliers(m, g.z, transverse=False).poincare
        np.testing.assert_allclose(np.abs(mult), np.abs(mref), rtol=0, atol=5e-10)


def test_the_command_line_scales_too(capsys):
    """`vhcjax gait` on the thesis's walker at a thousandth of its size and a thousand
    times its gravity: the same angles, the period over 1000."""
    _, ref = _json(capsys, ["gait", "--no-stability"])
    flags = ["--a", "5e-4", "--b", "5e-4", "--gravity", "9810", "--no-stability"]
    code, rec = _json(capsys, ["gait"] + flags)
    assert code == 0 and rec["method"] == ref["method"] == "vhc"
    for key in ("a", "c", "e", "g"):
        assert abs(rec["params"][key] - ref["params"][key]) < 1e-9
    assert abs(rec["params"]["T"] * 1000 - ref["params"]["T"]) < 1e-9
    assert abs(rec["params"]["b"] / 1000 - ref["params"]["b"]) < 1e-9


def test_models_carry_their_facts():
    """Slope change, reference gaits and units live on the models; the kneed walker's and
    the simplest walker's gaits come from the same finder."""
    for model in (vj.CompassGait(), vj.KneedWalker(), vj.SimplestWalker(), vj.PendulumWalker()):
        moved = model.with_slope(0.01)
        assert float(moved.psi) == 0.01
        assert set(model.UNITS.values()) <= {"mass", "length", "acceleration"}
    # the literals are gaits (the other models' are checked with their tests)
    ref, z = vj.PendulumWalker().reference_gait("stable")
    assert float(jnp.max(jnp.abs(vj.fixed_point(ref, z).z - z))) < 1e-9
    with pytest.raises(ValueError, match="one gait family"):
        vj.KneedWalker().reference_gait("unstable")
    kneed = vj.find_gait(vj.KneedWalker(psi=0.052))
    assert kneed.found_by == "shooting" and vj.result_names(kneed.result) == "successful"
    with pytest.raises(ValueError, match="VHC search"):
        vj.find_gait(vj.KneedWalker(), method="vhc")
