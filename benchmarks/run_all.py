"""Run every benchmark in this folder and print one table.

Each script (`bench_simulate.py`, `bench_gait_search.py`, `bench_stability.py`,
`bench_basin.py`, `bench_cli.py`, `bench_calls.py`) runs in a fresh Python process and writes its `--json` output; this
script reads those files and prints one row per job: vhcjax's time or throughput, the
scipy implementation of the same job measured in the same run, their ratio, and
vhcjax's compile time (reported separately, never included in the run time). A last
line names the machine: CPU model, cores, Python, JAX version, backend and device.

    python benchmarks/run_all.py [--quick] [--markdown] [--keep DIR]

`--quick` runs every script with its own `--quick` sizes (a check that the scripts work,
not a measurement). `--markdown` prints the table as markdown (for the README);
otherwise plain text. `--keep DIR` keeps the JSON files and the scripts' logs there.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))

# (name, script, extra arguments); rows are built from each script's JSON below.
JOBS = [
    ("simulate", "bench_simulate.py", ["--solver", "dopri8"]),
    ("simulate-devices", "bench_simulate.py", ["--solver", "dopri8", "--cpu-devices", "CORES"]),
    ("gait_search", "bench_gait_search.py", []),
    ("stability", "bench_stability.py", []),
    ("basin", "bench_basin.py", []),
    ("cli", "bench_cli.py", []),
    ("calls", "bench_calls.py", []),
]


def _machine():
    """CPU model, cores, Python, and JAX's version, backend and device (fresh process)."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    code = (
        "import json, jax; d = jax.devices()[0]; print(json.dumps(dict("
        "jax=jax.__version__, backend=jax.default_backend(), device=d.device_kind, "
        "num_devices=len(jax.devices()))))"
    )
    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True)
    info = json.loads(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 else {}
    return dict(cpu=cpu, cores=os.cpu_count(), python=platform.python_version(), **info)


def _run(script, args, out_json, log):
    """Run one benchmark script in a fresh process; return (json or None, seconds)."""
    cmd = [sys.executable, os.path.join(HERE, script), *args, "--json", out_json]
    print(f"[run_all] {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        rc = subprocess.run(cmd, check=False, stdout=fh, stderr=subprocess.STDOUT).returncode
    wall = time.perf_counter() - t0
    if rc != 0 or not os.path.exists(out_json):
        with open(log) as fh:
            tail = fh.read()[-2000:]
        print(
            f"[run_all] {script} failed (exit {rc}); last lines of its output:\n{tail}",
            file=sys.stderr,
            flush=True,
        )
        return None, wall
    with open(out_json) as fh:
        return json.load(fh), wall


def _fmt(x):
    """A rate or time to about three significant figures, with thousands separators."""
    if x is None:
        return "-"
    if abs(x) >= 100:
        return f"{x:,.0f}"
    if abs(x) >= 10:
        return f"{x:.1f}"
    return f"{x:.3g}"


def _peak(res):
    """The share of the CPU's peak double-precision rate that a simulation reached
    (right-hand-side work only, `roofline.py`)."""
    if res.get("fraction_of_peak") is None:
        return "-"
    return (
        f"{res['fraction_of_peak']:.1%} ({res['rhs_evaluations_per_walker_step']:.0f} "
        f"evaluations x {res['rhs_flops']:.0f} flops per walker-step; peak "
        f"{res['peak_gflops']:.0f} GFLOP/s)"
    )


def _rows(name, res):
    """Table rows (job, vhcjax, scipy, ratio, compile, share of peak) from one script's
    JSON; rows without a flop count get "-" in the last column (added below)."""
    if name.startswith("simulate"):
        tol = f"{res['rtol']:g}".replace("e-0", "e-")
        job = (
            f"simulation, {res['walkers']:,} walkers x {res['steps']} steps, "
            f"{res['solver']}, rtol = atol = {tol}, "
            f"{res['num_devices']} device{'s' if res['num_devices'] > 1 else ''}"
        )
        return [
            (
                job,
                f"{_fmt(res['vhcjax_walker_steps_per_s'])} walker-steps/s",
                (f"{_fmt(res['scipy_walker_steps_per_s'])} walker-steps/s ({res['scipy_method']})"),
                f"{res['speedup']:.1f}x",
                f"{res['compile_s']:.1f} s",
                _peak(res),
            )
        ]
    if name == "gait_search":
        rows = []
        for r in res["rows"]:
            method = "VHC (Problem 1)" if r["method"] == "vhc" else "shooting (Problem 2)"
            rows.append(
                (
                    f"gait search, {method}, B = {r['B']:,}",
                    f"{_fmt(r['jax_gaits_per_s'])} gaits/s",
                    f"{_fmt(r['scipy_gaits_per_s'])} gaits/s",
                    f"{r['ratio']:.1f}x",
                    f"{r['compile_s']:.1f} s",
                )
            )
        return rows
    if name == "stability":
        job = f"multipliers (transverse + Poincaré) of {res['slopes']:,} slopes, one call"
        return [
            (
                job,
                f"{_fmt(res['vhcjax_ms_per_slope_both_methods'])} ms/slope",
                f"{_fmt(res['scipy_ms_per_slope_fd'])} ms/slope (finite differences)",
                f"{res['speedup_per_slope']:.1f}x",
                f"{res['vhcjax_compile_s']:.1f} s",
            )
        ]
    if name == "basin":
        g = res["grid"]
        v, s = res["vhcjax"], res["scipy"]
        est = s["estimated_full_grid_s"]
        job = f"basin slice, {g[0]} x {g[1]} points, <= {res['max_steps']} steps each"
        return [
            (
                job,
                f"{v['run_s']:.1f} s ({_fmt(v['walker_steps_per_s'])} walker-steps/s)",
                f"~{est:.0f} s ({_fmt(s['walker_steps_per_s'])} walker-steps/s)"
                if est is not None
                else "-",
                f"{res['speedup']:.1f}x",
                f"{v['compile_s']:.1f} s",
            )
        ]
    if name == "cli":
        g, sw, lib = res["gait"], res["sweep"], res["library_first_call"]
        rows = [
            (
                "`vhcjax gait --slope-deg 3 --json`, first run (empty cache)",
                f"{g['first_s']:.1f} s",
                f"{g['scipy_s']:.2f} s (script)",
                f"{g['first_ratio']:.0f}x slower",
                "included",
            ),
            (
                "`vhcjax gait --slope-deg 3 --json`, second run",
                f"{g['second_s']:.1f} s",
                f"{g['scipy_s']:.2f} s (script)",
                f"{g['second_ratio']:.1f}x slower",
                "cached",
            ),
            (
                "the same, without stored programs (`VHCJAX_PROGRAMS=off`)",
                f"{g['second_unstored_s']:.1f} s",
                f"{g['scipy_s']:.2f} s (script)",
                f"{g['second_unstored_s'] / g['scipy_s']:.1f}x slower",
                "compiled code cached, traced again",
            ),
            (
                f"`vhcjax sweep` with `--csv`, {sw['n1']:,} and {sw['n2']:,} slopes "
                f"({sw['found2']:,} found)",
                f"{sw['per_gait_ms']:.2f} ms/gait + {sw['fixed_s']:.1f} s",
                f"{sw['scipy_per_gait_ms']:.1f} ms/gait (fsolve continuation)",
                f"{sw['ratio']:.0f}x",
                f"{sw['cold_fixed_s']:.1f} s fixed, empty cache",
            ),
            (
                "fresh Python process: `find_gait` + `gait_multipliers` at 3 deg, first run",
                f"{lib['empty_cache_s']:.1f} s",
                "-",
                "-",
                "included (empty cache)",
            ),
            (
                "the same, second run",
                f"{lib['wall_s']:.1f} s",
                "-",
                "-",
                "cached",
            ),
        ]
        for name_, t in res["commands"].items():
            rows.append(
                (
                    f"`vhcjax {name_}`, second run",
                    "failed" if t is None else f"{t:.1f} s",
                    "-",
                    "-",
                    "cached",
                )
            )
        h = res["help"]
        rows.append(
            (
                "`vhcjax --help`, fresh process",
                f"{h['help_s']:.2f} s",
                "-",
                "-",
                f"none: no JAX imported (`import vhcjax`: {h['import_s']:.1f} s)",
            )
        )
        return rows
    if name == "calls":
        rows = []
        for group in ("README ten lines", "a user's own model (RodWalker)"):
            warm = [r for r in res["runs"]["warm_cache"]["rows"] if r["group"] == group]
            cold = [r for r in res["runs"]["empty_cache"]["rows"] if r["group"] == group]
            first = max(warm, key=lambda r: r["first_s"])
            second = max(warm, key=lambda r: r["second_s"])
            rows.append(
                (
                    f"{group}, each call in a fresh process: slowest first call "
                    f"(`{first['call']}`); slowest second call (`{second['call']}`)",
                    f"{first['first_s']:.1f} s; {second['second_s']:.2f} s",
                    "-",
                    "-",
                    f"cached (empty cache: {sum(r['first_s'] for r in cold):.0f} s "
                    "for all first calls)",
                )
            )
        return rows
    raise ValueError(name)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="each script's --quick sizes")
    ap.add_argument("--markdown", action="store_true", help="print a markdown table")
    ap.add_argument("--keep", metavar="DIR", help="keep the JSON outputs and logs here")
    ap.add_argument(
        "--only",
        metavar="NAMES",
        help="comma-separated subset of: " + ", ".join(j[0] for j in JOBS),
    )
    args = ap.parse_args(argv)

    machine = _machine()
    cores = machine["cores"] or 1
    jobs = [j for j in JOBS if not args.only or j[0] in args.only.split(",")]
    if machine.get("backend", "cpu") != "cpu" or cores < 2:  # devices per core: CPU only
        jobs = [j for j in jobs if j[0] != "simulate-devices"]
    workdir = args.keep or tempfile.mkdtemp(prefix="vhcjax-bench-")
    os.makedirs(workdir, exist_ok=True)

    rows, failed, total = [], [], time.perf_counter()
    for name, script, extra in jobs:
        extra = [str(cores) if a == "CORES" else a for a in extra]
        if args.quick:
            extra = [*extra, "--quick"]
        res, _ = _run(
            script,
            extra,
            os.path.join(workdir, f"{name}.json"),
            os.path.join(workdir, f"{name}.log"),
        )
        if res is None:
            failed.append(name)
            rows.append((f"{name} ({script})", "failed", "-", "-", "-", "-"))
        else:
            rows.extend(_rows(name, res))
    total = time.perf_counter() - total
    rows = [r if len(r) == 6 else (*r, "-") for r in rows]

    header = ("job", "vhcjax", "scipy, same job", "ratio", "vhcjax compile", "share of peak")
    line = (
        f"Machine: {machine['cpu']}, {machine['cores']} cores; Python {machine['python']}, "
        f"JAX {machine.get('jax', '?')}, backend {machine.get('backend', '?')} "
        f"({machine.get('num_devices', '?')} x {machine.get('device', '?')}); float64. "
        f"`python benchmarks/run_all.py {' '.join(sys.argv[1:] if argv is None else argv)}`, "
        f"{total / 60:.0f} min in all."
    )
    if args.quick:
        line += " QUICK SIZES: a check that the scripts run, not a measurement."
    if args.markdown:
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        for r in rows:
            print("| " + " | ".join(r) + " |")
        print()
        print(line)
    else:
        widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
        for r in [header, *rows]:
            print("  ".join(str(c).ljust(w) for c, w in zip(r, widths)))
        print(line)
    if args.keep:
        print(f"[run_all] JSON and logs in {workdir}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
