"""`vhcjax contraction | basin | slope-sensitivity | push`: robustness of a gait."""

import math

from ._common import (
    FINITE,
    HALF_WIDTH,
    STATE,
    CLIError,
    ComputationFailed,
    add_method_flag,
    add_model_choice,
    add_model_flags,
    check_figure_file,
    count,
    describe,
    figure_output,
    find_walker_gait,
    number,
    print_json,
    progress,
    second_figure,
    shown,
    walker_from_args,
    warn,
)

#: Largest basin grid (points): each point is a simulation and some 100 bytes of results
#: in memory, more in JSON; beyond this, refuse up front rather than run out of memory.
MAX_GRID_POINTS = 4_000_000
MAX_SAMPLES = 10_000_000
MAX_RECOVERY_CELLS = 50_000_000  # perturbations x (steps + 1) distances kept in memory
AXIS_NAMES = ("q1", "dq1", "dq2")
#: Default half widths of the box of `basin --volume-samples` (q1, dq1, dq2).
BOX = (0.05, 0.2, 0.5)


def _common(p, png_help):
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


def _gait(args):
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


def _in_walker_units(model, value, kind):
    """A default given for the thesis's walker (20 kg, 1 m, 9.81 m/s^2), in the same
    proportion to `model`'s own units (`scales`): a scaled walker gets the scaled
    default. `kind`: `"angle"` (unchanged), `"rate"` (1/s), `"impulse"` (N s),
    `"force"` (N)."""
    import math

    s = {k: float(v) for k, v in model.scales().items()}
    unit = {
        "angle": 1.0,
        "rate": 1.0 / s["time"],
        "impulse": s["mass"] * math.sqrt(s["acceleration"] * s["length"]),
        "force": s["mass"] * s["acceleration"],
    }[kind]
    thesis = {"angle": 1.0, "rate": math.sqrt(9.81), "impulse": 20 * math.sqrt(9.81)}
    thesis["force"] = 20 * 9.81
    return float(f"{value * unit / thesis[kind]:.12g}")  # 0.4, not 0.4000000000000001


def _stability(args, model, z, out, consequence):
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


def _bar(args):
    return None if args.quiet else (lambda it: progress(it, total=len(it), desc=args.command))


