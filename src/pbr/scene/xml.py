"""Mitsuba 3 XML scene files -> Mitsuba scene dicts.

pbr speaks Mitsuba 3's scene language, and its loader works on the dict form that
``mitsuba.load_dict`` accepts. This module translates the XML form into that dict
form, so one code path (dict validation and assembly) serves both, and so that
``mi.load_dict(parse_file(p))`` builds the same scene as ``mi.load_file(p)``.

Every error raises :class:`XMLError`, whose message starts with ``"<file>:<line>: "``
pointing at the offending element; :func:`parse_file_lines` also returns where each key
path of the dict came from, so that the loader's errors can name the line too.
Supported: all object tags, every property tag Mitsuba 3 has (plus ``<blackbody>``),
transforms, ``<ref>``, ``<alias>``, ``<default>`` with ``$name`` substitution and keyword
overrides, ``<include>`` and ``<path>`` (search paths).

Relative file names are found the way Mitsuba's file resolver finds them: a search
path starts as [the main file's directory, the working directory]; ``<path value=..>``
(a direct child of a ``<scene>``) puts a directory in front; ``<include>`` looks in
the including file's directory first, then the search path, and a ``<path>`` inside
an included file only counts for that file's own includes. ``filename`` parameters
are looked up in the main file's search path once the whole file is read (Mitsuba
resolves them when it builds the plugins), then, as pbr's fallback where Mitsuba
would fail, in the directory of the file they appear in.
Scenes older than version 2.0.0 (camelCase parameter names) are rejected. Where
Mitsuba's own reading is surprising we follow it, for parity: ``<rotate>`` does not
normalise its axis, ``<lookat>`` without ``up`` picks Mitsuba's up vector, and keyword
parameters that no ``$name`` uses are errors.
"""
from __future__ import annotations

import functools
import os
import re
from dataclasses import dataclass, field
from xml.parsers import expat

import numpy as np

from ..bsdfs import bsdf_names
from ..cameras import SENSORS
from ..films import FILMS
from ..filters import FILTERS
from ..geometry import SHAPE_PARAMS
from ..integrators import INTEGRATORS
from ..lights import LIGHT_TYPES
from ..media import MEDIUM_TYPES
from ..phase import PHASE_TYPES
from ..samplers import SAMPLERS
from ..textures import TEXTURE_TYPES

__all__ = ["XMLError", "parse_file", "parse_file_lines", "parse_string"]


class XMLError(ValueError):
    """A malformed Mitsuba XML scene; the message starts with ``file:line: ``."""


# Tags that become nested plugin dicts (``spectrum`` only when it has a ``type``).
_OBJECT_TAGS = ("scene", "shape", "bsdf", "emitter", "sensor", "film", "sampler",
                "rfilter", "integrator", "texture", "medium", "phase", "volume",
                "spectrum")
_PROPERTY_TAGS = ("float", "integer", "boolean", "string", "point", "vector", "rgb",
                  "spectrum", "blackbody", "transform")
_SPECIAL_TAGS = ("ref", "default", "include", "alias", "path")
_TRANSFORM_OPS = ("translate", "rotate", "scale", "matrix", "lookat")
_PARAM_RE = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)?")
_SPLIT_RE = re.compile(r"[,\s]+")


class _Filename(str):
    """A ``filename`` value read from the file in directory ``fallback``, to be looked up
    in the main search path once parsing ends (:meth:`_Parser.resolve_filenames`)."""
    fallback: str


@dataclass
class _Node:
    """One XML element with the place it came from."""
    tag: str
    attrs: dict
    line: int
    file: str
    children: list = field(default_factory=list)


def _read_tree(text: str | bytes, file: str) -> _Node:
    """Parse XML text with expat into a tree of _Node recording line numbers."""
    parser = expat.ParserCreate()
    stack: list[_Node] = []
    roots: list[_Node] = []

    def start(tag, attrs):
        node = _Node(tag, dict(attrs), parser.CurrentLineNumber, file)
        (stack[-1].children if stack else roots).append(node)
        stack.append(node)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text, True)
    except expat.ExpatError as e:
        raise XMLError(f"{file}:{e.lineno}: malformed XML: "
                       f"{expat.errors.messages[e.code]}") from None
    return roots[0]


