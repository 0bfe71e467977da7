"""Every command that returns a number, on the thesis's walker and on two rescaled copies
of it: the same angles, multipliers, counts and codes, and the lengths, times, speeds,
energies, impulses and torques scaled by their units.

Gravity, lengths and masses only rescale a walker. `S1` has lengths x 1e-3, masses x 1e6
and gravity x 1e4, `S2` lengths x 1e3, masses x 1e-6 and gravity x 1e-4, so each factor
is tried at both extremes. Inputs the user gives in physical units (a start state,
heights, bounds, weights) are scaled by the test; defaults are the command's. Every
numeric field of each command's JSON has a unit in `UNITS` (a new field fails until it is
classified; `NOT_COMPARED` names the few that are not compared, and why). `design` runs
twice, with a dimensional objective (speed) and a dimensionless one (spectral radius).
`reproduce` is left out: it runs the thesis's walker only (it has no model flags).

"""

import contextlib
import csv
import io
import json
import math

import numpy as np
import pytest

from vhcjax.cli import main

#: (lengths, masses, gravity) factors of each walker.
WALKERS = {"ref": (1.0, 1.0, 1.0), "S1": (1e-3, 1e6, 1e4), "S2": (1e3, 1e-6, 1e-4)}

# Units as exponents of (length, mass, time); angles, multipliers and counts are `ONE`.
ONE = (0, 0, 0)
LENGTH = (1, 0, 0)
MASS = (0, 1, 0)
TIME = (0, 0, 1)
RATE = (0, 0, -1)  # rad/s
VELOCITY = (1, 0, -1)
ACCELERATION = (1, 0, -2)
ENERGY = (2, 1, -2)
IMPULSE = (1, 1, -1)
TORQUE = ENERGY
#: A difference of two computations at rounding level (agreement, residual): compared
#: as a difference, not relative to itself.
NOISE = "noise"


def _per(a, b):
    return tuple(x - y for x, y in zip(a, b))


#: The post-impact section coordinates (q1, dq1, dq2) and the state (q1, q2, dq1, dq2).
SECTION = (ONE, RATE, RATE)
STATE = (ONE, ONE, RATE, RATE)
#: The transverse coordinates (I, y, dy) of the compass gait: I in rad^2/s^2.
ZETA = ((0, 0, -2), ONE, RATE)


def _each(units, depth=-1):
    """Units per index of the list at `depth` (from the leaf: -1 is the innermost)."""
    return ("each", depth, units)


def _per_impulse(units):
    return tuple(_per(u, IMPULSE) for u in units)


_MULTIPLIERS = ONE  # [re, im] pairs
_GAIT = {"x0": _each(STATE), "params.T": TIME, "params.E0": ENERGY}
_GAIT.update({f"params.{k}": ONE for k in "aceg"})
_GAIT.update({f"params.{k}": RATE for k in "bdfh"})
_STABILITY = {
    "multipliers": _MULTIPLIERS,
    "multipliers_poincare": _MULTIPLIERS,
    "max_abs_multiplier": ONE,
    "transverse_disagreement": NOISE,
}
_ANALYSED = {"gait": _each(SECTION), "period": TIME, "gait_spectral_radius": ONE}


def _design_units(objective):
    """`design`'s fields, its objective in the unit `objective`."""
    params = [
        ("mass-hip", MASS),
        ("mass-leg", MASS),
        ("a", LENGTH),
        ("b", LENGTH),
        ("gravity", ACCELERATION),
    ]
    units = {
        f"{where}.params.{k}": u for where in ("initial", "optimum", "history") for k, u in params
    }
    return {
        **units,
        "slope_deg": ONE,
        "iterations": ONE,
        "initial.value": objective,
        "optimum.value": objective,
        "history.value": objective,
        "history.iteration": ONE,
        "initial.gradient.a": _per(objective, LENGTH),
        "optimum.gradient.a": _per(objective, LENGTH),
        "optimum.x0": _each(STATE),
        "optimum.multipliers": ONE,
        "optimum.spectral_radius": ONE,
        "projected_gradient": objective,  # objective per bound range
        "stationarity": objective,
        "sampling_radius": ONE,
    }


