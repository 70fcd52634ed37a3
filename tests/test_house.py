"""The package's shape: layers import one way, every module says what it exports, the top-level
API resolves. These fail when a change breaks the house rules of issue 11 (STYLE.md: data flows
one way; computation separate from plotting)."""

from __future__ import annotations

import ast
import importlib
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]

LAYERS = {
    # the exceptions, importable by everything
    "errors": -1,
    # Ctrl-C remembered where an extension swallowed it: checked before any output is put in place
    "interrupts": -1,
    # foundation: no maglev_oc imports but the exceptions
    "results": 0,
    "units": 0,
    "numerics": 0,
    "expressions": 0,
    "fileio": 0,
    "progress": 0,
    "model": 1,
    "data": 2,
    "estimation": 3,
    "control": 4,
    "sim": 5,
    "regression": 6,
    "validation": 6.5,  # residual tests on the regression layer's data; used by identification, diagnosis
    "identification": 7,
    "region": 7,
    "diagnosis": 8,
    "reporting": 9,
    "analyses": 10,
    "cli": 11,
    "__init__": 11,
}
"""Rank of each part of the package: a module may import only parts of lower rank (or its own)."""


def _modules():
    for path in sorted((ROOT / "maglev_oc").rglob("*.py")):
        parts = path.relative_to(ROOT / "maglev_oc").with_suffix("").parts
        yield path, parts[0]
    for path in sorted((ROOT / "analyses").rglob("*.py")):
        yield path, "analyses"


def _imported_parts(path: pathlib.Path):
    """(line, part) of every maglev_oc import in the file, including those inside functions."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            q = name.split(".")
            if q[0] == "maglev_oc":
                yield node.lineno, q[1] if len(q) > 1 else "__init__"


def test_layers_import_one_way():
    assert set(LAYERS) >= {part for _, part in _modules()}, "a new part of the package needs a rank"
    wrong = []
    for path, part in _modules():
        for line, target in _imported_parts(path):
            if target != part and LAYERS[target] >= LAYERS[part]:
                wrong.append(f"{path.relative_to(ROOT)}:{line}: {part} imports {target}")
    assert not wrong, "imports against the layering:\n" + "\n".join(wrong)


def test_the_layer_test_sees_a_violation(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from maglev_oc.control.gains import OMEGA0\n")
    assert list(_imported_parts(bad)) == [(2, "control")]


@pytest.mark.parametrize("path", [p for p, _ in _modules()], ids=lambda p: str(p.relative_to(ROOT)))
def test_every_module_declares_its_exports(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    declared = [
        node
        for node in tree.body
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets)
    ]
    if path.name == "__init__.py" and not any(isinstance(n, (ast.Import, ast.ImportFrom)) for n in tree.body):
        return  # an empty package marker
    assert declared, f"{path.relative_to(ROOT)} has no __all__"


def test_every_exported_name_exists():
    missing = []
    for path, _ in _modules():
        rel = path.relative_to(ROOT)
        if rel.parts[0] == "analyses":
            module_name = "maglev_oc.analyses." + ".".join(rel.with_suffix("").parts[1:])
        else:
            module_name = ".".join(rel.with_suffix("").parts)
        module_name = module_name.removesuffix(".__init__")
        module = importlib.import_module(module_name)
        missing += [f"{module_name}.{n}" for n in getattr(module, "__all__", ()) if not hasattr(module, n)]
    assert not missing, missing


def test_top_level_api():
    import maglev_oc as mo

    for name in mo.__all__:
        assert getattr(mo, name) is not None
    # the verbs are functions, not the subpackages that implement them
    assert callable(mo.diagnose) and callable(mo.identify)
    with pytest.raises(AttributeError, match="no attribute"):
        mo.no_such_name  # noqa: B018


def test_top_level_functions_document_parameters_and_returns():
    """numpydoc sections for every function of ``import maglev_oc as mo``: what each argument is
    (units included) and what comes back."""
    import inspect

    import maglev_oc as mo

    undocumented = []
    for name in mo.__all__:
        obj = getattr(mo, name)
        if not inspect.isfunction(obj):
            continue
        doc = inspect.getdoc(obj) or ""
        has_arguments = "Parameters\n----------" in doc or not inspect.signature(obj).parameters
        if not (has_arguments and "Returns\n-------" in doc):
            undocumented.append(name)
    assert not undocumented, undocumented


@pytest.mark.parametrize("module_name", ["maglev_oc.model.equilibrium", "maglev_oc.model.linearization"])
def test_docstring_examples_run(module_name):
    import doctest
    import importlib

    module = importlib.import_module(module_name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
