"""The flip-slope atlas of the compass gait over a grid of mass ratio x length ratio
(`vhcjax.atlas`): wall time of the whole computation (seeding homotopy, slope scan,
refinement of every flip, spectral radius at 3 degrees), in one process, first call
(compilation included) and, with `--repeat`, a second call; cells found; and a few cells
checked against `vhcjax.period_doubling_slope`.

    python benchmarks/bench_atlas.py [--n 100] [--repeat] [--json OUT]

The target is a 100 x 100 grid in under 10 minutes on a 2-core CPU.
"""

import argparse
import json
import math
import platform
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="grid points per axis (100)")
    ap.add_argument("--mu", default="1:5", help="mass ratio range LO:HI (1:5)")
    ap.add_argument("--beta", default="0.6:1.6", help="length ratio range LO:HI (0.6:1.6)")
    ap.add_argument("--repeat", action="store_true", help="time a second call too")
    ap.add_argument("--check", type=int, default=3, help="cells checked by bisection (3)")
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args(argv)

    import jax

    import vhcjax as vj
    from vhcjax.parameters._atlas import grid_model

    lo, hi = (float(x) for x in args.mu.split(":"))
    mu = np.linspace(lo, hi, args.n)
    lo, hi = (float(x) for x in args.beta.split(":"))
    beta = np.linspace(lo, hi, args.n)
    t0 = time.perf_counter()
    at = vj.atlas(mu, beta, slope=math.radians(3.0))
    first = time.perf_counter() - t0
    out = {
        "grid": [args.n, args.n],
        "cells": args.n**2,
        "first_call_s": first,
        "found": int(np.isfinite(at.flip_slope).sum()),
        "device": str(jax.devices()[0]),
        "cpu_count": __import__("os").cpu_count(),
        "platform": platform.platform(),
    }
    print(json.dumps(out), flush=True)
    if args.repeat:
        t0 = time.perf_counter()
        vj.atlas(mu, beta, slope=math.radians(3.0))
        out["second_call_s"] = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    ok = np.argwhere(np.isfinite(at.flip_slope))
    errs = []
    for i, j in ok[rng.choice(len(ok), size=min(args.check, len(ok)), replace=False)]:
        f = at.flip_slope[i, j]
        lo = f - math.radians(0.2)  # a bracket around the flip, the gait continued there
        m = grid_model(mu[i], beta[j], psi=lo)
        z = np.asarray(vj.find_gait(m, method="shooting").z)
        pd = vj.period_doubling_slope(lo, f + math.radians(0.2), z, model=m, tol=1e-12)
        errs.append(abs(math.degrees(f - pd.psi)))
    out["check_max_error_deg"] = max(errs) if errs else None
    print(json.dumps(out, indent=1))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
