"""Every public function and class documents each of its parameters (numpydoc), as python-control checks."""

import importlib
import inspect
import pkgutil
import re

import pytest

import contoursim


def _public_objects():
    for info in pkgutil.iter_modules(contoursim.__path__):
        if info.name.startswith("_") or info.name in ("cli", "__main__"):
            continue
        module = importlib.import_module(f"contoursim.{info.name}")
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name)
            if inspect.isclass(obj) or inspect.isfunction(obj) or hasattr(obj, "py_func"):
                yield f"{info.name}.{name}", getattr(obj, "py_func", obj)


OBJECTS = sorted(_public_objects())


def _documented(doc):
    """Names listed in the Parameters section of a numpydoc docstring."""
    section = re.search(r"Parameters\n\s*-+\n(.*?)(\n\s*\n\s*[A-Z][a-z]+\n\s*-+\n|\Z)", doc, re.S)
    if not section:
        return set()
    names = set()
    for line in section.group(1).splitlines():
        match = re.match(r"^\s{0,8}(\*{0,2}[A-Za-z_][\w, *]*?)\s*(:|$)", line)
        if match and not line.startswith(" " * 9):
            names.update(n.strip().lstrip("*") for n in match.group(1).split(","))
    return names


def _own_init(cls):
    """Whether a contoursim class in `cls`'s hierarchy defines its constructor."""
    return any("__init__" in vars(c) or "__new__" in vars(c) for c in cls.__mro__ if c.__module__.startswith("contoursim"))


@pytest.mark.parametrize("qualname, obj", OBJECTS, ids=[q for q, _ in OBJECTS])
def test_parameters_are_documented(qualname, obj):
    doc = inspect.getdoc(obj) or ""
    assert doc, f"{qualname} has no docstring"
    if inspect.isclass(obj) and issubclass(obj, BaseException) and not _own_init(obj):
        return  # it takes the built-in exception's message: none of its parameters are ours
    signature = inspect.signature(obj)  # every other public object has one: a failure here is a finding
    wanted = [p for p in signature.parameters if p not in ("self", "cls")]
    missing = [p for p in wanted if p not in _documented(doc)]
    assert not missing, f"{qualname}: parameters not documented: {missing}"
