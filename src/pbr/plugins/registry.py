"""Registries: a plugin family's type names and the code that builds each.

Every family keeps one :class:`Registry` beside its code (``BSDF_TYPES`` in
``bsdfs/base.py``, ``LIGHT_TYPES`` in ``lights/base.py``, ``INTEGRATORS`` in
``integrators/base.py``, ...), and each plugin registers itself where it is defined::

    @BSDF_TYPES.register("roughconductor")
    class RoughConductor(BSDFType): ...

The loader looks type names up in these tables, so a new plugin is one decorator and an
import of its module in the family's ``__init__.py``."""

from __future__ import annotations


class Registry(dict):
    """Type name -> class (or loading function) of one plugin family."""

    def __init__(self, family: str):
        super().__init__()
        self.family = family

    def register(self, *names: str):
        """Decorator: register the decorated object under every name in ``names``."""
        def add(obj):
            for name in names:
                if name in self and self[name] is not obj:
                    raise ValueError(f"{self.family} type {name!r} is registered twice "
                                     f"({self[name].__qualname__}, {obj.__qualname__})")
                self[name] = obj
            return obj
        return add

    def supported(self) -> str:
        """The registered names, sorted and comma-separated (for error messages)."""
        return ", ".join(sorted(self))
