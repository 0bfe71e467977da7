"""`python -m vhcjax`: the `vhcjax` command."""

import sys

from .cli import main

sys.exit(main())
