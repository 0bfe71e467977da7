"""The `vhcjax` console command, which answers `--help` and bad arguments before JAX loads.

Importing `vhcjax` imports JAX and switches on float64, which takes seconds. The command
line's modules (`vhcjax.cli`) import the library only inside the commands, so here the
package is registered without running its `__init__`, the arguments are read, and the
package is initialised (JAX imported) only for a command that runs. `python -m vhcjax`
and `vhcjax.cli.main` run the same command with the package imported first.
"""

import importlib.util
import sys


def main():
    """Run `vhcjax` with `sys.argv[1:]`; returns the exit status (`vhcjax.cli.main`)."""
    spec = importlib.util.find_spec("vhcjax")
    if "vhcjax" in sys.modules or spec is None or spec.loader is None:
        from vhcjax.cli import main as cli_main

        return cli_main()
    package = importlib.util.module_from_spec(spec)
    sys.modules["vhcjax"] = package  # submodules import; `__init__` has not run
    from vhcjax.cli._main import parse_command, run_command

    args = parse_command()
    if args is None:  # bad arguments: one line said
        return 2
    spec.loader.exec_module(package)  # imports JAX, switches on float64
    return run_command(args)


if __name__ == "__main__":
    sys.exit(main())
