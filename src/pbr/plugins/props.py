"""Typed, key-path-aware access to one plugin's dict of parameters, and the ranges
parameter values must lie in.

Every plugin constructor receives a :class:`Props`. Reading a parameter marks it used;
:meth:`Props.finish` then rejects anything left over, naming its full key path (e.g.
``scene.red-wall.bsdf.reflectance.valu``), so typos never pass silently.

:class:`Range` is the one check of a parameter's values, wherever they come from:
:meth:`Props.float` (scalars), the texture loaders (spectra and textures:
``pbr.textures.load_spectrum``), and ``params.update()`` after ``pbr.traverse``
(:func:`pbr.plugins.params.check_params`). Values must be finite and in the
parameter's physical range (albedos in [0, 1], radiance >= 0, an IOR > 0, ...).
"""

from __future__ import annotations

import numbers

import numpy as np


class SceneError(ValueError):
    """Invalid scene description; the message starts with the offending key path."""


# Every plugin type name pbr knows (filled in by the scene loader, which imports all the
# families), for messages about a nested plugin of an unknown type.
KNOWN_TYPES: set[str] = set()


# Mitsuba's usual names of nested plugins (``'film': {...}``), for the message about a
# value there that is not a plugin dict.
NESTED_SLOTS = frozenset(("bsdf", "emitter", "film", "sampler", "rfilter", "phase", "medium", "interior", "exterior",
                          "texture", "volume"))


