"""The documentation: every public name on an API page, docstrings that name public
things only, and the notebooks rendered into the site, current with their sources."""

import ast
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


def test_rendered_api_pages_show_every_public_name(tmp_path):
    """The built site (`mkdocs build --strict`, as CI builds it) has a heading for every
    public name: the check above, on what mkdocstrings rendered."""
    pytest.importorskip("mkdocs", reason="the docs extra (`pip install -e '.[docs]'`)")
    site = tmp_path / "site"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), NO_MKDOCS_2_WARNING="1")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(site)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
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
