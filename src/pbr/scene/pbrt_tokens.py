"""pbrt-v4 scene files -> tokens and directives (the syntax only; :mod:`.pbrt` gives
them meaning).

A pbrt-v4 file is a sequence of directives (``Shape "sphere" "float radius" 2``): an
unquoted word, positional arguments, then parameters, each a quoted ``"type name"``
followed by one value or a bracketed list. ``#`` starts a comment. Every token keeps the
file and line it came from, so that every error can name them. Files ending in ``.gz``
are read through gzip, as pbrt-v4 does.
"""
from __future__ import annotations

import gzip
import os
import re
from dataclasses import dataclass, field

from .xml import XMLError

__all__ = ["Token", "Param", "Directive", "tokenize", "read_directives", "last_of_each", "PARAM_TYPES"]

# pbrt-v4's parameter types, and the synonyms its parser accepts.
PARAM_TYPES = {
    "integer": "integer", "float": "float", "point2": "point2", "vector2": "vector2",
    "point3": "point3", "point": "point3", "vector3": "vector3", "vector": "vector3",
    "normal3": "normal", "normal": "normal", "rgb": "rgb", "color": "rgb",
    "spectrum": "spectrum", "blackbody": "blackbody", "bool": "bool", "string": "string",
    "texture": "texture",
}

_TOKEN_RE = re.compile(r'''
    (?P<ws>[ \t\r]+) | (?P<nl>\n) | (?P<comment>\#[^\n]*) |
    (?P<str>"(?:[^"\\\n]|\\.)*") | (?P<open>\[) | (?P<close>\]) |
    (?P<word>[^\s"\[\]\#]+) | (?P<bad>")''', re.VERBOSE)
_NUMBER_RE = re.compile(r"[+-]?(\d|\.\d)")      # how a number token starts
# How many quoted strings each directive takes before its parameters (pbrt-v4's syntax).
_STRING_ARGS = {k: 1 for k in (
    "Shape", "Material", "LightSource", "AreaLightSource", "Camera", "Film", "Sampler", "PixelFilter",
    "Integrator", "Accelerator", "MakeNamedMaterial", "MakeNamedMedium", "NamedMaterial", "ObjectBegin",
    "ObjectInstance", "Include", "Import", "CoordinateSystem", "CoordSysTransform", "ColorSpace", "Attribute")}
_STRING_ARGS.update(Texture=3, MediumInterface=2, Option=0)
_ESCAPES = {"b": "\b", "f": "\f", "n": "\n", "r": "\r", "t": "\t", "\\": "\\", "'": "'", '"': '"'}


@dataclass
class Token:
    """One token: ``text`` (quotes removed from strings), whether it was ``quoted``, and
    where it came from."""
    text: str
    quoted: bool
    file: str
    line: int

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass
class Param:
    """A parameter: its pbrt-v4 ``type`` (synonyms resolved), ``name``, ``values`` (floats,
    ints, bools or strings) and where it was declared. ``used`` marks parameters that
    the converter read, so that the rest can be reported; ``color_space``: the
    ``ColorSpace`` its RGB values are in (set when its directive runs, as pbrt-v4 ties
    it to each parameter, also to ``Attribute`` defaults)."""
    type: str
    name: str
    values: list
    where: str
    used: bool = False
    color_space: str | None = None


@dataclass
class Directive:
    """A directive: its ``name``, positional ``args`` (strings or numbers), ``params``
    and the place of its first token."""
    name: str
    args: list
    params: list = field(default_factory=list)
    where: str = ""


def _unescape(s: str) -> str:
    return re.sub(r"\\(.)", lambda m: _ESCAPES.get(m.group(1), m.group(1)), s)


def read_text(path: str, where: str | None = None) -> str:
    """The text of a scene file (gunzipped if it ends in ``.gz``)."""
    try:
        if path.endswith(".gz"):
            with gzip.open(path, "rt", encoding="utf-8", errors="replace") as f:
                return f.read()
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read()
    except OSError as e:
        raise XMLError(f"{where or path + ':0'}: cannot read {path!r}: {e.strerror or e}") from None


