"""The `vhcjax` command: a thin layer over the library (no physics here).

Each subcommand lives in its own module of `vhcjax.cli` exposing `register(subparsers)`;
bad input becomes a one-line message and exit status 2 instead of a traceback.
"""

import contextlib
import errno
import importlib
import os
import signal
import sys
import threading
import warnings

from .._io import WriteError, remove_pending
from ._common import (
    QUIET,
    ArgumentError,
    CLIError,
    ComputationFailed,
    Parser,
    check_distinct_outputs,
    count,
    one_line,
    shown_path,
)

# Subcommand modules, in the order they appear in `vhcjax --help`.
SUBCOMMANDS = [
    "_simulate",
    "_gait",  # gait, sweep
    "_bifurcation",  # bifurcation, multipliers
    "_contraction",
    "_basin",
    "_slope_sensitivity",
    "_push",
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
    for command in sub.choices.values():  # the same options for every command
        command.add_argument(
            "--quiet", action="store_true", help="no progress bars or notes on stderr"
        )
        group = command.add_argument_group(
            "several processes",
            "one job over several processes (JAX's distributed runtime), each computing "
            "its share of every batch; under srun or mpirun the launcher's values are used",
        )
        group.add_argument(
            "--coordinator", metavar="HOST:PORT", help="the address of process 0's coordinator"
        )
        group.add_argument(
            "--num-processes", type=count(1, 100_000), metavar="N", help="processes in the job"
        )
        group.add_argument(
            "--process-id",
            type=count(0, 99_999),
            metavar="I",
            help="this process's index, 0..N-1",
        )
    return parser


#: Signals that stop a command, and the word its one line says: Ctrl-C, a batch
#: scheduler's time limit or `kill`, a closed terminal. The exit status is 128 + the
#: signal's number (130, 143, 129), as a shell reports a process killed by it.
STOP_SIGNALS = {
    signal.SIGINT: "interrupted",
    signal.SIGTERM: "terminated (SIGTERM)",
    signal.SIGHUP: "hung up (SIGHUP)",
}


def _stop_on_signals():
    """Ctrl-C (SIGINT), SIGTERM and SIGHUP on the command line: one line, exit status 128
    + the signal's number, at once, with no partial output left.

    A Python signal handler runs only when the main thread executes bytecode, and it may
    sit in a compiled XLA program for minutes; a `KeyboardInterrupt` does not stop worker
    threads either. But the C-level handler that `signal.signal` installs writes the
    signal number to the wakeup file descriptor at once, from whichever thread the
    signal hits; one daemon thread blocked on reading it removes the partial output files
    and folders (`vhcjax._io`) and ends the process. A signal the process was started
    with ignored (`nohup`, a background job of a script) stays ignored.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    watched = {int(s) for s in STOP_SIGNALS if signal.getsignal(s) is not signal.SIG_IGN}
    if not watched:
        return
    command = next((a for a in sys.argv[1:] if not a.startswith("-")), None)
    prefix = f"vhcjax {command}" if command else "vhcjax"
    lines = {int(s): f"{prefix}: {word}\n".encode() for s, word in STOP_SIGNALS.items()}
    lock = threading.Lock()

    def stop(signum, *_):
        with lock:  # the handler and the thread may both get here
            remove_pending()
            try:
                os.write(2, lines[signum])
            except OSError:  # no terminal any more (SIGHUP): nothing to tell
                pass
            os._exit(128 + signum)

    r, w = os.pipe()
    os.set_blocking(w, False)
    for s in watched:
        signal.signal(s, stop)
    signal.set_wakeup_fd(w, warn_on_full_buffer=False)

    def wait():  # no import here: the main thread may hold the import locks
        while True:
            for signum in os.read(r, 64):
                if signum in watched:
                    stop(signum)

    threading.Thread(target=wait, name="vhcjax-signals", daemon=True).start()


def parse_command(argv=None):
    """The parsed command line `argv` (default `sys.argv[1:]`), or `None` for bad
    arguments, once their one line is printed; `--help` prints and exits. Imports no
    JAX (`vhcjax --help` answers at once). A process's own command line (`argv` is
    `None`) also gets its signal handlers (`_stop_on_signals`)."""
    os.environ.setdefault("MPLBACKEND", "Agg")  # figures go to files
    if argv is None:
        _stop_on_signals()
    try:
        return build_parser().parse_args(argv)
    except ArgumentError as e:
        print(e, file=sys.stderr)
        return None


def run_command(args):
    """Run the command `args` (`parse_command`); returns its exit status (see `main`).
    Without `--quiet`, a program that takes more than about 2 s to compile or load is
    named by a note on stderr (`vhcjax._programs.notes_to`)."""
    from .._programs import notes_to

    prefix = f"vhcjax {args.command}:"
    try:
        main_process = _join_processes(args)
    except CLIError as e:
        print(f"{prefix} error: {one_line(e)}", file=sys.stderr)
        return 2
    except Exception as e:  # the coordinator unreachable, a process missing: one line
        print(f"{prefix} cannot join the processes: {one_line(e)}", file=sys.stderr)
        return 1
    if not main_process:
        return _run_as_worker(args)
    QUIET["on"] = bool(getattr(args, "quiet", False))
    notes = contextlib.nullcontext() if QUIET["on"] else notes_to(_note_writer(args.command))
    stdout = sys.stdout
    sys.stdout = _Stdout(stdout)
    try:
        with warnings.catch_warnings(), notes:
            warnings.showwarning = _one_line_warning(args.command)
            return _run(args)
    finally:
        sys.stdout = stdout


def _join_processes(args):
    """Join the job's other processes (`vhcjax._distributed.initialize`) when the options
    or a launcher say there are some; **returns** whether this process prints and writes
    (process 0, or the only one)."""
    from .. import _distributed

    given = [getattr(args, k, None) for k in ("coordinator", "num_processes", "process_id")]
    if all(v is None for v in given) and _distributed.launched_processes() == 1:
        return True
    coordinator, num, pid = given
    if num is not None and pid is not None and pid >= num:
        raise CLIError(f"--process-id must be below --num-processes ({num}), got {pid}")
    if (coordinator is None or num is None or pid is None) and (
        _distributed.launched_processes() == 1
    ):
        raise CLIError(
            "without a launcher (srun, mpirun), give --coordinator, --num-processes and "
            "--process-id together"
        )
    _distributed.initialize(coordinator, num, pid)
    return _distributed.is_main()


def _run_as_worker(args):
    """Run the command as a process other than 0 of a job: the same computation (its
    share of each batch), with nothing printed or written; its exit status."""
    from .. import _io

    QUIET["on"] = True
    _io.DISCARD["on"] = True
    stdout = sys.stdout
    sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (closed below)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return _run(args)
    finally:
        sys.stdout.close()
        sys.stdout = stdout
        _io.DISCARD["on"] = False


def main(argv=None):
    """Run the command line `argv` (default `sys.argv[1:]`); returns the exit status:
    0, 1 (the computation failed, e.g. no gait found, or an output could not be
    written), 2 (bad input), 130 (interrupted); as a process also 143 (SIGTERM), 129
    (SIGHUP) and 141 (standard output closed by its reader, e.g. `| head`)."""
    args = parse_command(argv)
    return 2 if args is None else run_command(args)


def _note_writer(command):
    """Print a note as one line on stderr, above any progress bar."""

    def write(text):
        from tqdm import tqdm

        try:
            tqdm.write(f"vhcjax {command}: {one_line(text)}", file=sys.stderr)
        except OSError:  # no terminal any more: the command goes on, untold
            pass

    return write


class _StdoutError(OSError):
    """Standard output could not be written (its `errno` and `strerror`)."""


class _Stdout:
    """`sys.stdout` while a command runs: a failure to write there (a full disk, a closed
    pipe) raises `_StdoutError`, told apart from the command's other errors."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except OSError as e:
            raise _StdoutError(e.errno, e.strerror or str(e)) from e

    def flush(self):
        try:
            self._stream.flush()
        except OSError as e:
            raise _StdoutError(e.errno, e.strerror or str(e)) from e

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _run(args):
    prefix = f"vhcjax {args.command}:"
    try:
        check_distinct_outputs(args)
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a failure to write what was printed is this command's
        return status
    except ComputationFailed as e:
        print(f"{prefix} {one_line(e)}", file=sys.stderr)
        return 1
    except CLIError as e:
        print(f"{prefix} error: {one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        remove_pending()
        print(f"{prefix} interrupted", file=sys.stderr)
        return 130
    except _StdoutError as e:
        remove_pending()
        _drop_stdout(sys.stdout)
        if e.errno == errno.EPIPE:
            return 141  # its reader has gone (`| head`): nobody to tell
        print(f"{prefix} cannot write standard output: {e.strerror}", file=sys.stderr)
        return 1
    except OSError as e:  # disk full, file too large, permission lost: not a bug
        remove_pending()
        reason = e.strerror or str(e)
        if isinstance(e, WriteError):
            message = f"cannot write {shown_path(e.filename)}: {reason}"
        else:
            message = reason if e.filename is None else f"{shown_path(e.filename)}: {reason}"
        print(f"{prefix} {one_line(message)}", file=sys.stderr)
        return 1
    except Exception as e:  # a bug, not bad input: one line, the traceback on request
        remove_pending()
        if os.environ.get("VHCJAX_DEBUG"):
            raise
        msg = " ".join(str(e).split())[:300]
        print(
            f"{prefix} internal error: {type(e).__name__}: {msg} "
            "(VHCJAX_DEBUG=1 shows the traceback)",
            file=sys.stderr,
        )
        return 1


def _drop_stdout(stdout):
    """Point the process's standard output at `os.devnull` when `stdout` (a `_Stdout`)
    writes there: what is left in its buffer then goes nowhere at exit, instead of
    failing a second time."""
    stream = getattr(stdout, "_stream", None)
    if stream is None or stream is not sys.__stdout__:  # an in-process caller's stream
        return
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
    except (OSError, ValueError):  # no descriptor: nothing to redirect
        pass


def _one_line_warning(command):
    """A `warnings.showwarning` that prints a warning as the command's other warnings:
    one line on stderr."""

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"vhcjax {command}: warning: {one_line(message)}", file=sys.stderr)

    return show


if __name__ == "__main__":
    sys.exit(main())