#: Unit of every numeric field, per command; keys are the JSON's dict keys joined by
#: dots (list indices left out).
UNITS = {
    "gait": {
        **_GAIT,
        **_STABILITY,
        "slope_deg": ONE,
        "iterations": ONE,
        "residual": NOISE,  # the VHC search's, in the walker's own units
    },
    "sweep": {
        **{f"families.{f}.{k}": ONE for f in ("stable", "unstable") for k in ("found", "total")},
        **{f"families.{f}.found_by_shooting": ONE for f in ("stable", "unstable")},
        **{
            f"families.{f}.rows.{k}": u
            for f in ("stable", "unstable")
            for k, u in [
                *[(c, ONE) for c in "aceg"],
                *[(c, RATE) for c in "bdfh"],
                ("slope_deg", ONE),
                ("T", TIME),
                ("E0", ENERGY),
                ("step_length", LENGTH),
                ("speed", VELOCITY),
                ("max_abs_multiplier", ONE),
                *[
                    (f"{p}mult{i}_{c}", ONE)
                    for p in ("", "p")
                    for i in (1, 2, 3)
                    for c in ("re", "im")
                ],
            ]
        },
    },
    "multipliers": {**_STABILITY, "slope_deg": ONE, "z": _each(SECTION)},
    "bifurcation": {
        "period_doubling_slopes_deg": ONE,
        "period_doubling_slopes_deg_simulation": ONE,
        "first_fall_slope_deg": ONE,
        "no_gait_slopes_deg": ONE,
        "num_slopes": ONE,
        "num_no_gait": ONE,
        "num_fell": ONE,
        "num_aperiodic": ONE,
        "transient_steps": ONE,
        "recorded_steps": ONE,
        # the rows of --csv: the recorded step periods and their pattern
        "csv.slope_deg": ONE,
        "csv.pattern": ONE,
        "csv.periods": TIME,
    },
    "contraction": {
        **_ANALYSED,
        "multipliers": _MULTIPLIERS,
        "spectral_radius": ONE,
        "steps_10x": ONE,
        "steps_100x": ONE,
        "measured_rate": ONE,
        "measured_steps_10x": ONE,
        "measured_steps_100x": ONE,
    },
    "basin": {
        **_ANALYSED,
        "grid": ONE,
        "area": RATE,  # q1 x dq1: rad^2/s
        "fraction": ONE,
        **{f"counts.{k}": ONE for k in ("converged", "fell", "other_cycle", "undecided")},
        "max_converging.+q1": ONE,
        "max_converging.-q1": ONE,
        "max_converging.+dq1": RATE,
        "max_converging.-dq1": RATE,
        "offsets_x": ONE,
        "offsets_y": RATE,
        "label": ONE,
        "steps": ONE,
        "volume.box_half_widths": _each(SECTION),
        "volume.fraction": ONE,
        "volume.interval_95": ONE,
        "volume.volume": ONE,  # a fraction of the box
        **{f"volume.counts.{k}": ONE for k in ("converged", "fell", "other_cycle", "undecided")},
        "volume.samples": ONE,
    },
    "slope-sensitivity": {
        **_ANALYSED,
        "per_rad.dz": _each(SECTION),
        "per_rad.dperiod": TIME,
        "per_rad.dstep_length": LENGTH,
        "per_rad.dspeed": VELOCITY,
        "per_rad.dmultipliers": ONE,
        "per_rad.dmodulus": ONE,
        "values.step_length": LENGTH,
        "values.speed": VELOCITY,
        "values.multipliers": ONE,
        "gait_sensitivity_norm": _per(TIME, LENGTH),
        "dtimes_dh": _per(TIME, LENGTH),
        "max_step_down_m": LENGTH,
        "max_step_up_m": LENGTH,
        "recovery.heights_m": LENGTH,
        "recovery.label": ONE,
        "recovery.steps": ONE,
    },
    "push": {
        **_ANALYSED,
        "phases": ONE,
        # [phase][state component][direction]
        "sensitivity_dxplus_dP": _each(_per_impulse(STATE), -2),
        "transverse_dzeta_dP": _each(_per_impulse(ZETA), -2),
        "max_difference_autodiff_vs_transverse": NOISE,  # in the walker's own units
        "directions_deg": ONE,
        "largest": IMPULSE,
        "falls_at": IMPULSE,
        "most_fragile_phase": ONE,
    },
    "stabilize": {
        "slope_deg": ONE,
        "gait": _each(SECTION),
        "torque_limit": TORQUE,
        "open_loop_multipliers": ONE,
        "closed_loop_multipliers": ONE,
        "closed_loop_multipliers_transverse": ONE,
        "riccati_agreement": NOISE,
        "simulation.perturbation": _each(SECTION),
        "simulation.x0": _each(STATE),
        # in the walker's own units (rates times its time unit)
        "simulation.final_error": ONE,
        "simulation.passive_final_error": ONE,
        "simulation.x_final": _each(STATE),
        "simulation.steps": ONE,
        "simulation.steps_completed": ONE,
        "simulation.max_abs_torque": TORQUE,
        "simulation.rms_torque_first_step": TORQUE,
    },
    "design": _design_units(VELOCITY),  # --objective speed
    "design-rho": _design_units(ONE),  # --objective spectral-radius
    "atlas": {
        "mass_ratio": ONE,
        "length_ratio": ONE,
        "cells.mass_ratio": ONE,
        "cells.length_ratio": ONE,
        "cells.flip_slope_deg": ONE,
        "cells.stable_range_deg": ONE,
        "cells.spectral_radius": ONE,
    },
    "simulate": {
        "num_successful": ONE,
        "steps.x_plus": _each(STATE),
        "steps.x_minus": _each(STATE),
        "steps.period": TIME,
    },
}

