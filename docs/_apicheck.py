"""What the API reference checks of every public name: a docstring, and every parameter named.

Used by ``docs/conf.py`` (a warning per problem, which the strict build turns into an error)
and by ``tests/test_docs.py``.
"""

from __future__ import annotations

import dataclasses
import enum
import inspect
import re
import sys
from collections.abc import Iterator
from typing import Any

_MISSING = object()
SECTIONS = ("Args", "Arguments", "Parameters", "Attributes", "Keyword Args", "Other Parameters")
_SECTION = re.compile(r"^(\s*)(" + "|".join(SECTIONS) + r"):\s*$")
_ENTRY = re.compile(r"^\s*(\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)*)\s*(?:\([^)]*\))?:")
_NUMPY_ENTRY = re.compile(r"^\s*(\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)*)\s*(?::.*)?$")


def documented_names(doc: str) -> set[str]:
    """The names a docstring describes: Google-style ``Args:`` / ``Attributes:`` entries and
    numpy-style ``Parameters`` / ``Attributes`` entries."""
    names: set[str] = set()
    lines = doc.splitlines()
    for k, line in enumerate(lines):
        google = _SECTION.match(line)
        numpy = (
            line.strip() in SECTIONS and k + 1 < len(lines) and set(lines[k + 1].strip()) == {"-"}
        )
        if google:
            names |= _entries(lines[k + 1 :], len(google.group(1)), _ENTRY)
        elif numpy:
            names |= _entries(lines[k + 2 :], len(line) - len(line.lstrip()) - 1, _NUMPY_ENTRY)
    return names


def _entries(lines: list[str], section_indent: int, pattern: re.Pattern[str]) -> set[str]:
    """Entry names of one section: its lines at the first indent deeper than the heading's
    (numpy: at the heading's), up to the first line at or above the heading's."""
    names: set[str] = set()
    indent = None
    for line in lines:
        if not line.strip():
            continue
        depth = len(line) - len(line.lstrip())
        if depth <= section_indent or (pattern is _NUMPY_ENTRY and _is_heading(line)):
            break
        indent = depth if indent is None else indent
        entry = pattern.match(line)
        if depth == indent and entry:
            names.update(n.strip().lstrip("*") for n in entry.group(1).split(","))
    return names


def _is_heading(line: str) -> bool:
    return line.strip() in {*SECTIONS, "Returns", "Raises", "Yields", "Notes", "Examples"}


def _parameters(obj: Any) -> list[str]:
    """The parameters a caller passes: a function's, or a class's constructor's."""
    target = obj
    if inspect.isclass(obj):
        if issubclass(obj, enum.Enum | BaseException):
            return []
        if getattr(obj, "_is_protocol", False):
            target = obj.__call__
        elif "__init__" not in vars(obj) and not dataclasses.is_dataclass(obj):
            inherited = [klass for klass in obj.__mro__[1:] if "__init__" in vars(klass)]
            if not inherited or inherited[0].__module__.split(".")[0] != "pymc_vcc":
                return []
            target = inherited[0].__init__
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):
        return []
    return [
        name
        for name, parameter in signature.parameters.items()
        if name not in ("self", "cls")
        and parameter.kind not in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD)
    ]


def defining_modules(obj: Any, name: str) -> list[str]:
    """The loaded ``pymc_vcc`` modules that bind ``name`` to ``obj`` (a re-exported constant
    is bound in the module that defines it and in those that import it)."""
    return sorted(
        module_name
        for module_name, module in list(sys.modules.items())
        if module_name.split(".")[0] == "pymc_vcc" and vars(module).get(name, _MISSING) is obj
    )


def attribute_doc(obj: Any, name: str) -> str:
    """The docstring of the module constant ``name`` (the string right under its assignment),
    as Sphinx reads it from the source of the module that assigns it."""
    from sphinx.pycode import ModuleAnalyzer

    for module in defining_modules(obj, name):
        docs = ModuleAnalyzer.for_module(module).find_attr_docs().get(("", name))
        if docs:
            return "\n".join(docs)
    return ""


def problems(name: str, obj: Any) -> Iterator[str]:
    """What the public name ``name`` lacks: its docstring, or the description of a parameter."""
    if not (inspect.isclass(obj) or inspect.isfunction(obj)):
        if not attribute_doc(obj, name).strip():
            yield f"{name}: no docstring (a string right under its assignment)"
        return
    doc = inspect.getdoc(obj) or ""
    own = obj.__doc__ if inspect.isclass(obj) else doc
    if not (own or "").strip():
        yield f"{name}: no docstring"
        return
    described = documented_names(doc)
    if inspect.isclass(obj):
        # the constructor's own docstring, or that of the class whose constructor it inherits
        owner = next((k for k in obj.__mro__ if "__init__" in vars(k)), obj)
        for source in (owner.__doc__, vars(owner).get("__init__", None).__doc__):
            described |= documented_names(inspect.cleandoc(source or ""))
    missing = [p for p in _parameters(obj) if p not in described]
    if missing:
        yield f"{name}: parameter(s) {missing} not described (a 'Parameters' or 'Args:' section)"
