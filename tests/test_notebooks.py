"""Every notebook runs top to bottom (small sizes).

They run in the test process (`runpy`), not a subprocess: the library's jitted entry
points are shared, so a notebook reuses what earlier tests compiled instead of paying
every compilation again.
"""

import pathlib
import runpy

import matplotlib
import pytest

matplotlib.use("Agg")

NOTEBOOKS = sorted(pathlib.Path(__file__).parent.parent.joinpath("notebooks").glob("[0-9]*.py"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_runs(path, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    monkeypatch.delenv("VHCJAX_FULL", raising=False)
    out = tmp_path / "figures"
    monkeypatch.setenv("VHCJAX_NOTEBOOK_OUT", str(out))
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    try:
        runpy.run_path(str(path), run_name="__main__")
    finally:
        plt.close("all")
    # Nothing written into the working directory (the repository, when run by hand).
    assert list(work.iterdir()) == []
    # What the notebooks say they draw (no silent skip): thesis Figs 7.2-7.4 and the
    # walker animation (Fig 3.5); the new model's basin slice.
    drawn = {
        "01_quickstart.py": {"01_states.png", "01_phase.png", "01_periods.png", "01_walker.gif"},
        "05_new_model.py": {"05_basin.png"},
    }
    assert {p.name for p in out.iterdir()} >= drawn.get(path.name, set())
