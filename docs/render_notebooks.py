"""Run the notebooks and write their pages of the documentation site.

    python docs/render_notebooks.py               # every notebook
    python docs/render_notebooks.py 05_new_model  # some of them

Each `notebooks/NN_name.py` (jupytext percent format: `# %%` cells) runs top to bottom in
this process, at the notebooks' quick sizes unless `VHCJAX_FULL=1`. `docs/notebooks/NN_name.md`
gets its text, its code, what each cell printed and the figures the cell wrote (copied to
`docs/notebooks/figures/`, named `NN_...` by the notebook). The page records the SHA-256 of
its notebook's source, and `tests/test_docs.py` fails when a notebook has changed since
its page was written: render it again and commit both. The site build only reads these
pages; it never runs a notebook.
"""

import contextlib
import hashlib
import io
import os
import pathlib
import shutil
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"
PAGES = ROOT / "docs" / "notebooks"
FIGURES = PAGES / "figures"
#: The first line of a rendered page: the notebook's SHA-256 (see `source_hash`).
HEADER = "<!-- rendered by docs/render_notebooks.py from notebooks/{name} (sha256 {digest}) -->"


def source_hash(path):
    """SHA-256 of a notebook's source, as its page records it."""
    return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()


def cells(source):
    """`[(kind, text)]` of a percent-format notebook, kind `"markdown"` or `"code"`; the
    jupytext header and empty cells are left out, markdown loses its `# ` prefixes."""
    lines = source.splitlines()
    if lines and lines[0] == "# ---":  # the jupytext header, up to its closing `# ---`
        lines = lines[lines.index("# ---", 1) + 1 :]
    out = []
    for line in lines:
        if line.startswith("# %%"):
            out.append(["markdown" if "[markdown]" in line else "code", []])
        elif out:
            out[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"text before the first cell: {line!r}")
    result = []
    for kind, body in out:
        if kind == "markdown":
            body = [ln[2:] if ln.startswith("# ") else ln.lstrip("#") for ln in body]
        text = "\n".join(body).strip("\n")
        if text.strip():
            result.append((kind, text))
    return result


def _snapshot(folder):
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()} if folder.exists() else {}


def render(path):
    """Run notebook `path` and write its page; returns the page's path."""
    path = pathlib.Path(path)
    prefix = path.name.split("_", 1)[0] + "_"
    source = path.read_text()
    parts = [HEADER.format(name=path.name, digest=source_hash(path)), ""]
    sizes = "full sizes" if os.environ.get("VHCJAX_FULL") == "1" else "quick sizes"
    note = (
        f"!!! note\n    The output of `notebooks/{path.name}`, run top to bottom at its {sizes}"
        " on a CPU by `docs/render_notebooks.py`. Run the file yourself (`python"
        f" notebooks/{path.name}`, or open it in Jupyter with jupytext); `VHCJAX_FULL=1`"
        " for full sizes."
    )
    namespace = {"__name__": "__main__", "__file__": str(path)}
    work = pathlib.Path(tempfile.mkdtemp(prefix="vhcjax_render_"))
    written = work / "figures"
    old_cwd, old_out = os.getcwd(), os.environ.get("VHCJAX_NOTEBOOK_OUT")
    os.chdir(work)
    os.environ["VHCJAX_NOTEBOOK_OUT"] = "figures"  # printed paths read `figures/...`
    start = time.perf_counter()
    try:
        for i, (kind, text) in enumerate(cells(source)):
            if kind == "markdown":
                parts += [text, ""]
                if i == 0:  # after the title and introduction
                    parts += [note, ""]
                continue
            parts += ["```python", text, "```", ""]
            before = _snapshot(written)
            printed = io.StringIO()
            with contextlib.redirect_stdout(printed):
                exec(compile(text + "\n", f"{path.name}, cell {i}", "exec"), namespace)
            if printed.getvalue().strip():
                parts += ["```text", printed.getvalue().rstrip("\n"), "```", ""]
            after = _snapshot(written)
            for name in sorted((n for n in after if before.get(n) != after[n]), key=after.get):
                if not name.startswith(prefix):
                    raise ValueError(f"{path.name} wrote {name}: figures must start {prefix}")
                parts += [f"![{name}](figures/{name})", ""]
        for stale in FIGURES.glob(prefix + "*"):
            stale.unlink()
        FIGURES.mkdir(parents=True, exist_ok=True)
        for figure in written.iterdir() if written.exists() else ():
            shutil.copy(figure, FIGURES / figure.name)
    finally:
        os.chdir(old_cwd)
        if old_out is None:
            os.environ.pop("VHCJAX_NOTEBOOK_OUT", None)
        else:
            os.environ["VHCJAX_NOTEBOOK_OUT"] = old_out
        shutil.rmtree(work, ignore_errors=True)
        import matplotlib.pyplot as plt

        plt.close("all")
    page = PAGES / (path.stem + ".md")
    page.write_text("\n".join(parts).rstrip("\n") + "\n")
    print(f"{path.name}: {time.perf_counter() - start:.0f} s -> {page.relative_to(ROOT)}")
    return page


def main(names):
    os.environ.setdefault("MPLBACKEND", "Agg")
    sys.path.insert(0, str(ROOT / "src"))  # the library of this source tree
    paths = sorted(NOTEBOOKS.glob("[0-9]*.py"))
    unknown = [n for n in names if not any(n in (p.stem, p.name) for p in paths)]
    if unknown:
        raise SystemExit(f"no such notebooks: {unknown} (there are {[p.stem for p in paths]})")
    if names:
        paths = [p for p in paths if p.stem in names or p.name in names]
    for path in paths:
        render(path)


if __name__ == "__main__":
    main(sys.argv[1:])
