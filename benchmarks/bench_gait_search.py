"""Batched gait search (vhcjax, jit + vmap) against scipy (`solve_ivp` + `fsolve`).

B gaits (B = 1, 10, 100, 1000) at B slopes spread over 2.5-3.5 degrees, from the
thesis seed (7.2), stable family; VHC search (Problem 1) and shooting (Problem 2). The
baseline (`scipy_gait.py`: thesis closed forms, `solve_ivp` DOP853, `fsolve`, same ODE
tolerances) solves the same problems one by one on at most `--scipy-max` members (its cost
is linear in B); throughput is gaits per second of run time, compile time reported
separately (first call minus a warm call, JAX's caches cleared before each entry).

    python benchmarks/bench_gait_search.py [--cpu-devices 2] [--scipy-procs 2] [--quick] [--json OUT]
    python benchmarks/bench_gait_search.py --solvers newton,optimistix --sizes 1000

`--solvers` compares the library's batched Newton (one loop over the whole batch, each
member stopping at its own convergence; the default) with optimistix's Newton under
`vmap` (`find_gaits(..., solver="optimistix")`), the same problems in the same run.

On a CPU vhcjax runs the chunks of a large batch on all cores at once; the plain scipy
baseline runs on one. `--scipy-procs N` also times scipy with its members split over N
processes, for a comparison on the same cores.
"""

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scipy_gait  # noqa: E402
import scipy_reference as ref  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1,10,100,1000")
    ap.add_argument("--methods", default="vhc,shooting")
    ap.add_argument("--solvers", default="newton", help="newton (default), optimistix, or both")
    ap.add_argument("--scipy-max", type=int, default=20, help="members solved by scipy (20)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="B = 1, 10 only; 3 scipy members")
    ap.add_argument(
        "--cpu-devices",
        type=int,
        default=1,
        help="split each batch over this many CPU devices (XLA host devices)",
    )
    ap.add_argument(
        "--scipy-procs",
        type=int,
        default=1,
        help="also time scipy on this many processes at once (its members "
        "split over a process pool), for a same-cores comparison",
    )
    ap.add_argument("--json", metavar="OUT")
    args = ap.parse_args(argv)
    if args.cpu_devices > 1:  # must be set before JAX starts its CPU backend
        os.environ["XLA_FLAGS"] = (
            os.environ.get("XLA_FLAGS", "")
            + f" --xla_force_host_platform_device_count={args.cpu_devices}"
        )
    # Compile times are those of a first run: without the persistent compilation cache.
    os.environ["VHCJAX_CACHE_DIR"] = "off"
    if args.quick:
        args.sizes, args.scipy_max, args.repeats = "1,10", 3, 1

    import jax
    import jax.numpy as jnp

    import vhcjax as vj
    from vhcjax import gait as G

    sizes = [int(s) for s in args.sizes.split(",")]
    pool = None
    if args.scipy_procs > 1:  # started (and scipy imported) before any timing
        import multiprocessing

        pool = multiprocessing.get_context("spawn").Pool(args.scipy_procs)
        pool.starmap(_scipy_one, [("vhc", math.radians(3.0), (0.20, -1.0))] * args.scipy_procs)
    rows = []
    model = vj.CompassGait()
    cases = [
        (m, s, B) for m in args.methods.split(",") for s in args.solvers.split(",") for B in sizes
    ]
    for method, solver, B in cases:
        deg = np.linspace(2.5, 3.5, B) if B > 1 else np.array([3.0])
        psi = np.radians(deg)
        seeds = np.tile([0.20, -1.0], (B, 1))
        if method == "shooting":
            seeds = np.stack(
                [
                    np.asarray(G.complete_guess(vj.CompassGait(psi=p), s, "stable"))
                    for p, s in zip(psi[:1], seeds[:1])
                ]
            )
            seeds = np.tile(seeds[0], (B, 1))

        def run():
            g = G.find_gaits(
                model, jnp.asarray(seeds), "stable", method, psi=jnp.asarray(psi), solver=solver
            )
            jax.block_until_ready(g)
            return g

        # Each entry's compile time from cold caches, as in a fresh process (without
        # this, an entry would reuse traces of the functions the ones before it share):
        # (the disk cache is off in this benchmark, see `main`).
        vj.clear_caches()
        t0 = time.perf_counter()
        g = run()
        first = time.perf_counter() - t0
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            g = run()
            times.append(time.perf_counter() - t0)
        t_run = min(times)
        ok = np.asarray(g.result == vj.RESULTS.successful)
        # scipy on a subset
        n_sp = min(B, args.scipy_max)
        t0 = time.perf_counter()
        sp_ok, agree = [], []
        for i in range(n_sp):
            par = ref.Params(psi=float(psi[i]))
            if method == "vhc":
                x, good = scipy_gait.vhc_search(par, seeds[i])
                mine = np.array([float(g.a[i]), float(g.b[i])])
            else:
                x, good = scipy_gait.shooting_search(par, seeds[i])
                mine = np.array([float(g.a[i]), float(g.b[i]), float(g.f[i])])
            sp_ok.append(good)
            if good and ok[i]:
                agree.append(float(np.max(np.abs(x - mine))))
        t_sp = (time.perf_counter() - t0) / n_sp
        t_sp_pool = None
        if pool is not None:  # the same members, split over the pool's processes
            t0 = time.perf_counter()
            pool.starmap(_scipy_one, [(method, float(psi[i]), seeds[i]) for i in range(n_sp)])
            t_sp_pool = (time.perf_counter() - t0) / n_sp
        row = dict(
            method=method,
            solver=solver,
            B=B,
            jax_s=t_run,
            jax_gaits_per_s=B / t_run,
            compile_s=max(first - t_run, 0.0),
            jax_success=float(ok.mean()),
            scipy_s_per_gait=t_sp,
            scipy_gaits_per_s=1.0 / t_sp,
            scipy_success=float(np.mean(sp_ok)),
            ratio=(B / t_run) * t_sp,
            max_diff_vs_scipy=max(agree) if agree else None,
        )
        if t_sp_pool is not None:
            row.update(
                scipy_procs=args.scipy_procs,
                scipy_pool_gaits_per_s=1.0 / t_sp_pool,
                ratio_vs_pool=(B / t_run) * t_sp_pool,
            )
        rows.append(row)
        print(
            f"{method:8s} {solver:10s} B={B:5d}  vhcjax {row['jax_gaits_per_s']:9.1f} gaits/s "
            f"(compile {row['compile_s']:6.1f} s, success {row['jax_success']:.3f})  "
            f"scipy {row['scipy_gaits_per_s']:7.2f} gaits/s (success "
            f"{row['scipy_success']:.2f})  ratio {row['ratio']:8.1f}  "
            f"max |diff| {row['max_diff_vs_scipy']}",
            flush=True,
        )
        if t_sp_pool is not None:
            print(
                f"{'':8s}          scipy on {args.scipy_procs} processes "
                f"{row['scipy_pool_gaits_per_s']:7.2f} gaits/s  ratio "
                f"{row['ratio_vs_pool']:8.1f}",
                flush=True,
            )
    if pool is not None:
        pool.close()

    info = dict(
        device=str(jax.devices()[0]),
        num_devices=len(jax.devices()),
        cpus=os.cpu_count(),
        python=platform.python_version(),
        jax=jax.__version__,
    )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(info=info, rows=rows), fh, indent=1)
    return rows


def _scipy_one(method, psi, seed):
    """One scipy search (a process-pool task)."""
    par = ref.Params(psi=psi)
    search = scipy_gait.vhc_search if method == "vhc" else scipy_gait.shooting_search
    return search(par, np.asarray(seed))


if __name__ == "__main__":
    main()