class _Entries:
    """A plugin dict under construction: unique keys, generated keys for anonymous
    children, and explicit keys that may displace an earlier generated one."""

    def __init__(self, d: dict):
        self.d = d
        self.generated: set[str] = set()
        self.counters: dict[str, int] = {}
        self.nodes: dict[str, _Node] = {}      # key -> the element it came from

    def add(self, key: str | None, value, tag: str, node: _Node, err) -> str:
        """Insert value under key (or a generated '<tag>_<n>' key if None)."""
        if key is None:
            key = self._fresh(tag)
            self.generated.add(key)
        elif key in self.d:
            if key not in self.generated:
                raise err(node, f'duplicate name "{key}" within the same parent')
            # An explicit name wins over an earlier generated one: rename that one.
            new = self._fresh(key.rsplit("_", 1)[0])
            self.generated.discard(key)
            self.generated.add(new)
            self.d = {(new if k == key else k): v for k, v in self.d.items()}
            self.nodes[new] = self.nodes[key]
        self.d[key] = value
        self.nodes[key] = node
        return key

    def _fresh(self, tag: str) -> str:
        n = self.counters.get(tag, 0)
        while f"{tag}_{n}" in self.d:
            n += 1
        self.counters[tag] = n + 1
        return f"{tag}_{n}"


