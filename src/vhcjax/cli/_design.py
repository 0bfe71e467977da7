"""`vhcjax design` and `vhcjax atlas`: walker design by gradient, and the flip-slope atlas
over mass and length ratios."""

import argparse
import csv
import math

from ._common import (
    FINITE,
    POSITIVE,
    CLIError,
    add_method_flag,
    add_model_flags,
    check_figure_file,
    check_finite,
    check_output_file,
    count,
    figure_output,
    model_from_args,
    number,
    parse_range,
    print_json,
    progress,
    read_number,
    read_numbers,
    shown,
    warn,
)

PARAMETERS = ("mass-hip", "mass-leg", "a", "b", "gravity")
OBJECTIVES = ("spectral-radius", "flip-slope", "speed")
ATLAS_CSV = [
    "mass_ratio",
    "length_ratio",
    "flip_slope_deg",
    "stable_lo_deg",
    "stable_hi_deg",
    "spectral_radius",
    "reason",
]


SLOPE_DEG = number(float, lo=0.0, hi=30.0, lo_open=True, hi_open=True)


def register(subparsers):
    p = subparsers.add_parser(
        "design",
        help="optimise walker parameters by gradient (exact implicit derivatives)",
        description="Optimise the compass gait's parameters within bounds for an objective "
        "of its stable gait at --slope-deg: the spectral radius (minimised), the slope where "
        "the gait period-doubles (maximised) or the speed (maximised). Projected Adam "
        "(optax) on exact gradients (implicit function theorem at each gait), then gradient "
        "sampling where the objective has a kink; every iterate is a converged gait "
        "continued from the last, no worse than the last. The model flags give the start.",
    )
    add_model_flags(p)
    p.add_argument("--objective", required=True, choices=OBJECTIVES)
    p.add_argument(
        "--vary",
        required=True,
        metavar="NAMES",
        help="comma-separated parameters to vary, from " + ", ".join(PARAMETERS),
    )
    p.add_argument(
        "--bounds",
        metavar="NAME=LO:HI,...",
        help="bounds of varied parameters (SI units), e.g. mass-hip=1:40,a=0.1:0.9; "
        "default mass 1:40 (hip) 1:20 (leg) kg, lengths 0.1:0.9 m, gravity 1:20 m/s^2 "
        "for the thesis's walker (20 kg, 1 m), in the same proportion for others",
    )
    p.add_argument(
        "--steps", type=count(1, 10_000), default=30, help="iterations at most (default 30)"
    )
    p.add_argument(
        "--learning-rate",
        type=POSITIVE,
        default=0.05,
        help="Adam rate in the parameters scaled to [0, 1] (default 0.05)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help='print {"objective", "slope_deg", "vary", "result", "iterations", '
        '"initial", "optimum", "history"}',
    )
    p.add_argument("--png", metavar="FILE", help="objective and parameters against iteration")
    add_method_flag(p)
    p.set_defaults(func=run_design)

    a = subparsers.add_parser(
        "atlas",
        help="flip slope and stable slope range over mass and length ratios",
        description="Over a grid of mass ratio mu = mH/m and length ratio beta = b/a, the "
        "first period-doubling slope of the stable period-1 gait, the slope range where it "
        "is stable, and its spectral radius at --slope-deg if given; all cells batched. The "
        "leg mass (--mass-leg), leg length (--a + --b) and gravity only set the scales.",
    )
    add_model_flags(a, slope=False)
    for action in a._actions:  # the mass ratio sets the hip mass: refused (`run_atlas`)
        if action.dest == "mass_hip":
            action.default, action.help = None, argparse.SUPPRESS
    a.add_argument(
        "--mass-ratio",
        required=True,
        metavar="START:STOP:STEP|LIST",
        help="mass ratios mH/m, e.g. 1:4:0.5 (inclusive) or 1,2,3",
    )
    a.add_argument(
        "--length-ratio",
        required=True,
        metavar="START:STOP:STEP|LIST",
        help="length ratios b/a, e.g. 0.6:1.4:0.2 or 0.8,1,1.2",
    )
    a.add_argument(
        "--slope-deg",
        type=FINITE,  # range checked by run_atlas like the model flags
        default=None,
        help="report the spectral radius at this slope (degrees, in (0, 30))",
    )
    a.add_argument(
        "--scan-start-deg",
        type=SLOPE_DEG,
        default=1.0,
        help="slope where the scan starts (degrees, default 1)",
    )
    a.add_argument(
        "--scan-max-deg",
        type=SLOPE_DEG,
        default=12.0,
        help="highest slope scanned for the flip (degrees, default 12)",
    )
    a.add_argument(
        "--scan-step-deg",
        type=number(float, lo=0.0, hi=10.0, lo_open=True),
        default=0.5,
        help="slope step of the scan (degrees, default 0.5)",
    )
    a.add_argument(
        "--json",
        action="store_true",
        help='print {"mass_ratio", "length_ratio", "cells": [{"mass_ratio", '
        '"length_ratio", "flip_slope_deg", "stable_range_deg", "spectral_radius"}]}',
    )
    a.add_argument("--csv", metavar="FILE", help="one row per cell: " + ", ".join(ATLAS_CSV))
    a.add_argument("--png", metavar="FILE", help="heat map of the flip slope with contours")
    a.add_argument(
        "--checkpoint",
        metavar="FOLDER",
        help="write the cells to FOLDER in chunks as they finish (CSV files); the same "
        "command run again, after an interruption, computes only the chunks not there",
    )
    add_method_flag(a)
    a.set_defaults(func=run_atlas)