def did_you_mean(name, choices) -> str:
    """`` (did you mean 'x'?)`` for the known name closest to a misspelt ``name``, or ''."""
    import difflib
    close = difflib.get_close_matches(str(name), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


_FLOAT32_MAX = float(np.finfo(np.float32).max)


class Range:
    """The valid values of a parameter: finite (also in float32, as pbr renders), and
    within ``[lo, hi]`` (a bound is exclusive when ``open_lo``/``open_hi``; None:
    unbounded). ``what`` names the quantity in messages ("an albedo", "an IOR")."""

    def __init__(self, lo=None, hi=None, open_lo=False, open_hi=False, what=""):
        self.lo, self.hi, self.open_lo, self.open_hi, self.what = lo, hi, open_lo, open_hi, what

    def __repr__(self):
        return f"Range({self})"

    def __str__(self):
        if self.lo is not None and self.hi is not None:
            return f"in {'(' if self.open_lo else '['}{self.lo:g}, {self.hi:g}{')' if self.open_hi else ']'}"
        if self.lo is not None:
            return "positive" if self.lo == 0 and self.open_lo else f"{'>' if self.open_lo else '>='} {self.lo:g}"
        if self.hi is not None:
            return f"{'<' if self.open_hi else '<='} {self.hi:g}"
        return "finite"

    def bad(self, a):
        """Mask of the values of ``a`` (a NumPy or a Dr.Jit array) outside the range,
        non-finite ones included."""
        bad = ~(abs(a) <= _FLOAT32_MAX)      # NaN, inf, and what float32 rounds to inf
        if self.lo is not None:
            bad |= (a <= self.lo) if self.open_lo else (a < self.lo)
        if self.hi is not None:
            bad |= (a >= self.hi) if self.open_hi else (a > self.hi)
        return bad

    def check(self, value, where: str, at=None) -> None:
        """Raise a :class:`SceneError` naming ``where`` unless every value of ``value``
        (a number or an array of any shape) is finite and in range; ``at`` names the
        position of a bad value of a 1D array (index -> text), instead of its index."""
        a = np.asarray(value, np.float64)
        bad = self.bad(a)
        if not bad.any():
            return
        expected = f"must be {self}" + (f" ({self.what})" if self.what else "")
        if a.size == 1:
            raise SceneError(f"{where}: {expected}, got {a.reshape(-1)[0]:g}")
        first = np.unravel_index(np.argmax(bad), a.shape)
        pos = (f"index {tuple(int(i) for i in first)}" if a.ndim > 1 else
               at(int(first[0])) if at is not None else f"index {int(first[0])}")
        raise SceneError(f"{where}: {expected}, got {a[first]:g} at {pos} ({int(bad.sum())} of {a.size} values)")

    def factor(self) -> "Range":
        """The range of a factor on values of this range (a ``scale`` texture): >= 0 if
        the values must be, else any finite number."""
        return NONNEGATIVE if self.lo is not None and self.lo >= 0 else FINITE


FINITE = Range()
NONNEGATIVE = Range(0.0)
UNIT = Range(0.0, 1.0)
ALBEDO = Range(0.0, 1.0, what="an albedo")
RADIANCE = Range(0.0, what="radiance")
IOR = Range(0.0, open_lo=True, what="an index of refraction")
ROUGHNESS = Range(0.0, what="a roughness")
HG_ASYMMETRY = Range(-1.0, 1.0, what="a Henyey-Greenstein asymmetry")


def _is_transform(v) -> bool:
    """A Mitsuba transform object. Their Python type names change with the active variant
    (``mi.ScalarTransform4f`` is ``AffineTransform4f`` under ``scalar_rgb``), so test for
    the ``matrix`` attribute, not the name."""
    return hasattr(v, "matrix") and not isinstance(v, np.ndarray)


class Props:
    def __init__(self, d: dict, path: str, loader=None):
        if not isinstance(d, dict):
            raise SceneError(f"{path}: expected a dict, got {type(d).__name__}")
        self.d = d
        self.path = path
        self.loader = loader
        self.type = d.get("type")
        self.id = d.get("id", path.rsplit(".", 1)[-1])
        self._used = {"type", "id"}

    # -- generic ------------------------------------------------------------------
    def key(self, name: str) -> str:
        return f"{self.path}.{name}"

    def error(self, name: str | None, msg: str) -> SceneError:
        return SceneError(f"{self.key(name) if name else self.path}: {msg}")

    def has(self, name: str) -> bool:
        return name in self.d

    def raw(self, name: str, default=None):
        self._used.add(name)
        return self.d.get(name, default)

    def mark(self, *names: str) -> None:
        self._used.update(names)

    def finish(self) -> None:
        """Raise for parameters no plugin code asked for."""
        unknown = [k for k in self.d if k not in self._used]
        if unknown:
            k = unknown[0]
            t = self.d[k].get("type") if isinstance(self.d[k], dict) else None
            if isinstance(t, str) and KNOWN_TYPES and t not in KNOWN_TYPES:   # a misspelt nested plugin
                raise SceneError(f"{self.key(k)}: unknown plugin type {t!r}{did_you_mean(t, KNOWN_TYPES)}")
            hint = did_you_mean(k, self._used)
            if isinstance(t, str):      # a known plugin type this one does not read
                target = self.loader._target_type(self.d[k]) if t == "ref" and self.loader is not None else None
                hint += f", or a nested {t!r}" + (f" (to a {target!r})" if target else "") + " plugin that it does not take"
            elif k in NESTED_SLOTS and not isinstance(self.d[k], dict):
                hint += f" (a nested plugin is a dict with a 'type', got {type(self.d[k]).__name__} {self.d[k]!r})"
            raise SceneError(f"{self.key(k)}: unknown parameter {k!r} for plugin type {self.type!r}{hint}")

    # -- typed getters --------------------------------------------------------------
    def float(self, name: str, default=None, min=None, max=None, valid: Range | None = None) -> float:
        """A finite number in [min, max] (or in the range ``valid``)."""
        v = self.raw(name, default)
        if v is None:
            raise self.error(name, "missing required float parameter")
        if isinstance(v, (bool, np.bool_, str)):   # Mitsuba: "has the wrong type"
            raise self.error(name, f"expected a number, got {v!r}")
        if not isinstance(v, numbers.Real):
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise self.error(name, f"expected a number, got {v!r}") from None
        v = float(v)
        (valid or Range(min, max)).check(v, self.key(name))
        return v

    def int(self, name: str, default=None, min=None) -> int:
        v = self.raw(name, default)
        if v is None:
            raise self.error(name, "missing required integer parameter")
        if isinstance(v, (bool, np.bool_)):   # a bool is an Integral in Python, not here
            raise self.error(name, f"expected an integer, got {v!r}")
        if not isinstance(v, numbers.Integral):
            if isinstance(v, numbers.Real) and float(v).is_integer():
                v = int(v)
            else:
                raise self.error(name, f"expected an integer, got {v!r}")
        v = int(v)
        if min is not None and v < min:
            raise self.error(name, f"must be >= {min}, got {v}")
        return v

    def bool(self, name: str, default=None) -> bool:
        v = self.raw(name, default)
        if not isinstance(v, (bool, np.bool_)):
            raise self.error(name, f"expected true/false, got {v!r}")
        return bool(v)

    def string(self, name: str, default=None, choices=None) -> str:
        v = self.raw(name, default)
        if v is None:
            raise self.error(name, "missing required string parameter")
        if not isinstance(v, str):
            raise self.error(name, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(name, f"expected one of {', '.join(map(repr, choices))}, got {v!r}"
                                   f"{did_you_mean(v, choices)}")
        return v

    def vector3(self, name: str, default=None) -> np.ndarray:
        v = self.raw(name, default)
        if v is None:
            raise self.error(name, "missing required 3-vector")
        try:
            a = np.empty(0) if isinstance(v, (str, bool)) else np.asarray(v, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            a = np.empty(0)
        if a.size == 1:
            a = np.repeat(a, 3)
        if a.size != 3 or not np.all(np.isfinite(a)):
            raise self.error(name, f"expected 3 finite numbers, got {v!r}")
        return a

    def transform(self, name: str, default_identity: bool = True) -> np.ndarray:
        """A 4x4 float64 matrix from a Mitsuba transform object or a 4x4 array."""
        v = self.raw(name)
        if v is None:
            if default_identity:
                return np.eye(4)
            raise self.error(name, "missing required transform")
        if _is_transform(v):
            m = np.array(v.matrix, dtype=np.float64)
        else:
            try:
                m = np.asarray(v, dtype=np.float64)
            except (TypeError, ValueError):
                raise self.error(name, f"expected a transform (mi.ScalarTransform4f or 4x4 array), got {type(v).__name__}") from None
        # a JIT variant's transform (``mi.Transform4f``, ``mi.Transform3f``) has a trailing
        # width-1 axis: (4, 4, 1), (3, 3, 1)
        m = m.reshape(4, 4) if m.size == 16 else (m.reshape(3, 3) if m.size == 9 else m)
        if m.shape == (3, 3):
            # A 2D transform (``mi.ScalarTransform3f``, e.g. a texture's ``to_uv``): its
            # linear part and translation go where Mitsuba's 3x3 -> 4x4 expansion puts them.
            e = np.eye(4)
            e[:2, :2], e[:2, 3], e[3, :2] = m[:2, :2], m[:2, 2], m[2, :2]
            m = e
        if m.shape != (4, 4):
            raise self.error(name, f"expected a 4x4 matrix, got shape {m.shape}")
        if not np.all(np.isfinite(m)):
            raise self.error(name, f"the transform has non-finite entries ({int(np.sum(~np.isfinite(m)))} of 16: "
                                   "a nan/inf angle, scale or translation?)")
        return m

    def child(self, name: str) -> "Props":
        v = self.raw(name)
        return Props(v, self.key(name), self.loader)

    def children(self) -> list[tuple[str, dict]]:
        """Nested plugin dicts (entries that are dicts with a 'type'), in order."""
        return [(k, v) for k, v in self.d.items() if isinstance(v, dict) and "type" in v]
