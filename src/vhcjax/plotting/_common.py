"""What the figure modules share."""


def pyplot():
    """`matplotlib.pyplot`, imported when the first figure is drawn (importing vhcjax does
    not import matplotlib). The user's backend is left alone: the `vhcjax` command selects
    the non-interactive Agg backend for itself, and matplotlib falls back to it where
    there is no display."""
    import matplotlib.pyplot as plt

    return plt