def tokenize(text: str, file: str):
    """Yield the tokens of pbrt-v4 scene text ``text`` (named ``file`` in messages)."""
    line = 1
    for m in _TOKEN_RE.finditer(text):
        kind = m.lastgroup
        if kind == "nl":
            line += 1
        elif kind in ("ws", "comment"):
            continue
        elif kind == "str":
            yield Token(_unescape(m.group()[1:-1]), True, file, line)
        elif kind == "open":
            yield Token("[", False, file, line)
        elif kind == "close":
            yield Token("]", False, file, line)
        elif kind == "word":
            yield Token(m.group(), False, file, line)
        else:
            raise XMLError(f"{file}:{line}: unterminated string")


def _number(tok: Token, directive: str):
    try:
        v = float(tok.text)
    except ValueError:
        raise XMLError(f"{tok.where}: {directive}: expected a number, got {tok.text!r}") from None
    return int(v) if re.fullmatch(r"[+-]?\d+", tok.text) else v


def _convert(ptype: str, name: str, raw: list, where: str, directive: str) -> list:
    """Values of a parameter from its tokens, checked against its type."""
    out = []
    for t in raw:
        if ptype in ("string", "texture"):
            if not t.quoted:
                raise XMLError(f"{t.where}: {directive}: parameter {name!r} ({ptype}) expects quoted strings, got {t.text}")
            out.append(t.text)
        elif ptype == "bool":
            if t.text not in ("true", "false"):
                raise XMLError(f"{t.where}: {directive}: parameter {name!r} (bool) expects true or false, got {t.text!r}")
            out.append(t.text == "true")
        elif ptype == "spectrum" and t.quoted:
            out.append(t.text)           # a named spectrum or a file
        else:
            if t.quoted:
                raise XMLError(f"{t.where}: {directive}: parameter {name!r} ({ptype}) expects numbers, got \"{t.text}\"")
            v = _number(t, directive)
            if ptype == "integer":
                if not isinstance(v, int):
                    raise XMLError(f"{t.where}: {directive}: parameter {name!r} (integer) got non-integer {t.text}")
            else:
                v = float(v)
            out.append(v)
    sizes = {"point2": 2, "vector2": 2, "point3": 3, "vector3": 3, "normal": 3, "rgb": 3}
    n = sizes.get(ptype)
    if n and len(out) % n:
        raise XMLError(f"{where}: {directive}: parameter {name!r} ({ptype}) needs a multiple of {n} values, got {len(out)}")
    if ptype in ("string", "texture", "bool", "blackbody") and len(out) != 1 and ptype != "string":
        raise XMLError(f"{where}: {directive}: parameter {name!r} ({ptype}) takes one value, got {len(out)}")
    if ptype == "spectrum" and any(isinstance(v, str) for v in out) and len(out) != 1:
        raise XMLError(f"{where}: {directive}: parameter {name!r} (spectrum) takes one name or file")
    if ptype == "spectrum" and not any(isinstance(v, str) for v in out) and len(out) % 2:
        raise XMLError(f"{where}: {directive}: parameter {name!r} (spectrum) needs (wavelength, value) pairs, got {len(out)} numbers")
    if not out:
        raise XMLError(f"{where}: {directive}: parameter {name!r} has no value")
    return out


