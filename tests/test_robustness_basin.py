"""Basin of attraction: classification spot-checked by independent long simulations,
bisection brackets verified by simulation, Wilson interval against known values."""

import csv

import numpy as np
import pytest
from _robust import long_walk, returns_to, stable_gait

import vhcjax as vj
from vhcjax.robustness._basin import axis_directions, wilson_interval
from vhcjax.robustness._recovery import CONVERGED, FELL


@pytest.fixture(scope="module")
def slice8():
    model, z, _, _ = stable_gait()
    return vj.basin_slice(
        model, z, axes=(0, 1), half_widths=(0.08, 0.4), shape=(8, 8), num_steps=50, chunk=64
    )


def test_slice_classification_spot_checked(slice8):
    model, z, x_star, _ = stable_gait()
    b = slice8
    assert b.label.shape == (8, 8)
    conv = np.argwhere(b.label == CONVERGED)
    fell = np.argwhere(b.label == FELL)
    assert len(conv) >= 2 and len(fell) >= 2  # the slice straddles the basin boundary
    assert 0 < b.fraction < 1
    cell = (b.offsets_x[1] - b.offsets_x[0]) * (b.offsets_y[1] - b.offsets_y[0])
    assert np.isclose(b.area, np.sum(b.label == CONVERGED) * cell)
    rng = np.random.default_rng(0)
    for (iy, ix), expect in [(p, True) for p in conv[rng.choice(len(conv), 2, replace=False)]] + [
        (p, False) for p in fell[rng.choice(len(fell), 2, replace=False)]
    ]:
        zz = np.array(z, dtype=float)
        zz[0] += b.offsets_x[ix]
        zz[1] += b.offsets_y[iy]
        sim = long_walk(model, model.section_to_state(zz))
        if expect:
            assert returns_to(sim, x_star)
            assert 0 < b.steps[iy, ix] <= 50
        else:
            assert vj.result_names(sim.result) != "successful"
            # It fell on the same step in both simulations.
            assert int(sim.num_successful) + 1 == b.steps[iy, ix]


def test_chunks_on_host_threads_give_the_same_classification(slice8, monkeypatch):
    """Two chunks of the slice's 64-member program run at once from host threads (one per
    CPU core) and classify every point as the one-chunk slice did, in order."""
    from vhcjax.robustness._basin import classify_section_points

    model = stable_gait()[0]
    gx, gy = np.meshgrid(slice8.offsets_x, slice8.offsets_y)
    pts = np.repeat(np.asarray(slice8.z_star)[None], gx.size, 0)
    pts[:, 0] += gx.ravel()
    pts[:, 1] += gy.ravel()
    monkeypatch.setenv("VHCJAX_HOST_WORKERS", "2")
    out = classify_section_points(
        model, slice8.z_star, np.concatenate([pts, pts[::-1]]), num_steps=50, chunk=64
    )
    for key, ref in (("label", slice8.label), ("steps", slice8.steps), ("result", slice8.result)):
        np.testing.assert_array_equal(out[key][:64].reshape(8, 8), ref)
        np.testing.assert_array_equal(out[key][64:], out[key][:64][::-1])


@pytest.mark.parametrize(("workers", "expected"), [("2", 256), ("1", 1024)])
def test_concurrent_chunks_are_at_most_max_dispatch(monkeypatch, workers, expected):
    """Two concurrent 1,024-member chunks of the basin program deadlock XLA's CPU runtime
    (`vhcjax basin` with its defaults hung): with several host workers a chunk holds at
    most `MAX_DISPATCH` points; one worker keeps the chunk asked for."""
    import vhcjax.robustness._basin as B

    seen = {}

    def record(fn, *args, max_chunk, **kwargs):
        seen["max_chunk"] = max_chunk
        raise RuntimeError("recorded")

    monkeypatch.setattr(B, "padded_map", record)
    monkeypatch.setenv("VHCJAX_HOST_WORKERS", workers)
    with pytest.raises(RuntimeError, match="recorded"):
        B.classify_section_points(vj.CompassGait(), np.zeros(3), np.zeros((4096, 3)), chunk=1024)
    assert seen["max_chunk"] == expected


