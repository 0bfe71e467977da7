"""`vhcjax gait` and `vhcjax sweep`: find periodic gaits (one slope, or a family along
a range of slopes)."""

import csv
import math
from typing import Any

from ._common import (
    STATE,
    CLIError,
    ComputationFailed,
    add_method_flag,
    add_model_choice,
    add_model_flags,
    check_figure_file,
    check_method,
    check_output_file,
    check_slope_deg,
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
from ._multiplier_fields import CSV_COLUMNS as STABILITY_COLUMNS
from ._words import complex_words, method_words, section_words, verdict_words

#: CSV columns of `vhcjax sweep` (`sweep_rows` and `add_stability_columns` write them;
#: new ones go at the end).
CSV_COLUMNS = [
    "slope_deg",
    "result",
    "a",
    "b",
    "c",
    "d",
    "e",
    "f",
    "g",
    "h",
    "T",
    "E0",
    "step_length",
    "speed",
    *STABILITY_COLUMNS,
    "method",
]
PARAM_KEYS = ("a", "b", "c", "d", "e", "f", "g", "h", "T", "E0")
NUMBER_KEYS = PARAM_KEYS + ("step_length", "speed")


def register(subparsers):
    p = subparsers.add_parser(
        "gait",
        help="find a periodic gait (VHC search, shooting where it fails)",
        description="Find the periodic gait of a walker on one slope: the VHC search of "
        "thesis Problem 1 (unknowns a, b; d from the energy quadratic) where it applies, "
        "and shooting on the step-to-step map (Problem 2) wherever it fails (--method). "
        "Without --guess the gait is continued from the model's known reference gait, so "
        "no starting point is needed.",
    )
    add_model_flags(p)
    add_model_choice(p)
    _family_method(p, both=False)
    p.add_argument(
        "--guess",
        type=STATE,
        nargs="+",
        metavar="X",
        help="initial guess for q1 (rad) and dq1 (rad/s) just after impact, e.g. "
        "the thesis seed 0.20 -1.0 (shooting: optionally dq2 too; kneed walker: "
        "q1 dq1 dq2); default: continuation, no guess needed",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help='print {"result", "slope_deg", "family", "method", "x0", "params", '
        '"iterations", "residual"} and, for a gait found, its multipliers and '
        "stability verdict",
    )
    p.add_argument(
        "--no-stability",
        action="store_true",
        help="skip the multipliers and the stability verdict (faster)",
    )
    _transverse_flag(p)
    p.set_defaults(func=run_gait)

    s = subparsers.add_parser(
        "sweep",
        help="a gait family against the slope, by continuation",
        description="Follow a gait family over a range of slopes by continuation (secant "
        "predictor over anchor slopes, then every slope by the batched Newton search) and "
        "report where it ends and why.",
    )
    add_model_flags(s, slope=False)
    s.add_argument(
        "--slope-deg",
        required=True,
        metavar="START:STOP:STEP",
        help="slopes in degrees, e.g. 0.5:6:0.1 (inclusive) or one slope, each in (0, 30)",
    )
    _family_method(s, both=True)
    s.add_argument(
        "--csv", metavar="FILE", help="write one row per slope: " + ", ".join(CSV_COLUMNS)
    )
    s.add_argument("--png", metavar="FILE", help="plot a, b, T and speed against slope")
    s.add_argument("--json", action="store_true", help="print the sweep as JSON")
    _transverse_flag(s)
    s.set_defaults(func=run_sweep)


def _transverse_flag(p):
    p.add_argument(
        "--transverse",
        action="store_true",
        help="also compute the multipliers by the transverse linearization (thesis ch. 6) "
        "and check them against the Poincare-map Jacobian, which gives the verdict "
        "(several times slower)",
    )


def _family_method(p, both):
    p.add_argument(
        "--family",
        # gait: None until walker_from_args (a compass-gait flag, refused with --model kneed)
        default="stable" if both else None,
        choices=("stable", "unstable", "both") if both else ("stable", "unstable"),
        help="root of the energy quadratic (5.13): stable = thesis (7.3), "
        "unstable = (7.8) (default stable)",
    )
    add_method_flag(p)


def gait_json(gait, slope_deg) -> dict[str, Any]:
    """The JSON record of one gait (a dict; other commands may add keys)."""
    import numpy as np

    from .._results import result_names

    return {
        "result": result_names(gait.result),
        "slope_deg": slope_deg,
        "family": gait.family,
        "method": gait.found_by,
        "x0": np.asarray(gait.x_plus).tolist(),
        "params": {k: float(getattr(gait, k)) for k in PARAM_KEYS},
        "iterations": int(gait.iterations),
        "residual": float(gait.residual),
    }


def failed_json(error, args):
    """The JSON record of a search that found no gait: its code and why, no numbers."""
    return {
        "result": getattr(error, "result", "not_converged"),
        "slope_deg": args.slope_deg,
        "family": getattr(args, "family", None),
        "method": args.method,
        "x0": None,
        "params": None,
        "iterations": None,
        "residual": None,
        "reason": str(error),
    }


def run_gait(args):
    if args.guess is not None:
        kneed = args.model == "kneed"
        sizes = (3,) if kneed else (2,) if args.method == "vhc" else (2, 3)
        if len(args.guess) not in sizes:
            raise CLIError(
                f"--guess takes {' or '.join(map(str, sizes))} numbers here, got {len(args.guess)}"
            )
    if args.transverse and args.no_stability:
        raise CLIError("--transverse computes multipliers: it cannot go with --no-stability")
    if args.model == "kneed":
        if args.transverse:
            raise CLIError(
                "the kneed walker's multipliers come from its Poincare map only: drop --transverse"
            )
        return _run_kneed_gait(args)
    model = walker_from_args(args)
    check_method(args, model)
    if args.guess is None:  # continued from 3 degrees: in steps of at most 1.5 % of the slope
        _check_solved_slope(args.slope_deg, "without --guess")
    try:
        gait, why = find_walker_gait(args, model, args.family, args.guess, "--guess")
    except ComputationFailed as e:
        if not args.json:
            raise
        print_json(failed_json(e, args))
        return 1
    rec = gait_json(gait, args.slope_deg)
    if why:
        rec["method_reason"] = why
    stab = None
    if not args.no_stability:  # multipliers, two ways
        from ..stability import gait_multipliers
        from ._multiplier_fields import stability_json

        z = model.state_to_section(gait.x_plus)
        stab = stability_json(gait_multipliers(model, z, transverse=args.transverse))
        if stab["transverse_result"] == "not_requested":
            stab["multipliers_reason"] = "transverse linearization not requested (--transverse)"
        rec.update(stab)
        if args.transverse and stab.get("multipliers_reason"):
            warn(args, stab["multipliers_reason"])
    if args.json:
        print_json(rec)
        return 0
    _print_gait(args, gait, rec, stab)
    return 0


#: The gait parameters of thesis (5.2) in words, with their units.
PARAM_WORDS = {
    "a": ("rad", "q1 just after impact"),
    "b": ("rad/s", "dq1 just after impact"),
    "c": ("rad", "q1 just before impact"),
    "d": ("rad/s", "dq1 just before impact"),
    "e": ("rad", "q2 just after impact"),
    "f": ("rad/s", "dq2 just after impact"),
    "g": ("rad", "q2 just before impact"),
    "h": ("rad/s", "dq2 just before impact"),
    "T": ("s", "step period"),
    "E0": ("J", "energy after impact"),
}


def _print_gait(args, gait, rec, stab):
    """The text output of `vhcjax gait` (compass gait, simplest walker)."""
    print(
        f"{args.family} gait at slope {args.slope_deg:g} deg, found by "
        f"{method_words(rec['method'])}: {rec['iterations']} Newton iterations, "
        f"residual {rec['residual']:.1e}"
    )
    print("  gait parameters (thesis 5.2):")
    for k, v in rec["params"].items():
        unit, words = PARAM_WORDS[k]
        print(f"  {k:>4} = {v: .9f} {unit:<5}  {words}")
    print(f"  step length {float(gait.step_length):.6f} m, speed {float(gait.speed):.6f} m/s")
    if stab is None:
        return
    print(
        "  multipliers (Poincare-map Jacobian): "
        + ", ".join(complex_words(complex(*e)) for e in stab["multipliers_poincare"])
    )
    if args.transverse:
        if stab["multipliers"] is None:
            print(f"  transverse linearization: not used ({stab['multipliers_reason']})")
        else:
            print(
                "  multipliers (transverse linearization): "
                + ", ".join(complex_words(complex(*e)) for e in stab["multipliers"])
            )
            dis = stab["transverse_disagreement"]
            if dis is not None:
                print(f"  the two computations agree to {dis:.1e} (relative)")
    print(f"  verdict: {verdict_words(stab['stable'], stab['max_abs_multiplier'])}")


def _none_found(rows, method, family):
    """Why a sweep found no gait: the result codes met, by count, and the other method;
    where the family was followed onto the other root of (5.13), that."""
    from collections import Counter

    from .._results import RESULTS

    codes = Counter(r["result"] for r in rows).most_common()
    parts = [f"{name} at {n} slope{'s' if n > 1 else ''}" for name, n in codes]
    first = RESULTS[getattr(RESULTS, codes[0][0])]
    hint = "" if method == "auto" else "; try --method auto"
    if codes[0][0] == "other_cycle":
        other = "stable" if family == "unstable" else "unstable"
        hint = (
            f"; the {family} family, followed from the default walker at 3 deg, is there a "
            f"gait on the other root of the energy quadratic (5.13), of the {other} family: "
            "it passes a double root of (5.13) on the way"
        )
    return f"no gait found: {', '.join(parts)} ({first.rstrip('.')}){hint}"


def _run_kneed_gait(args):
    """The kneed walker: shooting (Newton on its step map) and Poincare multipliers."""
    import numpy as np

    from ..stability import gait_multipliers

    model = walker_from_args(args)
    check_method(args, model)
    try:
        gait, _ = find_walker_gait(args, model, "stable", args.guess, "--guess")
        result, why = "successful", None
    except ComputationFailed as e:
        if not args.json:
            raise
        gait, result, why = None, getattr(e, "result", "not_converged"), str(e)
    found = gait is not None
    rec = {  # the compass record's keys (and nulls where nothing was found) where they apply
        "result": result,
        "slope_deg": args.slope_deg,
        "family": None,  # the kneed walker has one family
        "method": "shooting",
        "model": "kneed",
        "z": np.asarray(gait.z).tolist() if gait is not None else None,
        "x0": np.asarray(gait.x_plus).tolist() if gait is not None else None,
        "params": None,
        "params_reason": "the gait parameters of (5.2) are the compass gait's: see z and x0",
        "iterations": int(gait.iterations) if gait is not None else None,
        "residual": float(gait.residual) if gait is not None else None,
    }
    if gait is not None:
        rec["period"] = float(gait.T)
    else:
        rec["reason"] = why
    if found and not args.no_stability:
        # the program of `vhcjax multipliers --model kneed`, and its fields
        from ._multiplier_fields import stability_json

        rec.update(stability_json(gait_multipliers(model, gait.z, transverse=False)))
        rec["multipliers_reason"] = (
            "the transverse linearization is computed for the compass gait; the kneed "
            "walker's multipliers are the Poincare map's"
        )
    if args.json:
        print_json(rec)
    else:
        # without --json a failed search has raised its one line already
        assert gait is not None and rec["z"] is not None
        print(
            f"kneed-walker gait at slope {args.slope_deg:g} deg, found by "
            f"{method_words('shooting')}: {rec['iterations']} Newton iterations, "
            f"residual {rec['residual']:.1e}"
        )
        print(f"  post-impact state: {section_words(rec['z'])}")
        print(f"  step period {rec['period']:.8f} s")
        if "multipliers_poincare" in rec:
            print(
                "  multipliers (Poincare-map Jacobian): "
                + ", ".join(complex_words(complex(*v)) for v in rec["multipliers_poincare"])
            )
            print(f"  verdict: {verdict_words(rec['stable'], rec['max_abs_multiplier'])}")
    return 0 if found else 1


def sweep_rows(gaits, slopes_deg):
    """CSV rows (dicts over `CSV_COLUMNS`, stability columns aside) of a batched gait, one
    per slope; a failed member has no numbers (empty in the CSV)."""
    import jax
    import numpy as np

    from .._results import result_codes, result_names

    g = jax.device_get(gaits)  # one transfer, then plain numpy per row
    names = result_names(np.atleast_1d(result_codes(g.result)))
    cols = {k: np.atleast_1d(np.asarray(getattr(g, k), float)) for k in NUMBER_KEYS}
    by = np.atleast_1d(np.asarray(g.shooting))
    rows = []
    for i, (name, slope) in enumerate(zip(names, slopes_deg)):
        row = {"slope_deg": slope, "result": name}
        ok = name == "successful"
        row.update({k: float(v[i]) if ok else None for k, v in cols.items()})
        row["method"] = ("shooting" if by[i] else "vhc") if ok else None
        rows.append(row)
    return rows


def _end_words(end):
    """Why a family ends (an entry of `Sweep.ends()`), in words: a bare result code is
    replaced by its description."""
    from .._results import RESULTS

    code = end["result"]
    if end["reason"] == code and hasattr(RESULTS, code):
        return RESULTS[getattr(RESULTS, code)].rstrip(".")
    return end["reason"]


def _nulls(row):
    """A sweep row for JSON: the empty stability columns of a failed gait as `null`."""
    return {k: (None if v == "" else v) for k, v in row.items()}


def _check_solved_slope(slope_deg, how=""):
    """Slopes below `vhcjax.gait.MIN_SLOPE` are not continued to (the gaits shrink to
    nothing at zero slope): a one-line error."""
    from ..gait import MIN_SLOPE

    if slope_deg < math.degrees(MIN_SLOPE):
        raise CLIError(
            f"--slope-deg: slopes below {math.degrees(MIN_SLOPE):.3g} deg are not solved"
            + (f" {how}" if how else "")
        )


def run_sweep(args):
    from ..gait import sweep

    slopes = parse_range(args.slope_deg)
    for v in slopes:
        check_slope_deg(v)
        _check_solved_slope(v)
    model = model_from_args(args, slope_deg=slopes[0])
    check_output_file(args.csv, "--csv")
    check_figure_file(args.png, "--png")
    stability = bool(args.csv or args.json)  # the outputs that show multipliers
    if args.transverse and not stability:
        raise CLIError("--transverse adds multipliers to the --csv or --json output: give one")
    families = ("stable", "unstable") if args.family == "both" else (args.family,)
    from .._batching import report_progress

    psis = [math.radians(v) for v in slopes]
    results, rows = {}, {}
    bar = progress(total=1, desc="sweep")
    stage = {"name": "", "family": ""}

    def on_chunk(name, done, total):  # a bar that moves with the chunks of each stage
        if name != stage["name"] or bar.total != total:
            stage["name"] = name
            bar.set_description(f"sweep {stage['family']}: {name}", refresh=False)
            bar.reset(total=total)
        bar.update(done - bar.n)

    with report_progress(on_chunk):
        for fam in families:
            stage.update(name="", family=fam)
            bar.set_description(f"sweep {fam}")
            results[fam] = sweep(model, psis, fam, args.method, tangents=False)
            rows[fam] = sweep_rows(results[fam].gaits, slopes)
            if stability:  # multipliers of every gait in one batched call
                from ._multiplier_fields import add_stability_columns

                stage["name"] = ""  # the next chunk starts the multipliers' count
                bar.set_description(f"sweep {fam}: multipliers")
                add_stability_columns(model, results[fam].gaits, psis, rows[fam], args.transverse)
    bar.close()
    if args.csv:
        from .._io import atomic_open

        with atomic_open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(
                fh,
                fieldnames=(["family"] if len(families) > 1 else []) + CSV_COLUMNS,
                extrasaction="ignore",
            )
            w.writeheader()
            for fam in families:
                for r in rows[fam]:
                    w.writerow({**r, "family": fam} if len(families) > 1 else r)
    if args.png:
        from ..plotting import plot_sweep

        with figure_output(args.png) as fh:
            plot_sweep(
                results, fh, case=describe(args, f"{args.method}, slopes {args.slope_deg} deg")
            )
    summary = {}
    for fam, sw in results.items():
        n_ok = sum(r["result"] == "successful" for r in rows[fam])
        summary[fam] = {"found": n_ok, "total": len(slopes), "ends": sw.ends()}
        summary[fam]["found_by_shooting"] = sum(r["method"] == "shooting" for r in rows[fam])
        if n_ok == 0:  # no end to report: say why nothing was found
            summary[fam]["reason"] = _none_found(rows[fam], args.method, fam)
    if args.json:
        print_json(
            {
                "method": args.method,
                "families": {
                    fam: {**summary[fam], "rows": [_nulls(r) for r in rows[fam]]}
                    for fam in families
                },
            }
        )
    else:
        span = f"{slopes[0]:g} to {slopes[-1]:g} deg" if len(slopes) > 1 else f"{slopes[0]:g} deg"
        for fam in families:
            s = summary[fam]
            by = f", {s['found_by_shooting']} of them by shooting" if s["found_by_shooting"] else ""
            print(f"{fam} family: gait found at {s['found']} of {s['total']} slopes ({span}{by})")
            if "reason" in s:
                print(f"  {s['reason']}")
            for e in s["ends"]:
                reason = _end_words(e)
                if e["isolated"]:
                    print(f"  not found at {e['slope_deg']:.4g} deg: {reason}")
                    continue
                print(
                    f"  ends after {e['last_slope_deg']:.4g} deg (not found at the next slope, "
                    f"{e['slope_deg']:.4g} deg): {reason}"
                )
    # exit 1 (the computation failed) only where no gait was found at all
    return 0 if any(s["found"] for s in summary.values()) else 1
