"""`vhcjax stabilize`: hold a (possibly unstable) gait by transverse-linearization feedback."""

import math

from ._common import (
    POSITIVE,
    CLIError,
    ComputationFailed,
    add_model_flags,
    check_finite,
    check_output_file,
    count,
    model_from_args,
    number,
    print_json,
)

FAMILIES = ("unstable", "stable")


def register(subparsers):
    p = subparsers.add_parser(
        "stabilize",
        help="stabilize a gait with a hip torque (transverse-linearization LQR)",
        description="Period-1 gait of the compass gait at the slope (family 'unstable', or "
        "'stable': the symmetric gait, unstable through a flip past its period doubling), "
        "its transverse linearization with a hip torque, the periodic hybrid Riccati "
        "solution (two ways), the closed-loop multipliers (two ways), a closed-loop "
        "simulation from the perturbed gait and, with --basin, basin slices with and "
        "without feedback.",
    )
    add_model_flags(p)
    p.add_argument(
        "--family", choices=FAMILIES, default="unstable", help="gait family (default unstable)"
    )
    p.add_argument(
        "--model",
        choices=("compass", "kneed"),
        default="compass",
        help="walker (default compass; kneed: not supported, multi-domain)",
    )
    p.add_argument(
        "--q",
        default="1,1,1",
        metavar="Q1,Q2,Q3",
        help="diagonal LQR weights on (delta q2, delta dq1, delta dq2) per second, "
        ">= 0 (default 1,1,1); also the jump weight",
    )
    p.add_argument("--r", type=POSITIVE, default=1.0, help="LQR weight on the torque, > 0")
    p.add_argument(
        "--torque-limit",
        type=POSITIVE,
        default=None,
        metavar="NM",
        help="saturation of the hip torque in N m, > 0 (default: none)",
    )
    p.add_argument(
        "--perturbation",
        type=number(float, lo=0.0, hi=1.0),
        default=1e-2,
        metavar="D",
        help="added to every post-impact section coordinate for the simulation "
        "(rad, rad/s; default 0.01)",
    )
    p.add_argument(
        "--steps", type=count(1, 10_000), default=30, help="simulated steps (default 30)"
    )
    p.add_argument(
        "--basin", action="store_true", help="basin slices over (q1, dq1) with and without feedback"
    )
    p.add_argument(
        "--basin-grid", type=count(2, 400), default=15, help="basin grid points per axis"
    )
    p.add_argument("--json", action="store_true", help="print the results as one JSON object")
    p.add_argument(
        "--png",
        metavar="FILE",
        help="save gains vs phase, recovery, basin with and without feedback",
    )
    p.set_defaults(func=run_stabilize)


def _weights(args):
    try:
        q = [float(v) for v in args.q.split(",")]
    except ValueError:
        raise CLIError(f"--q must be three comma-separated numbers, got {args.q!r}") from None
    if len(q) != 3:
        raise CLIError(f"--q needs 3 weights (delta q2, delta dq1, delta dq2), got {len(q)}")
    check_finite("--q", *q)
    if min(q) < 0 or max(q) == 0:
        raise CLIError(f"--q must be >= 0 and not all zero, got {args.q!r}")
    check_finite("--r", args.r)
    if args.r <= 0:
        raise CLIError(f"--r must be positive, got {args.r}")
    return q