def _positive(name, v):
    check_finite(name, v)
    if v <= 0:
        raise CLIError(f"{name} must be positive, got {v}")


def parse_vary(text):
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise CLIError("--vary needs at least one parameter")
    for n in names:
        if n not in PARAMETERS:
            raise CLIError(
                f"--vary: unknown parameter {shown(n)} (choose from {', '.join(PARAMETERS)})"
            )
    if len(set(names)) != len(names):
        raise CLIError(f"--vary lists a parameter twice: {shown(text)}")
    return names


#: Most slopes an atlas scan visits (they are solved in sequence).
MAX_SCAN_SLOPES = 2_000
#: Largest HI/LO of a design bound.
MAX_BOUND_RATIO = 1e3


def parse_bounds(text, vary):
    out = {}
    if not text:
        return out
    for item in text.split(","):
        try:
            name, rng = item.split("=")
            lo_text, hi_text = rng.split(":")
        except ValueError:
            raise CLIError(f"--bounds must be NAME=LO:HI,..., got {shown(item)}") from None
        name = name.strip()
        try:
            lo, hi = read_number(lo_text), read_number(hi_text)
        except ValueError as e:
            raise CLIError(f"--bounds {shown(name)}: {e}") from None
        if name not in vary:
            raise CLIError(f"--bounds: {shown(name)} is not in --vary")
        if name in out:
            raise CLIError(f"--bounds: {name} is given twice")
        check_finite("--bounds", lo, hi)
        if not 0 < lo < hi:
            raise CLIError(f"--bounds: {name} needs 0 < LO < HI, got {lo}:{hi}")
        if hi / lo > MAX_BOUND_RATIO:
            raise CLIError(
                f"--bounds: {name} spans {hi / lo:.3g} x (HI/LO); at most {MAX_BOUND_RATIO:g}: "
                "the design moves in parameters scaled to the bounds, and a wider box "
                "leaves gradient steps too small to move"
            )
        out[name] = (lo, hi)
    return out


def parse_values(text, name):
    """`START:STOP:STEP` (STOP included when on the grid, never passed) or a
    comma-separated list of positive numbers (`read_number`)."""
    if ":" in text:
        values = parse_range(text, name)  # never past STOP
    else:
        values = read_numbers(text, name)
    for v in values:
        _positive(name, v)
    if len(values) > 200:
        raise CLIError(f"{name}: at most 200 values, got {len(values)}")
    return values


def _params_json(params):
    return {k: float(v) for k, v in params.items()}


