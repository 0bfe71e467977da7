"""The `vhcjax` command: a thin layer over the library (no physics here).

Each subcommand lives in its own module of `vhcjax.cli` exposing `register(subparsers)`;
bad input becomes a one-line message and exit status 2 instead of a traceback.
"""

import importlib
import os
import signal
import sys
import threading

from .._io import remove_pending
from ._common import (
    QUIET,
    ArgumentError,
    CLIError,
    ComputationFailed,
    Parser,
    check_distinct_outputs,
)

# Subcommand modules, in the order they appear in `vhcjax --help`.
SUBCOMMANDS = [
    "_simulate",
    "_gait",  # gait, sweep
    "_bifurcation",  # bifurcation, multipliers
    "_robustness",  # contraction, basin, slope-sensitivity, push
    "_stabilize",  # stabilize (transverse-linearization feedback)
    "_design",  # design, atlas
    "_reproduce",  # reproduce (thesis chapter 7 report)
]


def build_parser():
    parser = Parser(
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
            command.add_argument(
                "--quiet", action="store_true", help="no progress bars or notes on stderr"
            )
    return parser


def _first_run_note():
    """Say so when the compilation cache is empty: the first run compiles the programs."""
    import jax

    directory = jax.config.values["jax_compilation_cache_dir"]
    if directory and (not os.path.isdir(directory) or not os.listdir(directory)):
        print(
            f"vhcjax: compiling (first run only; later runs load the programs from {directory})",
            file=sys.stderr,
        )


def _stop_on_interrupt():
    """Ctrl-C (SIGINT) on the command line: one line, exit status 130, at once.

    A Python signal handler runs only when the main thread executes bytecode, and it may
    sit in a compiled XLA program for minutes; a `KeyboardInterrupt` does not stop worker
    threads either. But the C-level handler that `signal.signal` installs writes the
    signal number to the wakeup file descriptor at once, from whichever thread the
    signal hits; one daemon thread blocked on reading it removes the partial output files
    (`vhcjax._io`) and ends the process.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    command = next((a for a in sys.argv[1:] if not a.startswith("-")), None)
    line = (f"vhcjax {command}: interrupted\n" if command else "vhcjax: interrupted\n").encode()
    lock = threading.Lock()

    def stop(*_):
        with lock:  # the handler and the thread may both get here
            remove_pending()
            os.write(2, line)
            os._exit(130)

    r, w = os.pipe()
    os.set_blocking(w, False)
    signal.signal(signal.SIGINT, stop)
    signal.set_wakeup_fd(w, warn_on_full_buffer=False)

    def wait():  # no import here: the main thread may hold the import locks
        while signal.SIGINT not in os.read(r, 64):
            pass
        stop()

    threading.Thread(target=wait, name="vhcjax-sigint", daemon=True).start()


def main(argv=None):
    """Run the command line `argv` (default `sys.argv[1:]`); returns the exit status:
    0, 1 (the computation failed, e.g. no gait found), 2 (bad input), 130 (interrupted)."""
    os.environ.setdefault("MPLBACKEND", "Agg")  # figures go to files
    if argv is None:
        _stop_on_interrupt()
    try:
        args = build_parser().parse_args(argv)
    except ArgumentError as e:
        print(e, file=sys.stderr)
        return 2
    QUIET["on"] = bool(getattr(args, "quiet", False))
    if not QUIET["on"]:
        _first_run_note()
    try:
        check_distinct_outputs(args)
        return int(args.func(args) or 0)
    except ComputationFailed as e:
        print(f"vhcjax {args.command}: {e}", file=sys.stderr)
        return 1
    except CLIError as e:
        print(f"vhcjax {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        remove_pending()
        print(f"vhcjax {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # a bug, not bad input: one line, the traceback on request
        remove_pending()
        if os.environ.get("VHCJAX_DEBUG"):
            raise
        msg = " ".join(str(e).split())[:300]
        print(
            f"vhcjax {args.command}: internal error: {type(e).__name__}: {msg} "
            "(VHCJAX_DEBUG=1 shows the traceback)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