def _check(args):
    q = _weights(args)
    if args.torque_limit is not None:
        check_finite("--torque-limit", args.torque_limit)
        if args.torque_limit <= 0:
            raise CLIError(f"--torque-limit must be positive, got {args.torque_limit}")
    check_finite("--perturbation", args.perturbation)
    if args.perturbation < 0:
        raise CLIError(f"--perturbation must be >= 0, got {args.perturbation}")
    if args.steps < 1:
        raise CLIError(f"--steps must be >= 1, got {args.steps}")
    if args.basin_grid < 2:
        raise CLIError(f"--basin-grid must be >= 2, got {args.basin_grid}")
    if args.model == "kneed":
        raise CLIError(
            "the kneed walker is a multi-domain model: closed-loop stabilization "
            "is implemented for single-domain walkers (--model compass) only"
        )
    return q


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
    q = _check(args)
    check_output_file(args.png, "--png")
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    from .. import control
    from .._results import result_names
    from ..hybrid import FAST_CONFIG
    from ..plotting import plot_stabilization
    from ..stability import period1_family

    model = model_from_args(args)
    psi = math.radians(args.slope_deg)
    fam = period1_family([psi], args.family, model=model)
    if result_names(fam.result)[0] != "successful":
        raise ComputationFailed(
            f"no {args.family} period-1 gait found at {args.slope_deg} deg "
            f"({result_names(fam.result)[0]})"
        )
    z = fam.z[0]
    limit = math.inf if args.torque_limit is None else args.torque_limit
    st = control.stabilize(model, z, jnp.asarray(q), jnp.asarray([args.r]))
    st = eqx.tree_at(lambda s: s.feedback, st, control.with_torque_limit(st.feedback, limit))
    zn = np.asarray(z)
    out = {
        "result": result_names(st.result),
        "slope_deg": args.slope_deg,
        "family": args.family,
        "model": args.model,
        "gait": zn,
        "weights": {"q": q, "r": args.r, "q_jump": q},
        "torque_limit": args.torque_limit,
        "open_loop_multipliers": st.open_loop_multipliers,
        "closed_loop_multipliers": st.closed_loop_multipliers,
        "closed_loop_multipliers_transverse": st.closed_loop_multipliers_transverse,
        "riccati_agreement": float(st.riccati_agreement),
        "max_gain": float(st.max_gain),
    }
    ok = out["result"] == "successful"
    stable = bool(np.max(np.abs(np.asarray(st.closed_loop_multipliers))) < 1) and ok
    out["stable"] = stable
    if not ok:
        out["reason"] = f"stabilization failed: {out['result']}"

    x0 = model.section_to_state(z + args.perturbation)
    sim = control.simulate_closed_loop(model, x0, st.feedback, args.steps)
    passive = control.simulate_closed_loop(model, x0, control.ZeroFeedback(), args.steps)

    def errors(s):
        zs = np.asarray(jax.vmap(model.state_to_section)(s.steps.x_plus))
        return np.max(np.abs(zs - zn), axis=1)

    err_c, err_p = errors(sim), errors(passive)
    out["simulation"] = {
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
    basin_plot = None
    if args.basin:
        kw = {
            "half_widths": (0.05, 0.3),
            "shape": (args.basin_grid, args.basin_grid),
            "num_steps": 25,
            "tol": 1e-4,
            "torque_points": 8,
            "config": FAST_CONFIG,
        }
        bc = control.closed_loop_basin(model, st.feedback, z, **kw)
        bp = control.closed_loop_basin(model, control.ZeroFeedback(), z, **kw)
        conv = np.asarray(bc.converged)
        tmax = np.asarray(bc.max_abs_torque)[conv]
        trms = np.asarray(bc.rms_torque)[conv]
        out["basin"] = {
            "axes": ["q1", "dq1"],
            "half_widths": [0.05, 0.3],
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
        title = (
            f"Compass gait, {args.family} period-1 gait at {args.slope_deg:g} deg, "
            f"stabilized by a hip torque (Q = diag({args.q}), R = {args.r:g}, {lim}); "
            f"perturbation {args.perturbation:g}"
        )
        plot_stabilization(
            args.png,
            title,
            np.asarray(st.system.s),
            np.asarray(st.riccati.K),
            err_c,
            err_p,
            basin_plot,
        )
    if args.json:
        print_json(_finite_or_none(out))
    else:
        fmt = lambda ev: ", ".join(f"{complex(v):.6g}" for v in np.asarray(ev))
        print(f"{args.family} gait at {args.slope_deg:g} deg: z = {np.round(zn, 8).tolist()}")
        print(f"open-loop multipliers:   {fmt(st.open_loop_multipliers)}")
        print(f"closed-loop multipliers: {fmt(st.closed_loop_multipliers)} (Poincare map)")
        print(f"                         {fmt(st.closed_loop_multipliers_transverse)} (transverse)")
        print(
            f"Riccati two ways agree to {float(st.riccati_agreement):.2e}; max gain "
            f"{float(st.max_gain):.4g}; stable: {stable}"
        )
        s = out["simulation"]

        def end(key):
            if s[key] is None:
                return s[key + "_reason"].split(";")[0]
            return f"error after {args.steps} steps {s[key]:.3e}"

        print(
            f"from +{args.perturbation:g}: {end('final_error')} with feedback (max torque "
            f"{s['max_abs_torque']:.4g} N m); {end('passive_final_error')} passive"
        )
        if args.basin:
            b = out["basin"]
            print(
                f"basin slice (q1, dq1): passive {b['passive_fraction']:.3f}, "
                f"with feedback {b['closed_loop_fraction']:.3f}"
            )
    return 0 if ok else 1
