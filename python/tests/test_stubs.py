"""The type stubs name exactly what the extension exports, with its parameter names."""

import ast
import inspect
import pathlib

import diffsvg
from diffsvg import _native


def stub_defs():
    src = (pathlib.Path(diffsvg.__file__).parent / "_native.pyi").read_text()
    out = {}
    for node in ast.parse(src).body:
        if isinstance(node, ast.FunctionDef):
            out[node.name] = [a.arg for a in node.args.args]
        elif isinstance(node, ast.ClassDef):
            out[node.name] = {n.name: [a.arg for a in n.args.args]
                              for n in node.body if isinstance(n, ast.FunctionDef)}
    return out


def test_stubs_match_the_extension():
    stubs = stub_defs()
    public = {n for n in dir(_native) if not n.startswith("_")}
    assert public == set(stubs), public ^ set(stubs)
    for name, params in stubs.items():
        if isinstance(params, list):
            sig = inspect.signature(getattr(_native, name))
            assert list(sig.parameters) == params, name
    methods = {n for n in dir(_native.Scene) if not n.startswith("_")}
    assert methods == set(stubs["Scene"]) - {"__init__"}, methods ^ set(stubs["Scene"])


def _returns(path):
    """(qualified name, return annotation or None) of every public function and method."""
    out = []
    tree = ast.parse(path.read_text())

    def visit(body, prefix):
        for node in body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                visit(node.body, f"{node.name}.")
            elif isinstance(node, ast.FunctionDef):
                if node.name.startswith("_") and node.name != "__init__":
                    continue
                ann = ast.unparse(node.returns) if node.returns is not None else None
                out.append((prefix + node.name, ann))

    visit(tree.body, "")
    return out


# Where the type is not known: the array module is the caller's (numpy or jax.numpy).
ANY_ALLOWED = {"Scene.flatten"}


def test_stubs_name_their_types():
    """No ``Any`` in the stubs, and every public function of the package states what it
    returns; ``Any`` only where no concrete type exists (``ANY_ALLOWED``)."""
    pkg = pathlib.Path(diffsvg.__file__).parent
    stub = (pkg / "_native.pyi").read_text()
    assert "Any" not in stub
    for name, ann in _returns(pkg / "_native.pyi"):
        assert ann is not None, f"_native.pyi: {name} has no return type"
    for module in ("__init__.py", "jax.py"):
        for name, ann in _returns(pkg / module):
            assert ann is not None, f"{module}: {name} has no return type"
            if name not in ANY_ALLOWED:
                assert "Any" not in ann and ann != "dict", f"{module}: {name} -> {ann}"
