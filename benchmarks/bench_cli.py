"""Whole commands as a user types them, in fresh processes, against scipy scripts doing
the same jobs in the same run.

- `vhcjax gait --slope-deg 3 --json` (gait and multipliers): first run with an empty
  compilation cache, then a second run, and a second run without stored programs
  (`VHCJAX_PROGRAMS=off`: compiled code from the cache, but traced again); against a scipy script (VHC search by `fsolve`,
  multipliers from a central-difference Jacobian of the `solve_ivp` step map), interpreter
  start included on both sides.
- `vhcjax sweep --slope-deg 0.5:4.3:STEP --family stable --csv FILE` at N1 and N2 slopes
  (second runs): the cost per gait from the difference (compile and start cancel) and the
  fixed overhead; with an empty cache too. scipy: a warm-started `fsolve` continuation
  over a subset of the same slopes with the multipliers of each gait (central-difference
  Jacobian of the step map, as the CSV's stability columns), its cost per gait.
- A fresh Python process: `find_gait` and `gait_multipliers` (both multiplier methods) at
  3 degrees, with an empty cache and again (warm cache).
- The other commands at the sizes users run, second runs.
- `vhcjax --help` and `vhcjax gait --help` in fresh processes, through the console
  command's entry point (`_vhcjax_command.main`, which imports no JAX for them), against
  `python -m vhcjax --help` and `import vhcjax` (which import JAX); the median of
  `--repeats` runs each. `--help-only` times only these.
- `--compiler-options`: only the first runs (`gait --json`, and `sweep` at N1 slopes),
  each with an empty cache, with vhcjax's XLA options on the CPU
  (`vhcjax._programs.compiler_options()`) and with XLA's defaults, alternating, the
  median of `--repeats` runs each.

    python benchmarks/bench_cli.py [--quick] [--json OUT] [--help-only] [--repeats R]
                                   [--compiler-options]
"""

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))

SCIPY_GAIT = r"""
import sys, math, numpy as np
sys.path.insert(0, {here!r})
import scipy_gait, scipy_reference as ref
par = ref.Params(psi=math.radians(3.0))
(a, b), ok = scipy_gait.vhc_search(par, np.array([0.2, -1.0]))
d, f, h = scipy_gait._abcd(par, scipy_gait._p(par), a, b, -1.0)
z = np.array([a, b, f])  # the section point (q1, dq1, dq2) after impact


def P(z):
    out = ref.step(par, np.array([z[0], -z[0] - 2 * par.psi, z[1], z[2]]))
    return np.array([out.x_plus[0], out.x_plus[2], out.x_plus[3]])


h = 1e-6
J = np.stack([(P(z + h * e) - P(z - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
print(ok, z, np.linalg.eigvals(J))
"""

SCIPY_SWEEP = r"""
import sys, math, time, numpy as np
sys.path.insert(0, {here!r})
import scipy_gait, scipy_reference as ref
deg = np.linspace(0.5, 4.3, {n})
x = np.array([0.2, -1.0])
x, _ = scipy_gait.vhc_search(ref.Params(psi=math.radians(3.0)), x)


def multipliers(par, a, b):  # the CSV's stability columns: central-difference Jacobian
    d, f, h = scipy_gait._abcd(par, scipy_gait._p(par), a, b, -1.0)
    z = np.array([a, b, f])

    def P(z):
        out = ref.step(par, np.array([z[0], -z[0] - 2 * par.psi, z[1], z[2]]))
        return np.array([out.x_plus[0], out.x_plus[2], out.x_plus[3]])

    J = np.stack([(P(z + 1e-6 * e) - P(z - 1e-6 * e)) / 2e-6 for e in np.eye(3)], axis=1)
    return np.linalg.eigvals(J)


t0 = time.perf_counter()
found = 0
for d in deg[::-1]:  # warm-started continuation from the top of the range down
    par = ref.Params(psi=math.radians(d))
    sol, ok = scipy_gait.vhc_search(par, x)
    if ok:
        x, found = sol, found + 1
        multipliers(par, *sol)
print((time.perf_counter() - t0, found))
"""

LIBRARY_FIRST = r"""
import time
t0 = time.perf_counter()
import math, vhcjax as vj
m = vj.CompassGait(psi=math.radians(3.0))
g = vj.find_gait(m, "stable")
mult = vj.gait_multipliers(m, m.state_to_section(g.x_plus))
print(mult.poincare, time.perf_counter() - t0)
"""


#: `python -m vhcjax` with XLA's default compiler options (none of vhcjax's own).
XLA_DEFAULTS_CLI = (
    "import sys, vhcjax._programs as p; p._CPU_OPTIONS.clear(); "
    "from vhcjax.cli import main; sys.exit(main())"
)