#: Fields not compared: about the run rather than the walker (the tolerance settings in
#: words; the LQR weights, which the test checks against `default_weights`), or
#: maxima over entries of different units, which no single unit scales.
NOT_COMPARED = {
    "bifurcation": {"tolerance"},
    "stabilize": {
        "weights.q",
        "weights.r",
        "weights.q_jump",
        # gains in N m/rad and N m s/rad
        "max_gain",
    },
}


def _model_flags(k, leg_mass_only=False):
    kl, km, kg = k
    flags = [] if leg_mass_only else ["--mass-hip", repr(10 * km)]
    return flags + [
        "--mass-leg",
        repr(5 * km),
        "--a",
        repr(0.5 * kl),
        "--b",
        repr(0.5 * kl),
        "--gravity",
        repr(9.81 * kg),
    ]


def _time_unit(k):
    kl, _, kg = k
    return math.sqrt(kl / kg)


def _argv(command, k, tmp):
    kl = k[0]
    t = _time_unit(k)
    walker = _model_flags(k)
    return {
        "gait": ["gait", *walker],
        "sweep": ["sweep", "--slope-deg", "2:4:1", "--family", "both", *walker],
        "multipliers": ["multipliers", *walker],
        "bifurcation": [
            "bifurcation",
            "--slope-deg",
            "4.3:4.5:0.1",
            "--transient",
            "20",
            "--record",
            "8",
            "--csv",
            str(tmp),
            *walker,
        ],
        "contraction": ["contraction", "--perturbations", "4", "--steps", "8", *walker],
        "basin": ["basin", "--grid", "3", "3", "--steps", "10", "--volume-samples", "8", *walker],
        "slope-sensitivity": [
            "slope-sensitivity",
            "--steps",
            "10",
            "--heights-mm",
            repr(-0.4 * kl),
            repr(0.2 * kl),
            *walker,
        ],
        "push": [
            "push",
            "--phases",
            "2",
            "--directions-deg",
            "0",
            "180",
            "--iterations",
            "4",
            "--steps",
            "10",
            "--check",
            *walker,
        ],
        "stabilize": ["stabilize", "--steps", "5", *walker],  # default weights: scaled
        "design-rho": [
            "design",
            "--objective",
            "spectral-radius",
            "--vary",
            "a",
            "--steps",
            "2",
            "--bounds",
            f"a={0.1 * kl!r}:{0.9 * kl!r}",
            *walker,
        ],
        "design": [
            "design",
            "--objective",
            "speed",
            "--vary",
            "a",
            "--steps",
            "2",
            "--bounds",
            f"a={0.1 * kl!r}:{0.9 * kl!r}",
            *walker,
        ],
        "atlas": [
            "atlas",
            "--mass-ratio",
            "2",
            "--length-ratio",
            "1",
            "--slope-deg",
            "3",
            "--scan-start-deg",
            "3",
            "--scan-max-deg",
            "6",
            "--scan-step-deg",
            "1",
            *_model_flags(k, leg_mass_only=True),
        ],
        "simulate": [
            "simulate",
            "--steps",
            "3",
            "--x0",
            *[repr(v) for v in (0.218669, -0.323389, -1.092386 / t, -0.377377 / t)],
            *walker,
        ],
    }[command]


