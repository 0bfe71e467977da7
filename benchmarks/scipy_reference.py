"""A plain numpy/scipy compass gait: the independent reference for tests and benchmarks.

Nothing here uses JAX or vhcjax. The equations are typed in from the thesis:

- equations of motion $M\\ddot q + C\\dot q + G = 0$ with the closed forms (3.8)-(3.10);
- heel strike: `solve_ivp` (DOP853 by default) with a terminal event on
  $q_1 + q_2 + 2\\psi$ crossing zero downward, looked for only once the swing leg is
  ahead of the stance leg ($q_2 > q_1$; before that the equal legs scuff through the
  slope mid-swing, which the thesis ignores);
- impact: conservation of angular momentum (3.17), with the `- p9` that the printed
  equation lacks in the first entry of the pre-impact matrix (appendix MATLAB has it),
  then the leg swap (3.32).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp


@dataclass(frozen=True)
class Params:
    """Compass-gait parameters (thesis Table 1 defaults); `psi` in radians."""

    m1: float = 5.0
    m2: float = 5.0
    mH: float = 10.0
    a: float = 0.5
    b: float = 0.5
    g: float = 9.81
    psi: float = math.radians(3.0)

    @property
    def l(self) -> float:
        return self.a + self.b

    def p(self) -> dict:
        """Thesis constants p1..p11 (3.8)-(3.10), (3.17)."""
        m1, m2, mH, a, b, g, l = self.m1, self.m2, self.mH, self.a, self.b, self.g, self.l
        return {
            1: mH * l**2 + m1 * b**2 + m2 * l**2,
            2: m2 * l * a,
            3: m2 * a**2,
            4: (m1 * b + m2 * l + mH * l) * g,
            5: m2 * a * g,
            6: m1 * l**2 + mH * l**2 + m2 * b**2,
            7: m1 * a * l,
            8: m1 * a**2,
            9: m1 * a * b,
            10: m2 * l * b + mH * l**2 + m1 * l * b,
            11: m2 * a * b,
        }


def M(par: Params, q) -> np.ndarray:
    """Mass matrix (3.8)."""
    p = par.p()
    c = math.cos(q[0] - q[1])
    return np.array([[p[1], -p[2] * c], [-p[2] * c, p[3]]])


def C(par: Params, q, dq) -> np.ndarray:
    """Coriolis/centrifugal matrix (3.9)."""
    p = par.p()
    s = math.sin(q[0] - q[1])
    return np.array([[0.0, -p[2] * dq[1] * s], [p[2] * dq[0] * s, 0.0]])


def G(par: Params, q) -> np.ndarray:
    """Gravity vector (3.10)."""
    p = par.p()
    return np.array([-p[4] * math.sin(q[0]), p[5] * math.sin(q[1])])


def make_rhs(par: Params):
    """Right-hand side of (3.7) in first-order form, with the constants hoisted."""
    p = par.p()
    p1, p2, p3, p4, p5 = p[1], p[2], p[3], p[4], p[5]

    def rhs(t, x):
        q1, q2, dq1, dq2 = x
        c, s = math.cos(q1 - q2), math.sin(q1 - q2)
        # M ddq = -(C dq + G), 2x2 solved by hand.
        r1 = p2 * s * dq2 * dq2 + p4 * math.sin(q1)
        r2 = -p2 * s * dq1 * dq1 - p5 * math.sin(q2)
        m12 = -p2 * c
        det = p1 * p3 - m12 * m12
        return [dq1, dq2, (p3 * r1 - m12 * r2) / det, (p1 * r2 - m12 * r1) / det]

    return rhs


def energy(par: Params, x) -> float:
    """Total energy, zero potential with both legs vertical."""
    q, dq = np.asarray(x[:2]), np.asarray(x[2:])
    p = par.p()
    K = 0.5 * dq @ M(par, q) @ dq
    P = p[4] * (math.cos(q[0]) - 1.0) - p[5] * (math.cos(q[1]) - 1.0)
    return float(K + P)


def impact(par: Params, x_minus) -> np.ndarray:
    """Angular-momentum impact map (3.17, with the -p9 fix) and leg swap (3.32)."""
    p = par.p()
    q1, q2, dq1, dq2 = x_minus
    c = math.cos(q1 - q2)
    Qp = np.array([[p[8] - p[7] * c, -p[7] * c + p[6]], [p[8], -p[7] * c]])
    Qm = np.array([[p[10] * c - p[9], -p[11]], [-p[9], 0.0]])
    dqp = np.linalg.solve(Qp, Qm @ np.array([dq1, dq2]))
    return np.array([q2, q1, dqp[1], dqp[0]])


def _gate(par):
    def gate(t, x):
        return x[1] - x[0]

    gate.terminal = True
    gate.direction = 1.0
    return gate


def _strike(par):
    def strike(t, x):
        return x[0] + x[1] + 2.0 * par.psi

    strike.terminal = True
    strike.direction = -1.0
    return strike


@dataclass
class StepOut:
    x_minus: np.ndarray
    x_plus: np.ndarray
    period: float
    ok: bool
    nfev: int


def step(par: Params, x0, *, rtol=1e-12, atol=1e-12, method="DOP853", t_max=None, dense=False):
    """One step from the post-impact state `x0`: swing (two stages: until the swing leg
    passes the stance leg, then until heel strike), impact, relabelling."""
    rhs = make_rhs(par)
    t_max = 10.0 * math.sqrt(par.l / par.g) if t_max is None else t_max
    x0 = np.asarray(x0, float)
    kw = dict(method=method, rtol=rtol, atol=atol, dense_output=dense)
    if x0[1] - x0[0] > 0:  # gate already open
        t_gate, x_gate, nfev, sol1 = 0.0, x0, 0, None
    else:
        sol1 = solve_ivp(rhs, (0.0, t_max), x0, events=_gate(par), **kw)
        nfev = sol1.nfev
        if sol1.status != 1:
            return StepOut(x0, x0, float("nan"), False, nfev)
        t_gate, x_gate = sol1.t_events[0][0], sol1.y_events[0][0]
    sol2 = solve_ivp(rhs, (t_gate, t_max), x_gate, events=_strike(par), **kw)
    nfev += sol2.nfev
    if sol2.status != 1 or math.cos(sol2.y_events[0][0][0] + par.psi) <= 0:
        return StepOut(x0, x0, float("nan"), False, nfev)
    x_minus = sol2.y_events[0][0]
    out = StepOut(x_minus, impact(par, x_minus), float(sol2.t_events[0][0]), True, nfev)
    if dense:
        out.sols = (sol1, sol2)
    return out


def simulate(par: Params, x0, num_steps, **kw):
    """`num_steps` steps; stops at the first failure. Returns the list of `StepOut`."""
    out, x = [], np.asarray(x0, float)
    for _ in range(num_steps):
        s = step(par, x, **kw)
        out.append(s)
        if not s.ok:
            break
        x = s.x_plus
    return out
