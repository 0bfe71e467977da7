"""`vhcjax reproduce --quick`: report, figures, results.json, computed verdicts."""

import json
import math

import numpy as np
import pytest
from _text import assert_plain_text

from vhcjax.cli import main
from vhcjax.reproduce import N_SECTIONS, _report as R, _run, reproduce


# ---- the verdict rule (no computation) ---------------------------------------------------
def test_printed_unit():
    assert R.printed_unit("0.735") == pytest.approx(1e-3)
    assert R.printed_unit("-1.092386") == pytest.approx(1e-6)
    assert R.printed_unit("4.4") == pytest.approx(0.1)
    assert R.printed_unit("10") == 1.0
    assert R.printed_unit("-1.2e-3") == pytest.approx(1e-4)
    assert R.printed_unit("+2.50") == pytest.approx(1e-2)


def test_verdict_digit_rule():
    # half a unit of 0.735 is 5e-4
    assert R.verdict("0.735", 0.7354) == "agrees"
    assert R.verdict("0.735", 0.7346) == "agrees"
    assert R.verdict("0.735", 0.7343464) == "last digit off"  # 6.5e-4 > 5e-4
    assert R.verdict("0.735", 0.7336) == "last digit off"
    assert R.verdict("0.735", 0.7334) == "differs"  # 1.6e-3 > 1.5e-3
    assert R.verdict("-1.805654", -1.805679) == "differs"
    assert R.verdict("0.218669", 0.2186688) == "agrees"
    assert R.verdict("4.4", 4.390898) == "agrees"
    assert R.verdict("4.857", 4.29149) == "differs"
    assert R.verdict("10", 11) == "last digit off"
    assert R.verdict("10", float("nan")) == "not computed"
    assert R.verdict("10", None) == "not computed"


def test_thesis_table_parses():
    """Every thesis value is a number string; the report's digit rule needs it."""
    for eq, vals in R.THESIS.items():
        for k, s in vals.items():
            assert isinstance(s, str) and math.isfinite(float(s)), (eq, k, s)
    # (7.5) is (a, e, b, f) of (7.4) as printed, (7.10) of (7.9), (7.14) of (7.13)
    for g, x in (("7.4", "7.5"), ("7.9", "7.10"), ("7.13", "7.14")):
        t, s = R.THESIS[g], R.THESIS[x]
        assert (s["q1"], s["q2"], s["dq1"], s["dq2"]) == (t["a"], t["e"], t["b"], t["f"])


