"""The simplest walking model in plain numpy/scipy: the independent reference for tests.

Nothing here uses JAX or vhcjax. The equations are typed in from Garcia, Chatterjee,
Ruina and Coleman (1998), "The simplest walking model: stability, complexity, and
scaling", J. Biomech. Eng. 120, in their non-dimensional variables: `theta` the stance
leg angle from the slope normal, `phi` the angle between the legs, `gamma` the slope,
time in units of $\\sqrt{l/g}$:

- swing: $\\ddot\\theta = \\sin(\\theta - \\gamma)$,
  $\\ddot\\phi = \\sin(\\theta - \\gamma) + (\\dot\\theta^2 - \\cos(\\theta - \\gamma))\\sin\\phi$;
- heel strike where $\\phi - 2\\theta$ reaches zero, looked for only once the swing leg
  has passed the stance leg ($\\phi < 0$; the foot scuffing at $\\phi \\approx 0$ is
  ignored, as in the paper): `solve_ivp` (DOP853) in two stages, the first ended by
  $\\phi$ crossing zero, the second by the heel strike;
- impact and leg swap: $\\theta^+ = -\\theta^-$, $\\phi^+ = -2\\theta^-$,
  $\\dot\\theta^+ = \\cos(2\\theta^-)\\dot\\theta^-$,
  $\\dot\\phi^+ = \\cos(2\\theta^-)(1 - \\cos(2\\theta^-))\\dot\\theta^-$.

The step-to-step map acts on $z = (\\theta, \\dot\\theta, \\dot\\phi)$ just after heel
strike ($\\phi = 2\\theta$ there). Fixed points of it and of its powers (period-k gaits)
by Newton's method, period-1 gaits from seeds of the small-slope analysis (`seed`);
Jacobians by central differences (Richardson-extrapolated); flips (a multiplier at -1)
by bisection; long walks step by step.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

RTOL = ATOL = 1e-12
T_MAX = 20.0  # longest step (units of sqrt(l/g)); gaits take about 3 to 4


def rhs(t, y, gamma):
    """Swing equations of motion (the paper's, foot-to-hip mass ratio $\\beta \\to 0$)."""
    theta, phi, dtheta, dphi = y
    s = math.sin(theta - gamma)
    return [dtheta, dphi, s, s + (dtheta * dtheta - math.cos(theta - gamma)) * math.sin(phi)]


def heel_strike(y):
    """Impact and leg swap (the paper's heel-strike equations, $\\beta \\to 0$)."""
    theta, _, dtheta, _ = y
    c = math.cos(2.0 * theta)
    return np.array([-theta, -2.0 * theta, c * dtheta, c * (1.0 - c) * dtheta])


def _legs_pass(t, y, gamma):
    return y[1]


_legs_pass.terminal, _legs_pass.direction = True, -1


def _strike(t, y, gamma):
    return 2.0 * y[0] - y[1]  # zero where phi = 2 theta


_strike.terminal, _strike.direction = True, -1


def _fall(t, y, gamma):
    return math.cos(y[0])  # the hip reaches the slope


_fall.terminal, _fall.direction = True, -1


def _solve(y0, t0, event, gamma):
    sol = solve_ivp(
        rhs,
        (t0, T_MAX),
        y0,
        method="DOP853",
        rtol=RTOL,
        atol=ATOL,
        events=(event, _fall),
        args=(gamma,),
    )
    if len(sol.t_events[0]) != 1:
        raise RuntimeError(f"no {event.__name__.strip('_')} event (fall or time out)")
    return sol.t_events[0][0], sol.y_events[0][0]


def step(z, gamma):
    """One step from the post-impact point `z`: `(z_next, tau, y_minus)` with `tau` the
    step period and `y_minus` = $(\\theta, \\phi, \\dot\\theta, \\dot\\phi)$ before impact."""
    theta, dtheta, dphi = z
    t1, y1 = _solve([theta, 2.0 * theta, dtheta, dphi], 0.0, _legs_pass, gamma)
    tau, y_minus = _solve(y1, t1, _strike, gamma)
    y_plus = heel_strike(y_minus)
    return np.array([y_plus[0], y_plus[2], y_plus[3]]), tau, y_minus


def step_map(z, gamma, k=1):
    """$P^k(z)$: the post-impact point after `k` steps."""
    for _ in range(k):
        z = step(z, gamma)[0]
    return z


def long_period_half(x0=1.9):
    """$\\tau/2$ of the long-period gait as $\\gamma \\to 0$: the root of
    $\\tan x = -3\\tanh x$ in $(\\pi/2, \\pi)$ (see `seed`)."""
    return brentq(lambda x: math.sin(x) + 3.0 * math.tanh(x) * math.cos(x), 1.6, 3.1)


def coefficient(family):
    """$C$ in $\\theta^* \\approx C\\gamma^{1/3}$ as $\\gamma \\to 0$:
    $C = \\tanh(\\tau_0/2)^{2/3}$ with $\\tau_0 = \\pi$ (short-period gait) or
    $2\\,$`long_period_half()` (long-period gait); see `seed`."""
    half = math.pi / 2 if family == "short" else long_period_half()
    return math.tanh(half) ** (2.0 / 3.0)


def seed(gamma, family):
    """Post-impact point of a period-1 gait to leading order in small `gamma`.

    To first order in the angles the stance leg is an inverted pendulum,
    $\\theta = -c\\sinh(t - \\tau/2)$ (symmetric about mid-step), and the swing leg a
    pendulum driven by it, $\\ddot\\phi + \\phi = \\theta$, from $\\phi = 2\\theta_0$,
    $\\dot\\phi = 0$; it meets $\\phi = -2\\theta_0$ at $t = \\tau$ when
    $\\cos(\\tau/2)\\,(3\\sinh(\\tau/2)\\cos(\\tau/2) + \\cosh(\\tau/2)\\sin(\\tau/2)) = 0$:
    $\\tau = \\pi$ (short period) or $\\tan(\\tau/2) = -3\\tanh(\\tau/2)$ (long period,
    $\\tau \\approx 3.81$). The energy balance (exact: swing conserves
    $\\dot\\theta^2/2 + \\cos(\\theta-\\gamma)$, heel strike multiplies $\\dot\\theta$ by
    $\\cos 2\\theta$) reads $\\dot\\theta_0^2\\tan^2(2\\theta_0) = 4\\sin\\theta_0\\sin\\gamma$,
    with $\\dot\\theta_0 = -\\theta_0\\coth(\\tau/2)$ to leading order:
    $\\theta_0 = (\\gamma\\tanh^2(\\tau/2))^{1/3}$.
    """
    if family not in ("long", "short"):
        raise ValueError(f"family must be 'long' or 'short', got {family!r}")
    theta = coefficient(family) * gamma ** (1.0 / 3.0)
    dtheta = -math.sqrt(4.0 * math.sin(theta) * math.sin(gamma)) / math.tan(2.0 * theta)
    return np.array([theta, dtheta, (1.0 - math.cos(2.0 * theta)) * dtheta])


def fixed_point(gamma, z0, k=1, max_iter=30):
    """Fixed point of the `k`-step map near `z0`: Newton with central-difference
    Jacobians, the step halved while the map fails (a fall) or the residual grows.
    Returns `(z, taus, residual)` with `taus` the `k` step periods."""
    z = np.asarray(z0, float)
    r = step_map(z, gamma, k) - z
    for _ in range(max_iter):
        if np.max(np.abs(r)) < 1e-13:
            break
        dz = np.linalg.solve(_central(z, gamma, 1e-7, k) - np.eye(3), -r)
        for _ in range(20):
            try:
                r_new = step_map(z + dz, gamma, k) - (z + dz)
            except RuntimeError:
                dz = dz / 2
                continue
            if np.max(np.abs(r_new)) < np.max(np.abs(r)) or np.max(np.abs(r)) < 1e-10:
                break
            dz = dz / 2
        z, r = z + dz, r_new
    z_next, taus = z, []
    for _ in range(k):
        z_next, tau, _ = step(z_next, gamma)
        taus.append(tau)
    residual = float(np.max(np.abs(z_next - z)))
    if residual > 1e-11:
        raise RuntimeError(f"fixed point not converged at gamma={gamma}: residual {residual:.1e}")
    return z, np.array(taus), residual


def _central(z, gamma, h, k=1):
    J = np.empty((3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        J[:, j] = (step_map(z + e, gamma, k) - step_map(z - e, gamma, k)) / (2.0 * h)
    return J


def jacobian(z, gamma, h=1e-5, k=1):
    """Jacobian of the `k`-step map at `z`: central differences with steps `h` and `2h`
    combined by Richardson extrapolation (error of order `h**4`). Plain central
    differences are not enough: the map's third derivatives are large (at the
    short-period gait, a multiplier from steps of 1e-5 is off by 3e-6)."""
    return (4.0 * _central(z, gamma, h, k) - _central(z, gamma, 2.0 * h, k)) / 3.0


def multipliers(z, gamma, h=1e-5, k=1):
    """Eigenvalues of the `k`-step map's Jacobian, largest modulus first."""
    ev = np.linalg.eigvals(jacobian(z, gamma, h, k))
    return ev[np.argsort(-np.abs(ev))]


def gait(gamma, family, z0=None):
    """The period-1 gait of `family` ("long" or "short") at `gamma`: a dict with `z`,
    `tau` (step period), `residual` and `multipliers`. From `seed` unless `z0` is given."""
    z, taus, residual = fixed_point(gamma, seed(gamma, family) if z0 is None else z0)
    return {"z": z, "tau": taus[0], "residual": residual, "multipliers": multipliers(z, gamma)}


def flip_function(gamma, z0, k=1):
    """`(1 + lambda_min, z)`: the most negative real multiplier of the period-`k` gait
    near `z0` (of its `k`-step map), plus one: it changes sign where the gait
    period-doubles."""
    z, _, _ = fixed_point(gamma, z0, k)
    ev = multipliers(z, gamma, k=k)
    real = ev[np.abs(ev.imag) < 1e-9].real
    return 1.0 + float(np.min(real)), z


def flip_slope(lo, hi, z_lo, tol=1e-9):
    """Slope in `[lo, hi]` where the long-period gait's multiplier crosses -1, by
    bisection on `flip_function` (the fixed point carried along from `z_lo` at `lo`)."""
    f_lo, z_lo = flip_function(lo, z_lo)
    f_hi, _ = flip_function(hi, z_lo)
    if not f_lo * f_hi < 0:
        raise ValueError(f"no multiplier crossing -1 in [{lo}, {hi}]: {f_lo}, {f_hi}")
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        f_mid, z_mid = flip_function(mid, z_lo)
        if f_mid * f_lo > 0:
            lo, f_lo, z_lo = mid, f_mid, z_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def walk(gamma, z0, num_steps):
    """Up to `num_steps` steps from `z0`: the step periods of the steps completed
    before a fall (all `num_steps` if none)."""
    z, taus = np.asarray(z0, float), []
    for _ in range(num_steps):
        try:
            z, tau, _ = step(z, gamma)
        except RuntimeError:
            break
        taus.append(tau)
    return np.array(taus)
