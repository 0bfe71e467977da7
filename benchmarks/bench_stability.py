"""Multipliers of the stable gait family at many slopes: vhcjax (one batched call, both the
transverse linearization and the autodiff Poincare Jacobian) against scipy (central finite
differences of a `solve_ivp` step map, one slope after another).

The gaits (fixed points) are computed first by `vhcjax.period1_family` and are
not timed. vhcjax: `family_multipliers` on all B slopes at once (vmap), compile time
reported separately from the run time (best of `--repeats`). scipy: for each of a subset
of the slopes (`--scipy-slopes`), the 3x3 Jacobian of the step map by central differences
(h = 1e-6, DOP853 at rtol = atol = 1e-12: 6 steps per slope) and `numpy.linalg.eigvals`;
its cost is linear in the number of slopes, so the per-slope time is what compares. The
largest disagreement of the multipliers (transverse vs Poincare, and vhcjax vs scipy on
the common slopes) is reported too.

    python benchmarks/bench_stability.py [--quick] [--json OUT]
"""

import argparse
import json
import os

# Compile times are those of a first run: without the persistent compilation cache.
os.environ.setdefault("VHCJAX_CACHE_DIR", "off")
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scipy_reference as ref  # noqa: E402


def scipy_multipliers(psi, z, h=1e-6, rtol=1e-12, atol=1e-12):
    par = ref.Params(psi=psi)

    def P(zz):
        x0 = np.array([zz[0], -zz[0] - 2 * psi, zz[1], zz[2]])
        s = ref.step(par, x0, rtol=rtol, atol=atol)
        return np.array([s.x_plus[0], s.x_plus[2], s.x_plus[3]])

    J = np.stack([(P(z + h * e) - P(z - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    ev = np.linalg.eigvals(J)
    return ev[np.argsort(-np.abs(ev))]


def _match(a, b):
    return max(float(np.min(np.abs(b - x))) for x in a)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slopes", type=int, default=1000, help="number of slopes B (1000)")
    ap.add_argument("--lo", type=float, default=0.5, help="first slope, deg (0.5)")
    ap.add_argument("--hi", type=float, default=6.0, help="last slope, deg (6.0)")
    ap.add_argument("--scipy-slopes", type=int, default=20, help="slopes run by scipy (20)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="small sizes (B=16, scipy 3)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON")
    args = ap.parse_args(argv)
    if args.quick:
        args.slopes, args.scipy_slopes, args.repeats = 16, 3, 1

    import jax
    import jax.numpy as jnp

    from vhcjax import RESULTS, CompassGait, stability as S

    psis = np.radians(np.linspace(args.lo, args.hi, args.slopes))
    t0 = time.perf_counter()
    fam = S.period1_family(psis, "stable")
    t_family = time.perf_counter() - t0
    zs = jnp.asarray(fam.z)
    model = CompassGait()

    t0 = time.perf_counter()
    out = S.family_multipliers(model, jnp.asarray(psis), zs)
    jax.block_until_ready(out.transverse)
    t_first = time.perf_counter() - t0
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        out = S.family_multipliers(model, jnp.asarray(psis), zs)
        jax.block_until_ready(out.transverse)
        times.append(time.perf_counter() - t0)
    t_run = min(times)
    tr, pc = np.asarray(out.transverse), np.asarray(out.poincare)
    ok = np.asarray(out.result == RESULTS.successful)
    diff_tp = max(_match(a, b) for a, b in zip(tr[ok], pc[ok]))

    idx = np.linspace(0, args.slopes - 1, min(args.scipy_slopes, args.slopes)).astype(int)
    t0 = time.perf_counter()
    sc = [scipy_multipliers(psis[i], np.asarray(fam.z[i])) for i in idx]
    t_scipy = time.perf_counter() - t0
    diff_sc = max(_match(tr[i], s) for i, s in zip(idx, sc))

    res = {
        "benchmark": "multipliers of the stable family",
        "device": str(jax.devices()[0]),
        "platform": platform.platform(),
        "slopes": args.slopes,
        "slope_range_deg": [args.lo, args.hi],
        "family_continuation_s": t_family,
        "vhcjax_compile_plus_first_run_s": t_first,
        "vhcjax_compile_s": t_first - t_run,
        "vhcjax_run_s": t_run,
        "vhcjax_ms_per_slope_both_methods": 1e3 * t_run / args.slopes,
        "vhcjax_success_rate": float(ok.mean()),
        "scipy_slopes": int(len(idx)),
        "scipy_s": t_scipy,
        "scipy_ms_per_slope_fd": 1e3 * t_scipy / len(idx),
        "speedup_per_slope": (t_scipy / len(idx)) / (t_run / args.slopes),
        "max_diff_transverse_vs_poincare": diff_tp,
        "max_diff_vhcjax_vs_scipy_fd": diff_sc,
        "num_unstable": int((~np.asarray(out.stable)).sum()),
        "first_unstable_slope_deg": (
            float(np.degrees(psis[~np.asarray(out.stable)][0]))
            if (~np.asarray(out.stable)).any()
            else None
        ),
    }
    for k, v in res.items():
        print(f"{k}: {v}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=2)
    return res


if __name__ == "__main__":
    main()