def test_max_converging_perturbation_brackets():
    model, z, x_star, _ = stable_gait()
    d = axis_directions(3)[:2]  # +q1, -q1
    th = vj.max_converging_perturbation(model, z, d, 0.3, iterations=8, scan=4)
    assert th.bracketed.all()
    assert np.all(th.hi - th.lo <= 0.3 / 5 / 2**8 * 1.0001)
    for i in range(2):
        ok = long_walk(model, model.section_to_state(z + th.lo[i] * d[i]))
        bad = long_walk(model, model.section_to_state(z + th.hi[i] * d[i]))
        assert returns_to(ok, x_star)
        assert not returns_to(bad, x_star, tol=1e-4)


def test_a_basin_resumes_from_its_checkpoint(slice8, tmp_path, monkeypatch):
    """The slice's points with a checkpoint folder, in parts of 24, stopped after the
    first part: the same call again computes only the other two, and the result equals
    the slice's; a part cut short is computed again; other inputs are refused."""
    import vhcjax.robustness._basin as basin

    model = stable_gait()[0]
    gx, gy = np.meshgrid(slice8.offsets_x, slice8.offsets_y)
    pts = np.repeat(np.asarray(slice8.z_star)[None], gx.size, 0)
    pts[:, 0] += gx.ravel()
    pts[:, 1] += gy.ravel()
    real, computed, allowed = basin.classify_section_points, [], [1]

    class Stopped(Exception):  # a Ctrl-C or a killed job, as far as the folder can tell
        pass

    def counted(model, z_star, z, **kwargs):
        if kwargs.get("checkpoint") is None:  # a part, not the call with the folder
            if len(computed) == allowed[0]:
                raise Stopped
            computed.append(len(z))
        return real(model, z_star, z, **kwargs)

    monkeypatch.setattr(basin, "classify_section_points", counted)
    ck = tmp_path / "ck"
    run = lambda: counted(  # noqa: E731
        model, slice8.z_star, pts, num_steps=50, chunk=64, checkpoint=ck, chunk_points=24
    )
    with pytest.raises(Stopped):
        run()
    assert sorted(p.name for p in ck.iterdir()) == [
        "manifest.json",
        "points-000000000-000000024.csv",
    ]
    allowed[0] = 99
    computed.clear()
    out = run()
    assert computed == [24, 16]
    for key, ref in (("label", slice8.label), ("steps", slice8.steps), ("result", slice8.result)):
        np.testing.assert_array_equal(out[key].reshape(8, 8), ref)
    with open(ck / "points-000000024-000000048.csv", newline="") as fh:
        part = list(csv.DictReader(fh))
    assert [int(r["index"]) for r in part] == list(range(24, 48))
    start = [[float(r[f"z{i}"]) for i in range(3)] for r in part]
    np.testing.assert_array_equal(start, pts[24:48])  # exact: floats written in full
    # a part cut short (a copy interrupted, say) is computed again, alone
    cut = ck / "points-000000024-000000048.csv"
    cut.write_text(cut.read_text()[:-40])
    computed.clear()
    again = run()
    assert computed == [24]
    for key in out:
        np.testing.assert_array_equal(again[key], out[key])
    # another walker in the same folder: refused, naming what differs
    with pytest.raises(ValueError, match="other settings .*inputs"):
        counted(model.with_slope(0.06), slice8.z_star, pts, num_steps=50, checkpoint=ck)


def test_wilson_interval():
    lo, hi = wilson_interval(50, 100)
    assert np.isclose(lo, 0.4038, atol=1e-4) and np.isclose(hi, 0.5962, atol=1e-4)
    lo, hi = wilson_interval(0, 20)
    assert lo == 0.0 and np.isclose(hi, 0.1611, atol=1e-4)