def read_directives(path: str, text: str | None = None, known=None):
    """Yield the directives of a pbrt-v4 file (not following ``Include``/``Import``).
    ``known``: the directive names; another name is yielded without arguments (they are
    skipped up to the next word), for the reader to report as unknown: read as a
    parameter list, they would give an error about that instead."""
    toks = list(tokenize(read_text(path) if text is None else text, path))
    i, n = 0, len(toks)
    while i < n:
        t = toks[i]
        if t.quoted or t.text in ("[", "]"):
            shown = f'"{t.text}"' if t.quoted else t.text
            raise XMLError(f"{t.where}: expected a directive, got {shown}")
        if known is not None and t.text not in known:
            i += 1
            while i < n and (toks[i].quoted or toks[i].text in ("[", "]") or _NUMBER_RE.match(toks[i].text)):
                i += 1
            yield Directive(t.text, [], [], t.where)
            continue
        d = Directive(t.text, [], [], t.where)
        i += 1
        if d.name == "ActiveTransform" and i < n and not toks[i].quoted:
            d.args.append(toks[i].text)      # its argument is an unquoted word
            i += 1
            yield d
            continue
        # Positional arguments: numbers (possibly in brackets), or the directive's quoted
        # strings (as many as it takes, so that a misspelt "type name" is a parameter).
        nstr = _STRING_ARGS.get(d.name)
        bracket = False
        while i < n:
            a = toks[i]
            if a.text == "[" and not a.quoted:
                if d.args or bracket or nstr is not None:
                    break
                bracket = True
                i += 1
                continue
            if a.text == "]" and not a.quoted:
                if not bracket:
                    raise XMLError(f"{a.where}: {d.name}: unexpected ']'")
                bracket = False
                i += 1
                break
            if a.quoted:
                if nstr is None or len(d.args) >= nstr:
                    break
                if d.name == "MediumInterface" and d.args and len(a.text.split()) == 2 \
                        and a.text.split()[0] in PARAM_TYPES:
                    break
                d.args.append(a.text)
            else:
                if nstr is not None or not _NUMBER_RE.match(a.text):
                    break       # the next directive
                d.args.append(_number(a, d.name))
            i += 1
        if bracket:
            raise XMLError(f"{d.where}: {d.name}: missing ']'")
        # Parameters.
        while i < n and toks[i].quoted:
            decl = toks[i]
            parts = decl.text.split()
            if len(parts) != 2:
                raise XMLError(f"{decl.where}: {d.name}: expected a parameter declaration \"type name\", got \"{decl.text}\"")
            ptype, pname = parts
            if ptype not in PARAM_TYPES:
                raise XMLError(f"{decl.where}: {d.name}: unknown parameter type {ptype!r} in \"{decl.text}\" "
                               f"(pbrt-v4's: {', '.join(sorted(set(PARAM_TYPES)))})")
            i += 1
            if i >= n:
                raise XMLError(f"{decl.where}: {d.name}: parameter {pname!r} has no value")
            raw = []
            if toks[i].text == "[" and not toks[i].quoted:
                i += 1
                while i < n and not (toks[i].text == "]" and not toks[i].quoted):
                    if toks[i].text == "[" and not toks[i].quoted:
                        raise XMLError(f"{toks[i].where}: {d.name}: nested '[' in parameter {pname!r}")
                    raw.append(toks[i])
                    i += 1
                if i >= n:
                    raise XMLError(f"{decl.where}: {d.name}: missing ']' after parameter {pname!r}")
                i += 1
            else:
                raw.append(toks[i])
                i += 1
            d.params.append(Param(PARAM_TYPES[ptype], pname, _convert(PARAM_TYPES[ptype], pname, raw, decl.where, d.name),
                                  decl.where))
        d.params = last_of_each(d.params)
        yield d


def last_of_each(params: list) -> list:
    """``params`` without the parameters shadowed by a later one of the same name:
    pbrt-v4 looks parameters up from the last given (its ParameterDictionary reverses
    them), so a repeated parameter overrides the earlier one without an error."""
    last = {q.name: i for i, q in enumerate(params)}
    return [q for i, q in enumerate(params) if last[q.name] == i]


def resolve(path: str, base: str) -> str:
    """``path`` relative to directory ``base`` (pbrt-v4: the directory of the main file)."""
    return path if os.path.isabs(path) else os.path.normpath(os.path.join(base, path))
