"""Plain scipy gait searches (the baseline of `bench_gait_search.py`).

- `vhc_search`: thesis Problem 1 exactly as in the thesis appendix C.3 (closed-form
  f0 (5.19), f, h (5.9), A, B, C (5.14)), `solve_ivp` over theta from a to c, `fsolve` on
  the residual (phi(c) - g, phi'(c) - h/d).
- `shooting_search`: Problem 2, `fsolve` on P(z) - z with the step map of
  `scipy_reference.step` (solve_ivp with terminal events, numpy impact map).
"""

import math
import os
import sys

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scipy_reference as ref  # noqa: E402


def _p(par):
    p = par.p()
    return [None] + [p[i] for i in range(1, 12)]


def f0(theta, y, E0, p):
    """Appendix C.3 `f0`; `y = (phi, phi')`."""
    _, p1, p2, p3, p4, p5 = p[:6]
    phi, Dphi = y
    c, s = math.cos(-theta + phi), math.sin(-theta + phi)
    den = -p1 * p3 + c * c * p2 * p2
    dd = (
        -1.0
        / den
        * (
            -c * p2 * p2 * s * Dphi
            + p3 * s * p2 * Dphi**3
            - c * p2 * p2 * s * Dphi**2
            + p1 * s * p2
        )
        - 1.0
        / den
        / (E0 - math.cos(theta) * p4 - p5 + math.cos(phi) * p5 + p4)
        * (
            -math.sin(theta) * p4 * p3 * Dphi
            + math.sin(theta) * p4 * p2 * c
            + math.sin(phi) * p5 * c * p2 * Dphi
            - math.sin(phi) * p5 * p1
        )
        * (p1 + p3 * Dphi**2 - 2 * p2 * c * Dphi)
        / 2
    )
    return [Dphi, dd]


def _abcd(par, p, a, b, sign):
    _, p1, p2, p3, p4, p5, p6, p7, p8, p9, p10, p11 = p
    psi = par.psi
    c2 = math.cos(2 * a + 2 * psi)
    A = (
        (p8 * p10 - p9 * p7) ** 2 / p8**2 / p11**2 * c2**2 * p3 / 2
        - p9**2 / p8**2 * p3 / 2
        + p1 / 2
        - (p8 * p10 - p9 * p7) / p8 / p11 * c2**2 * p2
    )
    B = (
        -p9 / p8 * c2 * p2 * b
        - (p7**2 / p8 / p11 * c2**2 - p6 / p11) * b * c2 * p2
        + (p7**2 / p8 / p11 * c2**2 - p6 / p11) * b * (p8 * p10 - p9 * p7) / p8 / p11 * c2 * p3
        + b * p7 * c2 * p9 / p8**2 * p3
    )
    C = (
        -p1 * b**2 / 2
        - math.cos(a) * p4
        + (p7**2 / p8 / p11 * c2**2 - p6 / p11) ** 2 * b**2 * p3 / 2
        - math.cos(a) * p5
        + b**2 * p7 * c2**2 / p8 * p2
        + math.cos(a + 2 * psi) * p4
        + math.cos(a + 2 * psi) * p5
        - b**2 * p7**2 * c2**2 / p8**2 * p3 / 2
    )
    D = B * B - 4 * A * C
    if D < 0:
        return None
    d = (-B + sign * math.sqrt(D)) / (2 * A)
    f = (p7 * c2 * b - p9 * d) / p8
    h = ((p7**2 * c2**2 - p6 * p8) * b + (p8 * p10 - p7 * p9) * c2 * d) / (p8 * p11)
    return d, f, h


def vhc_residual(x, par, p, sign, rtol, atol):
    a, b = x
    out = _abcd(par, p, a, b, sign)
    if out is None:
        return [1e3, 1e3]
    d, f, h = out
    c = e = -a - 2 * par.psi
    g = a
    _, p1, p2, p3, p4, p5 = p[:6]
    E0 = (
        -f * math.cos(a - e) * p2 * b
        + f**2 * p3 / 2
        + p1 * b**2 / 2
        + math.cos(a) * p4
        + p5
        - math.cos(e) * p5
        - p4
    )
    sol = solve_ivp(f0, (a, c), [e, f / b], args=(E0, p), method="DOP853", rtol=rtol, atol=atol)
    if sol.status != 0:
        return [1e3, 1e3]
    return [sol.y[0, -1] - g, sol.y[1, -1] - h / d]


def vhc_search(par, guess, family="stable", rtol=1e-12, atol=1e-12, xtol=1e-12):
    """Returns `(a, b, ok)`."""
    p = _p(par)
    sign = -1.0 if family == "stable" else 1.0
    x, info, ier, _ = fsolve(
        vhc_residual, guess, args=(par, p, sign, rtol, atol), xtol=xtol, full_output=True
    )
    res = np.max(np.abs(vhc_residual(x, par, p, sign, rtol, atol)))
    return x, bool(ier == 1 and res < 1e-9)


def shooting_residual(z, par, rtol, atol):
    x0 = np.array([z[0], -z[0] - 2 * par.psi, z[1], z[2]])
    out = ref.step(par, x0, rtol=rtol, atol=atol, method="DOP853")
    if not out.ok:
        return [1e3, 1e3, 1e3]
    xp = out.x_plus
    return [xp[0] - z[0], xp[2] - z[1], xp[3] - z[2]]


def shooting_search(par, guess3, rtol=1e-10, atol=1e-10, xtol=1e-12):
    x, info, ier, _ = fsolve(
        shooting_residual, guess3, args=(par, rtol, atol), xtol=xtol, full_output=True
    )
    res = np.max(np.abs(shooting_residual(x, par, rtol, atol)))
    return x, bool(ier == 1 and res < 1e-8)
