"""What the subcommands share: model flags, input checks, JSON output, progress bars."""

import argparse
import contextlib
import json
import math
import os
import re
import sys
import tempfile

from .._io import DISCARD, atomic_open, output_target
from .._json import to_jsonable as to_jsonable


class CLIError(Exception):
    """A user error: printed as one line, exit status 2."""


class ComputationFailed(CLIError):
    """The computation failed on valid input (e.g. no gait found): printed as one line,
    exit status 1. `result`: the result code of a failed gait search, where one failed."""

    result = "not_converged"


class ArgumentError(Exception):
    """An argparse error (unknown flag, bad value): printed as one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """`argparse.ArgumentParser` whose errors are one line (raised as `ArgumentError`, so
    that in-process callers of `main` get exit status 2 and no `SystemExit`), which
    reads a negative number in scientific notation (`-1e6`), `-inf`, `-nan` and a
    comma-separated list starting with a negative number (`-1,1,1`) as a value, not as
    an option (argparse alone only knows `-12` and `-1.5`), and which refuses a flag
    given twice (argparse would keep the last value and ignore the first)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # A value, not an option: "-" then anything but a letter or "-" (a negative
        # number, as typed or mistyped: -1e6, -1_0, a list -1,1,1), or -inf, -nan; it is
        # then read, or refused, by the flag's own number syntax (`read_number`).
        self._negative_number_matcher = re.compile(
            r"^-(?:[^-a-z]|(?:inf|infinity|nan)(?:,|$))", re.IGNORECASE
        )

    def parse_known_args(self, args=None, namespace=None):
        args = list(sys.argv[1:] if args is None else args)
        self._refuse_repeated(args)
        return super().parse_known_args(args, namespace)

    def _refuse_repeated(self, args):
        """A flag that takes a value, given twice: argparse keeps the last value and
        ignores the first; refused instead (one line)."""
        seen = set()
        for token in args:
            if token == "--":
                break
            if not token.startswith("--"):
                continue
            name = token.split("=", 1)[0]
            action = self._option_string_actions.get(name)
            if action is None and self.allow_abbrev:  # `--slope` for `--slope-deg`
                found = {a for o, a in self._option_string_actions.items() if o.startswith(name)}
                action = found.pop() if len(found) == 1 else None
            if action is None or action.nargs == 0:  # not ours, or a switch (--json)
                continue
            if action.dest in seen:
                self.error(f"{action.option_strings[0]} is given twice: give it once")
            seen.add(action.dest)

    def error(self, message):
        # "argument --x0: must be ..." -> "--x0 must be ...", as the model-flag checks say;
        # "argument --x0: expected ..." -> "--x0: expected ..."
        m = re.fullmatch(r"argument ([^:]+): (.*)", message)
        if m:
            message = f"{m[1]}{'' if m[2].startswith(('must ', 'is ')) else ':'} {m[2]}"
        # argparse quotes the values it echoes ("invalid choice: 'xxx...'"): cut long ones
        message = re.sub(
            rf"'([^']{{{SHOWN_CHARS + 1},}})'", lambda v: shown(v[1]), " ".join(message.split())
        )
        raise ArgumentError(one_line(f"{self.prog}: error: {message}"))


#: Longest value echoed whole in a message; a longer one is cut (`shown`).
SHOWN_CHARS = 40
#: Longest file name echoed whole (`shown_path`): names are long more often than values.
PATH_CHARS = 200
#: Longest message line; beyond, it is cut (`one_line`).
MAX_LINE = 3 * PATH_CHARS


def shown(text, limit=SHOWN_CHARS):
    """`text` (a value as the user typed it) for a one-line message: quoted, and cut to
    its first characters, with its length, when longer than `limit`."""
    text = str(text)
    if len(text) <= limit:
        return repr(text)
    return f"{text[: limit - 10]!r}... ({len(text):,} characters)"


def shown_path(path):
    """`shown` for a file name."""
    return shown(path, PATH_CHARS)


