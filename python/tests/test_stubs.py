"""The type stubs describe what the package has: every function, class and
method of the .pyi files exists, with the same parameter names."""

import ast
import inspect
import pathlib

import dccl
from dccl import _dccl


def stub_defs(path):
    tree = ast.parse(pathlib.Path(path).read_text())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            out[node.name] = [a.arg for a in node.args.args]
        elif isinstance(node, ast.ClassDef):
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    out.setdefault("%s.%s" % (node.name, item.name), [a.arg for a in item.args.args])
            out.setdefault(node.name, None)
    return out


def check(module, stub_path, native=False):
    checked = 0
    for name, params in stub_defs(stub_path).items():
        obj = module
        for part in name.split("."):
            assert hasattr(obj, part), "%s: %s is in the stubs but not in the module" % (stub_path, name)
            obj = getattr(obj, part)
        if params is not None and not native:
            got = list(inspect.signature(obj).parameters)
            if "." in name:
                got = ["self"] + got if not got or got[0] != "self" else got
            assert got == params, "%s: parameters %s, stubs say %s" % (name, got, params)
        checked += 1
    return checked


def test_package_stubs_match():
    stub = pathlib.Path(dccl.__file__).with_name("__init__.pyi")
    assert check(dccl, stub) > 20
    for name in dccl.__all__:
        assert name in stub.read_text(), "%s is public but has no stub" % name


def test_native_stubs_match():
    stub = pathlib.Path(dccl.__file__).with_name("_dccl.pyi")
    assert check(_dccl, stub, native=True) > 20
