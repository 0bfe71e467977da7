"""What the subcommands share: model flags, input checks, JSON output, progress bars."""

import json
import math
import sys

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


#: Kneed-walker flags: (dest, flag, KneedWalker field, help).
KNEED_FLAGS = (
    ("mass_shank", "--mass-shank", "ms", "shank mass in kg (default 0.05)"),
    ("mass_thigh", "--mass-thigh", "mt", "thigh mass in kg (default 0.5)"),
    ("shank_a", "--shank-a", "a1", "foot to shank centre of mass in m (default 0.375)"),
    ("shank_b", "--shank-b", "b1", "shank centre of mass to knee in m (default 0.125)"),
    ("thigh_a", "--thigh-a", "a2", "knee to thigh centre of mass in m (default 0.175)"),
    ("thigh_b", "--thigh-b", "b2", "thigh centre of mass to hip in m (default 0.325)"),
)


def add_model_choice(parser):
    """`--model compass|kneed` and the kneed walker's own flags (`--mass-hip` and
    `--gravity` apply to both; their defaults are each model's)."""
    parser.add_argument("--model", default="compass", choices=("compass", "kneed"),
                        help="compass gait (thesis) or passive kneed walker (Hsu Chen 2007 "
                        "parameters; --mass-hip defaults to 0.5 kg for it) (default %(default)s)")
    g = parser.add_argument_group("kneed walker (with --model kneed)")
    for dest, flag, _, text in KNEED_FLAGS:
        g.add_argument(flag, dest=dest, type=float, default=None, help=text)


def kneed_from_args(args, slope_deg):
    """Build and validate a `KneedWalker` from the flags (unset flags: its defaults)."""
    from .. import KneedWalker

    values = {}
    for dest, flag, field, _ in KNEED_FLAGS + (("mass_hip", "--mass-hip", "mh", ""),
                                              ("gravity", "--gravity", "g", "")):
        v = getattr(args, dest, None)
        if v is None or (dest in ("mass_hip", "gravity") and v == _COMPASS_DEFAULTS[dest]):
            continue
        check_finite(flag, v)
        if v <= 0:
            raise CLIError(f"{flag} must be positive, got {v}")
        values[field] = v
    check_slope_deg(slope_deg)
    return KneedWalker(psi=math.radians(slope_deg), **values)


_COMPASS_DEFAULTS = {"mass_hip": 10.0, "gravity": 9.81}


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
    from .. import CompassGait

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


from .._json import to_jsonable as to_jsonable


def print_json(obj):
    print(json.dumps(to_jsonable(obj)))


#: Set by `--quiet` (every command has it): no progress bars, no notes on stderr.
QUIET = {"on": False}


def progress(iterable=None, total=None, desc=None, disable=None):
    """A tqdm progress bar on stderr (silent with `--quiet`, when stderr is not a terminal
    and in CI)."""
    from tqdm import tqdm

    if QUIET["on"]:
        disable = True

    return tqdm(iterable, total=total, desc=desc, file=sys.stderr, leave=False,
                disable=disable, dynamic_ncols=True)
