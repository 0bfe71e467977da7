"""`vhcjax simulate`: walk the compass gait from a given state, step by step."""

import math
import os

from .._io import atomic_open, output_target
from ._common import (
    STATE,
    CLIError,
    add_model_choice,
    add_model_flags,
    check_output_dir,
    check_output_file,
    check_state,
    count,
    describe,
    figure_output,
    print_json,
    shown_path,
    walker_from_args,
)

THESIS_7_5 = (0.218669, -0.323389, -1.092386, -0.377377)  # thesis (7.5), 3 degrees
MAX_STEPS = 100_000
DENSE_POINTS = 40


def register(subparsers):
    p = subparsers.add_parser(
        "simulate",
        help="simulate the passive compass gait (or kneed walker) for a number of steps",
        description="Simulate the passive compass-gait biped (or, with --model kneed, the "
        "kneed walker) from a post-impact state: swing phases integrated to the exact heel "
        "strike (diffrax event), impact map, leg swap. "
        "Angles in radians (except --slope-deg), velocities in rad/s.",
    )
    add_model_flags(p)
    add_model_choice(p)
    p.add_argument(
        "--x0",
        type=STATE,
        nargs="+",
        metavar="X",
        default=None,
        help="initial state: the joint angles (rad, from the vertical, counter-clockwise) "
        "and their rates (rad/s): Q1 Q2 DQ1 DQ2 for the compass gait (stance and swing "
        "leg; default: thesis (7.5)), Q1 Q2 Q3 DQ1 DQ2 DQ3 for the kneed walker (stance "
        "leg, swing thigh, swing shank; default: its gait at 0.0504 rad)",
    )
    p.add_argument(
        "--steps",
        type=count(1, MAX_STEPS),
        default=20,
        help=f"number of steps, 1 to {MAX_STEPS} (default 20)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object {result, steps: [{x_plus, x_minus, period, "
        "result}, ...]} instead of a table",
    )
    p.add_argument("--animate", metavar="GIF", help="save an animation of the walk as a GIF")
    p.add_argument(
        "--plots", metavar="DIR", help="save states.png, phase.png and periods.png into DIR"
    )
    p.set_defaults(func=run)
    return p


def _check_start(model, x0):
    """The hip must start above the slope, and the swing foot must not start below it
    once the swing leg is ahead of the stance leg (where a heel strike would already
    have happened). A swing foot below the slope *behind* the stance leg is the
    mid-swing scuffing the model ignores (thesis 3.2): the thesis's own perturbed state
    (7.7) starts with it 5 mm below."""
    import jax.numpy as jnp

    q = jnp.asarray(x0[:2])
    tol = 1e-9 * float(model.l)
    if float(model.hip_height(q)) <= 0:
        raise CLIError(f"--x0 puts the hip below the slope (q1 = {x0[0]} rad)")
    if x0[1] > x0[0] and float(model.swing_foot_height(q)) < -tol:
        raise CLIError(
            f"--x0 puts the swing foot below the slope, ahead of the stance leg "
            f"(q1 = {x0[0]}, q2 = {x0[1]} rad); a post-impact state has "
            "q2 = -q1 - 2 psi"
        )


def _thesis_start(model):
    """Thesis (7.5), its rates in the same proportion to `model`'s time unit."""
    from ._analysed import in_walker_units

    q1, q2, dq1, dq2 = THESIS_7_5
    return [q1, q2, in_walker_units(model, dq1, "rate"), in_walker_units(model, dq2, "rate")]


def _reference_start(model):
    """The post-impact state of the model's reference gait (the kneed walker's at 0.0504
    rad, the simplest walker's at 0.009 rad), moved to the slope of `model` (the same
    section point)."""
    import jax.numpy as jnp

    from ..hybrid._simulate import section_units

    ref, z = model.reference_gait()
    z = jnp.asarray(z) * section_units(model) / section_units(ref)  # rates in its units
    return [float(v) for v in model.section_to_state(z)]


