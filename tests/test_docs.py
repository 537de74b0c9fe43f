"""Plugins document themselves: every registered type has a docstring that starts with
its name and has a parameter table (name, type, default, meaning) naming every parameter
its code reads by name (docs/architecture.md)."""

import ast
import inspect
import re
import textwrap

import pytest

from pbr.bsdfs import BSDF_TYPES, WRAPPERS, BSDFSet
from pbr.cameras import SENSORS
from pbr.films import FILMS
from pbr.filters import FILTERS
from pbr.integrators import INTEGRATORS
from pbr.lights import LIGHT_TYPES
from pbr.media import MEDIUM_TYPES, MediumSet
from pbr.phase import PHASE_TYPES
from pbr.samplers import SAMPLERS
from pbr.textures import TEXTURE_TYPES

GETTERS = {"float", "int", "bool", "string", "vector3", "transform", "raw", "has"}
TABLE = re.compile(r"^\s*=+( +=+){3}\s*$", re.M)


def plugins():
    out = []
    for reg in (BSDF_TYPES, LIGHT_TYPES, INTEGRATORS, SENSORS, FILMS, FILTERS, SAMPLERS, TEXTURE_TYPES, PHASE_TYPES):
        out += [(name, obj) for name, obj in reg.items()]
    out += [(name, getattr(BSDFSet, method)) for name, method in WRAPPERS.items()]
    out += [(name, getattr(MediumSet, method)) for name, method in MEDIUM_TYPES.items()]
    return out


def names_read(obj) -> set:
    """Parameter names read with a literal key (``props.float("name", ...)``) in the
    source of ``obj`` (a class: its own methods)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(obj)))
    out = set()
    for n in ast.walk(tree):
        if (isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr in GETTERS
                and isinstance(n.func.value, ast.Name) and n.func.value.id in ("props", "p") and n.args
                and isinstance(n.args[0], ast.Constant) and isinstance(n.args[0].value, str)):
            out.add(n.args[0].value)
    return out - {"type", "id"}


@pytest.mark.parametrize("name, obj", plugins(), ids=[n for n, _ in plugins()])
def test_plugin_docstring_has_a_parameter_table(name, obj):
    doc = inspect.getdoc(obj) or ""
    assert doc.startswith("``"), f"{name}: the docstring should start with the plugin's name"
    names_read_here = names_read(obj)
    if names_read_here:
        assert TABLE.search(doc), f"{name}: no parameter table (name, type, default, meaning)"
    missing = [k for k in sorted(names_read_here) if not re.search(rf"\b{re.escape(k)}\b", doc)]
    assert not missing, f"{name}: parameters read but not documented: {missing}"


def test_the_check_fails_on_an_undocumented_parameter():
    """Must-fail: a plugin reading a parameter its docstring does not name."""
    class Undocumented:
        """``x``: a plugin.

        ====  =====  =======  =======
        name  type   default  meaning
        ====  =====  =======  =======
        a     float  0        a value
        ====  =====  =======  =======
        """

        def __init__(self, props):
            self.a = props.float("a", 0.0)
            self.b = props.float("b", 1.0)

    assert names_read(Undocumented) == {"a", "b"}
    with pytest.raises(AssertionError, match=r"\['b'\]"):
        test_plugin_docstring_has_a_parameter_table("x", Undocumented)
