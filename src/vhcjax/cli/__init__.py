"""The `vhcjax` command line (`vhcjax --help`)."""

from ._common import (
    CLIError as CLIError,
    add_model_flags as add_model_flags,
    check_finite as check_finite,
    check_slope_deg as check_slope_deg,
    model_from_args as model_from_args,
    parse_range as parse_range,
    print_json as print_json,
    progress as progress,
    to_jsonable as to_jsonable,
)
from ._main import build_parser as build_parser, main as main
