"""The shipped type stubs (python/wmo/_core.pyi) describe the real module: every class,
method and property they declare exists at runtime and vice versa, and the package is
marked typed (py.typed)."""
from __future__ import annotations

import ast
import inspect
import pathlib

import wmo
from wmo import _core, geometry

PKG = pathlib.Path(wmo.__file__).resolve().parent


def stub_classes():
    tree = ast.parse((PKG / "_core.pyi").read_text())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            out[node.name] = {n.name for n in node.body
                              if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    return out


def public_members(cls):
    names = set()
    for name, _ in inspect.getmembers(cls):
        if name.startswith("_") and name not in ("__init__", "__mul__", "__len__", "__bool__"):
            continue
        # Members inherited from a bound base are declared on that base in the stub.
        if any(name in vars(base) for base in cls.__mro__[1:] if base.__module__ == cls.__module__):
            continue
        if name in vars(cls):
            names.add(name)
    return names


def test_py_typed_marker_is_shipped():
    assert (PKG / "py.typed").is_file()


def test_stub_classes_match_runtime():
    stubs = stub_classes()
    runtime = {n for n, v in vars(_core).items() if inspect.isclass(v) and not n.startswith("_")}
    assert set(stubs) == runtime
    for name, declared in stubs.items():
        cls = getattr(_core, name)
        if issubclass(cls, BaseException):
            continue
        actual = public_members(cls)
        declared = declared - {"__init__"} if "__init__" not in vars(cls) else declared
        assert declared <= actual | {"__init__"}, (name, declared - actual)
        assert actual - {"__init__"} <= declared, (name, actual - declared)


def test_geometry_exports_every_core_function():
    core_fns = {n for n, v in vars(_core.geometry).items()
                if callable(v) and not n.startswith("_") and n != "status_names"}
    assert core_fns <= set(geometry.__all__)
    for name in geometry.__all__:
        assert getattr(geometry, name).__doc__, name
