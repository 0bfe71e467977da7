"""First and second calls of library functions in a fresh Python process.

What a notebook user waits for: each call of the README's ten lines, of the main
functions on a user's own model (`RodWalker`, the two-rod walker of the docs' new-model
notebook, written as a user would), and of derivatives in the slope (`jax.grad` through
the gait search and the multipliers, open and closed loop), timed on its first call in a fresh process and on a
second call with the same shapes and other values (another slope). Two fresh processes
share one new compilation-cache folder: the first starts with it empty (tracing and
compiling everything), the second with it filled by the first (a user's next session).
The second call should never trace again, so it costs only the work itself.

No scipy column: these are latencies of single calls, not throughput (the other
benchmarks compare the same jobs with scipy).

    python benchmarks/bench_calls.py [--json OUT]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
TESTS = os.path.join(os.path.dirname(HERE), "tests")


def _child():
    """Time every call (first, then second with other values); print JSON."""
    t0 = time.perf_counter()
    import math

    import jax
    import jax.numpy as jnp
    import matplotlib

    matplotlib.use("Agg")
    import vhcjax as vj

    sys.path.insert(0, TESTS)
    from _user_model import RodWalker

    import_s = time.perf_counter() - t0
    rows = []

    def timed(group, name, fn, *values):
        times = []
        for v in values:
            t = time.perf_counter()
            out = jax.block_until_ready(fn(v))
            times.append(time.perf_counter() - t)
        rows.append(dict(group=group, call=name, first_s=times[0], second_s=times[1]))
        return out

    tmp = tempfile.mkdtemp()
    readme = "README ten lines"
    slopes = (3.0, 3.5)
    models = {d: vj.CompassGait(psi=math.radians(d)) for d in slopes}
    gaits = {}

    def find(d):
        gaits[d] = vj.find_gait(models[d], "stable")
        return gaits[d]

    timed(readme, 'find_gait(model, "stable")', find, *slopes)
    timed(readme, "gait.params()", lambda d: gaits[d].params(), *slopes)
    sims = {}

    def sim(d):
        sims[d] = vj.simulate(models[d], gaits[d].x_plus, 20, dense_points=60)
        return sims[d]

    timed(readme, "simulate(model, x, 20, dense_points=60)", sim, *slopes)
    timed(
        readme,
        "gait_multipliers(model, gait)",
        lambda d: vj.gait_multipliers(models[d], gaits[d]),
        *slopes,
    )
    timed(
        readme,
        "sweep(model, 5 slopes)",
        lambda d: vj.sweep(models[d], [math.radians(d + k) for k in (-2, -1, 0, 1, 2)]),
        *slopes,
    )
    timed(
        readme,
        "plotting.plot_phase_portrait(sim)",
        lambda d: vj.plotting.plot_phase_portrait(sims[d], path=os.path.join(tmp, f"{d}.png")),
        *slopes,
    )

    user = "a user's own model (RodWalker)"
    psis = (0.03, 0.031)
    rods = {p: RodWalker(psi=p) for p in psis}
    ug = {}

    def ufind(p):
        ug[p] = vj.find_gait(rods[p], guess=jnp.array([0.2, -1.0, -0.2]))
        return ug[p]

    timed(user, "find_gait(model, guess=z0)", ufind, *psis)
    timed(user, "fixed_point(model, z)", lambda p: vj.fixed_point(rods[p], ug[p].z), *psis)
    timed(
        user,
        "poincare_multipliers(model, z)",
        lambda p: vj.poincare_multipliers(rods[p], ug[p].z),
        *psis,
    )
    timed(
        user,
        "transverse_linearization(model, ...)",
        lambda p: vj.transverse_linearization(rods[p], ug[p].x_plus, ug[p].x_minus, ug[p].T),
        *psis,
    )
    timed(
        user, "gait_multipliers(model, gait)", lambda p: vj.gait_multipliers(rods[p], ug[p]), *psis
    )
    timed(
        user,
        "simulate(model, x, 20, dense_points=60)",
        lambda p: vj.simulate(rods[p], ug[p].x_plus, 20, dense_points=60),
        *psis,
    )

    grads = "derivatives in the slope"

    def radius(psi):
        m = vj.CompassGait(psi=psi)
        return vj.gait_spectrum(m, vj.find_gait(m, "stable")).spectral_radius

    timed(
        grads,
        "jax.grad(spectral radius of the gait)",
        lambda d: jax.grad(radius)(jnp.asarray(math.radians(d))),
        *slopes,
    )
    closed = vj.CompassGait(psi=math.radians(3.0))
    z = vj.find_gait(closed, "unstable").z
    feedback = vj.stabilize(closed, z).feedback  # held fixed

    def closed_loop_radius(psi):
        return jnp.abs(vj.closed_loop_multipliers(vj.CompassGait(psi=psi), feedback, z)[0])

    timed(
        grads,
        "jax.grad(closed-loop spectral radius)",
        lambda d: jax.grad(closed_loop_radius)(jnp.asarray(math.radians(d))),
        3.0,
        3.05,
    )
    print(json.dumps(dict(import_s=import_s, rows=rows)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=None, help="write the results here")
    ap.add_argument("--quick", action="store_true", help="the same run (it is short)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        _child()
        return 0
    cache = tempfile.mkdtemp(prefix="vhcjax-bench-calls-")
    env = dict(os.environ, VHCJAX_CACHE_DIR=cache)
    runs = {}
    for label in ("empty_cache", "warm_cache"):
        t0 = time.perf_counter()
        out = subprocess.run(
            [sys.executable, __file__, "--child"], env=env, capture_output=True, text=True
        )
        wall = time.perf_counter() - t0
        if out.returncode != 0:
            print(out.stderr[-3000:], file=sys.stderr)
            return 1
        runs[label] = dict(json.loads(out.stdout.strip().splitlines()[-1]), wall_s=wall)
    res = dict(runs=runs)
    print(f"{'call':<72} {'empty cache: 1st':>17} {'warm: 1st':>10} {'warm: 2nd':>10}")
    for a, b in zip(runs["empty_cache"]["rows"], runs["warm_cache"]["rows"]):
        name = f"{b['group']}: {b['call']}"
        print(f"{name:<72} {a['first_s']:>15.2f} s {b['first_s']:>8.2f} s {b['second_s']:>8.3f} s")
    warm = runs["warm_cache"]["rows"]
    res["warm_first_max"] = max(warm, key=lambda r: r["first_s"])
    res["warm_second_max"] = max(warm, key=lambda r: r["second_s"])
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