def one_line(message):
    """`message` on one line: whitespace runs (newlines included) become one space, a
    word longer than `PATH_CHARS` is cut as `shown` cuts a value, and a message still
    longer than `MAX_LINE` characters is cut there."""
    message = " ".join(str(message).split())
    message = re.sub(rf"\S{{{PATH_CHARS + 1},}}", lambda m: shown(m[0]), message)
    if len(message) > MAX_LINE:
        message = f"{message[: MAX_LINE - 30]}... ({len(message):,} characters)"
    return message


#: What a person types as a number: ASCII digits, at most one decimal point, an optional
#: exponent. Python's `float` and `int` read more (`1_0` as 10, full-width and other
#: Unicode digits, surrounding Unicode spaces, `0x10` in `int(x, 0)`): none of it here.
_DECIMAL = re.compile(r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_INTEGER = re.compile(r"[-+]?[0-9]+")
_NOT_FINITE = re.compile(r"[-+]?(?:inf|infinity|nan)", re.IGNORECASE)
#: Most digits of an integer value (beyond, it is out of every range anyway).
_MAX_DIGITS = 100


def read_number(text, kind=float):
    """The number of `kind` (float or int) that a person reads in `text`: ASCII digits
    with at most one decimal point and an exponent (`3`, `-0.5`, `.5`, `2.`, `1e-3`),
    for an integer digits alone, spaces or tabs around them allowed. Everything else is
    refused with a `ValueError` of one line (the value cut by `shown`): `inf` and `nan`
    as not finite, a value beyond the largest float as too large, and `0_3`, full-width
    digits, `0x10`, `1,5` or two points as not a number."""
    s = text.strip(" \t")
    if _NOT_FINITE.fullmatch(s):
        raise ValueError(f"must be a finite number, got {shown(text)}")
    if kind is int:
        if not _INTEGER.fullmatch(s):
            raise ValueError(f"expected an integer (digits only), got {shown(text)}")
        if len(s) > _MAX_DIGITS:
            raise ValueError(f"is out of range, got {shown(text)}")
        return int(s)
    if not _DECIMAL.fullmatch(s):
        raise ValueError(f"expected a number (digits, a point, an exponent), got {shown(text)}")
    v = float(s)
    if not math.isfinite(v):  # beyond the largest float
        raise ValueError(f"is too large, got {shown(text)}")
    return v


def read_numbers(text, name, kind=float):
    """A comma-separated list of numbers (`1,2,3`), each read by `read_number`; a
    `CLIError` naming `name` for a bad one."""
    try:
        return [read_number(t, kind) for t in text.split(",")]
    except ValueError as e:
        raise CLIError(f"{name}: {e}") from None


def number(kind=float, *, lo=None, hi=None, lo_open=False, hi_open=False):
    """An argparse `type` for a finite number of `kind` (float or int), read by
    `read_number`, in the range `lo`..`hi` (inclusive unless `lo_open` / `hi_open`):
    NaN, inf, what a person would not read as a number and values out of the range are
    refused before any work, with a one-line message."""

    def parse(text):
        try:
            v = read_number(text, kind)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        low_bad = lo is not None and (v <= lo if lo_open else v < lo)
        high_bad = hi is not None and (v >= hi if hi_open else v > hi)
        if low_bad or high_bad:
            left = "-inf" if lo is None else f"{lo:g}"
            right = "inf" if hi is None else f"{hi:g}"
            raise argparse.ArgumentTypeError(
                f"must be in {'(' if lo_open or lo is None else '['}{left}, {right}"
                f"{')' if hi_open or hi is None else ']'}, got {shown(text)}"
            )
        return v

    parse.__name__ = kind.__name__
    parse.bounds = (kind, lo, hi, lo_open, hi_open)  # for the tests of every flag
    return parse


FINITE = number(float)
POSITIVE = number(float, lo=0.0, lo_open=True)
#: Largest magnitude of a state entry on the command line, in the walker's own units
#: (angles in rad, rates times T = sqrt(l/g)): 1000 rad and rad/s for the thesis's walker,
#: far beyond any walking motion, and a bound that keeps the integrators' arithmetic
#: finite. Checked by `check_state` once the walker is known.
MAX_STATE = 1e3
STATE = FINITE
HALF_WIDTH = POSITIVE


def check_state(model, values, kinds, flag):
    """`values` (rad for `"angle"`, rad/s for `"rate"` in `kinds`) within `MAX_STATE`
    in the same proportion to `model`'s own units as 1000 rad/s to the thesis walker's,
    else a one-line `CLIError` naming `flag`."""
    from ._analysed import in_walker_units

    limits = {"angle": MAX_STATE, "rate": in_walker_units(model, MAX_STATE, "rate")}
    for v, kind in zip(values, kinds):
        if abs(v) > limits[kind]:
            raise CLIError(
                f"{flag}: {'an angle' if kind == 'angle' else 'a rate'} of {v:g} "
                f"{'rad' if kind == 'angle' else 'rad/s'} is beyond {limits[kind]:.4g} "
                "(far from any walking motion of this walker)"
            )


def count(lo=1, hi=100_000):
    """An integer in [`lo`, `hi`]."""
    return number(int, lo=lo, hi=hi)


def check_output_file(path, flag):
    """Refuse, before any work, an output that cannot be written: a missing or unwritable
    folder, a directory, a read-only file, a descriptor not open for writing. A symbolic
    link is checked where it points; a pipe or a device only for permission (opening a
    pipe would wait for its reader). Nothing is left behind."""
    if path is None or DISCARD["on"]:  # a process that writes nothing checks nothing
        return
    how, where, fd = output_target(path)
    if fd is not None:
        import fcntl

        try:
            access = fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE
        except OSError:
            raise CLIError(f"{flag} {shown_path(path)}: descriptor {fd} is not open") from None
        if access == os.O_RDONLY:
            raise CLIError(f"{flag} {shown_path(path)}: descriptor {fd} is open for reading only")
        return
    if os.path.isdir(path):
        raise CLIError(f"{flag} {shown_path(path)} is a directory")
    if how == "direct":  # a pipe, a device, a socket
        if not os.access(where, os.W_OK):
            raise CLIError(f"{flag} {shown_path(path)} cannot be written: permission denied")
        return
    folder = os.path.dirname(where)
    if not os.path.isdir(folder):
        what = "is not a folder" if os.path.exists(folder) else "does not exist"
        raise CLIError(f"{flag} {shown_path(path)}: folder {shown_path(folder)} {what}")
    existed = os.path.exists(where)
    try:
        with open(where, "a"):
            pass
    except OSError as e:
        raise CLIError(f"{flag} {shown_path(path)} cannot be written: {e.strerror}") from None
    if not existed:
        os.remove(where)
    if not os.access(folder, os.W_OK | os.X_OK):  # the file is written beside, then renamed
        raise CLIError(f"{flag} {shown_path(path)}: folder {shown_path(folder)} is not writable")


#: The options that name an output file, as `args` attributes.
OUTPUT_FILES = ("csv", "png", "png_multipliers", "animate")


def check_distinct_outputs(args):
    """Refuse two output options naming one file (the second would overwrite the first)."""
    seen = {}
    for name in OUTPUT_FILES:
        path = getattr(args, name, None)
        if path is None:
            continue
        flag = "--" + name.replace("_", "-")
        how, where, fd = output_target(path)
        key = (how, fd if fd is not None else os.path.realpath(where))
        if key in seen:
            raise CLIError(f"{seen[key]} and {flag} name the same file {shown_path(path)}")
        seen[key] = flag


#: Format of a figure written to a pipe, a device or a descriptor whose name has no
#: suffix (`/dev/stdout`, bash's `>(...)`): the flags that name figures are `--png`.
STREAM_FIGURE_FORMAT = "png"


def figure_format(path):
    """The format of the figure `path`: its suffix in lower case (`out.svg`: `"svg"`);
    `STREAM_FIGURE_FORMAT` for a pipe, a device or a descriptor without one; `None` for
    a file without one (matplotlib would write another file, `path` + ".png")."""
    fmt = os.path.splitext(path)[1].lstrip(".").lower()
    if fmt:
        return fmt
    return None if output_target(path).how == "replace" else STREAM_FIGURE_FORMAT


#: Why matplotlib cannot write each format tried in this process (`None`: it can).
_FORMAT_PROBLEMS: dict[str, str | None] = {}


def _format_problem(fmt):
    """Why matplotlib cannot write a figure as `fmt` here (PGF without LaTeX, a Pillow
    without WebP), else `None`: a small figure with text is saved to memory, once per
    format and process."""
    if fmt not in _FORMAT_PROBLEMS:
        import io

        from matplotlib.figure import Figure

        fig = Figure(figsize=(1, 1))
        ax = fig.add_subplot()
        ax.plot([0, 1], [0, 1])
        ax.set_title("x")
        try:
            fig.savefig(io.BytesIO(), format=fmt)
            _FORMAT_PROBLEMS[fmt] = None
        except Exception as e:  # whatever the writer raises: the format is not usable
            _FORMAT_PROBLEMS[fmt] = " ".join(str(e).split())[:200] or type(e).__name__
    return _FORMAT_PROBLEMS[fmt]


def check_figure_file(path, flag):
    """`check_output_file` for a figure: also a format (`figure_format`) that matplotlib
    writes, and writes here (tried on a small figure: PGF needs LaTeX)."""
    if path is None:
        return
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    known = ", ".join(sorted(formats))
    fmt = figure_format(path)
    if not fmt:
        raise CLIError(f"{flag} {shown_path(path)}: name the format by a suffix ({known})")
    if fmt not in formats:
        raise CLIError(
            f"{flag} {shown_path(path)}: a figure is written as {known}, not {shown(fmt)}"
        )
    problem = _format_problem(fmt)
    if problem:
        raise CLIError(f"{flag} {shown_path(path)}: matplotlib cannot write {fmt} here: {problem}")
    check_output_file(path, flag)


def second_figure(path, name, flag):
    """Where a command that writes several figures from one `flag` puts its figure
    `name`: beside the first (`path`), as STEM-NAME.EXT in the same format (`out.svg`:
    `out-slope.svg`). A pipe, a device or a descriptor takes one figure: refused."""
    if output_target(path).how != "replace":
        raise CLIError(
            f"{flag} {shown_path(path)} is a pipe or a device, which takes one figure; this "
            f"command also writes STEM-{name}.EXT beside it: name a file"
        )
    stem, ext = os.path.splitext(path)
    return f"{stem}-{name}{ext}"


@contextlib.contextmanager
def figure_output(path):
    """The file object that a plotting function, given it as its `path`, saves the
    figure `path` to: written by `atomic_open`, in `figure_format(path)`."""
    import matplotlib

    with (
        atomic_open(path, "wb") as fh,
        matplotlib.rc_context({"savefig.format": figure_format(path)}),
    ):
        yield fh


def check_output_dir(path, flag):
    """Create the output folder `path` (and its parents) now and check that a file can be
    written into it, before any work."""
    if path is None or DISCARD["on"]:
        return
    if os.path.exists(path) and not os.path.isdir(path):
        raise CLIError(f"{flag} {shown_path(path)} exists and is not a directory")
    try:
        os.makedirs(path, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".vhcjax-write-test-"):
            pass
    except OSError as e:
        raise CLIError(f"{flag} {shown_path(path)} cannot be written: {e.strerror}") from None


def add_model_flags(parser, *, slope=True, slope_default=3.0):
    """Model flags shared by every command (SI units; slope in degrees): finite numbers
    (`read_number`), their ranges checked by `model_from_args`."""
    g = parser.add_argument_group("model (compass gait, thesis Table 1 defaults)")
    if slope:
        g.add_argument(
            "--slope-deg",
            type=FINITE,
            default=slope_default,
            help="slope angle in degrees, in (0, 30) (default %(default)s)",
        )
    g.add_argument("--mass-hip", type=FINITE, default=10.0, help="hip mass mH in kg (default 10)")
    g.add_argument(
        "--mass-leg", type=FINITE, default=5.0, help="mass of each leg in kg (default 5)"
    )
    g.add_argument(
        "--a", type=FINITE, default=0.5, help="hip to leg centre of mass in m (default 0.5)"
    )
    g.add_argument(
        "--b",
        type=FINITE,
        default=0.5,
        help="leg centre of mass to foot in m, 0 for masses at the feet (default 0.5)",
    )
    g.add_argument("--gravity", type=FINITE, default=9.81, help="gravity in m/s^2 (default 9.81)")
    return g


#: The kneed walker's default slope (`KneedWalker.psi`, the slope of its reference gait).
KNEED_SLOPE_DEG = math.degrees(0.0504)
#: The simplest walking model's default slope (`SimplestWalker.psi`, 0.009 rad).
SIMPLEST_SLOPE_DEG = math.degrees(0.009)


def add_method_flag(parser):
    """`--method auto|vhc|shooting`, the gait search of every command that finds a gait."""
    parser.add_argument(
        "--method",
        default="auto",
        choices=("auto", "vhc", "shooting"),
        help="gait search: auto = the VHC search (thesis Problem 1) where it applies and "
        "shooting (Problem 2) wherever it fails; vhc or shooting alone (the VHC search "
        "is for the compass gait) (default %(default)s)",
    )


def check_method(args, model):
    """Refuse `--method vhc` for a model the VHC search is not written for."""
    from ..gait import vhc_applies

    if getattr(args, "method", "auto") == "vhc" and not vhc_applies(model):
        raise CLIError(
            f"the VHC search is for the compass gait: --method vhc cannot search the "
            f"{getattr(args, 'model', 'compass')} walker (use auto or shooting)"
        )


def find_walker_gait(args, model, family="stable", guess=None, flag=None):
    """The gait a command works on, found by the one gait finder (`vhcjax.find_gait`,
    `--method`), or a one-line `ComputationFailed`. A warning says when `auto` found it
    by shooting because the VHC search failed. **Returns:** `(gait, method_reason)`,
    the reason `None` unless `auto` switched to shooting."""
    import jax.numpy as jnp

    from .._results import RESULTS, result_names
    from ..gait import find_gait, vhc_applies

    check_method(args, model)
    method = getattr(args, "method", "auto")
    if guess is not None:  # section coordinates: q1, then rates
        check_state(model, guess, ["angle"] + ["rate"] * (len(guess) - 1), flag or "guess")
    g = None if guess is None else jnp.asarray(guess, float)
    gait = find_gait(model, family, method, g, throw=False)
    code = str(result_names(gait.result))
    if code != "successful":
        tried = (
            "by the VHC search or by shooting"
            if method == "auto" and vhc_applies(model)
            else f"by {'the VHC search' if method == 'vhc' else 'shooting'}"
        )
        start = f"from {flag} " if guess is not None and flag else ""
        name = f"{family} " if family and vhc_applies(model) else ""
        reason = RESULTS[getattr(RESULTS, code)].rstrip(".")
        hint = "" if method == "auto" else "; try --method auto"
        error = ComputationFailed(
            f"no {name}gait found {start}at slope {args.slope_deg:g} deg {tried} "
            f"({code}: {reason}){hint}"
        )
        error.result = code
        raise error
    return gait, method_reason(args, model, gait)


def method_reason(args, model, gait):
    """Why `auto` found `gait` by shooting (a warning too), or `None`."""
    from ..gait import vhc_applies

    if getattr(args, "method", "auto") != "auto" or not vhc_applies(model):
        return None
    if gait.found_by != "shooting":
        return None
    why = (
        "the VHC search (Problem 1) did not find this gait (its assumptions fail here): "
        "it was found by shooting (Problem 2)"
    )
    warn(args, why)
    return why


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
    """`--model compass|kneed|simplest` and the other walkers' own flags (`--mass-hip` and
    `--gravity` apply to all; their defaults are each model's)."""
    parser.add_argument(
        "--model",
        default="compass",
        choices=("compass", "kneed", "simplest"),
        help="compass gait (thesis), passive kneed walker (Hsu Chen 2007 parameters; "
        "--mass-hip defaults to 0.5 kg for it) or the simplest walking model (Garcia et al. "
        "1998: feet of negligible mass; --mass-hip, --gravity and --leg-length default to "
        "1) (default %(default)s)",
    )
    for action in parser._actions:  # each model's defaults (`walker_from_args`)
        if action.dest in _COMPASS_DEFAULTS:
            action.default = None  # given or not, whatever the value
        if action.dest == "slope_deg":
            action.default = None
            action.help = (
                "slope angle in degrees, in (0, 30) (default 3; with --model kneed "
                f"{KNEED_SLOPE_DEG:.6g} and with --model simplest {SIMPLEST_SLOPE_DEG:.6g}, "
                "the slopes of their reference gaits)"
            )
    g = parser.add_argument_group("kneed walker (with --model kneed)")
    for dest, flag, _, text in KNEED_FLAGS:
        g.add_argument(flag, dest=dest, type=POSITIVE, default=None, help=text)
    g = parser.add_argument_group("simplest walking model (with --model simplest)")
    g.add_argument(
        "--leg-length", type=POSITIVE, default=None, help="leg length l in m (default 1)"
    )


def _walker_from_flags(cls, flags, args, slope_deg):
    """Build and validate a `cls` walker from `flags` (`(dest, flag, field)`; unset flags:
    its defaults, every value given positive)."""
    values = {}
    for dest, flag, field in flags:
        v = getattr(args, dest, None)
        if v is None:
            continue
        check_finite(flag, v)
        if v <= 0:
            raise CLIError(f"{flag} must be positive, got {v}")
        values[field] = v
    check_slope_deg(slope_deg)
    return cls(psi=math.radians(slope_deg), **values)


def kneed_from_args(args, slope_deg):
    """Build and validate a `KneedWalker` from the flags (unset flags: its defaults)."""
    from .. import KneedWalker

    flags = [(dest, flag, field) for dest, flag, field, _ in KNEED_FLAGS]
    flags += [("mass_hip", "--mass-hip", "mh"), ("gravity", "--gravity", "g")]
    return _walker_from_flags(KneedWalker, flags, args, slope_deg)


#: The compass gait's flags and their defaults (thesis Table 1). With `--model` they
#: parse to `None` when not given, and `walker_from_args` sets the defaults.
_COMPASS_DEFAULTS = {"mass_hip": 10.0, "mass_leg": 5.0, "a": 0.5, "b": 0.5, "gravity": 9.81}
#: Flags of the compass gait alone (refused with `--model kneed`).
_COMPASS_ONLY = (("mass_leg", "--mass-leg"), ("a", "--a"), ("b", "--b"))


def simplest_from_args(args, slope_deg):
    """Build and validate a `SimplestWalker` from the flags (unset flags: its defaults)."""
    from .. import SimplestWalker

    flags = [
        ("mass_hip", "--mass-hip", "M"),
        ("gravity", "--gravity", "g"),
        ("leg_length", "--leg-length", "l"),
    ]
    return _walker_from_flags(SimplestWalker, flags, args, slope_deg)


def walker_from_args(args, slope_deg=None):
    """The model `--model` names (compass gait by default), built from its flags; a flag
    of another model is refused with one line, never ignored."""
    name = getattr(args, "model", "compass")
    kneed = name == "kneed"
    if args.slope_deg is None:  # not given: the model's own default
        args.slope_deg = {"kneed": KNEED_SLOPE_DEG, "simplest": SIMPLEST_SLOPE_DEG}.get(name, 3.0)
    slope = args.slope_deg if slope_deg is None else slope_deg
    if name == "simplest":
        for dest, flag in _COMPASS_ONLY + tuple((d, f) for d, f, _, _ in KNEED_FLAGS):
            if getattr(args, dest, None) is not None:
                raise CLIError(f"{flag} is not a parameter of the simplest walking model")
        if getattr(args, "family", None) is None:
            args.family = "stable"
        return simplest_from_args(args, slope)
    if getattr(args, "leg_length", None) is not None:
        raise CLIError(
            "--leg-length is a parameter of the simplest walking model: add --model simplest"
        )
    if kneed:
        for dest, flag in _COMPASS_ONLY:
            if getattr(args, dest) is not None:
                raise CLIError(f"{flag} is a compass-gait parameter: not with --model kneed")
        if getattr(args, "family", None) is not None:
            raise CLIError("--family is a compass-gait flag: the kneed walker has one family")
        return kneed_from_args(args, slope)
    for dest, default in _COMPASS_DEFAULTS.items():
        if getattr(args, dest, None) is None:
            setattr(args, dest, default)
    if hasattr(args, "family") and args.family is None:
        args.family = "stable"
    for dest, flag, _, _ in KNEED_FLAGS:
        if getattr(args, dest, None) is not None:
            raise CLIError(f"{flag} is a kneed-walker parameter: add --model kneed")
    return model_from_args(args, slope)


def check_finite(name, *values):
    for v in values:
        if not math.isfinite(v):
            raise CLIError(f"{name} must be a finite number, got {v}")


def check_slope_deg(value, name="--slope-deg"):
    check_finite(name, value)
    if not 0.0 < value < 30.0:
        raise CLIError(f"{name} must be in (0, 30) degrees, got {value:.6g}")


def model_from_args(args, slope_deg=None):
    """Build and validate a `CompassGait` from the shared flags."""
    from .. import CompassGait

    for flag in ("mass_hip", "mass_leg", "a", "b", "gravity"):
        v = getattr(args, flag)
        check_finite("--" + flag.replace("_", "-"), v)
        if flag == "b" and v == 0:  # the leg masses at the feet: a valid walker
            continue
        if flag == "a" and v == 0:
            raise CLIError(
                "--a 0 puts the leg masses at the hip: the swing leg then has no inertia and "
                "its motion is undetermined (the massless-leg limit, masses at the feet, is "
                "--b 0 with a light --mass-leg)"
            )
        if v <= 0:
            raise CLIError(f"--{flag.replace('_', '-')} must be positive, got {v}")
    if slope_deg is None:
        slope_deg = args.slope_deg
    check_slope_deg(slope_deg)
    return CompassGait(
        m1=args.mass_leg,
        m2=args.mass_leg,
        mH=args.mass_hip,
        a=args.a,
        b=args.b,
        g=args.gravity,
        psi=math.radians(slope_deg),
    )


def describe(args, slope_deg=None):
    """The case in words for figure titles: the slope and the parameters that differ
    from thesis Table 1, e.g. `"slope 3 deg, mH 0.1 kg, m 10 kg"`."""
    slope = args.slope_deg if slope_deg is None else slope_deg
    parts = [slope if isinstance(slope, str) else f"slope {slope:g} deg"]
    if getattr(args, "model", "compass") == "simplest":
        parts.append("simplest walking model")
        for dest, flag in (("mass_hip", "M"), ("gravity", "g"), ("leg_length", "l")):
            v = getattr(args, dest, None)
            if v is not None:
                parts.append(f"{flag} {v:g}")
        return ", ".join(parts)
    if getattr(args, "model", "compass") == "kneed":
        parts.append("kneed walker")
        extra = (("mass_hip", "--mass-hip", "", ""), ("gravity", "--gravity", "", ""))
        for dest, flag, _, _ in KNEED_FLAGS + extra:
            v = getattr(args, dest, None)
            if v is not None:
                parts.append(f"{flag[2:]} {v:g}")
        return ", ".join(parts)
    for flag, default, label in (
        ("mass_hip", 10.0, "mH {} kg"),
        ("mass_leg", 5.0, "m {} kg"),
        ("a", 0.5, "a {} m"),
        ("b", 0.5, "b {} m"),
        ("gravity", 9.81, "g {} m/s^2"),
    ):
        v = getattr(args, flag)
        if v != default:
            parts.append(label.format(f"{v:g}"))
    return ", ".join(parts)


def parse_range(text, name="--slope-deg"):
    """`START:STOP:STEP` (STOP included when on the grid, never passed), or one number,
    -> list of floats; each number read by `read_number`."""
    pieces = text.split(":")
    if len(pieces) not in (1, 3):
        raise CLIError(f"{name} must be START:STOP:STEP or one number, got {shown(text)}")
    try:
        parts = [read_number(p) for p in pieces]
    except ValueError as e:
        raise CLIError(f"{name} must be START:STOP:STEP or one number: {e}") from None
    if len(parts) == 1:
        return parts
    start, stop, step = parts
    if step <= 0 or stop < start:
        raise CLIError(f"{name} needs STEP > 0 and STOP >= START, got {shown(text)}")
    # STOP is included when it lies within 1e-9 of a step of the grid; nothing past it.
    span = (stop - start) / step
    if span >= 100_000:
        raise CLIError(f"{name} {shown(text)} gives {span + 1:.4g} values; at most 100000")
    n = math.floor(span + 1e-9) + 1
    # rounded to 1e-9 of a step: 0.9, not 0.8999999999999999 (0.3 + 2 x 0.3), and two
    # points of the grid never round to one; START as given
    digits = max(0, math.ceil(-math.log10(step)) + 9)
    return [start] + [min(round(start + i * step, digits), stop) for i in range(1, n)]


def print_json(obj):
    """Print `obj` as strict JSON: non-finite numbers become `null`, and a dict gains
    `"null_fields"`, the paths of those not explained by a `"<field>_reason"` key."""
    nulls = []
    out = to_jsonable(obj, nulls)
    unexplained = [
        p
        for p in nulls
        if isinstance(out, dict) and f"{p.split('.')[0].split('[')[0]}_reason" not in out
    ]
    if unexplained and isinstance(out, dict):
        out["null_fields"] = {
            p: "not a finite number (NaN or infinity): undefined here" for p in unexplained
        }
    print(json.dumps(out, allow_nan=False))


def warn(args, message):
    """A one-line warning on stderr."""
    print(f"vhcjax {args.command}: warning: {one_line(message)}", file=sys.stderr)


#: Set by `--quiet` (every command has it): no progress bars, no notes on stderr.
QUIET = {"on": False}
#: Seconds between redraws of a progress bar: its elapsed time moves while nothing
#: finishes (a compile, a long chunk).
TICK = 1.0


def progress(iterable=None, total=None, desc=None, disable=None):
    """A tqdm progress bar on stderr, redrawn every `TICK` seconds (silent with
    `--quiet`, when stderr is not a terminal and in CI)."""
    from tqdm import tqdm

    if QUIET["on"]:
        disable = True

    bar = tqdm(
        iterable,
        total=total,
        desc=desc,
        file=sys.stderr,
        leave=False,
        disable=disable,
        dynamic_ncols=True,
    )
    if not bar.disable:
        _keep_redrawing(bar)
    return bar


def _keep_redrawing(bar):
    """Redraw `bar` every `TICK` seconds from a daemon thread until it is closed."""
    import threading
    import weakref

    ref = weakref.ref(bar)  # a bar dropped without `close` stops the thread too
    closed = threading.Event()

    def redraw():
        while not closed.wait(TICK):
            shown = ref()
            if shown is None:
                return
            with shown.get_lock():  # `close` disables the bar, then clears it
                if shown.disable:
                    return
                shown.refresh(nolock=True)
            del shown

    threading.Thread(target=redraw, name="vhcjax-progress", daemon=True).start()
    weakref.finalize(bar, closed.set)
