"""The thesis chapter-7 report: every number recomputed and checked."""

from ._run import (
    N_SECTIONS as N_SECTIONS,
    reproduce as reproduce,
)