def run_design(args):
    import numpy as np

    from ..parameters import design

    model = model_from_args(args)
    check_figure_file(args.png, "--png")
    vary = parse_vary(args.vary)
    bounds = parse_bounds(args.bounds, vary)
    if not 1 <= args.steps <= 1000:
        raise CLIError(f"--steps must be in 1..1000, got {args.steps}")
    _positive("--learning-rate", args.learning_rate)
    if args.learning_rate > 1:
        raise CLIError(f"--learning-rate must be at most 1, got {args.learning_rate}")
    from ..parameters import default_bounds, parameters_of

    start = parameters_of(model)
    defaults = default_bounds(model)
    for name in vary:
        lo, hi = bounds.get(name, defaults[name])
        if not lo <= start[name] <= hi:
            raise CLIError(f"--{name} = {start[name]} is outside its bounds {lo}:{hi}")
    bar = progress(total=args.steps + 1, desc=f"design {args.objective}")
    try:
        res = design(
            args.objective,
            vary,
            model=model,
            bounds=bounds,
            steps=args.steps,
            learning_rate=args.learning_rate,
            callback=lambda h: bar.update(1),
            method=args.method,
        )
    except ValueError as e:
        raise CLIError(str(e)) from None
    finally:
        bar.close()
    flip = args.objective == "flip-slope"
    if not res.optimum["stable"]:
        warn(
            args,
            f"the optimal gait is unstable (spectral radius "
            f"{res.optimum['spectral_radius']:.4g}): the design left the stable walkers",
        )

    def value(v):
        v = math.degrees(v) if flip else v
        return v if math.isfinite(v) else None

    def grad(g):
        return {k: (math.degrees(v) if flip else v) for k, v in g.items()}

    out = {
        "objective": args.objective,
        "slope_deg": args.slope_deg,
        "vary": vary,
        "result": res.result,
        "iterations": res.iterations,
        "initial": {
            "params": _params_json(res.initial["params"]),
            "value": value(res.initial["value"]),
            "gradient": grad(res.initial["gradient"]),
        },
        "optimum": {
            "params": _params_json(res.optimum["params"]),
            "value": value(res.optimum["value"]),
            "gradient": grad(res.optimum["gradient"]),
            "x0": res.optimum["x0"],
            "multipliers": [
                [float(np.real(m)), float(np.imag(m))] for m in res.optimum["multipliers"]
            ],
            "spectral_radius": res.optimum["spectral_radius"],
            "stable": res.optimum["stable"],
        },
        "history": [
            {
                "iteration": h["iteration"],
                "params": _params_json(h["params"]),
                "value": value(h["value"]),
                "step": h["step"],
            }
            for h in res.history
        ],
        "projected_gradient": res.projected_gradient,
        "stationarity": res.stationarity,
        "sampling_radius": res.sampling_radius,
        "result_reason": _REASONS[res.result],
        "units": {
            "value": "deg" if flip else ("m/s" if args.objective == "speed" else "-"),
            "gradient": "value units per parameter unit (kg, m, m/s^2)",
            "projected_gradient": "objective (rad for flip-slope) per bound range: each "
            "varied parameter scaled to [0, 1] within its bounds",
            "stationarity": "as projected_gradient",
        },
    }
    if args.png:
        from ..plotting import plot_design

        with figure_output(args.png) as fh:
            plot_design(res, fh, args.slope_deg)
    if args.json:
        print_json(out)
    else:
        _print_design(args, out, vary)
    return 0 if res.result in ("successful", "max_iterations", "no_descent") else 1


#: Units of the parameters (`--vary` names).
UNITS = {"mass-hip": "kg", "mass-leg": "kg", "a": "m", "b": "m", "gravity": "m/s^2"}
#: Each objective in words: (what is done, the quantity, its unit).
_OBJECTIVE_WORDS = {
    "spectral-radius": ("minimise", "spectral radius", ""),
    "flip-slope": ("maximise", "period-doubling (flip) slope", " deg"),
    "speed": ("maximise", "speed", " m/s"),
}


def _print_design(args, out, vary):
    """The text output of `vhcjax design`: the summary `out` (its JSON) in words."""
    how, name, unit = _OBJECTIVE_WORDS[args.objective]
    print(
        f"design: {how} the {name} of the stable gait at slope {args.slope_deg:g} deg by "
        f"varying {', '.join(vary)}"
    )
    print(
        f"  ended after {out['iterations']} iterations: {out['result_reason']}"
        if out["result"] == "successful"
        else f"  stopped after {out['iterations']} iterations: {out['result_reason']}"
    )
    start, o = out["initial"], out["optimum"]

    def value(v):
        return "not defined" if v is None else f"{v:.6g}{unit}"

    print(f"  {name}: {value(start['value'])} -> {value(o['value'])}")
    for k in vary:
        print(f"  {k}: {start['params'][k]:.6g} -> {o['params'][k]:.6g} {UNITS[k]}")
    verdict = "stable" if o["stable"] else "unstable"
    print(f"  the final gait is {verdict} (largest multiplier modulus {o['spectral_radius']:.6g})")


#: What each `DesignResult.result` means (the JSON's `result_reason`).
_REASONS = {
    "successful": (
        "a stationary point: the projected gradient vanished (to its relative tolerance), "
        "or, where the objective has a kink, the shortest vector in the convex hull of "
        "the gradients sampled near the optimum did"
    ),
    "max_iterations": "the iteration limit (--steps) was reached before a stationary point",
    "no_descent": (
        "gradient sampling found no step that improves the objective, down to its "
        "smallest radius, and no stationary point either"
    ),
    "no_gait": "no gait was found along the last step from the last iterate",
}


