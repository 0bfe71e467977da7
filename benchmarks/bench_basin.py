"""Basin-of-attraction slice: vhcjax (batched, jitted, chunked) against a scipy loop.

A `G x G` grid of post-impact perturbations of the stable 3-degree gait in the
(q1, dq1) plane, at most `K` steps per point, each point classified as converging
(within 1e-4 of the gait), falling, another cycle or undecided. vhcjax runs
`vhcjax.basin_slice` (chunks of `--chunk`, a chunk stops when all its members are
decided). The baseline (`scipy_reference.py`: closed-form equations, `solve_ivp` with
terminal events, the same rtol = atol and the same stopping rule) classifies a random
sample of the grid points; its cost per walker-step is extrapolated to the whole grid.
Both classifications must agree on the sampled points. Compile time is reported
separately (a first call on one chunk).

    python benchmarks/bench_basin.py [--quick] [--json OUT]
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
import scipy_reference as ref  # noqa: E402

SEED = (0.2186688, -1.09238359, -0.37737395)


def scipy_classify(par, x0, x_star, num_steps, tol, rtol):
    """Same rule as vhcjax: converged when within tol, fell on a failed step."""
    x = np.asarray(x0, float)
    if np.max(np.abs(x - x_star)) < tol:
        return 0, 0
    for k in range(num_steps):
        s = ref.step(par, x, rtol=rtol, atol=rtol)
        if not s.ok:
            return 1, k + 1
        x = s.x_plus
        if np.max(np.abs(x - x_star)) < tol:
            return 0, k + 1
    return 3, num_steps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=200, help="grid points per axis (200)")
    ap.add_argument("--steps", type=int, default=50, help="steps per point at most (50)")
    ap.add_argument("--chunk", type=int, default=2048, help="vhcjax batch size (2048)")
    ap.add_argument("--rtol", type=float, default=1e-8, help="rtol = atol of both (1e-8)")
    ap.add_argument("--scipy-points", type=int, default=40, help="points run by scipy (40)")
    ap.add_argument("--quick", action="store_true", help="small sizes (grid 24, chunk 256)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON")
    args = ap.parse_args(argv)
    if args.quick:
        args.grid, args.chunk, args.scipy_points = 24, 256, 8

    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import vhcjax as vj
    from vhcjax.hybrid._poincare import fixed_point
    from vhcjax.hybrid._simulate import SolverConfig
    from vhcjax.robustness._basin import _recover_chunk

    model = vj.CompassGait()
    fp = eqx.filter_jit(fixed_point)(model, jnp.asarray(SEED))
    z_star = np.asarray(fp.z)
    x_star = np.asarray(fp.x0)
    cfg = SolverConfig(rtol=args.rtol, atol=args.rtol, max_steps=1024)
    hw = (0.08, 0.4)

    # compile once on a chunk of gait points (decided at once: no simulation cost)
    t0 = time.perf_counter()
    jax.block_until_ready(
        _recover_chunk(
            model,
            jnp.asarray(np.repeat(z_star[None], args.chunk, 0)),
            jnp.asarray(z_star),
            args.steps,
            1e-4,
            cfg,
        )
    )
    from vhcjax.robustness._gait_check import require_gait

    require_gait(model, z_star, "basin_slice")  # its one-step program, compiled here too
    compile_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    b = vj.basin_slice(
        model,
        z_star,
        axes=(0, 1),
        half_widths=hw,
        shape=(args.grid, args.grid),
        num_steps=args.steps,
        chunk=args.chunk,
        config=cfg,
    )
    run_s = time.perf_counter() - t0
    taken = np.where(b.label >= 2, args.steps, np.maximum(b.steps, 0))
    walker_steps = int(taken.sum())

    # scipy on a random sample of the same grid points
    par = ref.Params(psi=math.radians(3.0))
    rng = np.random.default_rng(0)
    idx = rng.choice(args.grid * args.grid, args.scipy_points, replace=False)
    agree, sp_steps = 0, 0
    t0 = time.perf_counter()
    for i in idx:
        iy, ix = divmod(int(i), args.grid)
        z = z_star.copy()
        z[0] += b.offsets_x[ix]
        z[1] += b.offsets_y[iy]
        x0 = np.array([z[0], -z[0] - 2 * par.psi, z[1], z[2]])
        lab, k = scipy_classify(par, x0, x_star, args.steps, 1e-4, args.rtol)
        sp_steps += k
        agree += int(lab == b.label[iy, ix])
    sp_s = time.perf_counter() - t0
    sp_rate = sp_steps / sp_s if sp_s > 0 else float("nan")
    out = {
        "benchmark": "basin_slice",
        "grid": [args.grid, args.grid],
        "max_steps": args.steps,
        "chunk": args.chunk,
        "rtol": args.rtol,
        "device": str(jax.devices()[0]),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "vhcjax": {
            "compile_s": compile_s,
            "run_s": run_s,
            "walker_steps": walker_steps,
            "walker_steps_per_s": walker_steps / run_s,
            "points_per_s": args.grid**2 / run_s,
            "fraction_converging": b.fraction,
        },
        "scipy": {
            "points": int(args.scipy_points),
            "walker_steps": sp_steps,
            "run_s": sp_s,
            "walker_steps_per_s": sp_rate,
            "estimated_full_grid_s": walker_steps / sp_rate if sp_rate > 0 else None,
            "label_agreement": agree / args.scipy_points,
        },
    }
    out["speedup"] = out["vhcjax"]["walker_steps_per_s"] / sp_rate
    print(
        f"vhcjax: {args.grid}x{args.grid} slice, {walker_steps} walker-steps in {run_s:.1f} s "
        f"({walker_steps / run_s:,.0f} walker-steps/s; compile {compile_s:.1f} s)"
    )
    print(
        f"scipy:  {sp_rate:,.0f} walker-steps/s on {args.scipy_points} points -> full grid "
        f"~{walker_steps / sp_rate:.0f} s; labels agree on {agree}/{args.scipy_points}"
    )
    print(f"speedup {out['speedup']:.1f}x")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
