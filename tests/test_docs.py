"""The documentation: every public name on an API page, docstrings that name public
things only, and the notebooks rendered into the site, current with their sources."""

import ast
import html as html_module
import importlib.util
import inspect
import os
import pathlib
import re
import subprocess
import sys
import types

import pytest

import vhcjax

ROOT = pathlib.Path(__file__).resolve().parent.parent
API_PAGES = sorted((ROOT / "docs" / "api").glob("*.md"))


def _exported(module):
    """Public names that `module`'s source binds (re-exports, definitions, assignments),
    without the third-party modules it imports."""
    tree = ast.parse(pathlib.Path(module.__file__).read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.FunctionDef | ast.ClassDef):
            names.add(node.name)
    out = {}
    for name in sorted(names):
        obj = getattr(module, name, None)
        foreign = isinstance(obj, types.ModuleType) and not obj.__name__.startswith("vhcjax")
        if not name.startswith("_") and hasattr(module, name) and not foreign:
            out[name] = obj
    return out


def public_names():
    """`{qualified name: object}`: `vhcjax.NAME` and `vhcjax.MODULE.NAME` of the public
    modules that the package exposes (`vhcjax.plotting`, `vhcjax.trig`)."""
    out = {}
    for name, obj in _exported(vhcjax).items():
        out[f"vhcjax.{name}"] = obj
        if isinstance(obj, types.ModuleType):
            out.update({f"vhcjax.{name}.{n}": o for n, o in _exported(obj).items()})
    return out


def _directives():
    return {m for page in API_PAGES for m in re.findall(r"^::: (\S+)\s*$", page.read_text(), re.M)}


def _is_constant(obj):
    return not (callable(obj) or inspect.isclass(obj) or isinstance(obj, types.ModuleType))


def test_public_names_found():
    names = public_names()
    assert {"vhcjax.find_gait", "vhcjax.CompassGait", "vhcjax.plotting.plot_states"} <= set(names)
    assert "vhcjax.plotting.plot_phase_portrait" in names and "vhcjax.trig.sin" in names
    assert not any(n.split(".")[-1].startswith("_") for n in names)
    assert "vhcjax.jax" not in names and "vhcjax.stability" not in names


