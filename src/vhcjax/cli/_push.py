"""`vhcjax push`: sensitivity of a gait to hip pushes along the step, and the largest
push survived."""

from ._analysed import add_analysis_flags, analysed_gait, progress_bar, report_stability
from ._common import (
    FINITE,
    POSITIVE,
    CLIError,
    check_figure_file,
    count,
    describe,
    figure_output,
    number,
    print_json,
    warn,
)


def register(subparsers):
    p = subparsers.add_parser(
        "push",
        help="sensitivity to hip pushes along the gait; largest push survived",
        description="Linear sensitivity of the next post-impact state to a hip impulse as a "
        "function of the phase of the step (autodiff; with --check also the transverse "
        "linearization), and the largest push survived per phase and direction.",
    )
    add_analysis_flags(p, "save sensitivity and largest push vs phase")
    p.add_argument(
        "--phases", type=count(1, 10_000), default=20, help="phases in [0, 1) (default 20)"
    )
    p.add_argument(
        "--directions-deg",
        type=FINITE,
        nargs="+",
        default=[0, 90, 180, 270],
        help="push directions, degrees from forward, counter-clockwise",
    )
    p.add_argument(
        "--duration",
        type=number(float, lo=0.0),
        default=0.0,
        help="pulse duration in s (0: instantaneous impulse, magnitudes in N s); the pulse "
        "must end before the gait's heel strike",
    )
    p.add_argument(
        "--max",
        type=POSITIVE,
        default=None,
        help="bisection upper bound (N s, or N with --duration; default 20 for the "
        "thesis's 20 kg walker, in proportion to the walker's own impulse or force unit)",
    )
    p.add_argument(
        "--iterations", type=count(1, 60), default=12, help="bisection halvings (1 to 60)"
    )
    p.add_argument("--steps", type=count(1, 100_000), default=30, help="steps after the push")
    p.add_argument(
        "--check",
        action="store_true",
        help="also compute the sensitivity by transverse linearization",
    )
    p.set_defaults(func=run_push)


#: Most largest-push searches (phases x directions) of one `push` command.
MAX_PUSHES = 10_000


