"""`vhcjax slope-sensitivity`: derivatives of a gait with respect to the slope, and
the floor steps it survives."""

import math

from ._analysed import (
    add_analysis_flags,
    analysed_gait,
    progress_bar,
    report_stability,
)
from ._common import (
    FINITE,
    CLIError,
    check_figure_file,
    count,
    describe,
    figure_output,
    print_json,
    second_figure,
    warn,
)
from ._words import bracket_words, list_words


def register(subparsers):
    p = subparsers.add_parser(
        "slope-sensitivity",
        help="derivatives w.r.t. the slope; floor-step disturbances",
        description="Derivatives of the gait, period, speed and multipliers with respect to "
        "the slope (implicit differentiation), the largest single step up/down survived, "
        "recovery curves and the gait sensitivity norm for floor-height disturbances.",
    )
    add_analysis_flags(
        p,
        "save the recovery after floor steps (and the derivatives beside it, in "
        "STEM-slope.EXT: out.svg gives out-slope.svg)",
    )
    p.add_argument(
        "--heights-mm",
        type=FINITE,
        nargs="+",
        default=None,
        help="floor steps (mm, + up) for the recovery curves, each at most half a leg "
        "length; default -15 -12 -5 2 5 mm per metre of leg (a+b)",
    )
    p.add_argument("--steps", type=count(1, 100_000), default=40, help="steps after the floor step")
    p.add_argument(
        "--no-derivatives",
        action="store_true",
        help="skip the slope derivatives (long first compilation)",
    )
    p.set_defaults(func=run_slope)


def run_slope(args):
    import jax.numpy as jnp
    import numpy as np

    from ..robustness import UNDECIDED, gait_sensitivity_norm, max_floor_step, terrain_recovery

    check_figure_file(args.png, "--png")
    slope_png = None  # the second figure (derivatives), beside the first
    if args.png and not args.no_derivatives:
        slope_png = second_figure(args.png, "slope", "--png")
        check_figure_file(slope_png, "--png (its second figure)")
    model, z, x_star, period, zn = analysed_gait(args)
    out = {"gait": zn, "period": period}
    if not args.no_derivatives:
        from ..robustness import slope_sensitivity

        s = slope_sensitivity(model, z)
        out["per_rad"] = {
            "dz": s.dz,
            "dperiod": s.dperiod,
            "dstep_length": s.dstep_length,
            "dspeed": s.dspeed,
            "dmultipliers": s.dmultipliers,
            "dmodulus": s.dmodulus,
        }
        out["values"] = {
            "step_length": s.step_length,
            "speed": s.speed,
            "multipliers": s.multipliers,
        }
    g = gait_sensitivity_norm(model, x_star, args.steps)
    out["gait_sensitivity_norm"] = g.norm
    out["dtimes_dh"] = g.dtimes[:10]
    report_stability(
        args,
        model,
        z,
        out,
        "even a walker perturbed by rounding leaves it, so the largest floor step survived "
        "measures the step budget (--steps), not robustness",
    )
    th = max_floor_step(model, x_star, num_steps=args.steps, progress=progress_bar(args))
    out["max_step_down_m"] = [th.lo[0], th.hi[0]]
    out["max_step_up_m"] = [th.lo[1], th.hi[1]]
    # A first failing step that did not fall was too slow to recover within --steps: the
    # threshold then measures the step budget, not the walker; say so.
    slow = [name for name, lab in zip(("down", "up"), th.hi_label) if lab == UNDECIDED]
    if slow:
        reason = (
            f"the first failing step {' and '.join(slow)} neither fell nor returned to the "
            f"gait within --steps {args.steps}: raise --steps to measure the walker"
        )
        out["max_step_reason"] = reason
        warn(args, reason)
    hs = jnp.asarray(_heights_m(args, model))
    rec = terrain_recovery(model, x_star, hs, args.steps, 1e-4)
    out["recovery"] = {"heights_m": hs, "label": rec.label, "steps": rec.steps}
    if args.png:
        from ..plotting import plot_slope, plot_terrain

        full = terrain_recovery(model, x_star, hs, args.steps, 0.0, stop_when_converged=False)
        with figure_output(args.png) as fh:
            plot_terrain(
                np.asarray(hs), full, period, fh, float(g.norm), case=f"gait at {describe(args)}"
            )
        if slope_png is not None:
            with figure_output(slope_png) as fh:
                plot_slope(s, fh, case=f"gait at {describe(args)}")
    if args.json:
        print_json(out)
    else:
        _print_slope(args, out, th, rec)