def test_interrupted_run_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    """A run stopped in a section (Ctrl-C) writes no figure and no report into the
    folder, and leaves the report of an earlier run whole."""
    (tmp_path / "report.md").write_text("earlier report")

    def draws(run, sec):
        with open(f"{run.out_dir}/fig.png", "wb") as f:
            f.write(b"png")
        sec.figures.append("fig.png")

    def stopped(run, sec):
        raise KeyboardInterrupt

    monkeypatch.setattr(_run, "SECTIONS", [("a", "draws", draws), ("b", "stopped", stopped)])
    with pytest.raises(KeyboardInterrupt):
        reproduce(str(tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.md"]
    assert (tmp_path / "report.md").read_text() == "earlier report"


# ---- the command (quick mode) ------------------------------------------------------------
@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    rc = main(["reproduce", "--quick", "--quiet", "--out", str(out)])
    assert rc == 0
    return out, json.loads((out / "results.json").read_text()), (out / "report.md").read_text()


def _row(res, section, quantity_prefix):
    rows = [
        r for r in res["sections"][section]["rows"] if r["quantity"].startswith(quantity_prefix)
    ]
    assert rows, (section, quantity_prefix)
    return rows[0]


def test_report_sections_and_figures(quick_run):
    out, res, report = quick_run
    assert res["mode"] == "quick"
    assert len(res["sections"]) == N_SECTIONS
    for key, sec in res["sections"].items():
        assert f"## {sec['title']}" in report, key
        assert sec["rows"], key
        for f in sec["figures"]:
            p = out / f
            assert p.exists() and p.stat().st_size > 10_000, f
            assert f"![{f}]({f})" in report
    figs = [f for s in res["sections"].values() for f in s["figures"]]
    for needed in (
        "fig7_1_multipliers_stable_3deg.png",
        "fig7_2_4_stable_3deg_states.png",
        "fig7_5_7_perturbed_3deg_phase.png",
        "fig7_8_multipliers_unstable_3deg.png",
        "fig7_15_multipliers_5deg.png",
        "sweep_families.png",
        "bifurcation.png",
        "basin_q1_dq1.png",
        "push.png",
    ):
        assert needed in figs
    assert "total run time" in report and "jax" in report and "device" in report


def test_report_reads_in_plain_words(quick_run):
    """The report opens with its findings, built from the computed numbers; it holds no
    internal names or reprs, explains every code it prints, and says each cross-check
    once (below its table), not on every row."""
    _, res, report = quick_run
    assert_plain_text(report)
    findings = report.split("## Findings", 1)[1].split("##", 1)[0]
    pd = res["sections"]["doubling"]["results"]["poincare"]
    assert f"period-doubles at {pd:.5f} deg" in findings
    assert "The stable gait at 3 deg (7.4) is confirmed" in findings
    assert "Period pattern" not in report and "differs (differs" not in report
    assert "recorded step periods repeat, by slope: every step from" in report
    for sec in res["sections"].values():
        text = report.split(f"## {sec['title']}\n", 1)[1].split("\n## ", 1)[0]
        rows = [line for line in text.splitlines() if line.startswith("|")]
        below = [line for line in text.splitlines() if not line.startswith("|")]
        for check in {str(r["cross_check"]) for r in sec["rows"]}:
            said = [
                line
                for line in below
                if line.split(". ", 1)[-1] == check or line.split(": ", 1)[-1] == check
            ]
            assert len(said) == 1, (sec["title"], check)
            assert not any(check in row for row in rows), (sec["title"], check)


def test_verdicts_are_computed(quick_run):
    _, res, _ = quick_run
    # every row with a thesis number carries the verdict of the digit rule on its values
    n = 0
    for sec in res["sections"].values():
        for r in sec["rows"]:
            if r["equation"] and isinstance(r["ours"], (int, float)):
                assert r["verdict"] == R.verdict(r["thesis"], r["ours"]), r
                n += 1
    assert n > 60
    a = _row(res, "stable3", "a")
    assert a["thesis"] == "0.218669" and a["verdict"] == "agrees"
    h = _row(res, "stable3", "h")
    assert h["verdict"] == "differs"  # thesis h is 25 units off (docs/gait_search.md)


def test_thesis_multipliers_differ_ours_agree(quick_run):
    _, res, _ = quick_run
    sec = res["sections"]["eig3"]
    for q in ("lambda1", "Re lambda2,3", "|Im lambda2,3|"):
        assert _row(res, "eig3", q)["verdict"] == "differs"
    assert sec["results"]["max_diff"] < 1e-6  # transverse vs Poincare
    assert res["sections"]["unstable3"]["results"]["max_diff"] < 1e-6
    assert res["sections"]["five"]["results"]["max_diff"] < 1e-6
    # the unstable gait's perturbations grow in simulation by its largest multiplier
    lam = _row(res, "unstable3", "lambda3")["ours"]
    growth = res["sections"]["unstable3"]["results"]["simulated_growth_per_step"]
    assert abs(growth - lam) < 0.05 * lam


def test_key_numbers(quick_run):
    _, res, _ = quick_run
    S = res["sections"]
    # VHC gaits and the hybrid simulator agree
    for k in ("stable3", "unstable3", "stable5", "stable287"):
        assert S["gaits"]["results"][k]["result"] == "successful"
        assert S["gaits"]["results"][k]["hybrid_step_x_minus_diff"] < 1e-8
    assert S["uphill"]["results"]["result"] == "infeasible_uphill"
    assert S["uphill"]["results"]["reversal_diff"] < 1e-8
    # 5 degrees: period-1 gait unstable (multiplier ~ -1.54), stable period-4 attractor
    lead = _row(res, "five", "largest multiplier")["ours"]
    assert -1.6 < lead < -1.5
    assert _row(res, "five", "minimal period")["ours"] == 4
    ev4 = np.array(S["five"]["results"]["period4"]["multipliers"])
    fd4 = np.array(S["five"]["results"]["period4"]["multipliers_fd"])
    assert np.max(np.hypot(*ev4.T)) < 1 and np.max(np.abs(ev4 - fd4)) < 1e-5
    assert S["five"]["results"]["period4_return"] < 1e-8
    # period doubling: two multiplier computations give the same slope
    pd = S["doubling"]["results"]
    assert abs(pd["poincare"] - pd["transverse"]) < 1e-4
    assert 4.38 < pd["poincare"] < 4.40


def test_the_gaits_section_by_each_method(quick_run, tmp_path):
    """`reproduce --method`: the gaits of chapter 7 by shooting alone are those of the
    default run (the VHC search), and the section names the method of each."""
    from vhcjax.reproduce import _sections as S

    auto = quick_run[1]["sections"]["gaits"]["results"]
    run = S.Run(str(tmp_path), _run.SIZES["quick"], "shooting")
    sec = R.Section("gaits", "gaits")
    S.gaits(run, sec)
    assert any("by shooting" in str(row) for row in sec.rows)
    assert "shooting (thesis Problem 2) alone" in " ".join(sec.notes)
    for key in ("stable3", "unstable3", "stable5", "stable287"):
        assert auto[key]["found_by"] == "vhc" and sec.results[key]["found_by"] == "shooting"
        for p in ("a", "b", "f"):
            assert math.isclose(auto[key][p], sec.results[key][p], rel_tol=0, abs_tol=1e-9), (
                key,
                p,
            )
        assert math.isclose(auto[key]["T"], sec.results[key]["T"], rel_tol=1e-9)
