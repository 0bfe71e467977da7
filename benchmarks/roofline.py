"""The floating-point work of a walker step, and the CPU's peak rate to compare with.

- `rhs_flops(model)`: flops of one evaluation of the swing dynamics (the right-hand side
  the ODE solver calls), from XLA's cost analysis of the compiled evaluation.
- `rhs_evaluations(model, x0, steps, config)`: right-hand-side evaluations executed by
  `simulate_batch` per walker-step, counted by a host callback in the vector field of a
  subclass of the model (under `vmap` a member that has finished its step still
  evaluates while the others go on: executed work, which is what the hardware does).
- `cpu_peak_gflops()`: cores x clock x double-precision flops per cycle (16 with AVX2
  and FMA, 32 with AVX-512), from `/proc/cpuinfo` (the highest clock `cpufreq` reports,
  else the current one); `None` where it cannot be read. An estimate: a processor that
  splits 512-bit operations in two peaks at half of it, a boost clock above the one
  reported raises it.

The achieved rate counts the right-hand side only (event location, the impact map and the
solver's own arithmetic come on top): the fraction of peak gives the order of magnitude.
"""

import os


def rhs_flops(model):
    import jax
    import jax.numpy as jnp

    x = jnp.asarray(model.section_to_state(jnp.asarray(model.reference_gait()[1])))
    cost = jax.jit(lambda x: model.vector_field(0.0, x)).lower(x).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    return float(cost["flops"])


def rhs_evaluations(model, x0, steps, config):
    import jax

    import vhcjax as vj

    count = [0]

    def tick(x):
        count[0] += 1

    class Counting(type(model)):
        def vector_field(self, t, x, args=None):
            jax.debug.callback(tick, x)
            return super().vector_field(t, x, args)

    import dataclasses

    fields = {f.name: getattr(model, f.name) for f in dataclasses.fields(model) if f.init}
    counting = Counting(**fields)
    sim = jax.block_until_ready(vj.simulate_batch(counting, x0, steps, config=config))
    done = int(sim.num_successful.sum())
    return count[0] / max(done, 1)


def cpu_peak_gflops():
    try:
        with open("/proc/cpuinfo") as fh:
            text = fh.read()
    except OSError:
        return None
    mhz, flags = None, set()
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == "cpu MHz" and mhz is None:
            mhz = float(value)
        if key.strip() == "flags" and not flags:
            flags = set(value.split())
    try:  # the highest clock (the "cpu MHz" above is the current one)
        with open("/sys/devices/system/cpu/cpu0/cpufreq/cpuinfo_max_freq") as fh:
            mhz = max(mhz or 0.0, float(fh.read()) / 1e3)
    except (OSError, ValueError):
        pass
    if not mhz:
        return None
    per_cycle = 32 if "avx512f" in flags else 16 if {"avx2", "fma"} <= flags else 4
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (cores or 1) * mhz / 1e3 * per_cycle