def register(subparsers):
    p = subparsers.add_parser(
        "contraction",
        help="speed of contraction to the gait (multipliers vs simulation)",
        description="Spectral radius of the step map at the gait, steps to shrink an error "
        "10x and 100x, and the decay rate measured from simulated recoveries.",
    )
    _common(p, "save the recovery curves with the rho^k prediction")
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

    p = subparsers.add_parser(
        "basin",
        help="region of attraction: 2-D slice and Monte-Carlo volume",
        description="Classify a grid of post-impact perturbations of the gait along two "
        "section coordinates (q1, dq1, dq2; the third nominal) as converging (with steps "
        "to converge), falling, settling elsewhere or undecided; optional Monte-Carlo "
        "estimate of the basin's volume fraction in a 3-D box.",
    )
    _common(p, "save the basin slice coloured by steps to converge")
    add_model_choice(p)
    p.add_argument("--axes", default="q1,dq1", help="two of q1,dq1,dq2 (default q1,dq1)")
    p.add_argument(
        "--half-widths",
        type=HALF_WIDTH,
        nargs=2,
        default=None,
        help="grid half widths along the two axes (rad, rad/s; default 0.08 rad for an "
        "angle and 0.4 rad/s for a rate, for the thesis's walker, scaled with the walker's "
        "time unit sqrt(l/g))",
    )
    p.add_argument(
        "--grid",
        type=count(2, MAX_GRID_POINTS // 2),
        nargs=2,
        default=[200, 200],
        help=f"grid points along each axis (at least 2; at most {MAX_GRID_POINTS} in all)",
    )
    p.add_argument("--steps", type=count(1, 100_000), default=50, help="steps simulated per point")
    p.add_argument(
        "--tol",
        type=number(float, lo=0.0, hi=1.0, lo_open=True),
        default=1e-4,
        help="convergence tolerance, in (0, 1]",
    )
    p.add_argument(
        "--chunk",
        type=count(1, 1_000_000),
        default=1024,
        help="batch size of one call (capped at 256 on a CPU with several cores)",
    )
    p.add_argument(
        "--volume-samples",
        type=count(0, MAX_SAMPLES),
        default=0,
        help="Monte-Carlo samples for the 3-D volume fraction (0: skip)",
    )
    p.add_argument(
        "--box",
        type=HALF_WIDTH,
        nargs=3,
        default=None,
        help="half widths of the 3-D box (q1 in rad, dq1 and dq2 in rad/s; default 0.05, "
        "0.2, 0.5 for the thesis's walker, the rates scaled with the walker's time unit)",
    )
    p.set_defaults(func=run_basin)

    p = subparsers.add_parser(
        "slope-sensitivity",
        help="derivatives w.r.t. the slope; floor-step disturbances",
        description="Derivatives of the gait, period, speed and multipliers with respect to "
        "the slope (implicit differentiation), the largest single step up/down survived, "
        "recovery curves and the gait sensitivity norm for floor-height disturbances.",
    )
    _common(
        p,
        "save the recovery after floor steps (and the derivatives beside it, in "
        "STEM-slope.EXT: out.svg gives out-slope.svg)",
    )
    p.add_argument(
        "--heights-mm",
        type=number(float, lo=-500.0, hi=500.0),
        nargs="+",
        default=[-15, -12, -5, 2, 5],
        help="floor steps (mm, + up) for the recovery curves",
    )
    p.add_argument("--steps", type=count(1, 100_000), default=40, help="steps after the floor step")
    p.add_argument(
        "--no-derivatives",
        action="store_true",
        help="skip the slope derivatives (long first compilation)",
    )
    p.set_defaults(func=run_slope)

    p = subparsers.add_parser(
        "push",
        help="sensitivity to hip pushes along the gait; largest push survived",
        description="Linear sensitivity of the next post-impact state to a hip impulse as a "
        "function of the phase of the step (autodiff; with --check also the transverse "
        "linearization), and the largest push survived per phase and direction.",
    )
    _common(p, "save sensitivity and largest push vs phase")
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
        type=number(float, lo=0.0, hi=10.0),
        default=0.0,
        help="pulse duration in s (0: instantaneous impulse, magnitudes in N s)",
    )
    p.add_argument(
        "--max",
        type=number(float, lo=0.0, hi=1e6, lo_open=True),
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
    model, z, _, period, zn = _gait(args)
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
        rate = float(c.measured_rate)
        measured = (
            f"measured {rate:.6f} from {args.perturbations} recoveries"
            if math.isfinite(rate)
            else out["measured_rate_reason"]
        )
        print(f"spectral radius {float(c.spectral_radius):.6f} (multipliers); {measured}")
        for k in ("10x", "100x"):
            m = float(out[f"measured_steps_{k}"])
            meas = f"{m:.0f} measured" if math.isfinite(m) else out[f"measured_steps_{k}_reason"]
            print(
                f"steps to shrink an error {k}: {float(out[f'steps_{k}']):.2f} predicted, "
                f"{meas}" + (" (median, transient included)" if k == "10x" else "")
            )


def run_basin(args):
    import numpy as np

    from ..robustness import basin_slice, basin_volume

    try:
        axes = tuple(AXIS_NAMES.index(a.strip()) for a in args.axes.split(","))
    except ValueError:
        raise CLIError(
            f"--axes must be two of {','.join(AXIS_NAMES)}, got {shown(args.axes)}"
        ) from None
    if len(axes) != 2 or axes[0] == axes[1]:
        raise CLIError(f"--axes needs two different coordinates, got {shown(args.axes)}")
    points = args.grid[0] * args.grid[1]
    if points > MAX_GRID_POINTS:
        raise CLIError(
            f"--grid {args.grid[0]} {args.grid[1]} is {points:,} points (one "
            f"simulation each, about {points * 100 / 1e9:.1f} GB of results in "
            f"memory); at most {MAX_GRID_POINTS:,}: use a coarser grid or several "
            "runs over smaller --half-widths"
        )
    if args.box is not None and args.volume_samples == 0:
        raise CLIError("--box is the box of --volume-samples: give --volume-samples too")
    check_figure_file(args.png, "--png")
    model, z, _, period, zn = _gait(args)
    if args.half_widths is None:
        args.half_widths = [
            _in_walker_units(model, 0.08, "angle")
            if AXIS_NAMES[a] == "q1"
            else _in_walker_units(model, 0.4, "rate")
            for a in axes
        ]
    if args.box is None:  # the thesis walker's box, in this walker's units
        q, dq1, dq2 = BOX
        rate = lambda v: _in_walker_units(model, v, "rate")  # noqa: E731
        args.box = [q, rate(dq1), rate(dq2)]
    b = basin_slice(
        model,
        z,
        axes=axes,
        half_widths=tuple(args.half_widths),
        shape=tuple(args.grid),
        num_steps=args.steps,
        tol=args.tol,
        chunk=args.chunk,
        progress=_bar(args),
    )
    counts = {
        n: int(np.sum(b.label == i))
        for i, n in enumerate(("converged", "fell", "other_cycle", "undecided"))
    }
    out = {
        "gait": zn,
        "axes": [AXIS_NAMES[a] for a in axes],
        "grid": list(args.grid),
        "area": b.area,
        "fraction": b.fraction,
        "counts": counts,
        "max_converging": {
            k.replace("x", AXIS_NAMES[axes[0]]).replace("y", AXIS_NAMES[axes[1]]): v
            for k, v in b.max_converging.items()
        },
        "offsets_x": b.offsets_x,
        "offsets_y": b.offsets_y,
        "label": b.label,
        "steps": b.steps,
    }
    _stability(
        args,
        model,
        z,
        out,
        "a perturbed walker leaves it, so its basin has no interior; points count as "
        "converging only where they land on its stable manifold within --tol",
    )
    if args.volume_samples > 0:
        v = basin_volume(
            model,
            z,
            args.box,
            num_samples=args.volume_samples,
            tol=args.tol,
            num_steps=args.steps,
            chunk=args.chunk,
            progress=_bar(args),
        )
        out["volume"] = {
            "box_half_widths": args.box,
            "fraction": v.fraction,
            "interval_95": v.interval,
            "volume": v.volume,
            "counts": v.counts,
            "samples": v.num_samples,
        }
    if args.png:
        from ..plotting import plot_basin

        with figure_output(args.png) as fh:
            plot_basin(b, fh, case=f"gait at {describe(args)}")
    if args.json:
        print_json(out)
    else:
        print(
            f"slice {args.axes}: converging fraction {b.fraction:.4f}, area {b.area:.5g}; "
            f"counts {counts}"
        )
        print(
            "largest converging offset along the grid lines through the gait: "
            + ", ".join(f"{k} {v:.4g}" for k, v in out["max_converging"].items())
        )
        if "volume" in out:
            vv = out["volume"]
            print(
                f"3-D box +-{args.box}: fraction {vv['fraction']:.4f}, 95% CI "
                f"[{vv['interval_95'][0]:.4f}, {vv['interval_95'][1]:.4f}]"
            )


def run_slope(args):
    import jax.numpy as jnp
    import numpy as np

    from ..robustness import UNDECIDED, gait_sensitivity_norm, max_floor_step, terrain_recovery

    check_figure_file(args.png, "--png")
    slope_png = None  # the second figure (derivatives), beside the first
    if args.png and not args.no_derivatives:
        slope_png = second_figure(args.png, "slope", "--png")
        check_figure_file(slope_png, "--png (its second figure)")
    model, z, x_star, period, zn = _gait(args)
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
    _stability(
        args,
        model,
        z,
        out,
        "even a walker perturbed by rounding leaves it, so the largest floor step survived "
        "measures the step budget (--steps), not robustness",
    )
    th = max_floor_step(model, x_star, num_steps=args.steps, progress=_bar(args))
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
    hs = jnp.asarray(np.asarray(args.heights_mm) / 1000.0)
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
        if "per_rad" in out:
            d = out["per_rad"]
            print(
                f"per degree of slope: dT {float(d['dperiod']) * math.pi / 180:+.5f} s, "
                f"dv {float(d['dspeed']) * math.pi / 180:+.5f} m/s, d|lambda| "
                f"{np.round(np.asarray(d['dmodulus']) * math.pi / 180, 5)}"
            )
        print(f"gait sensitivity norm (floor height -> step time): {float(g.norm):.4f} s/m")
        print(
            f"largest step down survived: {1000 * th.lo[0]:.2f} mm (falls at "
            f"{1000 * th.hi[0]:.2f}); step up: {1000 * th.lo[1]:.2f} mm (falls at "
            f"{1000 * th.hi[1]:.2f})"
        )


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
    model, z, x_star, period, zn = _gait(args)
    phases = np.arange(args.phases) / args.phases
    late = pulse_past_strike(phases, period, args.duration)
    if late:
        raise CLIError(f"--duration: {late}")
    angles = np.radians(np.asarray(args.directions_deg, float))
    D = push_sensitivity_autodiff(model, x_star, period, jnp.asarray(phases))
    out = {"gait": zn, "period": period, "phases": phases, "sensitivity_dxplus_dP": D}
    _stability(
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
        zad = np.einsum("ij,sjk->sik", np.asarray(lin.P_plus), np.asarray(D))
        out["transverse_dzeta_dP"] = Z
        out["max_abs_difference_autodiff_vs_transverse"] = float(np.max(np.abs(zad - Z)))
    if args.max is None:
        args.max = float(f"{push_bound(model, args.duration):.12g}")  # 20, not 20.000000000000004
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
        progress=_bar(args),
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
        for j, a in enumerate(args.directions_deg):
            col = res.largest[:, j]
            col = col[np.isfinite(col)]
            if col.size == 0:
                print(f"direction {a:g} deg: no push survived at any phase, not even 0 {unit}")
                continue
            fragile = res.most_fragile_phase[j]
            print(
                f"direction {a:g} deg: largest push survived {col.min():.4g}-"
                f"{col.max():.4g} {unit}; "
                + (
                    f"most fragile at phase {fragile:.2f}"
                    if np.isfinite(fragile)
                    else f"no phase known as the most fragile (--max {args.max:g} {unit} "
                    "bounds the search)"
                )
            )
        if args.check:
            print(
                "autodiff vs transverse linearization: max difference "
                f"{out['max_abs_difference_autodiff_vs_transverse']:.2e}"
            )