def run_atlas(args):
    import numpy as np

    from .._chunks import CheckpointError
    from ..parameters import atlas, atlas_json

    if args.mass_hip is not None:
        raise CLIError("--mass-hip is set by --mass-ratio here (mH = ratio x --mass-leg): drop it")
    args.mass_hip = 10.0  # a placeholder: each cell's hip mass is its ratio x --mass-leg
    model_from_args(args, slope_deg=3.0)  # validates the other model flags
    check_output_file(args.csv, "--csv")
    check_figure_file(args.png, "--png")
    mu = parse_values(args.mass_ratio, "--mass-ratio")
    beta = parse_values(args.length_ratio, "--length-ratio")
    if args.slope_deg is not None:
        check_finite("--slope-deg", args.slope_deg)
        if not 0 < args.slope_deg < 30:
            raise CLIError(f"--slope-deg must be in (0, 30) degrees, got {args.slope_deg}")
    for name in ("scan_start_deg", "scan_max_deg", "scan_step_deg"):
        v = getattr(args, name)
        flag = "--" + name.replace("_", "-")
        _positive(flag, v)
        if v >= 30:
            raise CLIError(f"{flag} must be below 30 degrees, got {v}")
    if args.scan_max_deg <= args.scan_start_deg:
        raise CLIError("--scan-max-deg must be above --scan-start-deg")
    scan = (args.scan_max_deg - args.scan_start_deg) / args.scan_step_deg
    if scan > MAX_SCAN_SLOPES:
        raise CLIError(
            f"--scan-step-deg {args.scan_step_deg:g} scans {scan:.3g} slopes one after "
            f"another; at most {MAX_SCAN_SLOPES}"
        )
    if args.slope_deg is not None and args.slope_deg < args.scan_start_deg:
        raise CLIError("--slope-deg must not be below --scan-start-deg")
    try:
        at = atlas(
            np.asarray(mu),
            np.asarray(beta),
            slope=None if args.slope_deg is None else math.radians(args.slope_deg),
            mass_leg=args.mass_leg,
            leg_length=args.a + args.b,
            gravity=args.gravity,
            psi_start=math.radians(args.scan_start_deg),
            psi_max=math.radians(args.scan_max_deg),
            step=math.radians(args.scan_step_deg),
            method=args.method,
            checkpoint=args.checkpoint,
        )
    except CheckpointError as e:
        raise CLIError(str(e)) from None
    rec = atlas_json(at)
    if args.csv:
        from .._io import atomic_open

        with atomic_open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=ATLAS_CSV)
            w.writeheader()
            for c in rec["cells"]:
                rng = c["stable_range_deg"] or [None, None]
                w.writerow(
                    {
                        "mass_ratio": c["mass_ratio"],
                        "length_ratio": c["length_ratio"],
                        "flip_slope_deg": c["flip_slope_deg"],
                        "stable_lo_deg": rng[0],
                        "stable_hi_deg": rng[1],
                        "spectral_radius": c["spectral_radius"],
                        "reason": c.get("reason", ""),
                    }
                )
    if args.png:
        from ..plotting import plot_atlas

        with figure_output(args.png) as fh:
            plot_atlas(
                at, fh, mass_leg=args.mass_leg, leg_length=args.a + args.b, gravity=args.gravity
            )
    if args.json:
        print_json(rec)
    else:
        _print_atlas(args, rec, mu, beta)
    return 0


def _print_atlas(args, rec, mu, beta):
    """The text output of `vhcjax atlas`: one line per cell."""
    found = sum(c["flip_slope_deg"] is not None for c in rec["cells"])
    print(
        f"atlas over the mass ratio mu = mH/m ({_span(mu)}) and the length ratio beta = b/a "
        f"({_span(beta)}): the first period-doubling (flip) slope of the stable gait, found "
        f"in {found} of {len(mu) * len(beta)} cells"
    )
    for c in rec["cells"]:
        f = c["flip_slope_deg"]
        line = f"  mu {c['mass_ratio']:.4g}, beta {c['length_ratio']:.4g}: "
        if f is None:
            line += c.get("reason", "no flip slope found")
        else:
            line += f"flip at {f:.5f} deg"
            rng = c.get("stable_range_deg")
            if rng:
                line += f", stable from {rng[0]:.4g} to {rng[1]:.4g} deg"
        rho = c.get("spectral_radius")
        if args.slope_deg is not None and rho is not None:
            line += f"; spectral radius {rho:.4g} at {args.slope_deg:g} deg"
        print(line)


def _span(values):
    """`"a"` or `"a to b"`: the first and last of some values, for a message."""
    return f"{values[0]:g}" if len(values) == 1 else f"{values[0]:g} to {values[-1]:g}"
