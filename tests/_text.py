"""A check of the commands' text output (and the report): words and units for people,
no Python or numpy reprs and no internal names."""

import re

#: What a person should not meet in the text output: Python and numpy reprs, names
#: internal to the code.
NOT_FOR_PEOPLE = (
    ("{'", "a Python dict"),
    ("array(", "a numpy array"),
    ("[[", "a nested list"),
    ("FAST_CONFIG", "an internal name"),
    ("DEFAULT_CONFIG", "an internal name"),
    ("_value", "an internal name"),
    ("RESULTS.", "an internal name"),
)
#: A Python complex number (`0.37+0j`) or a numpy vector (`[ 0.2 -1.09 -0.37]`).
REPRS = (
    (re.compile(r"\d[+-]\d[\d.e+-]*j\b"), "a Python complex number"),
    (re.compile(r"\[ ?-?\d[\d.e+-]* +-?\d"), "a numpy vector"),
)


def assert_plain_text(text):
    """Fail, naming the line, where `text` holds a Python or numpy repr or an internal
    name."""
    assert text.strip(), "no text output"
    for line in text.splitlines():
        for piece, what in NOT_FOR_PEOPLE:
            assert piece not in line, f"{what} ({piece!r}) in: {line}"
        for pattern, what in REPRS:
            assert not pattern.search(line), f"{what} in: {line}"