#: What a recovery label (`vhcjax.CONVERGED`, `FELL`, `OTHER_CYCLE`, `UNDECIDED`) says
#: happened, in words.
OUTCOME = {
    0: "back on the gait",
    1: "fell",
    2: "settled on another gait",
    3: "neither back on the gait nor fallen",
}


def _print_slope(args, out, th, rec):
    """The text output of `vhcjax slope-sensitivity`."""
    import numpy as np

    from ..robustness import CONVERGED, FELL, UNDECIDED

    per_deg = math.pi / 180
    if "per_rad" in out:
        d = out["per_rad"]
        moduli = list_words(np.asarray(d["dmodulus"]) * per_deg, "{:+.5f}")
        print(
            f"change per degree of slope: step period {float(d['dperiod']) * per_deg:+.5f} s, "
            f"speed {float(d['dspeed']) * per_deg:+.5f} m/s, multiplier moduli {moduli}"
        )
    print(
        "gait sensitivity norm (change of the step times per metre of floor height): "
        f"{float(out['gait_sensitivity_norm']):.4f} s/m"
    )
    print(
        "largest single floor step survived (first failing step by bisection; survived: "
        f"back on the gait within {args.steps} steps):"
    )
    for j, name in enumerate(("down", "up")):
        if th.fails_min[j]:
            print(f"  step {name}: none survived, not even {1000 * th.lo[j]:.3g} mm")
            continue
        if not np.isfinite(th.hi[j]):
            print(
                f"  step {name}: {1000 * th.lo[j]:.2f} mm survived, the largest tried: the "
                "limit lies beyond"
            )
            continue
        lo, hi = bracket_words(th.lo[j], th.hi[j], "mm", 1000.0)
        label = int(th.hi_label[j])
        why = {FELL: "fell", UNDECIDED: f"not back on the gait within {args.steps} steps"}.get(
            label, OUTCOME.get(label, "failed")
        )
        print(f"  step {name}: {lo} survived; {hi} {why}")
    heights = np.asarray(out["recovery"]["heights_m"]) * 1000
    parts = []
    for h, label, k in zip(heights, np.asarray(rec.label), np.asarray(rec.steps)):
        label, k = int(label), int(k)
        if label == CONVERGED:
            what = f"back on the gait after {k} steps"
        elif label == FELL:
            what = f"fell at step {k}"
        else:
            what = OUTCOME[label]
        parts.append(f"{h:+g} mm: {what}")
    print(f"recovery after a floor step (+ up, within {args.steps} steps): " + "; ".join(parts))


def _heights_m(args, model):
    """--heights-mm in metres: as given (each at most half a leg length), or the thesis
    walker's -15, -12, -5, 2, 5 mm in proportion to the leg length."""
    import numpy as np

    leg = float(model.scales()["length"])  # a + b, m
    if args.heights_mm is None:
        return np.array([-15.0, -12.0, -5.0, 2.0, 5.0]) * leg / 1000.0
    hs = np.asarray(args.heights_mm, float) / 1000.0
    if np.max(np.abs(hs)) > 0.5 * leg:
        raise CLIError(
            f"--heights-mm: a floor step of {np.max(np.abs(hs)) * 1000:g} mm is more than "
            f"half the leg length ({leg * 1000:g} mm)"
        )
    return hs
