"""The `vhcjax` command: a thin layer over the library (no physics here).

Each subcommand lives in its own module `vhcjax._cli_<name>` exposing
`register(subparsers)`; this module holds what they share: model flags, input checks,
JSON output, progress bars, and the error handling that turns bad input into a one-line
message and a non-zero exit instead of a traceback.
"""

import argparse
import importlib
import json
import math
import os
import sys

# Subcommand modules, in the order they appear in `vhcjax --help`.
SUBCOMMANDS = [
    "_cli_simulate",
    "_cli_gait",  # gait, sweep
    "_cli_bifurcation",  # bifurcation, multipliers
    "_cli_robustness",  # contraction, basin, slope-sensitivity, push
    "_cli_reproduce",  # reproduce (thesis chapter 7 report)
    "_cli_design",  # design, atlas
]


class CLIError(Exception):
    """A user error: printed as one line, exit status 2."""


def add_model_flags(parser, *, slope=True, slope_default=3.0):
    """Model flags shared by every command (SI units; slope in degrees)."""
    g = parser.add_argument_group("model (compass gait, thesis Table 1 defaults)")
    if slope:
        g.add_argument("--slope-deg", type=float, default=slope_default,
                       help="slope angle in degrees, in (0, 30) (default %(default)s)")
    g.add_argument("--mass-hip", type=float, default=10.0, help="hip mass mH in kg (default 10)")
    g.add_argument("--mass-leg", type=float, default=5.0, help="mass of each leg in kg (default 5)")
    g.add_argument("--a", type=float, default=0.5, help="hip to leg centre of mass in m (default 0.5)")
    g.add_argument("--b", type=float, default=0.5, help="leg centre of mass to foot in m (default 0.5)")
    g.add_argument("--gravity", type=float, default=9.81, help="gravity in m/s^2 (default 9.81)")
    return g


def check_finite(name, *values):
    for v in values:
        if not math.isfinite(v):
            raise CLIError(f"{name} must be a finite number, got {v}")


def check_slope_deg(value, name="--slope-deg"):
    check_finite(name, value)
    if not 0.0 < value < 30.0:
        raise CLIError(f"{name} must be in (0, 30) degrees, got {value}")


def model_from_args(args, slope_deg=None):
    """Build and validate a `CompassGait` from the shared flags."""
    from . import CompassGait

    for flag in ("mass_hip", "mass_leg", "a", "b", "gravity"):
        v = getattr(args, flag)
        check_finite("--" + flag.replace("_", "-"), v)
        if v <= 0:
            raise CLIError(f"--{flag.replace('_', '-')} must be positive, got {v}")
    if slope_deg is None:
        slope_deg = args.slope_deg
    check_slope_deg(slope_deg)
    return CompassGait(
        m1=args.mass_leg, m2=args.mass_leg, mH=args.mass_hip, a=args.a, b=args.b,
        g=args.gravity, psi=math.radians(slope_deg),
    )


def parse_range(text, name="--slope-deg"):
    """`START:STOP:STEP` (inclusive of STOP within half a step) -> list of floats."""
    try:
        parts = [float(p) for p in text.split(":")]
    except ValueError:
        raise CLIError(f"{name} must be START:STOP:STEP, got {text!r}") from None
    if len(parts) != 3:
        raise CLIError(f"{name} must be START:STOP:STEP, got {text!r}")
    start, stop, step = parts
    check_finite(name, start, stop, step)
    if step <= 0 or stop < start:
        raise CLIError(f"{name} needs STEP > 0 and STOP >= START, got {text!r}")
    n = int(math.floor((stop - start) / step + 0.5)) + 1
    return [start + i * step for i in range(n)]


def to_jsonable(obj):
    """numpy/JAX arrays and scalars to plain Python for `json.dumps`."""
    import numpy as np

    if isinstance(obj, dict):
        return {k: to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if hasattr(obj, "shape") or isinstance(obj, (np.generic,)):
        arr = np.asarray(obj)
        if np.iscomplexobj(arr):
            arr = np.stack([arr.real, arr.imag], axis=-1)
        return arr.tolist()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def print_json(obj):
    print(json.dumps(to_jsonable(obj)))


def progress(iterable=None, total=None, desc=None, disable=None):
    """A tqdm progress bar on stderr (silent when stderr is not a terminal and in CI)."""
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, file=sys.stderr, leave=False,
                disable=disable, dynamic_ncols=True)


def build_parser():
    parser = argparse.ArgumentParser(
        prog="vhcjax",
        description="Periodic gaits of the passive compass-gait biped: simulate, find gaits, "
        "check stability, measure robustness. Angles on the command line are in degrees "
        "where the flag says so, radians elsewhere.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f"vhcjax.{name}").register(sub)
    return parser


class _ArgParser(argparse.ArgumentParser):
    pass


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    if os.environ.get("VHCJAX_CACHE_DIR"):  # keep compiled programs on disk (README)
        from ._compile import enable_compilation_cache

        enable_compilation_cache(os.environ["VHCJAX_CACHE_DIR"])
    try:
        return int(args.func(args) or 0)
    except CLIError as e:
        print(f"vhcjax {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
