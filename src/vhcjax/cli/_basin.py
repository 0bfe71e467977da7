"""`vhcjax basin`: region of attraction of a gait, a 2-D slice and a Monte-Carlo
volume."""

from ._analysed import (
    add_analysis_flags,
    analysed_gait,
    in_walker_units,
    progress_bar,
    report_stability,
)
from ._common import (
    HALF_WIDTH,
    CLIError,
    add_model_choice,
    check_figure_file,
    check_state,
    count,
    describe,
    figure_output,
    number,
    print_json,
    shown,
)
from ._words import SECTION

#: Largest basin grid (points): each point is a simulation and some 100 bytes of results
#: in memory, more in JSON; beyond this, refuse up front rather than run out of memory.
MAX_GRID_POINTS = 4_000_000
MAX_SAMPLES = 10_000_000
AXIS_NAMES = ("q1", "dq1", "dq2")
#: Default half widths of the box of `basin --volume-samples` (q1, dq1, dq2).
BOX = (0.05, 0.2, 0.5)


def register(subparsers):
    p = subparsers.add_parser(
        "basin",
        help="region of attraction: 2-D slice and Monte-Carlo volume",
        description="Classify a grid of post-impact perturbations of the gait along two "
        "section coordinates (q1, dq1, dq2; the third nominal) as converging (with steps "
        "to converge), falling, settling elsewhere or undecided; optional Monte-Carlo "
        "estimate of the basin's volume fraction in a 3-D box.",
    )
    add_analysis_flags(p, "save the basin slice coloured by steps to converge")
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
    p.add_argument(
        "--checkpoint",
        metavar="FOLDER",
        help="write the points to FOLDER in parts as they finish (CSV files); the same "
        "command run again, after an interruption, computes only the parts not there",
    )
    p.set_defaults(func=run_basin)


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
    model, z, _, period, zn = analysed_gait(args)
    if args.half_widths is None:
        args.half_widths = [
            in_walker_units(model, 0.08, "angle")
            if AXIS_NAMES[a] == "q1"
            else in_walker_units(model, 0.4, "rate")
            for a in axes
        ]
    kinds = ["angle" if AXIS_NAMES[a] == "q1" else "rate" for a in axes]
    check_state(model, args.half_widths, kinds, "--half-widths")
    if args.box is not None:
        check_state(model, args.box, ["angle", "rate", "rate"], "--box")
    if args.box is None:  # the thesis walker's box, in this walker's units
        q, dq1, dq2 = BOX
        rate = lambda v: in_walker_units(model, v, "rate")  # noqa: E731
        args.box = [q, rate(dq1), rate(dq2)]
    b = _resumable(
        basin_slice,
        model,
        z,
        axes=axes,
        half_widths=tuple(args.half_widths),
        shape=tuple(args.grid),
        num_steps=args.steps,
        tol=args.tol,
        chunk=args.chunk,
        progress=progress_bar(args),
        checkpoint=_part(args, "slice"),
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
    report_stability(
        args,
        model,
        z,
        out,
        "a perturbed walker leaves it, so its basin has no interior; points count as "
        "converging only where they land on its stable manifold within --tol",
    )
    if args.volume_samples > 0:
        v = _resumable(
            basin_volume,
            model,
            z,
            args.box,
            num_samples=args.volume_samples,
            tol=args.tol,
            num_steps=args.steps,
            chunk=args.chunk,
            progress=progress_bar(args),
            checkpoint=_part(args, "volume"),
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
        _print_basin(args, out)


def _resumable(fn, *args, **kwargs):
    """`fn(*args, **kwargs)`, a checkpoint folder that cannot be used being bad input."""
    from .._chunks import CheckpointError

    try:
        return fn(*args, **kwargs)
    except CheckpointError as e:
        raise CLIError(str(e)) from None


def _part(args, name):
    """The checkpoint folder of the slice or the volume samples (`None` without one)."""
    import os

    return None if args.checkpoint is None else os.path.join(args.checkpoint, name)


#: Units of the section coordinates.
UNITS = dict(SECTION)
#: The labels of the basin's points, in words (`counts` keys).
LABEL_WORDS = {
    "converged": "returned to the gait",
    "fell": "fell",
    "other_cycle": "settled on another gait",
    "undecided": "did none of these",
}


def _print_basin(args, out):
    """The text output of `vhcjax basin`: the summary `out` (its JSON) in words."""
    x, y = out["axes"]
    ux, uy = UNITS[x], UNITS[y]
    area_unit = f"{ux} {uy}".replace("rad rad", "rad^2")
    hx, hy = args.half_widths
    total = sum(out["counts"].values())
    print(
        f"basin slice in ({x}, {y}) about the gait: {args.grid[0]} x {args.grid[1]} starts "
        f"within +-{hx:.4g} {ux} ({x}) and +-{hy:.4g} {uy} ({y}) of the gait's post-impact "
        f"state, {args.steps} steps each"
    )
    print(
        f"  of {total} starts, within {args.steps} steps: "
        + ", ".join(f"{n} {LABEL_WORDS[k]}" for k, n in out["counts"].items())
    )
    print(
        f"  converging fraction {out['fraction']:.4f}; converging area "
        f"{out['area']:.4g} {area_unit}"
    )
    reach = out["max_converging"]
    print(
        "  largest offset from the gait up to which every start on the grid line through "
        "it returns: " + ", ".join(f"{k} {v:.4g} {UNITS[k[1:]]}" for k, v in reach.items())
    )
    if "volume" in out:
        v = out["volume"]
        box = ", ".join(f"+-{w:.4g} {u} ({n})" for (n, u), w in zip(SECTION, v["box_half_widths"]))
        lo, hi = v["interval_95"]
        print(
            f"3-D box of {box} about the gait: converging fraction {v['fraction']:.4f} of "
            f"{v['samples']} random starts (95% confidence interval {lo:.4f} to {hi:.4f})"
        )