def steps_as_dicts(sim):
    """Per-step records up to and including the first failure (`x_plus` is None there)."""
    import numpy as np

    from .._results import result_names

    names = result_names(sim.steps.result)
    k = int(sim.num_successful)
    n = min(len(names), k + 1)
    xp, xm = np.asarray(sim.steps.x_plus), np.asarray(sim.steps.x_minus)
    T = np.asarray(sim.steps.period)
    out = []
    for i in range(n):
        good = names[i] == "successful"
        out.append(
            {
                "x_plus": xp[i].tolist() if good else None,
                "x_minus": xm[i].tolist(),
                "period": float(T[i]),
                "result": names[i],
            }
        )
    return out


def run(args):
    import jax.numpy as jnp

    from .._results import result_names
    from ..hybrid import simulate

    model = walker_from_args(args)
    if args.x0 is None:
        args.x0 = _thesis_start(model) if args.model == "compass" else _reference_start(model)
    if len(args.x0) != 2 * model.n_dof:
        names = "Q1 Q2 DQ1 DQ2" if model.n_dof == 2 else "Q1 Q2 Q3 DQ1 DQ2 DQ3"
        raise CLIError(f"--x0 takes {2 * model.n_dof} numbers ({names}) here, got {len(args.x0)}")
    n = model.n_dof
    check_state(model, args.x0, ["angle"] * n + ["rate"] * n, "--x0")
    if hasattr(model, "hip_height"):  # the compass gait
        _check_start(model, args.x0)
    elif bool(model.fallen(jnp.asarray(args.x0[:3], float))):
        raise CLIError(f"--x0 is a fallen kneed walker (angles {args.x0[:3]} rad)")
    if args.animate is not None:  # a GIF: a file named .gif, or a pipe or device
        suffix = os.path.splitext(args.animate)[1].lower()
        if suffix != ".gif" and (suffix or output_target(args.animate).how == "replace"):
            raise CLIError(f"--animate needs a .gif file name, got {shown_path(args.animate)}")
    check_output_file(args.animate, "--animate")
    check_output_dir(args.plots, "--plots")  # created now, before the work

    dense = DENSE_POINTS if (args.plots or args.animate) else 0
    sim = simulate(model, jnp.asarray(args.x0, float), args.steps, dense_points=dense)
    result = result_names(sim.result)
    steps = steps_as_dicts(sim)

    if args.plots:
        from .. import plotting as plotting

        if int(sim.num_successful) > 0:
            start = ", ".join(f"{v:.4g}" for v in args.x0)
            case = f"{describe(args)}, from x0 = ({start})"
            for name, plot in (
                ("states.png", plotting.plot_states),
                ("phase.png", plotting.plot_phase_portrait),
                ("periods.png", plotting.plot_step_periods),
            ):
                with figure_output(os.path.join(args.plots, name)) as fh:
                    plot(sim, path=fh, case=case)
    if args.animate:
        from .. import plotting as plotting

        if int(sim.num_successful) > 0:
            with atomic_open(args.animate, "wb") as fh:
                plotting.animate(sim, model, fh)

    if args.json:
        print_json({"result": result, "num_successful": int(sim.num_successful), "steps": steps})
    else:
        n = model.n_dof
        names = [f"q{j + 1}" for j in range(n)] + [f"dq{j + 1}" for j in range(n)]
        units = ["rad"] * n + ["rad/s"] * n
        start = ", ".join(f"{h} {v:.10g} {u}" for h, v, u in zip(names, args.x0, units))
        print(f"slope {math.degrees(float(model.psi)):g} deg, start: {start}")
        print(
            "state just after each impact (angles in rad, angular velocities in rad/s; "
            "for a step that failed, the last state reached):"
        )
        print(
            f"{'step':>4} {'period (s)':>11}  " + " ".join(f"{h:>10}" for h in names) + "  result"
        )
        for i, s in enumerate(steps, 1):
            x = s["x_plus"] if s["x_plus"] is not None else s["x_minus"]
            print(
                f"{i:>4} {s['period']:>11.8f}  "
                + " ".join(f"{v:>10.6f}" for v in x)
                + f"  {s['result']}"
            )
        print(f"result: {result} ({int(sim.num_successful)}/{args.steps} steps)")
        if int(sim.num_successful) == 0 and (args.plots or args.animate):
            print("no completed step: no figures written")
    return 0