def test_basin_volume_counts(slice8):
    model, z, _, _ = stable_gait()
    v = vj.basin_volume(model, z, [0.05, 0.2, 0.5], num_samples=64, chunk=64)
    assert sum(v.counts.values()) == 64
    assert v.interval[0] <= v.fraction <= v.interval[1]
    assert np.isclose(v.volume, v.fraction * 0.1 * 0.4 * 1.0)


@pytest.mark.parametrize(
    "argv",
    [
        ["basin", "--axes", "q1,foo"],
        ["basin", "--axes", "q1,q1"],
        ["basin", "--grid", "1", "5"],
        ["basin", "--half-widths", "0", "0.1"],
        ["push", "--phases", "0"],
        ["contraction", "--scale", "-1"],
        ["slope-sensitivity", "--heights-mm", "nan"],
    ],
)
def test_cli_rejects_bad_input(argv, capsys):
    from vhcjax.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"vhcjax {argv[0]}: error:") and err.count("\n") == 1


def test_basin_slice_refuses_a_grid_it_cannot_draw():
    z = np.array([0.2187, -1.0924, -0.3774])
    for kw in (
        {"half_widths": (-0.1, 0.4)},
        {"half_widths": (0.1, float("nan"))},
        {"shape": (0, 5)},
        {"axes": (1, 1)},
        {"axes": (0, 3)},
    ):
        with pytest.raises(ValueError, match="basin_slice"):
            vj.basin_slice(vj.CompassGait(), z, **kw)


def test_basin_refuses_a_point_that_is_not_a_gait():
    """A slice or a volume around a point one step moves by 3e-2 would count a start
    within `tol` of it as converged; both are refused. A grid of one point is the gait."""
    model, z, _, _ = stable_gait()
    off = np.asarray(z) + np.array([0.01, 0.0, 0.0])
    with pytest.raises(ValueError, match="basin_slice: z_star is not a period-1 gait"):
        vj.basin_slice(model, off, shape=(3, 3))
    with pytest.raises(ValueError, match="basin_volume: z_star is not a period-1 gait"):
        vj.basin_volume(model, off, [0.05, 0.2, 0.5], num_samples=8)
    for kw in ({"half_widths": [0.05, 0.2]}, {"half_widths": [0.05, 0.2, 0.5], "num_samples": 0}):
        with pytest.raises(ValueError, match="basin_volume"):
            vj.basin_volume(model, z, **kw)
    one = vj.basin_slice(model, z, shape=(1, 1), num_steps=5, chunk=64)
    assert one.offsets_x.tolist() == [0.0] and one.offsets_y.tolist() == [0.0]
    assert one.label.tolist() == [[CONVERGED]]


def test_cli_basin_with_a_checkpoint_gives_the_same_json_again(tmp_path, capsys):
    """`vhcjax basin --checkpoint`: the same JSON as without, again from the folder alone
    (slice and volume samples in their own parts); another grid there is refused."""
    import json

    from vhcjax.cli import main

    argv = ["basin", "--grid", "8", "8", "--chunk", "64", "--volume-samples", "64", "--json"]
    assert main([*argv, "--quiet"]) == 0
    plain = json.loads(capsys.readouterr().out)
    ck = tmp_path / "ck"
    for _ in range(2):
        assert main([*argv, "--quiet", "--checkpoint", str(ck)]) == 0
        assert json.loads(capsys.readouterr().out) == plain
    assert sorted(p.name for p in (ck / "slice").iterdir()) == [
        "manifest.json",
        "points-000000000-000000064.csv",
    ]
    assert len(list((ck / "volume").iterdir())) == 2
    assert main(["basin", "--grid", "8", "9", "--quiet", "--checkpoint", str(ck)]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds a run with other settings" in err and "\n" not in err
