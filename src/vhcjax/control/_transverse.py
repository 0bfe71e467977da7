"""Transverse linearization with an input, along any period-1 gait, and its jump matrix.

The phase is $\\theta = q_1$ (monotone along a gait); the moving Poincare sections are
$\\{\\theta = \\text{const}\\}$ (thesis ch. 6; Shiriaev et al. 2005, 2008). On a section the
state is $x = (\\theta, w)$, $w = (q_{2..n}, \\dot q_{1..n})$: $2n - 1$ transverse
coordinates $\\zeta = w - w_\\star(s)$ measured from the orbit point on the same
section, with the normalised phase $s = (\\theta - \\theta^+)/(\\theta^- - \\theta^+)
\\in [0, 1]$. With $s$ as independent variable the walker obeys
$dw/ds = (\\theta^- - \\theta^+)\\, f_w(x, u)/\\dot\\theta$, whose linearization along
$w_\\star$ is the transverse linearization, written per unit of orbit time
($dt/ds = (\\theta^- - \\theta^+)/\\dot\\theta_\\star$):
$$\\dot\\zeta = A(s)\\zeta + B(s)u, \\qquad \\zeta^+ = J\\zeta^-,$$
with $A$, $B$ by `jax.jacfwd` for any model, and $J$ the jump at impact: flow to the
guard (a first-order correction along the flow, as thesis 6.35), impact Jacobian (6.23),
flow back to the section $\\theta = \\theta^+$ (6.36). The open-loop multipliers
(eigenvalues of $J\\Phi$) equal those of thesis (6.42) and of the Poincare map.

A multi-domain model (e.g. the kneed walker: knee free, knee locked) gets one such
system per domain, each on its own phase, with the jump of each reset
(`HybridTransverseSystem`); joints locked in a domain leave fewer free coordinates
there, and the monodromy is taken where there are fewest.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._programs import stored_jit
from .._results import RESULTS, result_codes, results_from_codes
from ..hybrid import SolverConfig, check_state_shape, multidomain_step
from ..hybrid._simulate import _units, state_distance
from ..solvers import diffeqsolve
from ..stability import GAIT_TOL, guard_normal
from ._actuated import actuated_vector_field, is_multidomain, num_inputs


def phase_field(model, theta_plus, delta, s, w, u, domain=None):
    """$dw/ds$ and $dt/ds$ at phase `s`, transverse state `w` and input `u` (in domain
    `domain` of a multi-domain model)."""
    x = jnp.concatenate([(theta_plus + s * delta)[None], w])
    f = actuated_vector_field(model, x, u, domain)
    dt_ds = delta / f[0]
    return f[1:] * dt_ds, dt_ds


def phase_matrices(model, theta_plus, delta, s, w, domain=None):
    """$(A, B, dt/ds)$ at phase `s` on the orbit point `w` ($A$, $B$ per unit time)."""
    m = num_inputs(model)
    u0 = jnp.zeros(m, w.dtype)
    (dA, dB), c = jax.jacfwd(
        lambda ww, uu: phase_field(model, theta_plus, delta, s, ww, uu, domain),
        argnums=(0, 1),
        has_aux=True,
    )(w, u0)
    return dA / c, dB / c, c


def _guard_normal(model, x, domain):
    if domain is None:
        return guard_normal(model, x)
    n = model.n_dof
    gq = jax.grad(lambda q: model.domain_guard(domain, q))(x[:n])
    return jnp.concatenate([gq, jnp.zeros(n, x.dtype)])


def _reset(model, x, domain):
    return model.impact(x)[0] if domain is None else model.domain_reset(domain, x)[0]


@stored_jit
def jump_matrix(model, x_minus, domain=None):
    """$J = \\partial\\zeta^+/\\partial\\zeta^-$ at the pre-impact orbit point `x_minus`
    (at the end of domain `domain` of a multi-domain model, into the next domain).

    $J = [-f^+_w/f^+_\\theta,\\ I]\\; dF\\; (I - \\tilde f^- n^{-T}/n^{-T}\\tilde f^-)
    \\begin{bmatrix}0\\\\ I\\end{bmatrix}$ with $\\tilde f = f/f_\\theta$ the flow per unit
    of phase, $n^-$ the guard normal (6.25) and $dF$ the impact Jacobian (6.23).
    **Returns:** `(J, x_plus)`.
    """
    m = num_inputs(model)
    r = x_minus.shape[0] - 1
    u0 = jnp.zeros(m, x_minus.dtype)
    nxt = None if domain is None else (domain + 1) % model.num_domains
    fm = actuated_vector_field(model, x_minus, u0, domain)
    fm = fm / fm[0]
    nm = _guard_normal(model, x_minus, domain)
    E = jnp.eye(r + 1, r, k=-1, dtype=x_minus.dtype)
    P_minus = (jnp.eye(r + 1, dtype=x_minus.dtype) - jnp.outer(fm, nm) / jnp.dot(nm, fm)) @ E
    x_plus = _reset(model, x_minus, domain)
    dF = jax.jacfwd(lambda x: _reset(model, x, domain))(x_minus)
    fp = actuated_vector_field(model, x_plus, u0, nxt)
    S_plus = jnp.concatenate([-(fp[1:] / fp[0])[:, None], jnp.eye(r, dtype=x_minus.dtype)], 1)
    return S_plus @ dF @ P_minus, x_plus


# diffrax traces a vector field several times per solve (initial step, solver state,
# step); jitted, the later traces reuse the first one's jaxpr (as `vhcjax._transverse`).
phase_field = stored_jit(phase_field)
phase_matrices = stored_jit(phase_matrices)


class TransverseSystem(eqx.Module):
    """The transverse linearization of one gait, tabulated on a uniform phase grid.

    - `s`: phase grid on $[0, 1]$, shape `(N+1,)`.
    - `theta_plus`, `theta_minus`: $\\theta = q_1$ just after and just before impact.
    - `w`, `dw`: orbit $w_\\star(s)$ and $dw_\\star/ds$, shape `(N+1, 2n-1)`.
    - `A`, `B`: $A(s)$, $B(s)$ per unit time, shapes `(N+1, r, r)`, `(N+1, r, m)`.
    - `dt_ds`: $dt/ds$ on the grid; `period`: the step time $\\int dt$.
    - `J`: jump matrix at impact, `(r, r)`.
    - `Phi`: transition matrix of $d\\zeta/ds = (dt/ds) A\\zeta$ over $[0, 1]$.
    - `multipliers`: eigenvalues of $J\\Phi$, by modulus (descending).
    - `x_plus`, `x_minus`: post- and pre-impact orbit states.
    - `closure`: $\\|F(x_\\star^-) - x_\\star^+\\|_\\infty$ in the walker's own units
      (velocities times `model.time_scale`), how well the tabulated orbit closes.
    - `result`: a `RESULTS` code.
    """

    s: jax.Array
    theta_plus: jax.Array
    theta_minus: jax.Array
    w: jax.Array
    dw: jax.Array
    A: jax.Array
    B: jax.Array
    dt_ds: jax.Array
    period: jax.Array
    J: jax.Array
    Phi: jax.Array
    multipliers: jax.Array
    x_plus: jax.Array
    x_minus: jax.Array
    closure: jax.Array
    result: RESULTS


def _solve_code(sol):
    return RESULTS.where(
        sol.result == diffrax.RESULTS.successful,
        RESULTS.successful,
        RESULTS.where(
            sol.result == diffrax.RESULTS.max_steps_reached,
            RESULTS.max_steps_reached,
            RESULTS.nonfinite,
        ),
    )


def phase_units(model):
    """The units of the transverse coordinates $w = (q_{2..n}, \\dot q_{1..n})$: angles
    1, rates $1/T$ ($T$ = `model.time_scale`)."""
    return _units(model)[1][1:]


def free_units(P, units):
    """The units of the free coordinates $P^T w$ (`P` an orthonormal basis or `None`):
    the root mean square of the units they combine (a scale for tolerances)."""
    return units if P is None else jnp.sqrt((jnp.asarray(P) ** 2).T @ units**2)


def solve_in_phase(field, y0, t0, t1, saveat, rtol, atol, max_steps):
    """`diffeqsolve` of `field` over the phase from `t0` to `t1` (either way): Tsit5 with
    a PID controller, failures as diffrax result codes. `atol`: a scalar, or one value
    per component of `y0` (tolerances in the walker's own units); `SaveAt(ts=...)`
    storable (`solvers.diffeqsolve`)."""
    return diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Tsit5(),
        t0=t0,
        t1=t1,
        dt0=None,
        y0=y0,
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        saveat=saveat,
        max_steps=max_steps,
        throw=False,
    )


def _tabulate(model, x_start, theta_minus, num_points, domain, x_next):
    """The `TransverseSystem` of one domain: the orbit from `x_start` to the section
    $q_1 = $ `theta_minus`, with $A$, $B$, $dt/ds$ and $\\Phi$ on the phase grid, the jump
    at its end, and its closure against `x_next` (the state the reset should reach)."""
    r = x_start.shape[0] - 1
    m = num_inputs(model)
    u0 = jnp.zeros(m, x_start.dtype)
    theta_plus = x_start[0]
    delta = theta_minus - theta_plus
    s = jnp.linspace(0.0, 1.0, num_points)

    def field(ss, y, args):
        w = y[:r]
        dw, c = phase_field(model, theta_plus, delta, ss, w, u0, domain)
        A, _, _ = phase_matrices(model, theta_plus, delta, ss, w, domain)
        Phi = y[r + 1 :].reshape(r, r)
        return jnp.concatenate([dw, c[None], (c * A @ Phi).reshape(-1)])

    y0 = jnp.concatenate([x_start[1:], jnp.zeros(1, x_start.dtype), jnp.eye(r).reshape(-1)])
    # Fixed steps (Tsit5, 5th order) landing on the grid: the tabulated orbit is then
    # a smooth function of s to ~1e-14 (dense output between adaptive steps is not: its
    # error, differentiated by the feedback along the orbit, would show in the closed-loop
    # Poincare map).
    sol = diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Tsit5(),
        t0=0.0,
        t1=1.0,
        dt0=1.0 / (num_points - 1),
        y0=y0,
        stepsize_controller=diffrax.ConstantStepSize(),
        saveat=diffrax.SaveAt(ts=s),
        max_steps=num_points + 8,
        throw=False,
    )
    ys = sol.ys
    assert ys is not None  # saved at s
    w = ys[:, :r]
    A, B, c = jax.vmap(lambda ss, ww: phase_matrices(model, theta_plus, delta, ss, ww, domain))(
        s, w
    )
    dw = jax.vmap(lambda ss, ww: phase_field(model, theta_plus, delta, ss, ww, u0, domain)[0])(s, w)
    Phi = ys[-1, r + 1 :].reshape(r, r)
    x_minus = jnp.concatenate([theta_minus[None], w[-1]])
    J, xp = jump_matrix(model, x_minus, domain)
    code = _solve_code(sol)
    finite = jnp.all(jnp.isfinite(J)) & jnp.all(jnp.isfinite(Phi)) & jnp.all(jnp.isfinite(A))
    code = RESULTS.where((code == RESULTS.successful) & ~finite, RESULTS.nonfinite, code)
    return TransverseSystem(
        s,
        theta_plus,
        theta_minus,
        w,
        dw,
        A,
        B,
        c,
        ys[-1, r],
        J,
        Phi,
        _sorted_eigvals(J @ Phi),
        x_start,
        x_minus,
        state_distance(model, xp, x_next)[0],
        code,
    )


def _sorted_eigvals(M):
    ev = jnp.linalg.eigvals(M)
    return ev[jnp.argsort(-jnp.abs(ev))]


def transverse_system(model, x_plus, *, num_points=401):
    """Transverse linearization with input of the period-1 gait through `x_plus`.

    **Arguments:**

    - `model`: a `WalkerModel` with an `input_matrix`; $q_1$ must be monotone along the
      gait. For a multi-domain model (e.g. `KneedWalker`) see `HybridTransverseSystem`.
    - `x_plus`: post-impact state of the gait (a fixed point of the step map, e.g.
      `model.section_to_state(z)`); the orbit is passive ($u = 0$ on it).
    - `num_points`: phase-grid points (the feedback interpolates on this grid); the
      orbit and $\\Phi$ are integrated with fixed Tsit5 steps on this grid.

    **Returns:** a `TransverseSystem` (a `HybridTransverseSystem` for a multi-domain
    model). Its `result` is `orbit_not_closed` where the tabulated orbit does not come
    back to `x_plus` (not a gait, or too coarse a grid) and `bad_input` for an invalid
    model. A `ValueError` for an `x_plus` of another shape or `num_points` < 2.
    """
    x_plus = jnp.asarray(x_plus, float)
    check_state_shape(model, x_plus, "x_plus")
    if isinstance(num_points, bool) or not isinstance(num_points, int) or num_points < 2:
        raise ValueError(f"num_points must be an integer >= 2, got {num_points!r}")
    return _transverse_system(model, x_plus, num_points=num_points)


@stored_jit
def _transverse_system(model, x_plus, *, num_points):
    """`transverse_system` for a checked state and grid: one compiled program per model
    class and grid size (a stored program, see `vhcjax._programs`)."""
    if is_multidomain(model):
        system = _hybrid_transverse_system(model, x_plus, num_points)
    else:
        n = model.n_dof
        # The impact leaves the configuration unchanged and relabelling is an involution
        # on configurations, so the pre-impact configuration is the relabelled post-impact
        # one.
        q_minus = model.relabel(x_plus[:n], jnp.zeros(n, x_plus.dtype))[0]
        system = _tabulate(model, x_plus, q_minus[0], num_points, None, x_plus)
    # an invalid model, or a state whose orbit does not come back to it: no gait
    code = system.result
    off = system.closure > GAIT_TOL * state_distance(model, x_plus, x_plus)[1]
    code = RESULTS.where((code == RESULTS.successful) & off, RESULTS.orbit_not_closed, code)
    code = RESULTS.where(model.validate(), code, RESULTS.bad_input)
    return eqx.tree_at(lambda t: t.result, system, code)


class HybridTransverseSystem(eqx.Module):
    """The transverse linearization of a gait of a multi-domain model, one
    `TransverseSystem` per domain.

    Each domain $i$ has its own phase $s \\in [0, 1]$ on $\\theta = q_1$ from its start
    to its reset, and the same $2n - 1$ transverse coordinates $\\zeta = w - w_\\star(s)$.
    Joints locked in domain $i$ (`model.domain_constraint(i)`) leave only the
    coordinates in the range of `bases[i]` free; the Riccati equation and the
    multipliers use those, $\\zeta_i = P_i^T\\zeta$.

    - `domains`: a `TransverseSystem` per domain; its `J` is the jump at the end of the
      domain into the next one, its `Phi` the transition over the domain, its
      `multipliers` the eigenvalues of its own $J\\Phi$, its `closure` the distance of
      the reset of its tabulated end from the start of the next domain.
    - `bases`: per domain, `None` (all coordinates free) or an orthonormal basis
      $P_i$, shape `(2n-1, r_i)`, of the free coordinates.
    - `section_domain`: the domain with the fewest free coordinates (static); the
      monodromy is taken at its start.
    - `multipliers`: eigenvalues of the monodromy $\\prod_i P_{i+1}^TJ_i\\Phi_iP_i$ around
      the cycle from `section_domain`, by modulus (those of the Poincare map).
    - `x_plus`: post-impact state of the gait; `closure`: the largest domain closure.
    - `result`: a `RESULTS` code.
    """

    domains: tuple
    bases: tuple
    section_domain: int = eqx.field(static=True)
    multipliers: jax.Array
    x_plus: jax.Array
    closure: jax.Array
    result: RESULTS


def domain_basis(model, i):
    """Orthonormal basis (numpy, `(2n-1, r_i)`) of the transverse coordinates left free by
    the joints locked in domain `i` ($A\\delta q = 0$, $A\\delta\\dot q = 0$ with
    $\\delta q_1 = 0$ on a section), or `None` if no joint is locked there."""
    A = model.domain_constraint(i) if is_multidomain(model) else None
    if A is None:
        return None
    A = np.asarray(A, float)
    k, n = A.shape
    C = np.zeros((2 * k, 2 * n - 1))
    C[:k, : n - 1] = A[:, 1:]
    C[k:, n - 1 :] = A
    _, sv, Vt = np.linalg.svd(C)
    rank = int(np.sum(sv > 1e-12 * sv.max()))
    return Vt[rank:].T


def reduce(P, M):
    """$P^TMP$ (or `M` when `P` is `None`)."""
    return M if P is None else P.T @ M @ P


def reduced_jump(bases, J, i):
    """The jump at the end of domain `i` in free coordinates, $P_{i+1}^TJ_iP_i$."""
    P_in, P_out = bases[i], bases[(i + 1) % len(bases)]
    if P_in is not None:
        J = J @ P_in
    if P_out is not None:
        J = P_out.T @ J
    return J


def cycle_order(num_domains, start):
    """Domain indices around the cycle from `start`."""
    return [(start + j) % num_domains for j in range(num_domains)]


def cycle_monodromy(bases, start, transitions, jumps):
    """$\\prod$ (jump $\\cdot$ transition) around the cycle from the start of domain
    `start`, in free coordinates (`transitions[i]` already reduced)."""
    M = None
    for i in cycle_order(len(bases), start):
        step = reduced_jump(bases, jumps[i], i) @ transitions[i]
        M = step if M is None else step @ M
    return M


def _hybrid_transverse_system(model, x_plus, num_points):
    _, info = multidomain_step(model, x_plus, SolverConfig(rtol=1e-12, atol=1e-12, max_steps=8192))
    D = model.num_domains
    nexts = [info.x_start[i + 1] for i in range(D - 1)] + [x_plus]
    domains = tuple(
        _tabulate(model, info.x_start[i], info.x_end[i][0], num_points, i, nexts[i])
        for i in range(D)
    )
    bases = tuple(domain_basis(model, i) for i in range(D))
    sizes = [x_plus.shape[0] - 1 if P is None else P.shape[1] for P in bases]
    k = int(np.argmin(sizes))
    # the passive cycle's first failure (e.g. a state that is not on a gait)
    code = results_from_codes(result_codes(info.result)[-1])
    for d in domains:
        code = RESULTS.where(code == RESULTS.successful, d.result, code)
    M = cycle_monodromy(
        bases, k, [reduce(P, d.Phi) for P, d in zip(bases, domains)], [d.J for d in domains]
    )
    return HybridTransverseSystem(
        tuple(domains),
        bases,
        k,
        _sorted_eigvals(M),
        x_plus,
        jnp.max(jnp.stack([d.closure for d in domains])),
        code,
    )