#: What the `vhcjax` console script runs (`[project.scripts]` in `pyproject.toml`).
CONSOLE = [sys.executable, "-c", "import sys; from _vhcjax_command import main; sys.exit(main())"]


def time_help(work, repeats):
    """Fresh processes answering `--help` (the median of `repeats` runs each)."""
    env = dict(os.environ, VHCJAX_CACHE_DIR=os.path.join(work, "cache-help"))
    jobs = {  # key: (what a user types, the command)
        "help_s": ("vhcjax --help", CONSOLE + ["--help"]),
        "gait_help_s": ("vhcjax gait --help", CONSOLE + ["gait", "--help"]),
        "python_m_help_s": ("python -m vhcjax --help", [sys.executable, "-m", "vhcjax", "--help"]),
        "import_s": ("python -c 'import vhcjax'", [sys.executable, "-c", "import vhcjax"]),
    }
    rows = {}
    for key, (name, cmd) in jobs.items():
        t = statistics.median(_timed(cmd, env, work)[0] for _ in range(repeats))
        rows[key] = t
        print(f"{name}: {t:.2f} s (median of {repeats}, fresh processes)", flush=True)
    return {"help": dict(repeats=repeats, **rows)}


def _timed(cmd, env, cwd):
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({out.returncode}): {out.stderr[-1500:]}")
    return wall, out.stdout


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--quick", action="store_true", help="small sweeps (a check, not a measurement)"
    )
    ap.add_argument("--json", metavar="OUT")
    ap.add_argument(
        "--compiler-options",
        action="store_true",
        help="only first runs, with vhcjax's XLA options and with XLA's defaults",
    )
    ap.add_argument(
        "--repeats", type=int, default=3, help="runs of each (--help timings, --compiler-options)"
    )
    ap.add_argument("--help-only", action="store_true", help="only the --help timings")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be at least 1")
    n1, n2 = (100, 400) if args.quick else (1000, 10000)
    n_scipy = 10 if args.quick else 50
    vhcjax = [sys.executable, "-m", "vhcjax"]
    work = tempfile.mkdtemp(prefix="vhcjax-bench-cli-")
    env = dict(os.environ, VHCJAX_CACHE_DIR=os.path.join(work, "cache"))
    if args.compiler_options:
        rows = compare_compiler_options(work, n1, args.repeats)
        _finish(work, args, rows)
        return
    rows = time_help(work, max(args.repeats, 5))
    if args.help_only:
        _finish(work, args, rows)
        return

    # gait + multipliers: first run (empty cache), second run; scipy script
    first, _ = _timed(vhcjax + ["gait", "--slope-deg", "3", "--json", "--quiet"], env, work)
    second, _ = _timed(vhcjax + ["gait", "--slope-deg", "3", "--json", "--quiet"], env, work)
    # the same second run without stored programs (compiled code from the cache, traced
    # anew); its programs are compiled differently, so a first run fills the cache
    for _ in range(2):
        unstored, _ = _timed(
            vhcjax + ["gait", "--slope-deg", "3", "--json", "--quiet"],
            dict(env, VHCJAX_PROGRAMS="off"),
            work,
        )
    sp, _ = _timed([sys.executable, "-c", SCIPY_GAIT.format(here=HERE)], env, work)
    rows["gait"] = dict(
        first_s=first,
        second_s=second,
        second_unstored_s=unstored,
        scipy_s=sp,
        first_ratio=first / sp,
        second_ratio=second / sp,
    )
    print(
        f"gait --json: first {first:.1f} s, second {second:.1f} s (without stored programs "
        f"{unstored:.1f} s), scipy {sp:.2f} s ({first / sp:.0f}x, {second / sp:.1f}x)",
        flush=True,
    )

    # library: a fresh Python process, with an empty cache (what a notebook meets first)
    # and with a warm one (the second run)
    cold_env = dict(env, VHCJAX_CACHE_DIR=os.path.join(work, "cache-library"))
    lib_cold, _ = _timed([sys.executable, "-c", LIBRARY_FIRST], cold_env, work)
    lib, out = _timed([sys.executable, "-c", LIBRARY_FIRST], cold_env, work)
    rows["library_first_call"] = dict(
        wall_s=lib, in_process_s=float(out.split()[-1]), empty_cache_s=lib_cold
    )
    print(
        f"fresh process find_gait + gait_multipliers: {lib_cold:.1f} s with an empty cache, "
        f"{lib:.1f} s warm",
        flush=True,
    )

    # sweeps
    def sweep(n, cache_env):
        step = (4.3 - 0.5) / (n - 1)
        csv = os.path.join(work, f"sweep{n}.csv")
        t, _ = _timed(
            vhcjax
            + [
                "sweep",
                "--slope-deg",
                f"0.5:4.3:{step!r}",
                "--family",
                "stable",
                "--csv",
                csv,
                "--quiet",
            ],
            cache_env,
            work,
        )
        with open(csv) as fh:
            found = sum(1 for line in fh if ",successful," in line)
        return t, found

    cold_env = dict(env, VHCJAX_CACHE_DIR=os.path.join(work, "cache-cold"))
    cold, _ = sweep(n1, cold_env)
    t1, f1 = sweep(n1, env)
    t1, f1 = sweep(n1, env)  # second run
    t2, f2 = sweep(n2, env)
    t2, f2 = sweep(n2, env)
    per_gait = (t2 - t1) / (n2 - n1)
    fixed = t1 - n1 * per_gait
    sp_out = subprocess.run(
        [sys.executable, "-c", SCIPY_SWEEP.format(here=HERE, n=n_scipy)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    sp_t, sp_found = eval(sp_out.strip())  # noqa: S307 (our own script's tuple)
    sp_per_gait = sp_t / n_scipy
    rows["sweep"] = dict(
        n1=n1,
        n2=n2,
        t1_s=t1,
        t2_s=t2,
        found1=f1,
        found2=f2,
        per_gait_ms=1e3 * per_gait,
        fixed_s=fixed,
        cold_n1_s=cold,
        cold_fixed_s=cold - n1 * per_gait,
        scipy_per_gait_ms=1e3 * sp_per_gait,
        scipy_found=sp_found,
        ratio=sp_per_gait / per_gait,
    )
    print(
        f"sweep: {n1} slopes {t1:.1f} s ({f1} found), {n2} slopes {t2:.1f} s ({f2} found): "
        f"{1e3 * per_gait:.2f} ms/gait, fixed {fixed:.1f} s (empty cache {cold:.1f} s at "
        f"{n1}); scipy {1e3 * sp_per_gait:.1f} ms/gait: {sp_per_gait / per_gait:.0f}x",
        flush=True,
    )

    # other commands, second runs
    others = {
        "simulate": ["simulate", "--steps", "20"],
        "multipliers": ["multipliers", "--slope-deg", "3"],
        "contraction": ["contraction"],
        "push": ["push", "--phases", "5"],
        "slope-sensitivity": ["slope-sensitivity"],
        "bifurcation": ["bifurcation", "--slope-deg", "4:5:0.05"],
    }
    rows["commands"] = {}
    for name, cmd in others.items():
        try:
            _timed(vhcjax + cmd + ["--quiet"], env, work)
            t, _ = _timed(vhcjax + cmd + ["--quiet"], env, work)
        except RuntimeError as e:
            print(f"{name}: {e}", flush=True)
            t = None
        rows["commands"][name] = t
        print(f"{' '.join(cmd)}: second run {t if t is None else round(t, 1)} s", flush=True)

    _finish(work, args, rows)


def compare_compiler_options(work, n1, repeats):
    """First runs (empty caches) with vhcjax's XLA options and with XLA's defaults,
    alternating; the median wall time of each and their ratio."""
    step = (4.3 - 0.5) / (n1 - 1)
    jobs = {
        "gait": ["gait", "--slope-deg", "3", "--json", "--quiet"],
        "sweep": ["sweep", "--slope-deg", f"0.5:4.3:{step!r}", "--family", "stable"]
        + ["--csv", os.path.join(work, "sweep.csv"), "--quiet"],
    }
    runners = {
        "vhcjax_options": [sys.executable, "-m", "vhcjax"],
        "xla_defaults": [sys.executable, "-c", XLA_DEFAULTS_CLI],
    }
    times = {job: {name: [] for name in runners} for job in jobs}
    for i in range(repeats):
        for job, cmd in jobs.items():
            order = list(runners.items())
            for name, runner in order if i % 2 == 0 else order[::-1]:  # either first in turn
                cache = os.path.join(work, f"cache-{job}-{name}-{i}")
                t, _ = _timed(runner + cmd, dict(os.environ, VHCJAX_CACHE_DIR=cache), work)
                times[job][name].append(t)
    rows = {}
    for job, t in times.items():
        ours, xla = (statistics.median(t[k]) for k in runners)
        rows[job] = dict(
            vhcjax_options_s=t["vhcjax_options"],
            xla_defaults_s=t["xla_defaults"],
            vhcjax_options_median_s=ours,
            xla_defaults_median_s=xla,
            ratio=xla / ours,
        )
        print(
            f"{job}, first run: vhcjax options {ours:.1f} s, XLA defaults {xla:.1f} s "
            f"(medians of {repeats}): {xla / ours:.2f}x",
            flush=True,
        )
    return {"compiler_options": dict(repeats=repeats, **rows)}


def _finish(work, args, rows):
    info = dict(python=platform.python_version(), cpus=os.cpu_count(), quick=args.quick)
    shutil.rmtree(work, ignore_errors=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(info=info, **rows), fh, indent=1)


if __name__ == "__main__":
    main()
