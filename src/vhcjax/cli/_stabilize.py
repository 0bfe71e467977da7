"""`vhcjax stabilize`: hold a (possibly unstable) gait by transverse-linearization feedback."""

import math
import sys

from ._common import (
    POSITIVE,
    CLIError,
    add_method_flag,
    add_model_choice,
    add_model_flags,
    check_figure_file,
    check_finite,
    count,
    figure_output,
    find_walker_gait,
    print_json,
    read_numbers,
    shown,
    walker_from_args,
    warn,
)
from ._words import complex_words, section_words

FAMILIES = ("unstable", "stable")


def register(subparsers):
    p = subparsers.add_parser(
        "stabilize",
        help="stabilize a gait with joint torques (transverse-linearization LQR)",
        description="Period-1 gait at the slope (compass gait: family 'unstable', or "
        "'stable': the symmetric gait, unstable through a flip past its period doubling; "
        "kneed walker: its gait, continued in the slope from its reference gait), its "
        "transverse linearization with the joint torques (compass gait: hip; kneed "
        "walker: hip and knee), the periodic hybrid Riccati solution (two ways), the "
        "closed-loop multipliers (two ways), a closed-loop simulation from the perturbed "
        "gait and, with --basin, basin slices with and without feedback.",
    )
    add_model_flags(p)
    p.add_argument(
        "--family",
        choices=FAMILIES,
        default=None,
        help="compass-gait family (default unstable)",
    )
    add_method_flag(p)
    add_model_choice(p)
    p.add_argument(
        "--q",
        default=None,
        metavar="Q1,Q2,...",
        help="diagonal LQR weights per second on the transverse coordinates, not all 0: "
        "compass gait (delta q2, delta dq1, delta dq2), kneed walker (delta q2, delta q3, "
        "delta dq1, delta dq2, delta dq3); default all 1 for the thesis walker, the same "
        "problem in a rescaled walker's units; each nonzero weight within [1e-8, 1e8] "
        "times its default",
    )
    p.add_argument(
        "--q-jump",
        default=None,
        metavar="Q1,Q2,...",
        help="diagonal LQR weights per heel strike on the same coordinates, >= 0 "
        "(default: the --q numbers times T/T0, T = sqrt(l/g) of this walker and T0 of the "
        "thesis walker's)",
    )
    p.add_argument(
        "--r",
        default=None,
        metavar="R[,R2]",
        help="LQR weight per second on each torque: one value for all, or one per torque "
        "(kneed walker: hip,knee); default 1 for the thesis walker, scaled like --q",
    )
    p.add_argument(
        "--torque-limit",
        type=POSITIVE,
        default=None,
        metavar="NM",
        help="saturation of each joint torque in N m, > 0 (default: none)",
    )
    p.add_argument(
        "--perturbation",
        default=None,
        metavar="D[,D2,D3]",
        help="added to the post-impact section coordinates q1, dq1, dq2 for the "
        "simulation (rad, rad/s, rad/s; one value for all), each in [0, 1] rad or "
        "[0, 1/T] rad/s, T = sqrt(l/g); default 0.01 rad and 0.01 rad/s for the thesis's "
        "walker, the same in its own units for others",
    )
    p.add_argument(
        "--steps", type=count(1, 10_000), default=30, help="simulated steps (default 30)"
    )
    p.add_argument(
        "--basin", action="store_true", help="basin slices over (q1, dq1) with and without feedback"
    )
    p.add_argument(
        "--basin-grid",
        type=count(2, 400),
        default=None,
        help="basin grid points per axis, with --basin (default 15)",
    )
    p.add_argument("--json", action="store_true", help="print the results as one JSON object")
    p.add_argument(
        "--png",
        metavar="FILE",
        help="save gains vs phase, recovery, basin with and without feedback",
    )
    p.set_defaults(func=run_stabilize)


#: Transverse coordinates and torques of each model (the --q and --r entries).
_COORDINATES = {
    "compass": ("delta q2", "delta dq1", "delta dq2"),
    "kneed": ("delta q2", "delta q3", "delta dq1", "delta dq2", "delta dq3"),
}
_TORQUES = {"compass": ("hip",), "kneed": ("hip", "knee")}


