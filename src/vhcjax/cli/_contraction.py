"""`vhcjax contraction`: speed of contraction to a gait, predicted by its multipliers
and measured by simulated recoveries."""

import math

from ._analysed import (
    add_analysis_flags,
    analysed_gait,
)
from ._common import (
    CLIError,
    check_figure_file,
    count,
    describe,
    figure_output,
    number,
    print_json,
    warn,
)

MAX_RECOVERY_CELLS = 50_000_000  # perturbations x (steps + 1) distances kept in memory


def register(subparsers):
    p = subparsers.add_parser(
        "contraction",
        help="speed of contraction to the gait (multipliers vs simulation)",
        description="Spectral radius of the step map at the gait, steps to shrink an error "
        "10x and 100x, and the decay rate measured from simulated recoveries.",
    )
    add_analysis_flags(p, "save the recovery curves with the rho^k prediction")
    p.add_argument(
        "--perturbations",
        type=count(1, 100_000),
        default=32,
        help="simulated recoveries (1 to 100000)",
    )
    p.add_argument(
        "--scale",
        type=number(float, lo=0.0, hi=0.5, lo_open=True),
        default=1e-3,
        help="size of the perturbations, in (0, 0.5]",
    )
    p.add_argument(
        "--steps", type=count(8, 100_000), default=30, help="steps per recovery (8 to 100000)"
    )
    p.set_defaults(func=run_contraction)


def run_contraction(args):
    from ..robustness import contraction

    cells = args.perturbations * (args.steps + 1)
    if cells > MAX_RECOVERY_CELLS:
        raise CLIError(
            f"--perturbations {args.perturbations} x --steps {args.steps} keeps "
            f"{cells:,} distances (about {cells * 8 / 1e9:.1f} GB); at most "
            f"{MAX_RECOVERY_CELLS:,}"
        )
    check_figure_file(args.png, "--png")
    model, z, _, period, zn = analysed_gait(args)
    c = contraction(
        model,
        z,
        num_perturbations=args.perturbations,
        scale=args.scale,
        num_steps=args.steps,
        fit_window=(5, args.steps),
    )
    out = {
        "gait": zn,
        "period": period,
        "multipliers": c.multipliers,
        "spectral_radius": c.spectral_radius,
        "steps_10x": c.steps_10x,
        "steps_100x": c.steps_100x,
        "measured_rate": c.measured_rate,
        "measured_steps_10x": c.measured_steps_10x,
        "measured_steps_100x": c.measured_steps_100x,
    }
    rho = float(c.spectral_radius)  # the gait's, as push and basin report it
    out["gait_spectral_radius"] = rho
    out["gait_stable"] = rho < 1.0
    if rho >= 1.0:
        out["gait_stable_reason"] = (
            f"the gait is unstable (spectral radius {rho:.4g} of its Poincare map): "
            "perturbations grow, and the measured rate is not a contraction"
        )
        warn(args, out["gait_stable_reason"])
    if not math.isfinite(float(c.measured_rate)):
        out["measured_rate_reason"] = (
            "no recovery stayed near the gait (each fell, or its error grew tenfold)"
        )
    for k, f in (("10x", 10), ("100x", 100)):
        if not math.isfinite(float(out[f"measured_steps_{k}"])):
            out[f"measured_steps_{k}_reason"] = (
                f"no recovery shrank its error {f}x within --steps {args.steps} steps"
            )
    if args.png:
        from ..plotting import plot_contraction

        with figure_output(args.png) as fh:
            plot_contraction(c, fh, case=f"gait at {describe(args)}")
    if args.json:
        print_json(out)
    else:
        _print_contraction(args, c, out)


def _print_contraction(args, c, out):
    """The text output: the predicted figures (asymptotic, from the multipliers) beside
    the measured ones (medians over simulated recoveries, their first steps included),
    each labelled so that a difference between them does not read as a contradiction."""
    k0, k1 = c.fit_window
    rho = float(c.spectral_radius)
    print(f"spectral radius of the step-to-step map: {rho:.6f} (largest multiplier modulus)")
    rate = float(c.measured_rate)
    measured = (
        f"{rate:.6f} measured (median over {args.perturbations} simulated recoveries, fitted "
        f"over steps {k0} to {k1})"
        if math.isfinite(rate)
        else f"not measured: {out['measured_rate_reason']}"
    )
    print(f"error factor per step: {rho:.6f} predicted (the spectral radius); {measured}")
    for k, note in (
        (
            "10x",
            "median over the recoveries, counted from the perturbation: the first steps, "
            "where an error can grow before it decays, are included",
        ),
        ("100x", "median, first steps included"),
    ):
        m = float(out[f"measured_steps_{k}"])
        meas = (
            f"{m:.0f} measured ({note})"
            if math.isfinite(m)
            else f"not measured: {out[f'measured_steps_{k}_reason']}"
        )
        p = float(out[f"steps_{k}"])
        pred = (
            f"{p:.2f} predicted (asymptotic rate)"
            if math.isfinite(p) and p > 0
            else "none predicted (spectral radius >= 1: an error does not shrink)"
        )
        print(f"steps to shrink an error {k}: {pred}, {meas}")
