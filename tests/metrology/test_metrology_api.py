"""Public API of servosurf.metrology: exports and signature-versus-docstring."""

from __future__ import annotations

import inspect
import re

import pytest

import servosurf.metrology as sm
from servosurf.viz import _surface_plots

FUNCTIONS = [
    getattr(sm, name) for name in sm.__all__ if inspect.isfunction(getattr(sm, name))
] + [getattr(_surface_plots, name) for name in _surface_plots.__all__]


def _documented_parameters(doc: str) -> set[str]:
    """Names listed in the numpydoc ``Parameters`` section."""
    m = re.search(
        r"Parameters\n\s*-+\n(.*?)(\n\s*\n\s*[A-Z][a-z]+( [A-Z][a-z]+)?\n\s*-+|\Z)",
        doc,
        re.S,
    )
    assert m, "no Parameters section"
    names: set[str] = set()
    for line in m.group(1).splitlines():
        if re.match(r"^ {4}\S", line):
            head = line.strip().split(" : ")[0]
            names.update(n.strip() for n in head.split(","))
    return names


def test_all_names_exist():
    for name in sm.__all__:
        assert hasattr(sm, name), name


@pytest.mark.parametrize("func", FUNCTIONS, ids=lambda f: f.__name__)
def test_docstring_documents_every_parameter(func):
    doc = func.__doc__ or ""
    for section in ("Parameters", "Returns"):
        assert section in doc, f"{func.__name__}: no {section} section"
    params = set(inspect.signature(func).parameters)
    documented = _documented_parameters(doc)
    assert params == documented, (
        f"{func.__name__}: undocumented {params - documented}, "
        f"stale {documented - params}"
    )


@pytest.mark.parametrize("func", FUNCTIONS, ids=lambda f: f.__name__)
def test_unknown_keyword_raises_type_error(func):
    with pytest.raises(TypeError):
        func(no_such_option=1)