class _Parser:
    """State of one parse: parameters, declared ids, references, include stack."""

    def __init__(self, params: dict):
        self.params = {k: str(v) for k, v in params.items()}
        self.overrides = set(params)
        self.used: set[str] = set()
        self.ids: dict[str, _Node] = {}
        self.aliases: dict[str, str] = {}
        self.refs: list[tuple[dict, _Node]] = []
        self.include_stack: list[str] = []
        self.nodes: dict[int, dict] = {}      # id(plugin dict) -> its entries' elements
        # Mitsuba's file resolver: the search path of the file being read (a copy inside
        # includes) and the main file's (used for ``filename`` values).
        self.search: list[str] = [os.getcwd()]
        self.main_search = self.search

    # ----------------------------------------------------------------- helpers
    @staticmethod
    def err(node: _Node, msg: str) -> XMLError:
        """An XMLError located at node."""
        return XMLError(f"{node.file}:{node.line}: <{node.tag}>: {msg}")

    def attrs(self, node: _Node, required=(), optional=()) -> dict:
        """Substituted attributes of node, checking required and allowed names."""
        allowed = set(required) | set(optional)
        for k in node.attrs:
            if k not in allowed:
                raise self.err(node, f'unexpected attribute "{k}" '
                               f"(expected {', '.join(sorted(allowed)) or 'none'})")
        for k in required:
            if k not in node.attrs:
                raise self.err(node, f'missing required attribute "{k}"')
        return {k: self.subst(node, v) for k, v in node.attrs.items()}

    def subst(self, node: _Node, value: str) -> str:
        """Replace every $name in value by its parameter value."""
        def repl(m):
            name = m.group(1)
            if name is None:
                raise self.err(node, f'"$" not followed by a parameter name in "{value}"')
            if name not in self.params:
                raise self.err(node, f"undefined parameter ${name} (declare it with "
                               f'<default name="{name}" value="..."/> or pass {name}=...)')
            self.used.add(name)
            return self.params[name]
        return _PARAM_RE.sub(repl, value)

    def no_children(self, node: _Node):
        """Reject child elements of a leaf element."""
        if node.children:
            raise self.err(node, f"unexpected child <{node.children[0].tag}> "
                           f"(line {node.children[0].line}); this element takes none")

    def floats(self, node: _Node, attr: str, text: str, counts=None) -> list[float]:
        """Parse a comma/space separated list of floats, optionally of given lengths."""
        parts = [p for p in _SPLIT_RE.split(text.strip()) if p]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise self.err(node, f'attribute "{attr}": expected numbers, got "{text}"') from None
        if counts is not None and len(vals) not in counts:
            raise self.err(node, f'attribute "{attr}": expected '
                           f"{' or '.join(map(str, counts))} numbers, got {len(vals)}")
        return vals

    def number(self, node: _Node, attr: str, text: str) -> float:
        """Parse a single float."""
        return self.floats(node, attr, text, (1,))[0]

    def vec3(self, node: _Node, a: dict, default: float | None, broadcast=True) -> list[float]:
        """A 3-vector from value="x, y, z" (or one number if broadcast) or x/y/z attributes;
        missing x/y/z take default, or are errors when default is None."""
        if "value" in a:
            if any(k in a for k in "xyz"):
                raise self.err(node, 'give either "value" or "x"/"y"/"z", not both')
            v = self.floats(node, "value", a["value"], (1, 3) if broadcast else (3,))
            return v * 3 if len(v) == 1 else v
        out = []
        for k in "xyz":
            if k in a:
                out.append(self.number(node, k, a[k]))
            elif default is None:
                raise self.err(node, f'missing required attribute "{k}" (or "value")')
            else:
                out.append(default)
        return out

    @staticmethod
    def lookup(dirs, filename: str) -> str | None:
        """Absolute path of the first ``dir/filename`` that exists, or None."""
        if os.path.isabs(filename):
            return filename if os.path.exists(filename) else None
        for d in dirs:
            cand = os.path.join(d, filename)
            if os.path.exists(cand):
                return os.path.abspath(cand)
        return None

    def resolve(self, base_dir: str, filename: str) -> str:
        """A file named in a file in ``base_dir``, looked up in the current search path,
        then in base_dir; unchanged when it is in neither."""
        if os.path.isabs(filename):
            return filename
        found = self.lookup(self.search + [base_dir], filename)
        return found if found is not None else filename

    def resolve_filenames(self, d: dict) -> dict:
        """Look up every deferred ``filename`` value of ``d`` (recursively) in the main
        search path, then in the directory of the file it came from (pbr's fallback)."""
        for k, v in d.items():
            if isinstance(v, _Filename):
                found = self.lookup(self.main_search + [v.fallback], str(v))
                d[k] = found if found is not None else str(v)
            elif isinstance(v, dict):
                self.resolve_filenames(v)
        return d

    # ------------------------------------------------------------------ parsing
    def parse_root(self, root: _Node, base_dir: str) -> dict:
        """Convert the root element (a scene, or any single object) to a dict."""
        if root.tag not in _OBJECT_TAGS:
            raise self.err(root, "root element must be <scene> or an object tag")
        if "version" not in root.attrs:
            raise self.err(root, 'missing required attribute "version" on the root element')
        self.check_version(root, self.subst(root, root.attrs["version"]))
        self.search.insert(0, os.path.abspath(base_dir))
        node = _Node(root.tag, {k: v for k, v in root.attrs.items() if k != "version"},
                     root.line, root.file, root.children)
        out = self.object(node, base_dir, is_root=True)
        self.finish(root)
        return self.resolve_filenames(out)

    def check_version(self, node: _Node, version: str):
        m = re.fullmatch(r"(\d+)\.(\d+)\.(\d+)", version.strip())
        if not m:
            raise self.err(node, f'version "{version}": expected "major.minor.patch"')
        if int(m.group(1)) < 2:
            raise self.err(node, f"scene version {version} predates Mitsuba 2; "
                           "upgrading old scene files is not supported")

    def finish(self, root: _Node):
        """Check references and unused keyword parameters once everything is read."""
        for ref, node in self.refs:
            target = ref["id"]
            seen = set()
            while target in self.aliases and target not in seen:
                seen.add(target)
                target = self.aliases[target]
            if target not in self.ids:
                raise self.err(node, f'reference to unknown id "{ref["id"]}"')
            ref["id"] = target
        unused = sorted(self.overrides - self.used)
        if unused:
            raise self.err(root, "unused parameters: "
                           + ", ".join(f"${k}={self.params[k]}" for k in unused))

    def object(self, node: _Node, base_dir: str, is_root=False) -> dict:
        """Convert an object element (scene, shape, bsdf, ...) and its children."""
        if node.tag == "scene":
            if not is_root:
                raise self.err(node, "<scene> may only be the root element")
            self.attrs(node)
            d = {"type": "scene"}
        else:
            a = self.attrs(node, required=("type",), optional=("id", "name"))
            self.check_tag(node, a["type"])
            d = {"type": a["type"]}
        if not is_root and "id" in a:
            d["id"] = a["id"]
        entries = _Entries(d)
        self.children(node, entries, base_dir, is_scene=node.tag == "scene")
        self.nodes[id(entries.d)] = entries.nodes
        return entries.d

    def check_tag(self, node: _Node, t: str) -> None:
        """A type pbr knows only under other tags is an error here (``<sensor
        type="rectangle">``, ``<bsdf type="area">``): Mitsuba refuses such a mismatch.
        Types pbr does not know at all are left to the loader's message."""
        families = tag_types()
        if node.tag not in families or t in families[node.tag]:
            return
        owners = [tag for tag, types in families.items() if t in types and tag != "spectrum"]
        if owners:
            def a(w):
                return ("an " if w[0] in "aeiou" else "a ") + w
            raise self.err(node, f"type {t!r} is {a(' or '.join(owners))} type, not {a(node.tag)} type "
                                 f"(write <{owners[0]} type=\"{t}\">)")

    def lines(self, d: dict, path: str = "scene", out: dict | None = None) -> dict:
        """Key path (``scene.<id>.<name>...``, as the loader names them) -> ``file:line``
        of the element that gave it, for ``d`` and the dicts nested in it."""
        out = {} if out is None else out
        nodes = self.nodes.get(id(d), {})
        for k, v in d.items():
            if k in nodes:
                out[f"{path}.{k}"] = f"{nodes[k].file}:{nodes[k].line}"
            if isinstance(v, dict):
                self.lines(v, f"{path}.{k}", out)
        return out

    def declare(self, node: _Node, ident: str):
        """Record a new global id; ids must be unique across the scene."""
        if not ident:
            raise self.err(node, "empty id")
        if ident in self.ids:
            prev = self.ids[ident]
            raise self.err(node, f'duplicate id "{ident}" (first declared at '
                           f"{prev.file}:{prev.line})")
        self.ids[ident] = node

    def children(self, node: _Node, entries: _Entries, base_dir: str, is_scene: bool):
        """Add the converted children of node to entries, defaults first."""
        defaults = [c for c in node.children if c.tag == "default"]
        declared = set()
        for c in defaults:
            if not is_scene:
                raise self.err(c, "<default> is only allowed directly inside <scene>")
            a = self.attrs(c, required=("name", "value"))
            self.no_children(c)
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", a["name"]):
                raise self.err(c, f'invalid parameter name "{a["name"]}"')
            if a["name"] in declared:
                raise self.err(c, f'duplicate default for "{a["name"]}"')
            declared.add(a["name"])
            self.params.setdefault(a["name"], a["value"])
        for c in node.children:
            if c.tag != "default":
                self.child(c, entries, base_dir, is_scene)

    def child(self, c: _Node, entries: _Entries, base_dir: str, is_scene: bool):
        """Convert one child element into entries."""
        tag = c.tag
        if tag in _OBJECT_TAGS and (tag != "spectrum" or "type" in c.attrs):
            self.nested_object(c, entries, base_dir, is_scene)
        elif tag in _PROPERTY_TAGS:
            name, value = self.property(c, base_dir)
            entries.add(name, value, tag, c, self.err)
        elif tag == "ref":
            a = self.attrs(c, required=("id",), optional=("name",))
            self.no_children(c)
            ref = {"type": "ref", "id": a["id"]}
            self.refs.append((ref, c))
            entries.add(a.get("name"), ref, "ref", c, self.err)
        elif tag == "alias":
            a = self.attrs(c, required=("id", "as"))
            self.no_children(c)
            self.declare(c, a["as"])
            self.aliases[a["as"]] = a["id"]
        elif tag == "include":
            if not is_scene:
                raise self.err(c, "<include> is only allowed directly inside <scene>")
            a = self.attrs(c, required=("filename",), optional=("name",))
            self.no_children(c)
            self.include(c, a["filename"], entries, base_dir)
        elif tag == "path":
            if not is_scene:
                raise self.err(c, "<path> is only allowed directly inside <scene>")
            a = self.attrs(c, required=("value",))
            self.no_children(c)
            self.add_search_path(c, a["value"], base_dir)
        elif tag in _TRANSFORM_OPS:
            raise self.err(c, "transform operations must be inside <transform>")
        else:
            raise self.err(c, "unknown element (expected an object tag such as <shape>, "
                           "a property tag such as <float>, or <ref>/<default>/<include>)")

    def nested_object(self, c: _Node, entries: _Entries, base_dir: str, is_scene: bool):
        """Add a child object: at scene level keyed by id (else name), deeper keyed by
        name (else id, which is also kept as an 'id' entry so refs can find it)."""
        d = self.object(c, base_dir)
        ident = d.get("id")
        if ident is not None:
            self.declare(c, ident)
        name = self.subst(c, c.attrs["name"]) if "name" in c.attrs else None
        if is_scene:
            # Top-level objects are keyed by id (load_dict turns the key into the id).
            d.pop("id", None)
            key = ident if ident is not None else name
        else:
            key = name if name is not None else ident
        entries.add(key, d, c.tag, c, self.err)

    def add_search_path(self, c: _Node, value: str, base_dir: str):
        """``<path value=..>``: put a directory (relative to this file's directory, else
        found in the search path) in front of the current search path."""
        path = value if os.path.isabs(value) else os.path.join(base_dir, value)
        if not os.path.isdir(path):
            path = self.lookup(self.search, value) or path
        if not os.path.isdir(path):
            raise self.err(c, f'folder "{value}" not found (looked in {base_dir} and the search path '
                           f"{self.search})")
        self.search.insert(0, os.path.abspath(path))

    def include(self, c: _Node, filename: str, entries: _Entries, base_dir: str):
        """Merge the children of an included file's <scene> in place. The file is looked
        up in the including file's directory, then the search path; it is read with a
        copy of the search path (its own ``<path>`` elements stay local to it)."""
        search = [os.path.abspath(base_dir)] + self.search
        path = self.lookup(search, filename)
        if path is None:
            path = os.path.abspath(filename if os.path.isabs(filename) else os.path.join(base_dir, filename))
        if path in self.include_stack:
            raise self.err(c, f'recursive include of "{filename}"')
        try:
            with open(path, "rb") as f:
                text = f.read()
        except OSError as e:
            raise self.err(c, f'cannot read included file "{filename}" '
                           f"(looked for {path}): {e.strerror}") from None
        root = _read_tree(text, path)
        if root.tag != "scene":
            raise self.err(root, "an included file's root element must be <scene>")
        a = self.attrs(root, optional=("version",))
        if "version" in a:
            self.check_version(root, a["version"])
        self.include_stack.append(path)
        outer, self.search = self.search, search
        try:
            self.children(root, entries, os.path.dirname(path), is_scene=True)
        finally:
            self.search = outer
            self.include_stack.pop()

    # --------------------------------------------------------------- properties
    def property(self, c: _Node, base_dir: str):
        """Convert a property element into (name, value)."""
        tag = c.tag
        if tag == "transform":
            a = self.attrs(c, required=("name",))
            return a["name"], self.transform(c)
        self.no_children(c)
        if tag in ("float", "integer", "boolean", "string"):
            a = self.attrs(c, required=("name", "value"))
            v = a["value"]
            if tag == "float":
                return a["name"], self.number(c, "value", v)
            if tag == "integer":
                try:
                    return a["name"], int(v.strip())
                except ValueError:
                    raise self.err(c, f'attribute "value": expected an integer, '
                                   f'got "{v}"') from None
            if tag == "boolean":
                if v.strip().lower() not in ("true", "false"):
                    raise self.err(c, f'attribute "value": expected "true" or "false", '
                                   f'got "{v}"')
                return a["name"], v.strip().lower() == "true"
            if a["name"] == "filename" and not os.path.isabs(v):
                v = _Filename(v)
                v.fallback = base_dir
            return a["name"], v
        if tag in ("point", "vector"):
            a = self.attrs(c, required=("name",), optional=("value", "x", "y", "z"))
            return a["name"], self.vec3(c, a, default=None)
        if tag == "rgb":
            a = self.attrs(c, required=("name", "value"))
            v = self.floats(c, "value", a["value"], (1, 3))
            return a["name"], {"type": "rgb", "value": v * 3 if len(v) == 1 else v}
        if tag == "blackbody":
            a = self.attrs(c, required=("name", "temperature"))
            return a["name"], {"type": "blackbody",
                               "temperature": self.number(c, "temperature", a["temperature"])}
        # <spectrum> without a type
        a = self.attrs(c, required=("name",), optional=("value", "filename"))
        if ("value" in a) == ("filename" in a):
            raise self.err(c, 'expected exactly one of the attributes "value" or "filename"')
        if "filename" in a:
            return a["name"], {"type": "spectrum",
                               "filename": self.resolve(base_dir, a["filename"])}
        return a["name"], {"type": "spectrum", "value": self.spectrum_value(c, a["value"])}

    def spectrum_value(self, c: _Node, text: str):
        """"0.5" -> 0.5; "400:0.1, 500:0.2" -> [(400.0, 0.1), (500.0, 0.2)]."""
        parts = [p for p in re.split(r"\s*,\s*|\s+", text.strip()) if p]
        if len(parts) == 1 and ":" not in parts[0]:
            return self.number(c, "value", parts[0])
        pairs = []
        for p in parts:
            wl, sep, val = p.partition(":")
            if not sep:
                raise self.err(c, f'attribute "value": expected one number or '
                               f'"wavelength:value" pairs, got "{text}"')
            pairs.append((self.number(c, "value", wl), self.number(c, "value", val)))
        return pairs

    # --------------------------------------------------------------- transforms
    def transform(self, node: _Node):
        """Compose the transform operations of <transform> in document order."""
        import mitsuba as mi
        T = mi.ScalarTransform4f()
        for op in node.children:
            if op.tag not in _TRANSFORM_OPS:
                raise self.err(op, "unknown transform operation (expected "
                               + ", ".join(f"<{t}>" for t in _TRANSFORM_OPS) + ")")
            self.no_children(op)
            T = self.transform_op(op, mi) @ T
        return T

    def transform_op(self, op: _Node, mi):
        """One transform operation as a mi.ScalarTransform4f."""
        I = mi.ScalarTransform4f()
        if op.tag == "translate":
            a = self.attrs(op, optional=("value", "x", "y", "z"))
            return I.translate(self.vec3(op, a, default=0.0, broadcast=False))
        if op.tag == "scale":
            a = self.attrs(op, optional=("value", "x", "y", "z"))
            return I.scale(self.vec3(op, a, default=1.0))
        if op.tag == "rotate":
            a = self.attrs(op, required=("angle",), optional=("value", "x", "y", "z"))
            axis = self.vec3(op, a, default=0.0, broadcast=False)
            if not any(axis):
                raise self.err(op, "rotation axis must be non-zero")
            return I.rotate(axis, self.number(op, "angle", a["angle"]))
        if op.tag == "matrix":
            a = self.attrs(op, required=("value",))
            v = self.floats(op, "value", a["value"], (9, 16))
            if not np.all(np.isfinite(v)):
                # Checked here: a composed transform keeps only the affine rows, so a NaN in
                # the last row would be dropped silently.
                raise self.err(op, f'attribute "value": expected finite numbers, got "{a["value"]}"')
            if len(v) == 9:
                m = np.eye(4)
                m[:3, :3] = np.array(v).reshape(3, 3)
            else:
                m = np.array(v).reshape(4, 4)
            return mi.ScalarTransform4f(m)
        # lookat
        a = self.attrs(op, required=("origin", "target"), optional=("up",))
        origin = np.array(self.floats(op, "origin", a["origin"], (3,)))
        target = np.array(self.floats(op, "target", a["target"], (3,)))
        d = target - origin
        if not np.linalg.norm(d) > 0:
            raise self.err(op, "origin and target coincide")
        d = d / np.linalg.norm(d)
        if "up" in a:
            up = np.array(self.floats(op, "up", a["up"], (3,)))
        else:  # like Mitsuba: the first tangent of the orthonormal basis of
            # Duff et al. 2017, "Building an Orthonormal Basis, Revisited"
            sign = 1.0 if d[2] >= 0 else -1.0
            k = -1.0 / (sign + d[2])
            up = np.array([1.0 + sign * d[0] * d[0] * k, sign * d[0] * d[1] * k,
                           -sign * d[0]])
        if not np.linalg.norm(np.cross(up, d)) > 1e-12 * max(np.linalg.norm(up), 1e-300):
            raise self.err(op, '"up" is zero or parallel to the viewing direction')
        return I.look_at(origin=origin.tolist(), target=target.tolist(), up=up.tolist())


