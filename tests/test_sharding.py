"""A batch spread over 4 (forced host) devices gives the same result as one device: the
generic `batched_map`, the basin classification and the bifurcation diagram."""

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import jax, jax.numpy as jnp, numpy as np
    import vhcjax as vj
    from vhcjax._sharding import batched_map, default_mesh

    assert len(jax.devices()) == 4, jax.devices()
    x0 = jnp.array([0.2186688, -0.32338856, -1.09238359, -0.37737395])
    slopes = jnp.deg2rad(jnp.linspace(2.0, 4.0, 6))  # 6 members: padded to 8 on 4 devices

    def run(psi):
        sim = vj.simulate(vj.CompassGait(psi=psi), x0, 3, config=vj.FAST_CONFIG)
        return sim.steps.period, sim.steps.x_plus, sim.result._value

    four = batched_map(run, slopes)
    one = batched_map(run, slopes, mesh=default_mesh(jax.devices()[:1]))
    for a, b in zip(four, one):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    sharding = four[0].sharding
    print("OK", np.asarray(four[0]).shape, type(sharding).__name__)

    # library entry points shard their batches over all local devices by themselves
    from vhcjax._basin import classify_section_points
    from vhcjax._stability import bifurcation_diagram

    m = vj.CompassGait()
    z_star = jnp.array([0.2186688, -1.09238359, -0.37737395])
    pts = z_star + jnp.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.0], [0.05, -0.3, 0.0],
                              [-0.04, 0.2, 0.1], [0.3, 0.5, 0.0], [0.0, 0.05, 0.0]])
    kw = dict(num_steps=6, chunk=6, config=vj.FAST_CONFIG)
    b4 = classify_section_points(m, z_star, pts, **kw)
    b1 = classify_section_points(m, z_star, pts, mesh=default_mesh(jax.devices()[:1]), **kw)
    for k in b1:
        np.testing.assert_array_equal(b4[k], b1[k])
    psis = np.radians([2.5, 3.0, 3.5])
    zs = np.repeat(np.asarray(z_star)[None], 3, axis=0)
    d4 = bifurcation_diagram(psis, zs, num_transient=3, num_record=2)
    d1 = bifurcation_diagram(psis, zs, num_transient=3, num_record=2,
                             mesh=default_mesh(jax.devices()[:1]))
    np.testing.assert_array_equal(d4.periods, d1.periods)
    np.testing.assert_array_equal(d4.result, d1.result)
    print("LIBRARY OK", sorted(set(b4["label"].tolist())), d4.periods.shape)
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
