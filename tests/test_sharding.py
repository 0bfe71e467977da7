"""A batch spread over 4 (forced host) devices gives the same result as one device: the
generic `padded_map`, batched simulation, the basin classification and the bifurcation
diagram; and a batched gait search on 4 devices finds gaits that the 4-device hybrid
simulation returns to."""

import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp, numpy as np
    import vhcjax as vj
    from vhcjax._batching import default_mesh, padded_map

    assert len(jax.devices()) == 4, jax.devices()

    def same(a, b):
        # Identical up to rounding: partitioned programs may contract a*b+c into FMAs
        # differently (measured differences <= 2e-15); result codes must match exactly.
        a, b = np.asarray(a), np.asarray(b)
        if np.issubdtype(a.dtype, np.floating):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-13)
        else:
            np.testing.assert_array_equal(a, b)
    x0 = jnp.array([0.2186688, -0.32338856, -1.09238359, -0.37737395])
    slopes = jnp.deg2rad(jnp.linspace(2.0, 4.0, 6))  # 6 members: padded to 8 on 4 devices

    def run(psi):
        sim = vj.simulate(vj.CompassGait(psi=psi), x0, 3, config=vj.FAST_CONFIG)
        return sim.steps.period, sim.steps.x_plus, vj.result_codes(sim.result)

    run_many = jax.jit(jax.vmap(run))
    devices_seen = []

    def fn(psis):
        devices_seen.append(len(psis.sharding.device_set))
        return run_many(psis)

    four = padded_map(fn, slopes)
    one = padded_map(fn, slopes, mesh=default_mesh(jax.devices()[:1]))
    assert devices_seen == [4, 1], devices_seen  # the padded chunk split over 4 devices
    for a, b in zip(four, one):
        same(a, b)
    print("OK", np.asarray(four[0]).shape)

    # library entry points shard their batches over all local devices by themselves
    from vhcjax.robustness._basin import classify_section_points
    from vhcjax.stability import bifurcation_diagram

    m = vj.CompassGait()
    z_star = jnp.array([0.2186688, -1.09238359, -0.37737395])
    pts = z_star + jnp.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.0], [0.05, -0.3, 0.0],
                              [-0.04, 0.2, 0.1], [0.3, 0.5, 0.0], [0.0, 0.05, 0.0]])
    kw = dict(num_steps=6, chunk=6, config=vj.FAST_CONFIG)
    b4 = classify_section_points(m, z_star, pts, **kw)
    b1 = classify_section_points(m, z_star, pts, mesh=default_mesh(jax.devices()[:1]), **kw)
    for k in b1:
        same(b4[k], b1[k])
    psis = np.radians([2.5, 3.0, 3.5])
    zs = np.repeat(np.asarray(z_star)[None], 3, axis=0)
    d4 = bifurcation_diagram(psis, zs, num_transient=3, num_record=2)
    d1 = bifurcation_diagram(psis, zs, num_transient=3, num_record=2,
                             mesh=default_mesh(jax.devices()[:1]))
    same(d4.periods, d1.periods)
    same(d4.result, d1.result)
    print("LIBRARY OK", sorted(set(b4["label"].tolist())), d4.periods.shape)

    # batched simulation: 4 devices == 1 device == unbatched
    X = x0 + 0.01 * jnp.arange(6)[:, None] * jnp.array([1.0, -1.0, 0.0, 0.0])
    s4 = vj.simulate_batch(m, X, 3, config=vj.FAST_CONFIG)
    s1 = vj.simulate_batch(m, X, 3, config=vj.FAST_CONFIG, mesh=default_mesh(jax.devices()[:1]))
    same(s4.steps.x_plus, s1.steps.x_plus)
    same(vj.result_codes(s4.result), vj.result_codes(s1.result))
    single = vj.simulate(m, X[4], 3, config=vj.FAST_CONFIG)
    same(s4.steps.x_plus[4], single.steps.x_plus)
    print("SIMULATE OK", s4.steps.period.shape)

    # batched gait search split over 4 devices (3 slopes padded to 8): each gait is a
    # fixed point of the hybrid simulation (an independent computation)
    seeds = jnp.array([[0.21, -1.06, -0.45], [0.22, -1.09, -0.38], [0.22, -1.12, -0.3]])
    g = vj.find_gaits(m, seeds, psi=psis, method="shooting")
    assert np.all(np.asarray(g.result == vj.RESULTS.successful))
    x_star = jnp.stack([g.a, -g.a - 2 * jnp.asarray(psis), g.b, g.f], axis=1)
    ret = [vj.simulate_batch(vj.CompassGait(psi=p), x_star[i:i + 1], 1).steps.x_plus[0, 0]
           for i, p in enumerate(psis)]
    err = float(np.max(np.abs(np.asarray(jnp.stack(ret)) - np.asarray(x_star))))
    assert err < 1e-8, err
    print("GAITS OK", err)
    """
)


def test_batch_sharded_over_four_cpu_devices_matches_one_device():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4")
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "OK (6, 3)" in out.stdout
    assert "LIBRARY OK" in out.stdout and "(3, 2)" in out.stdout
    assert "SIMULATE OK (6, 3)" in out.stdout
    assert "GAITS OK" in out.stdout


def test_in_chunks_runs_chunks_concurrently_and_keeps_their_order():
    """With several workers the chunks run from host threads at once (each chunk here waits
    until two have started) and the results come back in batch order."""
    import threading

    import jax.numpy as jnp
    import numpy as np

    from vhcjax._batching import in_chunks

    started = threading.Barrier(2, timeout=30)
    threads = set()

    def fn(i, j):
        threads.add(threading.get_ident())
        if i < 4:  # the first two chunks: deadlocks unless they run concurrently
            started.wait()
        return {"x": jnp.arange(i, j, dtype=float), "y": jnp.full((j - i, 2), float(i))}

    out = in_chunks(fn, 7, 2, workers=2)
    np.testing.assert_array_equal(np.asarray(out["x"]), np.arange(7.0))
    np.testing.assert_array_equal(np.asarray(out["y"][:, 0]), [0, 0, 2, 2, 4, 4, 6])
    assert len(threads) == 2
    serial = in_chunks(
        lambda i, j: {"x": jnp.arange(i, j, dtype=float), "y": jnp.full((j - i, 2), float(i))}, 7, 2
    )
    np.testing.assert_array_equal(np.asarray(serial["y"]), np.asarray(out["y"]))


def test_host_workers_one_per_cpu_core_or_as_set(monkeypatch):
    import jax

    from vhcjax._batching import default_mesh, host_workers

    monkeypatch.delenv("VHCJAX_HOST_WORKERS", raising=False)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if jax.devices()[0].platform == "cpu":
        assert host_workers(default_mesh(jax.devices()[:1])) == max(1, cores)
    monkeypatch.setenv("VHCJAX_HOST_WORKERS", "3")
    assert host_workers() == 3
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv("VHCJAX_HOST_WORKERS", bad)
        with pytest.raises(ValueError, match="VHCJAX_HOST_WORKERS must be a positive integer"):
            host_workers()


def test_padded_map_one_padding_rule():
    """Chunks of one padded size (a power of two, at most `max_chunk`), padded with copies
    of their first member and cut back; the results are those of the members alone."""
    import jax.numpy as jnp
    import numpy as np

    from vhcjax._batching import padded_map

    sizes, firsts = [], []  # chunks may run at once from host threads: compare sorted

    def fn(x, y):
        sizes.append(x.shape[0])
        firsts.append((float(x[0]), float(x[-1])))  # first and last member of the chunk
        return {"sum": x + y[:, 0], "y": y}

    x = np.arange(300.0)
    y = np.stack([np.arange(300.0) * 2, np.ones(300)], axis=1)
    out = padded_map(fn, x, y, max_chunk=128)
    assert sizes == [128, 128, 128]  # 300 members: three chunks of 128, the last padded
    assert sorted(firsts) == [(0.0, 127.0), (128.0, 255.0), (256.0, 256.0)]  # padded: copies
    np.testing.assert_array_equal(np.asarray(out["sum"]), 3 * x)
    np.testing.assert_array_equal(np.asarray(out["y"]), y)
    sizes.clear()
    small = padded_map(fn, jnp.arange(5.0), jnp.ones((5, 2)))
    assert sizes == [8] and small["sum"].shape == (5,)
