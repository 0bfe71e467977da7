"""What the robustness commands (`contraction`, `basin`, `slope-sensitivity`, `push`)
share: their flags, the gait they analyse, its stability verdict, defaults in the
walker's own units and the progress bar."""

from ._common import (
    STATE,
    ComputationFailed,
    add_method_flag,
    add_model_flags,
    find_walker_gait,
    progress,
    walker_from_args,
    warn,
)


def add_analysis_flags(p, png_help):
    """The flags every robustness command takes: the model, `--gait`, `--method`,
    `--json` and `--png` (described by `png_help`)."""
    add_model_flags(p)
    p.add_argument(
        "--gait",
        type=STATE,
        nargs=3,
        metavar=("Q1", "DQ1", "DQ2"),
        default=None,
        help="seed of the gait search: post-impact q1 (rad), dq1, dq2 (rad/s); "
        "default: the stable gait, as `vhcjax gait` finds it (continued from the model's "
        "reference gait)",
    )
    add_method_flag(p)
    p.add_argument("--json", action="store_true", help="print the results as one JSON object")
    p.add_argument("--png", metavar="FILE", help=png_help)


def analysed_gait(args):
    """The gait the command analyses, or a one-line error: the stable gait, found as
    `vhcjax gait` finds it (`vhcjax.find_gait` with `--method`: continued from the
    model's reference gait to this model and slope), or the gait of either family
    searched from `--gait`, then
    made a fixed point of the step map the simulations use by Newton shooting from
    there (it moves the gait by the integration tolerance). Newton from one fixed seed
    would land on whichever gait is nearest: at 0.5 degrees an unstable one, with a
    heavy hip none."""
    import numpy as np

    from .._results import result_names
    from ..gait import vhc_applies
    from ..hybrid import fixed_point

    model = walker_from_args(args)
    try:
        gait, _ = find_walker_gait(args, model, "stable", args.gait, "--gait")
    except ComputationFailed:
        if args.gait is None or not vhc_applies(model):
            raise
        # a seed may name a gait of either family (the unstable one, say)
        gait, _ = find_walker_gait(args, model, "unstable", args.gait, "--gait")
    z = model.state_to_section(gait.x_plus)
    fp = fixed_point(model, z)
    if result_names(fp.result) != "successful":
        raise ComputationFailed(
            f"the gait at slope {args.slope_deg:g} deg is no fixed point of the simulated "
            f"step map (Newton shooting from it ended {result_names(fp.result)})"
        )
    return model, fp.z, fp.x0, float(fp.periods[0]), np.asarray(fp.z)


def in_walker_units(model, value, kind):
    """`vhcjax.in_walker_units` as a float rounded to 12 digits (0.4, not
    0.4000000000000001), for flags and printed defaults. `kind`: `"angle"` or `"rate"`.
    (The push bound's is `push_bound`.)"""
    from ..hybrid import in_walker_units as scaled

    return float(f"{float(scaled(model, value, kind)):.12g}")


def report_stability(args, model, z, out, consequence):
    """Spectral radius of the step map at the gait into `out`; a warning (and
    `gait_stable: false`) when the gait is unstable, saying what that means for the
    figure (`consequence`)."""
    import numpy as np

    from ..hybrid import jacobian

    rho = float(np.max(np.abs(np.linalg.eigvals(np.asarray(jacobian(model, z))))))
    out["gait_spectral_radius"] = rho
    out["gait_stable"] = rho < 1.0
    if rho >= 1.0:
        reason = (
            f"the gait is unstable (spectral radius {rho:.4g} of its Poincare map): " + consequence
        )
        out["gait_stable_reason"] = reason
        warn(args, reason)


def progress_bar(args):
    """A progress bar for the command's batches, or `None` with `--quiet`."""
    return None if args.quiet else (lambda it: progress(it, total=len(it), desc=args.command))