#: Range of every LQR weight: the Riccati equation is solved in double precision, and
#: weights further apart than this make it overflow or lose every digit.
_WEIGHT_RANGE = (1e-8, 1e8)


def _numbers(flag, text, n, names):
    values = read_numbers(text, flag)
    if len(values) != n:
        what = "weight" if n == 1 else "weights"
        raise CLIError(f"{flag} needs {n} {what} ({', '.join(names)}), got {len(values)}")
    check_finite(flag, *values)
    return values


def _weights(args):
    """--q, --r and --q-jump as given (lists, `None` where not given), their signs and
    counts checked; the range check needs the walker (`_scaled_weights`)."""
    coords, torques = _COORDINATES[args.model], _TORQUES[args.model]
    q = q_jump = r = None
    if args.q is not None:
        q = _numbers("--q", args.q, len(coords), coords)
        if min(q) < 0 or max(q) == 0:
            raise CLIError(f"--q must be >= 0 and not all zero, got {shown(args.q)}")
    if args.q_jump is not None:
        q_jump = _numbers("--q-jump", args.q_jump, len(coords), coords)
        if min(q_jump) < 0:
            raise CLIError(f"--q-jump must be >= 0, got {shown(args.q_jump)}")
    if args.r is not None:
        n = 1 if "," not in args.r else len(torques)
        r = _numbers("--r", args.r, n, torques)
        if min(r) <= 0:
            raise CLIError(f"--r must be positive, got {shown(args.r)}")
        r = r * (len(torques) // n)
    return q, r, q_jump


def _scaled_weights(model, given):
    """The weights `(q, r, q_jump)`: those given, the others `control.default_weights`
    (the thesis walker's 1 in this walker's units; `q_jump`: `q` held over the time
    unit). Each nonzero weight must be within `_WEIGHT_RANGE` of its default."""
    import numpy as np

    from ..control import default_weights

    q0, r0, qj0 = (np.asarray(w).tolist() for w in default_weights(model))
    q, r, q_jump = given
    q = q0 if q is None else q
    r = r0 if r is None else r
    q_jump = [v * qj0[0] / q0[0] for v in q] if q_jump is None else q_jump
    lo, hi = _WEIGHT_RANGE
    for flag, values, default in (("--q", q, q0), ("--q-jump", q_jump, qj0), ("--r", r, r0)):
        if any(v != 0 and not lo <= v / d <= hi for v, d in zip(values, default)):
            shown_default = ",".join(f"{d:.4g}" for d in default)
            raise CLIError(
                f"{flag}: each nonzero weight must be within [{lo:g}, {hi:g}] times its "
                f"default ({shown_default} for this walker), got "
                f"{','.join(f'{v:g}' for v in values)}"
            )
    return q, r, q_jump


def _read_perturbation(args):
    """--perturbation as 3 numbers (q1, dq1, dq2), or `None` for the default."""
    if args.perturbation is None:
        return None
    values = read_numbers(args.perturbation, "--perturbation")
    if len(values) not in (1, 3):
        raise CLIError(f"--perturbation needs 1 or 3 values (q1, dq1, dq2), got {len(values)}")
    check_finite("--perturbation", *values)
    if min(values) < 0:
        raise CLIError(f"--perturbation must be >= 0, got {shown(args.perturbation)}")
    return values * (3 // len(values))


def _perturbation(values, model):
    """The perturbation per section coordinate (q1, dq1, dq2): as given (each at most
    1 rad or 1/T rad/s), or the thesis walker's 0.01 rad and 0.01 rad/s in `model`'s own
    units."""
    from ._analysed import in_walker_units

    if values is None:
        rate = in_walker_units(model, 0.01, "rate")
        return [0.01, rate, rate]
    rate_unit = 1.0 / float(model.time_scale)
    if any(v > b for v, b in zip(values, (1.0, rate_unit, rate_unit))):
        raise CLIError(
            f"--perturbation: each value must be at most 1 rad (q1) or {rate_unit:.4g} rad/s "
            f"(dq1, dq2: 1/T, T = sqrt(l/g) of this walker), got {values}"
        )
    return values


def _check(args):
    if args.model == "simplest":
        raise CLIError(
            "the simplest walking model takes no torques (its legs carry no mass): use a "
            "compass gait with light feet (--b 0 --mass-leg 1e-3)"
        )
    if args.model == "kneed" and args.family is not None:
        raise CLIError("--family is a compass-gait flag: the kneed walker has one family")
    if args.model == "compass" and args.family is None:
        args.family = "unstable"
    weights = _weights(args)
    args.perturbation_values = _read_perturbation(args)
    if args.torque_limit is not None:
        check_finite("--torque-limit", args.torque_limit)
        if args.torque_limit <= 0:
            raise CLIError(f"--torque-limit must be positive, got {args.torque_limit}")
    if args.steps < 1:
        raise CLIError(f"--steps must be >= 1, got {args.steps}")
    if args.basin_grid is not None and not args.basin:
        raise CLIError("--basin-grid sets the grid of --basin: give --basin too")
    if args.basin_grid is None:
        args.basin_grid = 15
    return weights


def _finite_or_none(obj):
    """Plain JSON values; every non-finite number becomes null."""
    import numpy as np

    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if hasattr(obj, "shape") or isinstance(obj, np.generic):
        arr = np.asarray(obj)
        if np.iscomplexobj(arr):
            arr = np.stack([arr.real, arr.imag], axis=-1)
        return _finite_or_none(arr.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def run_stabilize(args):
    given = _check(args)
    check_figure_file(args.png, "--png")
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .. import control
    from .._results import RESULTS, result_names
    from ..hybrid import FAST_CONFIG
    from ..hybrid._simulate import section_units
    from ..plotting import plot_stabilization

    kneed = args.model == "kneed"
    model = walker_from_args(args)
    q, r, q_jump = _scaled_weights(model, given)
    perturbation = _perturbation(args.perturbation_values, model)
    gait, _ = find_walker_gait(args, model, args.family or "stable")
    z = model.state_to_section(gait.x_plus)
    limit = math.inf if args.torque_limit is None else args.torque_limit
    st = control.stabilize(model, z, jnp.asarray(q), jnp.asarray(r), jnp.asarray(q_jump))
    st = eqx.tree_at(lambda s: s.feedback, st, control.with_torque_limit(st.feedback, limit))
    zn = np.asarray(z)
    out = {
        "result": result_names(st.result),
        "slope_deg": args.slope_deg,
        "family": args.family,
        "model": args.model,
        "gait": zn,
        "weights": {"q": q, "r": r if kneed else r[0], "q_jump": q_jump},
        "torques": list(_TORQUES[args.model]),
        "torque_limit": args.torque_limit,
        "open_loop_multipliers": st.open_loop_multipliers,
        "closed_loop_multipliers": st.closed_loop_multipliers,
        "closed_loop_multipliers_transverse": st.closed_loop_multipliers_transverse,
        "riccati_agreement": float(st.riccati_agreement),
        "max_gain": float(st.max_gain),
    }
    check = result_names(st.riccati_check.result)
    if check != "successful":
        out["riccati_agreement_reason"] = (
            f"the Hamiltonian check did not hold ({check}): {RESULTS[st.riccati_check.result]}"
        )
    ok = out["result"] == "successful"
    stable = bool(np.max(np.abs(np.asarray(st.closed_loop_multipliers))) < 1) and ok
    out["stable"] = stable
    if not ok:
        # nothing closed-loop was computed: no numbers that look like results
        out["reason"] = f"stabilization failed: {out['result']}: {RESULTS[st.result]}"
        failed = (
            "closed_loop_multipliers",
            "closed_loop_multipliers_transverse",
            "riccati_agreement",
            "max_gain",
        )
        for key in failed:
            out[key] = None
        out["null_fields"] = {key: out["reason"] for key in failed}
        if args.json:
            print_json(_finite_or_none(out))
        else:
            print(f"vhcjax stabilize: {out['reason']}", file=sys.stderr)
        return 1

    x0 = model.section_to_state(z + jnp.asarray(perturbation))
    # errors in the walker's own units: angles, and rates times T = sqrt(l/g)
    unit = np.asarray(section_units(model))
    size = float(np.max(np.asarray(perturbation) / unit))
    sim = control.simulate_closed_loop(model, x0, st.feedback, args.steps)
    zero = control.ZeroFeedback(len(_TORQUES[args.model]))
    passive = control.simulate_closed_loop(model, x0, zero, args.steps)

    def errors(s):
        zs = np.asarray(jax.vmap(model.state_to_section)(s.steps.x_plus))
        return np.max(np.abs(zs - zn) / unit, axis=1)

    err_c, err_p = errors(sim), errors(passive)
    out["simulation"] = {
        "perturbation": perturbation,
        "x0": x0,
        "x_final": sim.steps.x_plus[-1],
        "steps": args.steps,
        "result": result_names(sim.result),
        "steps_completed": int(sim.num_successful),
        "final_error": float(err_c[-1]),
        "max_abs_torque": float(np.max(sim.max_abs_torque)),
        "rms_torque_first_step": float(sim.rms_torque[0]),
        "passive_result": result_names(passive.result),
        "passive_final_error": float(err_p[-1]),
    }
    # a run that failed has no final error: say where it stopped instead
    for key, run, res in (
        ("final_error", sim, "result"),
        ("passive_final_error", passive, "passive_result"),
    ):
        done = int(run.num_successful)
        if done < args.steps:
            out["simulation"][key] = None
            out["simulation"][key + "_reason"] = (
                f"{out['simulation'][res]} after {done} of {args.steps} steps; "
                + ("x_final is the last state reached" if key == "final_error" else "")
            ).rstrip("; ")
    # the verdict is local (multipliers); the simulation says whether this perturbation
    # came back: a saturated torque or a start outside the basin may keep it away
    sim_out = out["simulation"]
    sim_out["recovered"] = bool(
        int(sim.num_successful) == args.steps and err_c[-1] <= max(0.1 * size, 1e-8)
    )
    if stable and not sim_out["recovered"]:
        done = int(sim.num_successful)
        how = (
            f"ended {sim_out['result']} after {done} steps"
            if done < args.steps
            else f"error {err_c[-1]:.3g} after {args.steps} steps"
        )
        rho = float(np.max(np.abs(np.asarray(st.closed_loop_multipliers))))
        saturated = args.torque_limit is not None and float(
            np.max(sim.max_abs_torque)
        ) >= args.torque_limit * (1 - 1e-9)
        if saturated:
            cause = f"the torque limit of {args.torque_limit:g} N m saturates the feedback"
        elif done == args.steps and err_c[-1] < size:
            cause = (
                f"the error is still decaying (closed-loop spectral radius {rho:.3g}): "
                "more --steps may show it recovered"
            )
        else:
            cause = "the perturbation may lie outside the closed-loop basin"
        sim_out["recovered_reason"] = (
            f"stable is the local verdict (closed-loop multipliers inside the unit circle), "
            f"but the simulation from the perturbed gait was not recovered ({how}): "
            f"{cause}"
        )
        warn(args, sim_out["recovered_reason"])
    basin_plot = None
    if args.basin:
        from ._analysed import in_walker_units

        half_widths = [0.05, in_walker_units(model, 0.3, "rate")]  # the thesis walker's
        kw = {
            "half_widths": tuple(half_widths),
            "shape": (args.basin_grid, args.basin_grid),
            "num_steps": 25,
            "tol": 1e-4,
            "torque_points": 8,
            "config": FAST_CONFIG,
        }
        bc = control.closed_loop_basin(model, st.feedback, z, **kw)
        bp = control.closed_loop_basin(model, zero, z, **kw)
        conv = np.asarray(bc.converged)
        tmax = np.asarray(bc.max_abs_torque)[conv]
        trms = np.asarray(bc.rms_torque)[conv]
        out["basin"] = {
            "axes": ["q1", "dq1"],
            "half_widths": half_widths,
            "grid": args.basin_grid,
            "passive_fraction": float(bp.fraction),
            "closed_loop_fraction": float(bc.fraction),
            "max_abs_torque": float(tmax.max()) if tmax.size else None,
            "rms_torque_first_step_max": float(trms.max()) if trms.size else None,
        }
        if not tmax.size:
            out["basin"]["reason"] = "no grid point converged with feedback"
        basin_plot = {
            "z_star": zn,
            "offsets_x": np.asarray(bc.offsets_x),
            "offsets_y": np.asarray(bc.offsets_y),
            "closed": conv,
            "passive": np.asarray(bp.converged),
        }
    else:
        out["basin"] = {
            "passive_fraction": None,
            "closed_loop_fraction": None,
            "reason": "not computed (run with --basin)",
        }
    if args.png:
        lim = (
            "no torque limit"
            if args.torque_limit is None
            else f"torque limit {args.torque_limit:g} N m"
        )
        weights = f"Q = diag({','.join(f'{v:g}' for v in q)}), R = {','.join(f'{v:g}' for v in r)}"
        case = (
            f"Kneed walker, gait at {args.slope_deg:g} deg, stabilized by hip and knee torques"
            if kneed
            else f"Compass gait, {args.family} period-1 gait at {args.slope_deg:g} deg, "
            "stabilized by a hip torque"
        )
        shown_p = ", ".join(f"{v:.3g}" for v in perturbation)
        title = f"{case} ({weights}, {lim}); perturbation ({shown_p}) rad, rad/s, rad/s"
        s_grid = np.asarray(st.system.domains[0].s if kneed else st.system.s)
        with figure_output(args.png) as fh:
            plot_stabilization(
                fh,
                title,
                s_grid,
                np.asarray(st.riccati.K),
                err_c,
                err_p,
                basin_plot,
                coordinates=_COORDINATES[args.model],
                torques=_TORQUES[args.model],
                reset_names=("knee strike",) if kneed else None,
            )
    if args.json:
        print_json(_finite_or_none(out))
    else:
        _print_stabilize(args, out, zn, check)
    return 0 if ok else 1


def _print_stabilize(args, out, zn, check):
    """The text output of `vhcjax stabilize`: the summary `out` (its JSON) in words."""
    import numpy as np

    kneed = args.model == "kneed"
    what = "kneed-walker" if kneed else args.family
    torques = " and ".join(_TORQUES[args.model])

    def moduli(key):
        ev = np.asarray(out[key])
        words = ", ".join(complex_words(v) for v in ev)
        return f"{words} (largest modulus {np.max(np.abs(ev)):.4g})"

    print(f"{what} gait at slope {args.slope_deg:g} deg, post-impact state {section_words(zn)}")
    print(f"multipliers without feedback: {moduli('open_loop_multipliers')}")
    print(
        f"multipliers with {torques} torque feedback (Poincare-map Jacobian): "
        f"{moduli('closed_loop_multipliers')}"
    )
    print(
        f"  the same by the transverse linearization: "
        f"{moduli('closed_loop_multipliers_transverse')}"
    )
    agreement = (
        f"its two computations agree to {out['riccati_agreement']:.1e}"
        if check == "successful"
        else out["riccati_agreement_reason"]
    )
    print(
        f"periodic Riccati solution: {agreement}; largest feedback gain "
        f"{out['max_gain']:.4g} (N m/rad or N m s/rad)"
    )
    print(f"verdict with feedback: {'stable' if out['stable'] else 'unstable'}")
    s = out["simulation"]

    def end(key):
        if s[key] is None:
            return s[key + "_reason"].split(";")[0]
        return f"error {s[key]:.2e} after {args.steps} steps"

    p = s["perturbation"]
    print(
        f"from the gait's post-impact state + ({p[0]:.3g} rad, {p[1]:.3g} rad/s, "
        f"{p[2]:.3g} rad/s) on (q1, dq1, dq2) (error: largest deviation from the gait "
        "after impact in the walker's units: rad, and rad/s times sqrt(l/g)):"
    )
    print(f"  with feedback: {end('final_error')} (largest torque {s['max_abs_torque']:.4g} N m)")
    print(f"  without feedback: {end('passive_final_error')}")
    if args.basin:
        b = out["basin"]
        print(
            f"basin slice in (q1, dq1), {args.basin_grid} x {args.basin_grid} starts within "
            f"+-{b['half_widths'][0]:g} rad and +-{b['half_widths'][1]:.4g} rad/s of the gait: "
            "converging fraction "
            f"{b['passive_fraction']:.3f} without feedback, {b['closed_loop_fraction']:.3f} "
            "with feedback"
        )
