"""`vhcjax bifurcation` and `vhcjax multipliers`: period doubling, bifurcation diagram,
multipliers in the complex plane."""

import math

from ._common import (
    CLIError,
    ComputationFailed,
    add_method_flag,
    add_model_choice,
    add_model_flags,
    check_figure_file,
    check_method,
    check_output_file,
    check_slope_deg,
    count,
    describe,
    figure_output,
    find_walker_gait,
    model_from_args,
    parse_range,
    print_json,
    progress,
    walker_from_args,
    warn,
)
from ._words import complex_words, method_words, section_words, verdict_words


def register(subparsers):
    p = subparsers.add_parser(
        "bifurcation",
        help="bifurcation diagram and period-doubling slopes of the stable gait family",
        description="Continue the stable period-1 gait over the slopes, compute its "
        "multipliers (transverse linearization), locate period doublings (Newton-free "
        "regula falsi on det(I + J), to 1e-5 deg), follow the period-2 gait, and simulate "
        "every slope for TRANSIENT + RECORD steps from the period-1 gait (batched) to "
        "record the step periods of the last RECORD steps.",
    )
    add_model_flags(p, slope=False)
    p.add_argument(
        "--slope-deg",
        required=True,
        metavar="START:STOP:STEP",
        help="slopes in degrees, e.g. 0.5:5.5:0.01 (inclusive) or one slope",
    )
    p.add_argument(
        "--transient",
        type=count(0, 100_000),
        default=300,
        help="steps discarded as transient (default 300)",
    )
    p.add_argument(
        "--record",
        type=count(2, 10_000),
        default=64,
        help="steps recorded (default 64); patterns of 1, 2, 4, ..., 32 steps shorter than "
        "RECORD are detected",
    )
    p.add_argument(
        "--csv",
        metavar="FILE",
        help="write slope_deg, result, pattern, period_1..period_RECORD (pattern: "
        "steps per repetition, 0 aperiodic, -1 fell: no periods after the fall; empty "
        "where no period-1 gait was found: result is the search's)",
    )
    add_method_flag(p)
    p.add_argument("--png", metavar="FILE", help="save the bifurcation diagram")
    p.add_argument(
        "--png-multipliers",
        metavar="FILE",
        help="save |multipliers| of the period-1 family against slope",
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.add_argument(
        "--checkpoint",
        metavar="FOLDER",
        help="write the long simulations to FOLDER in parts as they finish (CSV files); "
        "the same command run again, after an interruption, computes only the parts "
        "not there",
    )
    p.set_defaults(func=run_bifurcation)

    q = subparsers.add_parser(
        "multipliers",
        help="multipliers of a gait in the complex plane (two methods)",
        description="Multipliers of the period-1 gait of FAMILY at the slope, by transverse "
        "linearization (thesis ch. 6) and by autodiff of the Poincare map through the heel-"
        "strike events; optional plot with the unit circle (thesis Figs 7.1, 7.8, 7.15).",
    )
    add_model_flags(q)
    add_model_choice(q)
    q.add_argument(
        "--family",
        choices=["stable", "unstable"],
        default=None,  # set by walker_from_args (a compass-gait flag)
        help="gait family (default stable)",
    )
    add_method_flag(q)
    q.add_argument("--png", metavar="FILE", help="save the complex-plane plot")
    q.add_argument("--json", action="store_true", help="print a JSON object")
    q.set_defaults(func=run_multipliers)
    return p


def _c(ev):
    return [[float(e.real), float(e.imag)] for e in ev]


def run_multipliers(args):
    import numpy as np

    from .. import stability as S
    from ..gait import vhc_applies
    from ._multiplier_fields import stability_json

    kneed = args.model == "kneed"
    model = walker_from_args(args)
    check_method(args, model)
    check_figure_file(args.png, "--png")
    # continued from the model's reference gait to this model (any parameters)
    gait, why = find_walker_gait(args, model, args.family or "stable")
    z = model.state_to_section(gait.x_plus)
    compass = vhc_applies(model)  # the transverse linearization is the compass gait's
    gm = S.gait_multipliers(model, z, transverse=compass)
    pc = np.asarray(gm.poincare)
    tr = None if gm.transverse is None else np.asarray(gm.transverse)
    stab = stability_json(gm)
    if not compass:
        stab["multipliers_reason"] = (
            "the transverse linearization is computed for the compass gait; the "
            f"{args.model} walker's multipliers are the Poincare map's"
        )
    trusted = stab["multipliers"] is not None
    if not trusted and compass:
        warn(args, stab["multipliers_reason"])
    if args.png:
        from ..plotting import plot_multipliers_complex

        sets, labels = (
            ([tr, pc], ["transverse linearization", "Poincare (autodiff)"])
            if trusted
            else ([pc], ["Poincare (autodiff)"])
        )
        title = describe(args) if kneed else f"{args.family} family, {describe(args)}"
        with figure_output(args.png) as fh:
            plot_multipliers_complex(sets, labels, fh, title=title)
    family = None if kneed else args.family  # the kneed walker: its one family
    out = {"slope_deg": args.slope_deg, "family": family, "z": np.asarray(z), **stab}
    out["method"] = gait.found_by
    if why:
        out["method_reason"] = why
    out["model"] = args.model
    if args.json:
        print_json(out)
    else:
        what = "kneed-walker gait" if kneed else f"{args.family} gait"
        print(f"{what} at slope {args.slope_deg:g} deg, found by {method_words(gait.found_by)}")
        print(f"  post-impact state: {section_words(np.asarray(z))}")
        if trusted and tr is not None:
            print("  multipliers, two independent computations:")
            print(f"    {'Poincare-map Jacobian':<28}{'transverse linearization':<28}modulus")
            for i, b in enumerate(pc):
                print(f"    {complex_words(b, 8):<28}{complex_words(tr[i], 8):<28}{abs(b):.8f}")
        else:
            why_not = "" if compass else f" ({stab['multipliers_reason']})"
            print(f"  multipliers (Poincare-map Jacobian){why_not}:")
            for b in pc:
                print(f"    {complex_words(b, 8):<28}modulus {abs(b):.8f}")
        print(f"  verdict: {verdict_words(stab['stable'], stab['max_abs_multiplier'])}")
    return 0


#: Largest number of recorded step periods (slopes x --record) one run keeps (160 MB).
MAX_RECORDED = 20_000_000


def run_bifurcation(args):
    import numpy as np

    from .. import stability as S
    from .._results import result_names

    slopes = parse_range(args.slope_deg)
    for s in slopes:
        check_slope_deg(s)
    if len(slopes) * args.record > MAX_RECORDED:
        raise CLIError(
            f"{len(slopes)} slopes x --record {args.record} is {len(slopes) * args.record:,} "
            f"recorded periods; at most {MAX_RECORDED:,} (fewer slopes or a shorter --record)"
        )
    model = model_from_args(args, slope_deg=slopes[0])
    check_output_file(args.csv, "--csv")
    for flag in ("png", "png_multipliers"):
        check_figure_file(getattr(args, flag), "--" + flag.replace("_", "-"))
    psis = np.radians(slopes)
    bar = progress(total=5, desc="bifurcation")
    fam = S.period1_family(psis, "stable", model=model, method=args.method)
    ok1 = np.array(result_names(fam.result)) == "successful"
    if not ok1.any():
        raise ComputationFailed(
            "no stable period-1 gait found at any slope (continued from the "
            "default model's 3-degree gait, by --method " + args.method + "); check the "
            "model flags"
        )
    bar.update(1)
    mult = S.family_multipliers(model, fam.psi, fam.z, transverse=False)
    stable1 = np.asarray(mult.stable) & ok1
    bar.update(1)
    flips = []
    pd2 = None
    # first flip: the stable family loses stability through -1
    idx = np.where(ok1[:-1] & ok1[1:] & stable1[:-1] & ~stable1[1:])[0]
    if len(idx):
        i = int(idx[0])
        pd = S.period_doubling_slope(psis[i], psis[i + 1], np.asarray(fam.z[i]), model=model)
        flips.append(pd.psi)
        pd2 = pd
    bar.update(1)
    branch2 = None
    if pd2 is not None:
        branch2 = S.period2_branch(model, pd2, psis[psis > pd2.psi])
        if branch2 is not None and branch2["flip_psi"] is not None:
            flips.append(branch2["flip_psi"])
    bar.update(1)
    # simulated from the period-1 gait, where there is one
    sim = np.flatnonzero(ok1)
    sim_slopes = [slopes[i] for i in sim]
    from .._chunks import CheckpointError

    try:
        diag = S.bifurcation_diagram(
            psis[sim],
            np.asarray(fam.z)[sim],
            model=model,
            num_transient=args.transient,
            num_record=args.record,
            checkpoint=args.checkpoint,
        )
    except CheckpointError as e:
        raise CLIError(str(e)) from None
    bar.update(1)
    bar.close()
    family_names = result_names(fam.result)
    missed = [s for s, ok in zip(slopes, ok1) if not ok]
    names = result_names(diag.result)
    aperiodic = np.asarray(diag.period_pattern) == 0
    if aperiodic.any():
        warn(args, _aperiodic_message(sim_slopes, aperiodic, args.transient, args.record))
    if args.csv:
        from .._io import atomic_open

        with atomic_open(args.csv, "w") as f:
            f.write(
                "slope_deg,result,pattern,"
                + ",".join(f"period_{i + 1}" for i in range(args.record))
                + "\n"
            )
            row = {int(i): j for j, i in enumerate(sim)}
            for i, s in enumerate(slopes):
                if i not in row:  # no gait to start from: the search's code, no pattern
                    f.write(f"{s:.10g},{family_names[i]}," + "," * args.record + "\n")
                    continue
                j = row[i]
                nd = diag.period_pattern[j]
                # the steps after a fall have no period (zero): empty cells
                cells = ("" if nd < 0 and x == 0 else f"{x:.12g}" for x in diag.periods[j])
                f.write(f"{s:.10g},{names[j]},{nd}," + ",".join(cells) + "\n")
    if args.png:
        from ..plotting import plot_bifurcation

        branches = [("period 1", np.degrees(psis)[ok1], np.asarray(fam.periods)[ok1], stable1[ok1])]
        if branch2 is not None and len(branch2["psi"]):
            branches.append(
                ("period 2", np.degrees(branch2["psi"]), branch2["periods"], branch2["stable"])
            )
        with figure_output(args.png) as fh:
            plot_bifurcation(
                diag,
                branches,
                fh,
                flips_deg=[math.degrees(f) for f in flips],
                case=describe(args, f"slopes {args.slope_deg} deg"),
                no_gait_deg=missed,
            )
    if args.png_multipliers:
        from ..plotting import plot_multipliers_vs_slope

        with figure_output(args.png_multipliers) as fh:
            plot_multipliers_vs_slope(
                np.degrees(psis)[ok1],
                {"stable family": np.asarray(mult.poincare)[ok1]},
                fh,
                case="Poincare-map Jacobian, " + describe(args, f"slopes {args.slope_deg} deg"),
            )
    fell = np.asarray(diag.fell)
    out = {
        "period_doubling_slopes_deg": [math.degrees(f) for f in flips],
        "period_doubling_slopes_deg_simulation": [
            math.degrees(f) for f in S.period_doubling_slopes_from_diagram(diag)
        ],
        "first_fall_slope_deg": sim_slopes[int(np.argmax(fell))] if fell.any() else None,
        "num_slopes": len(slopes),
        "num_no_gait": len(slopes) - len(sim),
        "no_gait_slopes_deg": missed,
        "num_fell": int(fell.sum()),
        "num_aperiodic": int(aperiodic.sum()),
        "transient_steps": args.transient,
        "recorded_steps": args.record,
        "tolerance": "rtol=atol=1e-8 (relative and absolute, of the simulations)",
    }
    if not fell.any():
        out["first_fall_slope_deg_reason"] = "no walker fell at any slope simulated"
    if missed:  # a flip or a fall may lie at a slope without a gait: not a full answer
        out["period_doubling_slopes_deg_reason"] = (
            f"no period-1 gait found at {len(missed)} of {len(slopes)} slopes "
            f"({_span(missed)} deg): a period doubling there is not seen"
        )
    if args.json:
        print_json(out)
    else:
        _print_bifurcation(out, slopes)
    if missed:
        raise ComputationFailed(
            f"incomplete: no period-1 gait found at {len(missed)} of {len(slopes)} slopes "
            f"({_span(missed)} deg, by --method {args.method}): not simulated, and a "
            "period doubling there is not seen (their --csv rows give the search's result)"
        )
    return 0


def _print_bifurcation(out, slopes):
    """The text output of `vhcjax bifurcation`: the summary `out` (its JSON) in words."""
    flips = out["period_doubling_slopes_deg"]
    names = ("the period-1 gait", "the period-2 gait")
    if flips:
        for name, f in zip(names, flips):
            print(f"period doubling of {name} (a multiplier crosses -1): {f:.6f} deg")
    else:
        print("period doubling (a multiplier crossing -1): none in the slopes given")
    seen = out["period_doubling_slopes_deg_simulation"]
    print(
        "period doublings seen in the simulations (midway between the grid slopes where "
        "the steps first repeat every 2, 4, ... steps): "
        + (", ".join(f"{v:.4g} deg" for v in seen) if seen else "none")
    )
    print(
        f"simulated {out['num_slopes'] - out['num_no_gait']} of {out['num_slopes']} slopes "
        f"({_span(slopes)} deg) from the period-1 gait: {out['transient_steps']} transient "
        f"steps, then {out['recorded_steps']} recorded (integration tolerance 1e-8, "
        "relative and absolute)"
    )
    first = out["first_fall_slope_deg"]
    print(
        f"  the walker fell at {out['num_fell']} slopes"
        + (f" (first at {first:g} deg)" if first is not None else "")
    )
    if out["num_aperiodic"]:
        print(
            f"  at {out['num_aperiodic']} slopes the recorded steps repeat with no period "
            "found (chaotic or not settled)"
        )
    if out["num_no_gait"]:
        print(
            f"  no period-1 gait found at {out['num_no_gait']} slopes "
            f"({_span(out['no_gait_slopes_deg'])} deg): not simulated"
        )


def _aperiodic_message(slopes, aperiodic, transient, record):
    """The warning for slopes whose recorded step periods show no period that they can
    show (`detect_period` 0): a chaotic walk, or one not yet settled."""
    import numpy as np

    from ..stability._bifurcation import PERIOD_CANDIDATES

    where = np.asarray(slopes)[np.asarray(aperiodic)]
    tried = [str(p) for p in PERIOD_CANDIDATES if p < record]
    tried = "1 step" if len(tried) == 1 else ", ".join(tried[:-1]) + f" or {tried[-1]} steps"
    return (
        f"at {len(where)} of {len(slopes)} slopes ({_span(where)} deg) the {record} recorded step "
        f"periods repeat with no period of {tried}: a chaotic walk, another period, "
        "or a walk not settled "
        f"after {transient} transient steps (a longer --transient tells them apart; the "
        "simulated period-doubling slopes count settled patterns only)"
    )


def _span(slopes):
    """`"a"` or `"a to b"`: the first and last of some slopes (deg), for a message."""
    first, last = f"{slopes[0]:g}", f"{slopes[-1]:g}"
    return first if len(slopes) == 1 else f"{first} to {last}"
