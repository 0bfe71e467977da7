"""How the commands' text output (without `--json`) writes numbers: in words, with units,
never as Python or numpy reprs."""

import math

#: The section coordinates of every walker of the command line, with their units.
SECTION = (("q1", "rad"), ("dq1", "rad/s"), ("dq2", "rad/s"))

#: How each gait search is named (`Gait.found_by`).
METHODS = {
    "vhc": "the VHC search (thesis Problem 1)",
    "shooting": "shooting on the step-to-step map (thesis Problem 2)",
}


def section_words(z, digits=8):
    """A post-impact section point `(q1, dq1, dq2)` with units:
    `"q1 0.21866880 rad, dq1 -1.09238359 rad/s, dq2 -0.37737395 rad/s"`."""
    return ", ".join(f"{n} {float(v):.{digits}f} {u}" for (n, u), v in zip(SECTION, z))


def complex_words(value, digits=6):
    """A multiplier as a person writes it: `"-0.199726 + 0.544476i"`, or the real part
    alone when the imaginary part is zero (`"0.131573"`)."""
    v = complex(value)
    re = f"{v.real:.{digits}g}"
    if v.imag == 0:
        return re
    return f"{re} {'-' if v.imag < 0 else '+'} {abs(v.imag):.{digits}g}i"


def list_words(values, fmt="{:.6g}"):
    """Numbers separated by commas: `"0.5, 0.25, 0.125"`."""
    return ", ".join(fmt.format(float(v)) for v in values)


def method_words(found_by):
    """The gait search that found a gait, in words."""
    return METHODS.get(found_by, str(found_by))


def verdict_words(stable, largest):
    """The stability verdict with its reason: `"stable (largest multiplier modulus
    0.579952 < 1)"`."""
    if not math.isfinite(largest):
        return "no verdict (the multipliers are not finite numbers)"
    sign = "<" if largest < 1 else ">="
    word = "stable" if stable else "unstable"
    return f"{word} (largest multiplier modulus {largest:.6g} {sign} 1)"


def bracket_words(lo, hi, unit, scale=1.0):
    """The two ends of a bisection bracket, with as many decimals as tell them apart:
    `("14.386 mm", "14.393 mm")` for 0.014386 and 0.014393 m at `scale` 1000."""
    a, b = lo * scale, hi * scale
    width = abs(b - a)
    decimals = (
        2 if width == 0 or not math.isfinite(width) else max(2, 1 - math.floor(math.log10(width)))
    )
    return f"{a:.{decimals}f} {unit}", f"{b:.{decimals}f} {unit}"