def run_push(args):
    import jax.numpy as jnp
    import numpy as np

    from ..robustness import (
        UNDECIDED,
        max_push,
        pulse_past_strike,
        push_bound,
        push_sensitivity_autodiff,
        push_sensitivity_transverse,
    )

    check_figure_file(args.png, "--png")
    pushes = args.phases * len(args.directions_deg)
    if pushes > MAX_PUSHES:
        raise CLIError(
            f"--phases {args.phases} x {len(args.directions_deg)} --directions-deg gives "
            f"{pushes:,} largest-push searches (bisections); at most {MAX_PUSHES:,}"
        )
    model, z, x_star, period, zn = analysed_gait(args)
    phases = np.arange(args.phases) / args.phases
    late = pulse_past_strike(phases, period, args.duration)
    if late:
        raise CLIError(f"--duration: {late}")
    angles = np.radians(np.asarray(args.directions_deg, float))
    D = push_sensitivity_autodiff(model, x_star, period, jnp.asarray(phases))
    out = {"gait": zn, "period": period, "phases": phases, "sensitivity_dxplus_dP": D}
    report_stability(
        args,
        model,
        z,
        out,
        "even an unpushed walker perturbed by rounding leaves it, so the largest push "
        "survived measures the step budget (--steps), not robustness",
    )
    if args.check:
        from ..hybrid import step

        xm = step(model, x_star).x_minus
        Z, lin = push_sensitivity_transverse(model, x_star, xm, period, jnp.asarray(phases))
        from ..stability._transverse import _own_units

        zad = np.einsum("ij,sjk->sik", np.asarray(lin.P_plus), np.asarray(D))
        out["transverse_dzeta_dP"] = Z
        # in the walker's own units: each transverse coordinate in its unit, per impulse
        # unit M L / T, so that a rescaled walker gives the same number
        sc = model.scales()
        impulse = float(sc["mass"] * sc["length"] / model.time_scale)
        unit = np.asarray(_own_units(model)[2])[None, :, None] / impulse
        out["max_difference_autodiff_vs_transverse"] = float(np.max(np.abs(zad - Z) / unit))
    bound = float(push_bound(model, args.duration))
    if args.max is None:
        args.max = float(f"{bound:.12g}")  # 20, not 20.000000000000004
    elif args.max > 5e4 * bound:  # 1e6 N s for the thesis's walker
        unit = "N s" if args.duration == 0 else "N"
        raise CLIError(
            f"--max {args.max:g} {unit} is beyond {5e4 * bound:.4g} {unit}, 50,000 times the "
            "default bound for this walker (far from any push it could survive)"
        )
    res = max_push(
        model,
        x_star,
        period,
        phases,
        angles,
        p_max=args.max,
        duration=args.duration,
        iterations=args.iterations,
        num_steps=args.steps,
        progress=progress_bar(args),
    )
    unit = "N s" if args.duration == 0 else "N"
    out.update(
        {
            "directions_deg": args.directions_deg,
            "unit": unit,
            "largest": res.largest,
            "falls_at": res.threshold.hi.reshape(res.largest.shape),
            "most_fragile_phase": res.most_fragile_phase,
        }
    )
    # Pairs where the push of --max was survived (and none of the scan below it failed):
    # `falls_at` is null, and `largest` is the bound of the search, not the walker's limit.
    top = np.asarray(res.threshold.survives_max) & ~np.asarray(res.threshold.fails_min)
    ceiling = int(np.sum(top))
    if ceiling:
        reason = (
            f"at {ceiling} of {res.threshold.hi.size} (phase, direction) pairs the push of "
            f"--max {args.max:g} {unit} was survived (and none tried below it failed): "
            "`largest` is a lower bound there; raise --max to find the limit"
        )
        out["falls_at_reason"] = reason
        warn(args, reason)
    if not np.isfinite(res.most_fragile_phase).all():
        out["most_fragile_phase_reason"] = (
            "null for a direction where no push survived at any phase, or where every "
            "phase survived --max: no phase is known to be the most fragile"
        )
    # First failing pushes that neither fell nor recovered within --steps: there the
    # threshold measures the step budget, not the walker; say so (as slope-sensitivity).
    slow = int(np.sum(res.threshold.hi_label == UNDECIDED))
    if slow:
        reason = (
            f"at {slow} of {res.threshold.hi.size} (phase, direction) pairs the first failing "
            f"push neither fell nor returned to the gait within --steps {args.steps}: raise "
            "--steps to measure the walker"
        )
        out["largest_reason"] = reason
        warn(args, reason)
    if args.png:
        from ..plotting import plot_push

        with figure_output(args.png) as fh:
            plot_push(
                phases,
                D,
                angles,
                res.largest,
                fh,
                unit,
                p_max=args.max,
                case=f"gait at {describe(args)}",
            )
    if args.json:
        print_json(out)
    else:
        _print_push(args, res, phases, unit, top.reshape(res.largest.shape), out)


def _print_push(args, res, phases, unit, top, out):
    """The text output of `vhcjax push`: per direction the smallest and the largest over
    the phases of the largest push survived, each with its phase (labelled as such, not
    a range of uncertainty)."""
    import numpy as np

    what = "impulse" if args.duration == 0 else f"force held {args.duration:g} s"
    print(
        f"largest hip push ({what}) survived, per direction (degrees from forward, "
        f"counter-clockwise), over {len(phases)} phases of the step (phase 0 = just after "
        "heel strike, 1 = the next one):"
    )
    for j, a in enumerate(args.directions_deg):
        col = np.asarray(res.largest[:, j], float)
        known = np.isfinite(col)
        if not known.any():
            print(f"  {a:g} deg: no push survived at any phase, not even 0 {unit}")
            continue
        lo = int(np.argmin(np.where(known, col, np.inf)))
        hi = int(np.argmax(np.where(known, col, -np.inf)))

        bound = " or more (the search bound --max)"
        value = [f"{v:.4g} {unit}" + (bound if t else "") for v, t in zip(col, top[:, j])]
        if np.all(top[:, j] | ~known):
            print(
                f"  {a:g} deg: the search bound {args.max:g} {unit} survived at every phase "
                "(raise --max to find the limits)"
            )
            continue
        fragile = " (the most fragile phase)" if np.isfinite(res.most_fragile_phase[j]) else ""
        print(
            f"  {a:g} deg: smallest over the phases {value[lo]} at phase {phases[lo]:.2f}"
            f"{fragile}; largest {value[hi]} at phase {phases[hi]:.2f}"
        )
    if args.check:
        print(
            "sensitivity by autodiff and by the transverse linearization: largest "
            f"difference {out['max_difference_autodiff_vs_transverse']:.2e} (in the walker's "
            "own units: transverse coordinates per impulse M l/T)"
        )