def _read_csv(path):
    """The rows of `bifurcation --csv`: slope, pattern and the recorded periods."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return [
        {
            "slope_deg": float(r["slope_deg"]),
            "result": r["result"],
            "pattern": int(r["pattern"]),
            "periods": [float(v) for k, v in r.items() if k.startswith("period_")],
        }
        for r in rows
    ]


_RUNS = {}


def _run(command, walker, tmp_path_factory):
    """Exit code and JSON of `command` on `walker` (run once per session)."""
    if (command, walker) not in _RUNS:
        tmp = tmp_path_factory.mktemp("scaling") / "out.csv"
        argv = _argv(command, WALKERS[walker], tmp) + ["--json", "--quiet"]
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = main(argv)
        rec = json.loads(out.getvalue()) if code == 0 else None
        if rec is not None and command == "bifurcation":
            rec["csv"] = _read_csv(tmp)
        _RUNS[command, walker] = code, rec
    return _RUNS[command, walker]


def _leaves(x, path=(), index=()):
    """`(dotted key, list indices, value)` of every leaf of a JSON value."""
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _leaves(v, path + (k,), index)
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _leaves(v, path, index + (i,))
    else:
        yield ".".join(path), index, x


def _unit(spec, index):
    if spec[0] == "each":
        _, depth, units = spec
        return units[index[depth]]
    return spec


def compare(command, ref, rec, k):
    """Worst disagreement of `rec` (walker scaled by `k`) with `ref`, each value divided
    by its unit's factor, over the largest |value| of its field and unit (`NOISE`
    fields: their difference): `{"one": (error, field), "dimensional": (error, field)}`.
    Fails on a field without a unit, a missing or extra field, or a different string,
    flag, null or integer count."""
    kl, km, kg = k
    t = _time_unit(k)
    table, skip = UNITS[command], NOT_COMPARED.get(command, set())
    a = [leaf for leaf in _leaves(ref) if leaf[0] not in skip]
    b = [leaf for leaf in _leaves(rec) if leaf[0] not in skip]
    assert [x[:2] for x in a] == [x[:2] for x in b], "the fields differ"
    scale, pairs = {}, []
    worst = {"one": (0.0, None), "dimensional": (0.0, None)}

    def note(kind, err, where):
        if err > worst[kind][0]:
            worst[kind] = (err, where)

    for (key, index, x), (_, _, y) in zip(a, b):
        if key.endswith("reason"):  # words; that a reason is there is compared above
            continue
        if isinstance(x, (str, bool)) or x is None or y is None:
            assert x == y, f"{key}{list(index)}: {x!r} vs {y!r}"
            continue
        assert key in table, f"{command}: numeric field {key!r} has no unit in UNITS"
        unit = _unit(table[key], index)
        if unit == NOISE:
            note("one", abs(x - y), key)
            continue
        if isinstance(x, int) and isinstance(y, int) and unit == ONE:
            assert x == y, f"{key}{list(index)}: {x} vs {y}"
        factor = kl ** unit[0] * km ** unit[1] * t ** unit[2]
        scale[key, unit] = max(scale.get((key, unit), 0.0), abs(x))
        pairs.append((key, index, unit, x, y / factor))
    for key, index, unit, x, y in pairs:
        err = abs(y - x) / (scale[key, unit] or 1.0)
        note("one" if unit == ONE else "dimensional", err, f"{key}{list(index)}")
    return worst


#: Largest disagreement allowed (see `compare`), `(dimensionless, dimensional)`: about
#: 10x the measured one (at least 1e-12, for other hardware).
TOL = {
    "gait": (1e-12, 1e-12),
    "sweep": (1e-12, 1e-12),
    "multipliers": (1e-10, 1e-12),
    "bifurcation": (1e-12, 3e-11),
    "contraction": (3e-10, 1e-12),
    "basin": (1e-12, 3e-11),  # the default half widths are rounded to 12 digits
    "slope-sensitivity": (5e-12, 1e-12),
    # --check: the transverse sensitivity agrees with autodiff to ~2e-11 (own units)
    "push": (3e-10, 4e-10),
    # the closed-loop simulation is as accurate as its solver on a field that is only
    # piecewise smooth in the phase (gain table): its RMS torque at the default
    # tolerance is within 2e-7 of a 1e-12 solve, its final error 10x less accurate
    "stabilize": (3e-6, 2e-7),
    "design": (1e-12, 3e-12),
    "design-rho": (7e-12, 7e-12),
    "atlas": (1e-12, 1e-12),
    "simulate": (1e-12, 1e-12),
}

CASES = [
    pytest.param(command, walker, id=f"{command}-{walker}")
    for command in UNITS
    for walker in ("S1", "S2")
]


@pytest.mark.parametrize("command, walker", CASES)
def test_scaling(command, walker, tmp_path_factory):
    code_ref, ref = _run(command, "ref", tmp_path_factory)
    assert code_ref == 0
    code, rec = _run(command, walker, tmp_path_factory)
    assert code == 0
    worst = compare(command, ref, rec, WALKERS[walker])
    tol_one, tol_dimensional = TOL[command]
    assert worst["one"][0] <= tol_one, worst
    assert worst["dimensional"][0] <= tol_dimensional, worst
    if command == "stabilize":  # the default weights: the thesis walker's 1, rescaled
        kl, km, kg = WALKERS[walker]
        t, torque = _time_unit(WALKERS[walker]), km * kg * kl
        w = rec["weights"]
        np.testing.assert_allclose(w["q"], [1 / t, t, t], rtol=1e-12)
        np.testing.assert_allclose(w["q_jump"], [1, t**2, t**2], rtol=1e-12)
        np.testing.assert_allclose(w["r"], 1 / (torque**2 * t), rtol=1e-12)
        assert ref["weights"] == {"q": [1.0, 1.0, 1.0], "r": 1.0, "q_jump": [1.0, 1.0, 1.0]}