def parse_string(text: str, base_dir: str | None = None, **kwargs) -> dict:
    """Convert Mitsuba XML text to a Mitsuba scene dict.

    base_dir is where relative include/filename paths are looked up (default: the
    current directory); kwargs override ``<default>`` parameters like mi.load_string.
    """
    return _parse(text, "<string>", base_dir or os.getcwd(), kwargs)


def parse_file(path, **kwargs) -> dict:
    """Convert a Mitsuba XML file to a Mitsuba scene dict (``mi.load_dict``-ready).

    kwargs override ``<default>`` parameters, as in ``mi.load_file(path, **kwargs)``.
    """
    return parse_file_lines(path, **kwargs)[0]


def parse_file_lines(path, **kwargs) -> tuple[dict, dict]:
    """:func:`parse_file`, and the ``file:line`` of each key path of the dict
    (``{'scene.light.emitter.radiance': 'scene.xml:12', ...}``)."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            text = f.read()
    except OSError as e:
        raise XMLError(f"{path}:0: cannot read scene file: {e.strerror}") from None
    base_dir = os.path.dirname(os.path.abspath(path))
    p = _Parser(kwargs)
    p.include_stack.append(os.path.abspath(path))
    d = p.parse_root(_read_tree(text, path), base_dir)
    return d, p.lines(d)


def locate(error: str, lines: dict) -> str:
    """An error message that starts with a key path, prefixed with the ``file:line`` of
    the longest prefix of that path in ``lines`` (unchanged if there is none)."""
    key = error.split(": ", 1)[0].split(".")
    for n in range(len(key), 1, -1):
        where = lines.get(".".join(key[:n]))
        if where is not None:
            return f"{where}: {error}"
    return error


def _parse(text, file: str, base_dir: str, kwargs: dict) -> dict:
    """Parse XML text labelled file (for messages) with includes under base_dir."""
    return _Parser(kwargs).parse_root(_read_tree(text, file), base_dir)


# ----------------------------------------------------------------------------- writing

@functools.lru_cache(maxsize=None)
def tag_types() -> dict:
    """Object tag -> the type names pbr knows under it (every family registers its types
    when pbr is imported, so this is built once)."""
    return {"shape": frozenset(SHAPE_PARAMS) | {"shapegroup", "instance"}, "bsdf": frozenset(bsdf_names()),
            "emitter": frozenset(LIGHT_TYPES), "sensor": frozenset(SENSORS), "film": frozenset(FILMS),
            "sampler": frozenset(SAMPLERS), "rfilter": frozenset(FILTERS), "integrator": frozenset(INTEGRATORS),
            "texture": frozenset(TEXTURE_TYPES), "spectrum": frozenset(TEXTURE_TYPES),
            "medium": frozenset(MEDIUM_TYPES), "phase": frozenset(PHASE_TYPES),
            "volume": frozenset({"gridvolume", "constvolume"})}


def _xml_tags():
    """(XML tag, type names) in the order ``to_xml`` tries them (other types: shapes).
    Sensors and samplers include Mitsuba types pbr does not render, so that any scene
    dict is written with the right tags; ``mix`` (a BSDF and a texture) is a BSDF."""
    return (("bsdf", bsdf_names()), ("emitter", LIGHT_TYPES),
            ("sensor", {"thinlens", "orthographic"} | set(SENSORS)), ("film", FILMS),
            ("sampler", {"orthogonal"} | set(SAMPLERS)), ("rfilter", FILTERS),
            ("integrator", INTEGRATORS), ("spectrum", ("blackbody", "d65", "uniform")),
            ("texture", ("bitmap", "checkerboard", "scale", "mix", "mesh_attribute")),
            ("medium", MEDIUM_TYPES), ("phase", PHASE_TYPES), ("volume", ("gridvolume", "constvolume")))


def to_xml(d: dict, base_dir: str | None = None) -> str:
    """Mitsuba 3 XML for a scene dict (the inverse of :func:`parse_string` for the value
    kinds it produces: numbers, booleans, strings, 3-vectors, rgb/spectrum/blackbody
    values, transforms, references and nested objects). With ``base_dir`` (the directory
    the XML file will be in), absolute ``filename`` values are written relative to it, as
    the XML loaders resolve them, so a scene folder can be moved or shared as a whole."""
    import numpy as np
    from xml.sax.saxutils import quoteattr

    def filename(v):
        if base_dir is None or not os.path.isabs(v):
            return v
        return os.path.relpath(v, os.path.abspath(base_dir)).replace(os.sep, "/")

    def num(v):
        return repr(float(v)) if not float(v).is_integer() else str(float(v))

    def matrix(v):
        m = np.array(v.matrix if hasattr(v, "matrix") else v, dtype=np.float64).reshape(4, 4)
        return " ".join(num(x) for x in m.ravel())

    def prop(name, v, ind):
        q = quoteattr(name)
        pad = "    " * ind
        if isinstance(v, bool):
            return f'{pad}<boolean name={q} value="{str(v).lower()}"/>'
        if isinstance(v, int):
            return f'{pad}<integer name={q} value="{v}"/>'
        if isinstance(v, float):
            return f'{pad}<float name={q} value="{num(v)}"/>'
        if isinstance(v, str):
            v = filename(v) if name == "filename" else v
            return f"{pad}<string name={q} value={quoteattr(v)}/>"
        if name == "transform_times" and np.size(v) == 2:   # pbr's motion times: "t0 t1"
            return f'{pad}<string name={q} value="{" ".join(num(float(x)) for x in v)}"/>'
        if hasattr(v, "matrix") or (isinstance(v, np.ndarray) and v.size == 16):
            return f'{pad}<transform name={q}><matrix value="{matrix(v)}"/></transform>'
        if isinstance(v, (list, tuple, np.ndarray)) and len(v) == 3 and not isinstance(v[0], (list, tuple)):
            return f'{pad}<point name={q} value="{", ".join(num(x) for x in v)}"/>'
        if isinstance(v, dict):
            t = v.get("type")
            if t == "rgb":
                val = v["value"]
                val = [val] * 3 if np.ndim(val) == 0 else val
                return f'{pad}<rgb name={q} value="{", ".join(num(x) for x in val)}"/>'
            if t == "spectrum" and "value" in v:
                val = v["value"]
                if np.ndim(val) == 0:
                    return f'{pad}<spectrum name={q} value="{num(val)}"/>'
                return f'{pad}<spectrum name={q} value="{", ".join(f"{num(a)}:{num(b)}" for a, b in val)}"/>'
            if t == "ref":
                return f'{pad}<ref name={q} id={quoteattr(v["id"])}/>'
            return obj(v, ind, name)
        raise TypeError(f"to_xml: cannot write parameter {name!r} of type {type(v).__name__}")

    def tag_of(t):
        for tag, names in _xml_tags():
            if t in names:
                return tag
        return "shape"

    def obj(v, ind, name=None, oid=None):
        pad = "    " * ind
        t = v["type"]
        attrs = f" type={quoteattr(t)}"
        if oid is not None:
            attrs += f" id={quoteattr(oid)}"
        if name is not None:
            attrs += f" name={quoteattr(name)}"
        body = [prop(k, x, ind + 1) for k, x in v.items() if k not in ("type", "id")]
        if not body:
            return f"{pad}<{tag_of(t)}{attrs}/>"
        return "\n".join([f"{pad}<{tag_of(t)}{attrs}>", *body, f"{pad}</{tag_of(t)}>"])

    lines = ['<scene version="3.0.0">']
    for k, v in d.items():
        if k == "type":
            continue
        lines.append(obj(v, 1, oid=k))
    lines.append("</scene>")
    return "\n".join(lines) + "\n"
