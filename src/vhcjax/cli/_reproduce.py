"""`vhcjax reproduce`: recompute thesis chapter 7 and write figures and a report."""

from ._common import add_method_flag, check_output_dir, progress


def register(subparsers):
    p = subparsers.add_parser(
        "reproduce",
        help="recompute every result of thesis chapter 7; figures, report.md, results.json",
        description="Recompute the results of thesis chapter 7 (gaits at 2.87, 3 and 5 deg, "
        "their eigenvalues, the perturbed start, the uphill solution, the period-doubling "
        "slope) and the library's analyses (slope sweeps, bifurcation diagram, basin "
        "slice, push sensitivity); write PNG figures, DIR/report.md (thesis value, vhcjax "
        "value, difference, computed verdict, independent cross-check, run times) and "
        "DIR/results.json.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument(
        "--quick",
        action="store_true",
        help="small sizes (short sweeps, coarse basin, few slopes): for tests",
    )
    add_method_flag(p)
    p.set_defaults(func=run_reproduce)
    return p


def run_reproduce(args):
    import os

    from ..reproduce import N_SECTIONS, reproduce

    check_output_dir(args.out, "--out")
    bar = progress(total=N_SECTIONS, desc="reproduce", disable=True if args.quiet else None)
    res = reproduce(args.out, quick=args.quick, progress=bar, method=args.method)
    bar.close()
    counts = ", ".join(f"{v} {k}" for k, v in sorted(res["verdict_counts"].items()))
    print(
        f"wrote {os.path.join(args.out, 'report.md')} and results.json in "
        f"{res['total_seconds']:.0f} s; the thesis's numbers against ours: {counts}"
    )
    return 0
