"""Basin slice of the kneed walker (docs/figures/kneed_walker_basin.png): a 21 x 21 grid in
(q1, dq1) around the gait on the 0.0504 rad slope, 40 steps per point. Run from
docs/figures."""

import time

import jax.numpy as jnp
import numpy as np

import vhcjax as vj


def main(n=21):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = vj.KneedWalker(psi=jnp.asarray(0.0504))
    fp = vj.fixed_point(m, jnp.array([0.19, -1.10, -0.04]))
    t = time.time()
    bs = vj.basin_slice(
        m, fp.z, axes=(0, 1), half_widths=(0.08, 0.6), shape=(n, n), num_steps=40, chunk=512
    )
    print("time", time.time() - t, "fraction", bs.fraction, "reach", bs.max_converging)
    conv = np.asarray(bs.label) == vj.CONVERGED
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.pcolormesh(
        fp.z[0] + bs.offsets_x, fp.z[1] + bs.offsets_y, conv, cmap="Greens", shading="nearest"
    )
    ax.plot(fp.z[0], fp.z[1], "r*", ms=10, label="gait")
    ax.set_xlabel("q1 after heel strike (rad)")
    ax.set_ylabel("dq1 after heel strike (rad/s)")
    ax.set_title(
        f"Kneed walker, slope 0.0504 rad: basin slice {n}x{n}\n"
        "(green: back to the gait within 40 steps)",
        fontsize=9,
    )
    ax.legend()
    fig.tight_layout()
    fig.savefig("kneed_walker_basin.png", dpi=110)


if __name__ == "__main__":
    main()
