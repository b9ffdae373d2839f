"""The `hapcal` namespace holds its own names only, and the type stubs declare the same ones."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path
from typing import Dict, List

import hapcal

STUB = Path(__file__).resolve().parents[1] / "hapcal" / "__init__.pyi"


def test_the_namespace_is_exactly_all() -> None:
    """No module imported for the implementation (numpy, json, typing's names) leaks into
    `hapcal`: every public name is one of `__all__`, and every name of `__all__` is there."""
    public = sorted(n for n in dir(hapcal) if not n.startswith("_"))
    assert public == sorted(hapcal.__all__)
    assert len(set(hapcal.__all__)) == len(hapcal.__all__)


def test_public_objects_say_they_are_hapcals() -> None:
    for name in hapcal.__all__:
        obj = getattr(hapcal, name)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            assert obj.__module__ == "hapcal", f"{name}: {obj.__module__}"


def _stub() -> ast.Module:
    return ast.parse(STUB.read_text(encoding="utf-8"))


def _stub_public_names(tree: ast.Module) -> List[str]:
    names: List[str] = []
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names.append(node.name)
        elif isinstance(node, ast.Assign):
            names.extend(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.append(node.target.id)
    return sorted(n for n in names if not n.startswith("_"))


def test_the_stub_declares_the_same_names() -> None:
    tree = _stub()
    assert _stub_public_names(tree) == sorted(hapcal.__all__)
    declared = next(
        node.value
        for node in tree.body
        if isinstance(node, ast.Assign)
        and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets)
    )
    assert ast.literal_eval(declared) == hapcal.__all__


def test_the_stub_gives_the_functions_their_parameters() -> None:
    """Each Python-level function of `__all__` takes, in the stub, the parameters it takes
    (names, order, positional or keyword-only)."""
    stubbed: Dict[str, ast.FunctionDef] = {
        n.name: n for n in _stub().body if isinstance(n, ast.FunctionDef)
    }
    functions = [n for n in hapcal.__all__ if inspect.isfunction(getattr(hapcal, n))]
    assert {"calibrate", "check", "diagnose", "import_urdf"} <= set(functions)
    for name in functions:
        params = inspect.signature(getattr(hapcal, name)).parameters.values()
        positional = [p.name for p in params if p.kind is p.POSITIONAL_OR_KEYWORD]
        keyword = [p.name for p in params if p.kind is p.KEYWORD_ONLY]
        args = stubbed[name].args
        assert [a.arg for a in args.args] == positional, name
        assert [a.arg for a in args.kwonlyargs] == keyword, name