def test_every_public_name_on_an_api_page():
    """`::: vhcjax.NAME` (or `vhcjax.MODULE.NAME`) on a page of `docs/api/`; a module's
    directive shows only what the module itself defines (mkdocstrings leaves out the
    names it imports), and a constant may be named in the text instead."""
    directives = _directives()
    text = "\n".join(page.read_text() for page in API_PAGES)
    missing = []
    for qual, obj in public_names().items():
        parent = qual.rpartition(".")[0]
        if isinstance(obj, types.ModuleType) or qual in directives:
            continue
        if parent in directives and getattr(obj, "__module__", None) == parent:
            continue
        if _is_constant(obj) and f"`{qual}`" in text:
            continue
        missing.append(qual)
    assert not missing, f"public names on no API page (docs/api/*.md): {missing}"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site as CI builds it (`mkdocs build --strict`), from this source tree."""
    pytest.importorskip("mkdocs", reason="the docs extra (`pip install -e '.[docs]'`)")
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), NO_MKDOCS_2_WARNING="1")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    return out


def test_rendered_api_pages_show_every_public_name(site):
    """A heading for every public name in the built API pages: the check above, on what
    mkdocstrings rendered."""
    html = "\n".join(p.read_text() for p in (site / "api").rglob("index.html"))
    ids = set(re.findall(r'id="(vhcjax\.[A-Za-z0-9_.]+)"', html))
    missing = [
        qual
        for qual, obj in public_names().items()
        if not isinstance(obj, types.ModuleType)
        and qual not in ids
        and not (_is_constant(obj) and f"<code>{qual}</code>" in html)
    ]
    assert not missing, f"public names the built API pages do not show: {missing}"


def test_api_pages_name_public_objects_only():
    names = public_names()
    stray = sorted(d for d in _directives() if d not in names)
    assert not stray, f"API pages document names that are not public: {stray}"


def _shown_docstrings(obj):
    """The docstrings an API page shows for `obj`: its own and, for a class or a module,
    those of its public members defined there."""
    yield obj.__doc__ or ""
    if inspect.isclass(obj):
        members = vars(obj).items()
    elif isinstance(obj, types.ModuleType):
        members = [
            (k, v) for k, v in vars(obj).items() if getattr(v, "__module__", "") == obj.__name__
        ]
    else:
        return
    for name, member in members:
        if not name.startswith("_") and (callable(member) or isinstance(member, property)):
            yield getattr(member, "__doc__", None) or ""


def _private_names(public):
    """Names of functions and classes of vhcjax's modules that are not public, less those
    that are also public attributes, fields or argument names (a docstring naming an
    argument `direction` names no private function of that name)."""
    defined = set()
    for mname, module in list(sys.modules.items()):
        if mname.startswith("vhcjax.") and not mname.startswith("vhcjax.cli"):
            for name, obj in vars(module).items():
                if (inspect.isfunction(obj) or inspect.isclass(obj)) and getattr(
                    obj, "__module__", ""
                ).startswith("vhcjax"):
                    defined.add(name)
    shared = {q.rpartition(".")[2] for q in public}
    for obj in public.values():
        if inspect.isclass(obj):
            shared |= set(dir(obj)) | set(getattr(obj, "__annotations__", {}))
        if callable(obj):
            try:
                shared |= set(inspect.signature(obj).parameters)
            except (TypeError, ValueError):
                pass
    return defined - shared


def test_docstrings_name_public_things_only():
    """What an API page shows names no private module, function or class: a reader could
    not look it up."""
    public = public_names()
    private = _private_names(public)
    found = []
    for qual, obj in public.items():
        for doc in _shown_docstrings(obj):
            for code in re.findall(r"`([^`]+)`", doc):
                for ident in re.findall(
                    r"[A-Za-z_][A-Za-z_0-9]*(?:\.[A-Za-z_][A-Za-z_0-9]*)*", code
                ):
                    parts = ident.split(".")
                    underscored = any(p.startswith("_") and not p.startswith("__") for p in parts)
                    head = ".".join(parts[:2])
                    unlisted = (parts[0] == "vhcjax" and len(parts) > 1 and head not in public) or (
                        isinstance(public.get(head), types.ModuleType)
                        and len(parts) > 2
                        and ".".join(parts[:3]) not in public
                    )
                    if underscored or unlisted or ident in private:
                        found.append(f"{qual}: `{code}`")
    assert not found, "docstrings naming private things:\n" + "\n".join(found)


# ---- notebooks, rendered with their outputs into the site ----
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9]*.py"))
FIGURES = ROOT / "docs" / "notebooks" / "figures"


def _renderer():
    spec = importlib.util.spec_from_file_location(
        "render_notebooks", ROOT / "docs" / "render_notebooks.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_page_is_current(notebook):
    """Each notebook has a rendered page, written from its present source (the page
    records the source's SHA-256), with the figures it shows."""
    render = _renderer()
    page = ROOT / "docs" / "notebooks" / f"{notebook.stem}.md"
    again = f"render it again: python docs/render_notebooks.py {notebook.stem}"
    assert page.is_file(), again
    text = page.read_text()
    header = render.HEADER.format(name=notebook.name, digest=render.source_hash(notebook))
    assert text.splitlines()[0] == header, f"{notebook.name} changed since its page: {again}"
    for kind, cell in render.cells(notebook.read_text()):
        assert cell in text, f"a {kind} cell of {notebook.name} is not on its page"
    for figure in re.findall(r"\]\(figures/([^)]+)\)", text):
        assert (FIGURES / figure).is_file(), figure
    nav = (ROOT / "mkdocs.yml").read_text()
    assert f"notebooks/{notebook.stem}.md" in nav, f"{page.name} is in no nav entry of mkdocs.yml"


def test_notebook_figures_all_shown():
    shown = {
        f
        for p in FIGURES.parent.glob("*.md")
        for f in re.findall(r"\]\(figures/([^)]+)\)", p.read_text())
    }
    assert {p.name for p in FIGURES.iterdir()} == shown


def test_site_holds_the_executed_notebooks(site):
    """The built site has each notebook's page, with its printed output and figures."""
    for notebook in NOTEBOOKS:
        html = (site / "notebooks" / notebook.stem / "index.html").read_text()
        page = (ROOT / "docs" / "notebooks" / f"{notebook.stem}.md").read_text()
        for figure in re.findall(r"\]\(figures/([^)]+)\)", page):
            assert figure in html and (site / "notebooks" / "figures" / figure).is_file()
        printed = re.findall(r"^```text\n(.*)$", page, re.M)
        assert printed, f"{notebook.name} printed nothing"
        for line in printed:
            assert html_module.escape(line, quote=False) in html, line


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_uses_public_names_only(notebook):
    """Imports from vhcjax and attributes of its modules (`vj.find_gait`,
    `plotting.plot_basin`) are public names: a notebook teaches what a user can rely on."""
    public = public_names()
    modules = {"vhcjax": vhcjax} | {
        q: o for q, o in public.items() if isinstance(o, types.ModuleType)
    }
    aliases, bad = {}, []
    tree = ast.parse(notebook.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("vhcjax"):
                    if a.name not in modules:
                        bad.append(f"import {a.name}")
                    aliases[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("vhcjax"):
            for a in node.names:
                qual = f"{node.module}.{a.name}"
                if node.module not in modules or qual not in public:
                    bad.append(f"from {node.module} import {a.name}")
                elif qual in modules:
                    aliases[a.asname or a.name] = qual
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            module = aliases.get(node.value.id)
            if module is not None and f"{module}.{node.attr}" not in public:
                bad.append(f"{node.value.id}.{node.attr}")
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Attribute)
            and isinstance(node.value.value, ast.Name)
            and aliases.get(node.value.value.id) == "vhcjax"
        ):
            module = f"vhcjax.{node.value.attr}"
            if module in modules and f"{module}.{node.attr}" not in public:
                bad.append(f"{node.value.value.id}.{node.value.attr}.{node.attr}")
    assert aliases, f"{notebook.name} does not import vhcjax"
    assert not bad, f"{notebook.name} uses names that are not public: {bad}"
