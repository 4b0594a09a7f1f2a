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
