"""The `vhcjax` command: a thin layer over the library (no physics here).

Each subcommand lives in its own module of `vhcjax.cli` exposing `register(subparsers)`;
bad input becomes a one-line message and exit status 2 instead of a traceback.
"""

import argparse
import importlib
import os
import sys

from ._common import QUIET, CLIError

# Subcommand modules, in the order they appear in `vhcjax --help`.
SUBCOMMANDS = [
    "_simulate",
    "_gait",  # gait, sweep
    "_bifurcation",  # bifurcation, multipliers
    "_robustness",  # contraction, basin, slope-sensitivity, push
    "_stabilize",  # stabilize (transverse-linearization feedback)
    "_reproduce",  # reproduce (thesis chapter 7 report)
]


def build_parser():
    parser = argparse.ArgumentParser(
        prog="vhcjax",
        description="Periodic gaits of the passive compass-gait biped: simulate, find gaits, "
        "check stability, measure robustness. Angles on the command line are in degrees "
        "where the flag says so, radians elsewhere.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f"vhcjax.cli.{name}").register(sub)
    for command in sub.choices.values():
        if not any("--quiet" in a.option_strings for a in command._actions):
            command.add_argument("--quiet", action="store_true",
                                 help="no progress bars or notes on stderr")
    return parser


def _first_run_note():
    """Say so when the compilation cache is empty: the first run compiles the programs."""
    import jax

    directory = jax.config.jax_compilation_cache_dir
    if directory and (not os.path.isdir(directory) or not os.listdir(directory)):
        print(f"vhcjax: compiling (first run only; later runs load the programs from "
              f"{directory})", file=sys.stderr)


def main(argv=None):
    os.environ.setdefault("MPLBACKEND", "Agg")  # figures go to files
    parser = build_parser()
    args = parser.parse_args(argv)
    QUIET["on"] = bool(getattr(args, "quiet", False))
    if not QUIET["on"]:
        _first_run_note()
    try:
        return int(args.func(args) or 0)
    except CLIError as e:
        print(f"vhcjax {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
