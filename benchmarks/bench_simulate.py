"""Batched compass-gait simulation (vmap + jit) against a scipy `solve_ivp` loop.

N walkers x K steps from random starts around the stable 3-degree gait. vhcjax runs them
with `simulate_batch` (one jitted, vmapped program; with `--cpu-devices N` the batch is
split over N CPU devices, one per core, by `jax.sharding`); the baseline
(`scipy_reference.py`: thesis closed-form equations, `solve_ivp` with terminal events,
numpy impact map) loops over walkers and
steps in Python, at the same rtol/atol, on a subset of the walkers (its cost is linear in
the number of walker-steps). Compile time is reported separately from run time (best of
`--repeats`). Both must agree on the step periods. The floating-point work of a
walker-step and the share of the CPU's peak rate it reaches are counted as in
`roofline.py` (right-hand side only: a lower bound).

    python benchmarks/bench_simulate.py [--solver dopri8] [--cpu-devices 2] [--trig plain]
        [--quick] [--json OUT]
"""

import argparse
import json
import math
import os

# Compile times are those of a first run: without the persistent compilation cache.
os.environ.setdefault("VHCJAX_CACHE_DIR", "off")
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import roofline  # noqa: E402
import scipy_reference as ref  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--walkers", type=int, default=1000, help="batch size N (default 1000)")
    ap.add_argument("--steps", type=int, default=10, help="steps per walker K (default 10)")
    ap.add_argument("--rtol", type=float, default=1e-8, help="rtol = atol of both (1e-8)")
    ap.add_argument("--solver", default="tsit5", help="vhcjax solver: tsit5, dopri5, dopri8")
    ap.add_argument("--max-steps", type=int, default=1024, help="ODE steps per walker step")
    ap.add_argument("--scipy-method", default="DOP853", help="solve_ivp method (DOP853)")
    ap.add_argument("--scipy-walkers", type=int, default=30, help="walkers run by scipy (30)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spread", type=float, default=0.02, help="random start spread (0.02)")
    ap.add_argument(
        "--cpu-devices",
        type=int,
        default=1,
        help="split the batch over this many CPU devices (XLA host devices)",
    )
    ap.add_argument(
        "--trig",
        choices=("library", "plain"),
        default="library",
        help="sin/cos in the model: the library's (each angle's pair computed once, see "
        "vhcjax.trig) or plain jnp.sin/jnp.cos, to measure what that buys (default library)",
    )
    ap.add_argument("--quick", action="store_true", help="small sizes (N=64, K=3)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON")
    args = ap.parse_args(argv)
    if args.quick:
        args.walkers, args.steps, args.scipy_walkers, args.repeats = 64, 3, 5, 1

    if args.cpu_devices > 1:  # must be set before JAX starts its CPU backend
        os.environ["XLA_FLAGS"] = (
            os.environ.get("XLA_FLAGS", "")
            + f" --xla_force_host_platform_device_count={args.cpu_devices}"
        )
    import jax
    import jax.numpy as jnp

    import vhcjax as vj

    if args.trig == "plain":  # the same model, traced with plain jnp.sin/jnp.cos
        vj.trig.sin_cos = lambda x: (jnp.sin(x), jnp.cos(x))
        os.environ["VHCJAX_PROGRAMS"] = "off"  # never a stored program of the library's

    psi = math.radians(3.0)
    rng = np.random.default_rng(0)
    z = np.array([0.2186688, -1.09238359, -0.37737395])
    zs = z + args.spread * rng.normal(size=(args.walkers, 3)) * np.array([0.2, 1.0, 1.0])
    x0 = np.stack([zs[:, 0], -zs[:, 0] - 2 * psi, zs[:, 1], zs[:, 2]], axis=1)

    model = vj.CompassGait(psi=psi)
    config = vj.SolverConfig(
        rtol=args.rtol, atol=args.rtol, max_steps=args.max_steps, solver=args.solver
    )
    X = jnp.asarray(x0)

    t = time.perf_counter()
    sim = jax.block_until_ready(vj.simulate_batch(model, X, args.steps, config=config))
    compile_s = time.perf_counter() - t  # compile + first run
    times = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        sim = jax.block_until_ready(vj.simulate_batch(model, X, args.steps, config=config))
        times.append(time.perf_counter() - t)
    run_s = min(times)
    compile_s -= run_s
    ok = np.asarray(sim.num_successful)
    walker_steps = int(ok.sum())
    jax_rate = walker_steps / run_s

    # the floating-point work: right-hand-side flops x evaluations per walker-step
    rhs_flops = roofline.rhs_flops(model)
    evals = roofline.rhs_evaluations(model, X[:64], min(args.steps, 5), config)
    rhs_gflops = jax_rate * evals * rhs_flops / 1e9
    peak = roofline.cpu_peak_gflops() if jax.default_backend() == "cpu" else None

    par = ref.Params(psi=psi)
    nsc = min(args.scipy_walkers, args.walkers)
    t = time.perf_counter()
    sc_steps, max_dT = 0, 0.0
    for i in range(nsc):
        out = ref.simulate(
            par, x0[i], args.steps, rtol=args.rtol, atol=args.rtol, method=args.scipy_method
        )
        good = [s for s in out if s.ok]
        sc_steps += len(good)
        if good and len(good) == int(ok[i]):
            dT = np.abs(
                np.array([s.period for s in good]) - np.asarray(sim.steps.period[i, : len(good)])
            )
            max_dT = max(max_dT, float(dT.max()))
    sc_s = time.perf_counter() - t
    sc_rate = sc_steps / sc_s

    res = {
        "device": str(jax.devices()[0].device_kind),
        "num_devices": len(jax.devices()),
        "platform": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "walkers": args.walkers,
        "steps": args.steps,
        "rtol": args.rtol,
        "solver": args.solver,
        "trig": args.trig,
        "scipy_method": args.scipy_method,
        "compile_s": compile_s,
        "run_s": run_s,
        "success_rate": float(np.mean(ok == args.steps)),
        "vhcjax_walker_steps_per_s": jax_rate,
        "scipy_walkers": nsc,
        "scipy_s": sc_s,
        "scipy_walker_steps_per_s": sc_rate,
        "speedup": jax_rate / sc_rate,
        "max_period_difference_s": max_dT,
        "rhs_flops": rhs_flops,
        "rhs_evaluations_per_walker_step": evals,
        "rhs_gflops": rhs_gflops,
        "peak_gflops": peak,
        "fraction_of_peak": None if peak is None else rhs_gflops / peak,
    }
    print(
        f"vhcjax  {args.walkers} walkers x {args.steps} steps on {len(jax.devices())} "
        f"{jax.devices()[0].platform} device(s) ({args.solver}, rtol=atol="
        f"{args.rtol:g}): {run_s:.3f} s, {jax_rate:,.0f} walker-steps/s "
        f"(compile {compile_s:.1f} s, success {res['success_rate']:.1%})"
    )
    print(
        f"scipy   {nsc} walkers x {args.steps} steps ({args.scipy_method}): {sc_s:.3f} s, "
        f"{sc_rate:,.0f} walker-steps/s"
    )
    print(f"speedup {res['speedup']:.1f}x   max |period difference| {max_dT:.2e} s")
    share = "-" if peak is None else f"{rhs_gflops / peak:.1%} of the CPU's {peak:.0f} GFLOP/s"
    print(
        f"work    {evals:.0f} right-hand-side evaluations per walker-step x {rhs_flops:.0f} "
        f"flops = {rhs_gflops:.2f} GFLOP/s ({share})"
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)
    return res


if __name__ == "__main__":
    main()
