"""Loading textures: a Mitsuba spectrum-valued parameter (a float or a texture/spectrum
dict) -> a texture slot, by a table of one loading function per plugin type
(:data:`TEXTURE_TYPES`).

Constant spectra cover Mitsuba's ``rgb`` (albedo / unbounded / illuminant forms),
``spectrum`` (a constant, ``wavelength:value`` pairs or a file), ``blackbody``, ``d65``,
``uniform`` and plain floats; tabulated spectra are resampled at 1 nm, piecewise linear
and zero outside their range (as Mitsuba's ``regular``/``irregular`` spectra). Emitters
use the illuminant (D65) form for RGB and floats, as Mitsuba's spectral variants do.
Children of combinators get key paths below their parent (``mat.reflectance.tex.data``,
``mat.reflectance.amount.value``), as nested textures do in ``mi.traverse``.

Every value is checked against the parameter's range (:class:`~pbr.plugins.props.Range`:
finite, and e.g. an albedo in [0, 1], radiance >= 0); the texture keeps the range for
``params.update()`` (:func:`~pbr.plugins.params.check_params`).
"""

from __future__ import annotations

import os
import warnings

import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..image import linear_to_srgb, read_image
from ..plugins.params import check_params
from ..plugins.props import ALBEDO, FINITE, RADIANCE, UNIT, Props, Range, SceneError, did_you_mean
from ..plugins.registry import Registry
from . import meshattr, mipmap, procedural, volume
from .grid import load_gridvolume
from .kinds import (BASE_ONE, BASE_SIGMOID, BASE_TABLE, CONSTANT, OP_CHECKER, OP_MIX, OP_SCALE, OP_SQRT, TAB_N,
                    Bitmap, Checkerboard, Composite, ConstantSpectrum, MeshAttribute)

# Type name -> loading function ``fn(loader, props, form, emitter, unbounded) -> slot``
# (``mix`` is also a BSDF type: the scene loader tells them apart).
TEXTURE_TYPES = Registry("texture")


def default_range(emitter: bool, unbounded) -> Range:
    """The range of a spectrum-valued parameter that names none: radiance >= 0 for
    emitters, any finite value for unbounded spectra, else an albedo in [0, 1]."""
    return RADIANCE if emitter else (FINITE if unbounded else ALBEDO)


def load_spectrum(loader, value, path: str, emitter: bool, unbounded=False, valid: Range | None = None,
                  scalar: bool = False) -> int:
    """The texture slot of a spectrum-valued parameter ``value`` at key path ``path``: a
    float, or a dict ``{'type': 'rgb'|'spectrum'|'blackbody'|'d65'|'uniform'|
    'checkerboard'|'bitmap'|'scale'|'mix'|'sqrt'|'mesh_attribute'|'ref', ...}`` as in Mitsuba
    dicts. ``emitter``: the illuminant form; ``unbounded``: RGB values may exceed 1 (True:
    pbrt-v4's unbounded upsampling; ``"mitsuba"``: a parameter Mitsuba reads as an unbounded
    texture, whose ``rgb`` values it clamps to [0, 1], unless the ``rgb`` dict asks for
    ``'upsampling': 'unbounded'``: see :func:`_rgb`).
    ``valid``: the range of the values (default: :func:`default_range`; the textures
    nested in a texture have their parent's, which the loader holds in
    ``texture_range`` meanwhile).
    ``scalar``: the parameter is a float that Mitsuba reads with ``Texture::eval_1``
    (roughness, weights, opacity, the principled BSDFs' lobe parameters), where its
    ``checkerboard`` puts ``color0`` on the other squares (:func:`_checkerboard`).
    The texture keeps ``path`` as its key for :func:`pbr.traverse` (``red.reflectance``)."""
    outer = getattr(loader, "texture_range", None)
    valid = valid or outer or default_range(emitter, unbounded)
    loader.texture_range = valid
    try:
        return _load_spectrum(loader, value, path, emitter, unbounded, valid, scalar)
    finally:
        loader.texture_range = outer


def _load_spectrum(loader, value, path, emitter, unbounded, valid, scalar) -> int:
    textures = loader.textures
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        valid.check(value, path)
        v = float(value)
        if emitter:
            tex = ConstantSpectrum(path, BASE_SIGMOID, "illuminant", mi.Color3f(v))
        else:
            tex = ConstantSpectrum(path, BASE_ONE, value=mi.Float(v))
        tex.valid = {"value": valid}
        return textures.add(tex)
    if not isinstance(value, dict) or "type" not in value:
        raise SceneError(f"{path}: expected a float or a texture/spectrum dict with a 'type', got {value!r}")
    p = Props(value, path, loader)
    if p.type == "ref":
        obj = loader.resolve_ref(p.string("id"), path)
        p.finish()
        with loader.following(obj, path):
            return load_spectrum(loader, obj, path, emitter, unbounded, scalar=scalar)
    if p.type not in TEXTURE_TYPES:
        raise SceneError(f"{path}: unsupported texture/spectrum type {p.type!r}"
                         f"{did_you_mean(p.type, [*TEXTURE_TYPES, 'ref'])} (supported: {TEXTURE_TYPES.supported()}, ref)")
    form = "illuminant" if emitter else ("unbounded" if unbounded else "albedo")
    if p.type in _SCALAR_AWARE:
        slot = TEXTURE_TYPES[p.type](loader, p, form, emitter, unbounded, scalar=scalar)
    else:
        slot = TEXTURE_TYPES[p.type](loader, p, form, emitter, unbounded)
    _check_texture(textures.items[slot], valid, path)
    return slot


def _check_texture(tex, valid: Range, path: str) -> None:
    """Check a new texture's values against ``valid`` and keep the ranges of its
    parameters for ``params.update()``. Albedo bitmaps are exempt from the range (their
    texels are clipped to [0, 1] when read, as Mitsuba's upsampling does), not from
    finiteness."""
    if isinstance(tex, Bitmap):
        tex.valid = {"data": valid}
        data = np.asarray(tex.raw_values if tex.raw_values is not None else tex.params["data"])
        (FINITE if tex.form == "albedo" else valid).check(data, f"{path}.data")
        outside = int(np.count_nonzero((data < 0) | (data > 1))) if tex.form == "albedo" else 0
        if outside:     # Mitsuba warns the same ("contains pixels that exceed the [0, 1] range")
            warnings.warn(f"{path}.data: {outside} of {data.size} texel values are outside [0, 1] and are "
                          f"clipped to it (an albedo)", stacklevel=2)
        return
    if isinstance(tex, MeshAttribute):
        tex.valid = {"scale": valid.factor()}
    elif isinstance(tex, ConstantSpectrum):
        tex.valid = {"value": valid}
        if tex.table is not None:
            valid.check(tex.table, f"{path}.value", at=lambda i: f"{spec.LAMBDA_MIN + i:g} nm")
        if tex.scale != 1.0:
            valid.factor().check(tex.scale, f"{path}.scale")
    check_params(tex, path=path)


def read_spectrum_file(p: Props, name: str = "filename") -> tuple[np.ndarray, np.ndarray]:
    """(wavelengths, values) of the two-column ``.spd`` file parameter ``name`` of ``p``
    names, found by the load context (``p.loader``: relative to the scene file); a file
    that is missing or not such a table is a :class:`SceneError` naming the key path."""
    fname = p.string(name)
    path = p.loader.resolve_path(fname, p.key(name)) if p.loader is not None else fname
    try:
        return spec.read_spd(path)
    except OSError as e:
        raise p.error(name, f"cannot read spectrum file {fname!r}: {e.strerror}") from None
    except ValueError as e:     # read_table's message names the file and line
        raise p.error(name, f"not a spectrum file (wavelength value per line): {e}") from None


def add_tabulated(loader, wavelengths, values, path: str) -> int:
    """A texture slot for a tabulated spectrum (piecewise linear between samples)."""
    return loader.textures.add(ConstantSpectrum(path, BASE_TABLE, table=table_from_pairs(wavelengths, values, path)))


def table_from_pairs(wl: np.ndarray, vals: np.ndarray, where: str) -> np.ndarray:
    """(wavelength, value) samples -> the 1 nm table of a tabulated spectrum."""
    wl = np.asarray(wl, np.float64).reshape(-1)
    vals = np.asarray(vals, np.float64).reshape(-1)
    if wl.size != vals.size:
        raise SceneError(f"{where}: {wl.size} wavelengths but {vals.size} values")
    if wl.size < 2 or not np.all(np.diff(wl) > 0) or not wl[0] > 0:
        raise SceneError(f"{where}: wavelengths must be at least two strictly increasing values, in nm (> 0), "
                         f"got {', '.join(f'{x:g}' for x in wl[:6])}{', ...' if wl.size > 6 else ''}")
    FINITE.check(vals, where, at=lambda i: f"{wl[i]:g} nm")
    grid = spec.LAMBDA_MIN + np.arange(TAB_N)
    # Zero outside the given range, as Mitsuba's irregular/regular spectra.
    return np.where((grid >= wl[0]) & (grid <= wl[-1]), np.interp(grid, wl, vals), 0.0)


# Loading functions that take ``scalar`` (the others ignore it: constants and bitmaps).
_SCALAR_AWARE = ("checkerboard", "scale", "mix", "sqrt")


# ---------------------------------------------------------------- constant spectra

@TEXTURE_TYPES.register("rgb")
def _rgb(loader, p, form, emitter, unbounded):
    """``rgb``: an RGB colour, upsampled (Jakob-Hanika): albedo form in [0, 1], unbounded
    form, or illuminant form times D65 (emitters).

    ==========  ======  =========  ====================================================
    name        type    default    meaning
    ==========  ======  =========  ====================================================
    value       color   -          the colour (required)
    upsampling  string  'clamped'  for the parameters Mitsuba reads as unbounded
                                   textures (conductor ``eta``/``k``, roughness
                                   ``alpha``): 'clamped' (Mitsuba's: the colour is
                                   clamped to [0, 1] and upsampled as a reflectance)
                                   or 'unbounded' (pbrt-v4's RGBUnboundedSpectrum:
                                   ``2 max(rgb) S(rgb / (2 max(rgb)))``, values > 1 kept)
    ==========  ======  =========  ====================================================
    """
    rgb = p.vector3("value")
    if unbounded == "mitsuba":
        loader.texture_range.check(np.asarray(rgb, np.float64), p.key("value"))   # before the clamp
        if p.string("upsampling", "clamped", choices=("clamped", "unbounded")) == "clamped":
            rgb, form = np.clip(rgb, 0.0, 1.0), "albedo"
    p.finish()
    return loader.textures.add(ConstantSpectrum(p.path, BASE_SIGMOID, form, mi.Color3f(*map(float, rgb))))


@TEXTURE_TYPES.register("spectrum")
def _spectrum(loader, p, form, emitter, unbounded):
    """``spectrum``: a constant, ``wavelength:value`` pairs (piecewise linear, 0 outside)
    or a file.

    ========  ===========  =======  ==================================================
    name      type         default  meaning
    ========  ===========  =======  ==================================================
    value     float|pairs  -        a float, or (wavelength, value) pairs / 'l:v, ...'
    filename  string       -        a .spd file instead
    ========  ===========  =======  ==================================================
    """
    textures, path = loader.textures, p.path
    if p.has("filename"):
        wl, vals = read_spectrum_file(p)
        p.finish()
        table = table_from_pairs(wl, vals, p.key("filename"))
        return textures.add(ConstantSpectrum(path, BASE_TABLE, table=table))
    v = p.raw("value")
    p.finish()
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return textures.add(ConstantSpectrum(path, BASE_ONE, value=mi.Float(float(v))))
    if isinstance(v, str):
        try:
            pairs = [tuple(float(x) for x in item.split(":")) for item in v.replace(",", " ").split()]
        except ValueError:
            raise SceneError(f"{path}.value: expected 'wavelength:value' pairs, got {v!r}") from None
        v = pairs
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.empty(0)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise SceneError(f"{path}.value: expected a float or a list of (wavelength, value) pairs, got {v!r}")
    table = table_from_pairs(arr[:, 0], arr[:, 1], f"{path}.value")
    return textures.add(ConstantSpectrum(path, BASE_TABLE, table=table))


@TEXTURE_TYPES.register("blackbody")
def _blackbody(loader, p, form, emitter, unbounded):
    """``blackbody``: Planck's law in W/(m^2 sr nm), unnormalised (Mitsuba's convention).

    ==============  =====  =======  =================
    name            type   default  meaning
    ==============  =====  =======  =================
    temperature     float  -        kelvin (required)
    wavelength_min  float  360      0 below
    wavelength_max  float  830      0 above
    ==============  =====  =======  =================
    """
    temp = p.float("temperature", min=1.0)
    lo = p.float("wavelength_min", spec.LAMBDA_MIN)
    hi = p.float("wavelength_max", spec.LAMBDA_MAX)
    p.finish()
    grid = spec.LAMBDA_MIN + np.arange(TAB_N)
    table = np.where((grid >= lo) & (grid <= hi), spec.blackbody(grid, temp), 0.0)
    return loader.textures.add(ConstantSpectrum(p.path, BASE_TABLE, table=table))


@TEXTURE_TYPES.register("d65")
def _d65(loader, p, form, emitter, unbounded):
    """``d65``: the CIE D65 illuminant.

    =====  =====  =======  ===============================
    name   type   default  meaning
    =====  =====  =======  ===============================
    scale  float  1        factor
    color  color  -        an RGB colour times D65 instead
    =====  =====  =======  ===============================
    """
    scale = p.float("scale", 1.0)
    if p.has("color"):
        rgb = p.vector3("color")
        p.finish()
        return loader.textures.add(ConstantSpectrum(p.path, BASE_SIGMOID, "illuminant", mi.Color3f(*map(float, rgb)),
                                                    scale=scale))
    p.finish()
    return loader.textures.add(ConstantSpectrum(p.path, BASE_ONE, "illuminant", scale=scale))


@TEXTURE_TYPES.register("uniform")
def _uniform(loader, p, form, emitter, unbounded):
    """``uniform``: a constant.

    =====  =====  =======  ====================
    name   type   default  meaning
    =====  =====  =======  ====================
    value  float  -        the value (required)
    =====  =====  =======  ====================
    """
    v = p.float("value")
    p.finish()
    return loader.textures.add(ConstantSpectrum(p.path, BASE_ONE, value=mi.Float(v)))


# -------------------------------------------------------------- spatially varying

_PBRT_CHECKER_KEYS = ("tex1", "tex2", "dimension", "mapping", "uscale", "vscale", "udelta", "vdelta", "v1", "v2",
                      "to_world")


@TEXTURE_TYPES.register("checkerboard")
def _checkerboard(loader, p, form, emitter, unbounded, scalar=False):
    """``checkerboard``: Mitsuba's (``color0``/``color1``: two colours alternating on the
    unit squares of uv), or pbrt-v4's (``tex1``/``tex2``, a 2D pattern over a mapping or
    a 3D one, box-filtered over the pixel footprint): the parameters tell which.

    ==========  =========  ========  ===================================================
    name        type       default   meaning
    ==========  =========  ========  ===================================================
    color0      texture    0.4       Mitsuba's: colour of the even squares
    color1      texture    0.2       Mitsuba's: colour of the odd squares
    to_uv       transform  identity  Mitsuba's: texture-coordinate transform
    tex1        texture    1         pbrt-v4's: where floor(s) + floor(t) (+ floor(z))
                                     is even
    tex2        texture    0         pbrt-v4's: on the other squares
    dimension   int        2         pbrt-v4's: 2 (over a 2D mapping) or 3 (over
                                     texture space)
    mapping     string     'uv'      pbrt-v4's 2D mapping (see ``dots``) and its
                                     ``uscale``, ``vscale``, ``udelta``, ``vdelta``,
                                     ``v1``, ``v2``, ``to_world``
    ==========  =========  ========  ===================================================

    Mitsuba's even squares are those where frac(u) > 1/2 and frac(v) > 1/2 agree. As in
    Mitsuba, its checkerboard given to a float parameter (read with ``eval_1``:
    roughness, blend weights, opacity, principled lobe weights) has ``color0`` on the odd
    squares.
    """
    if any(p.has(k) for k in _PBRT_CHECKER_KEYS):
        for k in ("color0", "color1", "to_uv"):
            if p.has(k):
                raise p.error(k, "Mitsuba's checkerboard parameter mixed with pbrt-v4's (tex1, tex2, dimension, "
                                 "mapping, ...): use one or the other")
        dim = p.int("dimension", 2)
        if dim not in (2, 3):
            raise p.error("dimension", f"expected 2 or 3, got {dim}")
        pattern = procedural.CHECKER2D if dim == 2 else procedural.CHECKER3D
        return _pbrt_blend(loader, p, form, emitter, unbounded, pattern, ("tex1", 1.0), ("tex2", 0.0), dim == 2)
    textures = loader.textures
    keys = ("color1", "color0") if scalar else ("color0", "color1")
    c0 = load_spectrum(loader, p.raw(keys[0], {"color0": 0.4, "color1": 0.2}[keys[0]]), p.key(keys[0]), emitter,
                       unbounded, scalar=scalar)
    c1 = load_spectrum(loader, p.raw(keys[1], {"color0": 0.4, "color1": 0.2}[keys[1]]), p.key(keys[1]), emitter,
                       unbounded, scalar=scalar)
    to_uv = p.transform("to_uv")
    p.finish()
    if textures.kind_of(c0) == CONSTANT and textures.kind_of(c1) == CONSTANT:
        return textures.add(Checkerboard(p.path, c0, c1, to_uv))
    return textures.add(Composite(p.path, OP_CHECKER, c0, c1, to_uv=to_uv))   # textured colours: a combinator


# ------------------------------------------------ pbrt-v4's procedural textures

def _texture_space(p) -> np.ndarray:
    """texture-from-world: the inverse of ``to_world`` (texture -> world)."""
    m = p.transform("to_world")
    try:
        return np.linalg.inv(m)
    except np.linalg.LinAlgError:
        raise p.error("to_world", "the texture transform is singular") from None


def _mapping_2d(p) -> dict:
    """pbrt-v4's 2D mapping parameters -> :class:`~.procedural.Procedural` keywords."""
    name = p.string("mapping", "uv", choices=tuple(procedural.MAPPINGS))
    kw = {"mapping": procedural.MAPPINGS[name], "texture_from_world": _texture_space(p)}
    if name == "uv":
        kw["uv"] = (p.float("uscale", 1.0), p.float("vscale", 1.0), p.float("udelta", 0.0), p.float("vdelta", 0.0))
    elif name == "planar":
        kw["uv"] = (1.0, 1.0, p.float("udelta", 0.0), p.float("vdelta", 0.0))
        kw["planar"] = (p.vector3("v1", [1.0, 0.0, 0.0]), p.vector3("v2", [0.0, 1.0, 0.0]))
    return kw


def _pbrt_blend(loader, p, form, emitter, unbounded, pattern, a, b, two_d):
    """A pattern blending two child textures: ``mix`` (x = ``a``, y = ``b``) whose amount
    is the pattern's weight (a procedural slot)."""
    x = load_spectrum(loader, p.raw(a[0], a[1]), p.key(a[0]), emitter, unbounded)
    y = load_spectrum(loader, p.raw(b[0], b[1]), p.key(b[0]), emitter, unbounded)
    kw = _mapping_2d(p) if two_d else {"mapping": procedural.MAP_UV, "texture_from_world": _texture_space(p)}
    p.finish()
    m = loader.textures.add(procedural.Procedural(p.path + ".pattern", pattern, **kw))
    return loader.textures.add(Composite(p.path, OP_MIX, x, y, m))


def _noise_params(p, octaves=True):
    kw = {"mapping": procedural.MAP_UV, "texture_from_world": _texture_space(p)}
    if octaves:
        kw["octaves"] = p.int("octaves", 8, min=0)
        if kw["octaves"] > 30:
            raise p.error("octaves", f"at most 30 octaves, got {kw['octaves']}")
        kw["omega"] = p.float("roughness", 0.5)
    return kw


@TEXTURE_TYPES.register("fbm")
def _fbm(loader, p, form, emitter, unbounded):
    """``fbm`` (pbrt-v4's): fractional Brownian motion, sum of octaves of Perlin noise
    (values around [-1, 1]; the same at every wavelength), up to the pixel footprint's
    frequency.

    =========  =========  ========  ===============================================
    name       type       default   meaning
    =========  =========  ========  ===============================================
    octaves    int        8         most octaves
    roughness  float      0.5       amplitude factor per octave (omega)
    to_world   transform  identity  texture space -> world (points use its inverse)
    =========  =========  ========  ===============================================
    """
    kw = _noise_params(p)
    p.finish()
    return loader.textures.add(procedural.Procedural(p.path, procedural.FBM, **kw))


@TEXTURE_TYPES.register("wrinkled")
def _wrinkled(loader, p, form, emitter, unbounded):
    """``wrinkled`` (pbrt-v4's): turbulence, the sum of octaves of |noise| (octaves past
    the pixel footprint count their mean, 0.2).

    =========  =========  ========  ===============================================
    name       type       default   meaning
    =========  =========  ========  ===============================================
    octaves    int        8         most octaves
    roughness  float      0.5       amplitude factor per octave (omega)
    to_world   transform  identity  texture space -> world (points use its inverse)
    =========  =========  ========  ===============================================
    """
    kw = _noise_params(p)
    p.finish()
    return loader.textures.add(procedural.Procedural(p.path, procedural.WRINKLED, **kw))


@TEXTURE_TYPES.register("windy")
def _windy(loader, p, form, emitter, unbounded):
    """``windy`` (pbrt-v4's): |fbm(p / 10, 3 octaves)| * fbm(p, 6 octaves), waves on water.

    ========  =========  ========  ===============================================
    name      type       default   meaning
    ========  =========  ========  ===============================================
    to_world  transform  identity  texture space -> world (points use its inverse)
    ========  =========  ========  ===============================================
    """
    kw = _noise_params(p, octaves=False)
    p.finish()
    return loader.textures.add(procedural.Procedural(p.path, procedural.WINDY, **kw))


@TEXTURE_TYPES.register("marble")
def _marble(loader, p, form, emitter, unbounded):
    """``marble`` (pbrt-v4's): sin(y + variation fbm) through pbrt-v4's colour spline,
    an sRGB albedo.

    =========  =========  ========  ===============================================
    name       type       default   meaning
    =========  =========  ========  ===============================================
    octaves    int        8         most octaves of the fbm
    roughness  float      0.5       amplitude factor per octave (omega)
    scale      float      1         frequency of the pattern (points times scale)
    variation  float      0.2       strength of the fbm perturbation
    to_world   transform  identity  texture space -> world (points use its inverse)
    =========  =========  ========  ===============================================
    """
    kw = _noise_params(p)
    kw["scale"] = p.float("scale", 1.0)
    kw["variation"] = p.float("variation", 0.2)
    p.finish()
    return loader.textures.add(procedural.Procedural(p.path, procedural.MARBLE, **kw))


@TEXTURE_TYPES.register("dots")
def _dots(loader, p, form, emitter, unbounded):
    """``dots`` (pbrt-v4's): polka dots (radius 0.35, randomly placed in the unit cells
    of the 2D mapping where noise > 0).

    ========  =========  =========  =================================================
    name      type       default    meaning
    ========  =========  =========  =================================================
    inside    texture    1          inside the dots
    outside   texture    0          elsewhere
    mapping   string     'uv'       'uv', 'spherical', 'cylindrical' or 'planar'
    uscale    float      1          'uv': s = uscale u + udelta
    vscale    float      1          'uv': t = vscale v + vdelta
    udelta    float      0          'uv' and 'planar': offset of s
    vdelta    float      0          'uv' and 'planar': offset of t
    v1        vector     (1, 0, 0)  'planar': s axis
    v2        vector     (0, 1, 0)  'planar': t axis
    to_world  transform  identity   texture space -> world ('spherical',
                                    'cylindrical', 'planar' use its inverse)
    ========  =========  =========  =================================================
    """
    return _pbrt_blend(loader, p, form, emitter, unbounded, procedural.DOTS, ("inside", 1.0), ("outside", 0.0), True)


@TEXTURE_TYPES.register("bilerp")
def _bilerp(loader, p, form, emitter, unbounded):
    """``bilerp`` (pbrt-v4's): bilinear interpolation of four values over the 2D mapping's
    (s, t): (1 - s)(1 - t) v00 + s (1 - t) v10 + (1 - s) t v01 + s t v11 (s, t are not
    clamped: the plane extends beyond the unit square).

    ========  =========  =========  =================================================
    name      type       default    meaning
    ========  =========  =========  =================================================
    v00       texture    0          the value at (s, t) = (0, 0)
    v10       texture    0          at (1, 0)
    v01       texture    1          at (0, 1)
    v11       texture    1          at (1, 1)
    mapping   string     'uv'       2D mapping (see ``dots``), with ``uscale``,
                                    ``vscale``, ``udelta``, ``vdelta``, ``v1``,
                                    ``v2``, ``to_world``
    ========  =========  =========  =================================================
    """
    v = {k: load_spectrum(loader, p.raw(k, d), p.key(k), emitter, unbounded)
         for k, d in (("v00", 0.0), ("v10", 0.0), ("v01", 1.0), ("v11", 1.0))}
    kw = _mapping_2d(p)
    p.finish()
    T = loader.textures
    s = T.add(procedural.Procedural(p.path + ".s", procedural.COORD_S, **kw))
    t = T.add(procedural.Procedural(p.path + ".t", procedural.COORD_T, **kw))
    row0 = T.add(Composite(p.path + ".t0", OP_MIX, v["v00"], v["v10"], s))
    row1 = T.add(Composite(p.path + ".t1", OP_MIX, v["v01"], v["v11"], s))
    return T.add(Composite(p.path, OP_MIX, row0, row1, t))


@TEXTURE_TYPES.register("directionmix")
def _directionmix(loader, p, form, emitter, unbounded):
    """``directionmix`` (pbrt-v4's): a |n . dir| tex1 + (1 - |n . dir|) tex2, n the
    surface's geometric normal, ``dir`` normalised after ``to_world`` (tex1 where the
    surface faces along dir, tex2 where it is parallel to it).

    ========  =========  =========  ==============================================
    name      type       default    meaning
    ========  =========  =========  ==============================================
    tex1      texture    0          where n is along dir
    tex2      texture    1          where n is perpendicular to dir
    dir       vector     (0, 1, 0)  the direction, in texture space
    to_world  transform  identity   texture space -> world (applied to dir)
    ========  =========  =========  ==============================================
    """
    x = load_spectrum(loader, p.raw("tex1", 0.0), p.key("tex1"), emitter, unbounded)
    y = load_spectrum(loader, p.raw("tex2", 1.0), p.key("tex2"), emitter, unbounded)
    d = np.asarray(p.transform("to_world"), np.float64)[:3, :3] @ np.asarray(p.vector3("dir", [0.0, 1.0, 0.0]),
                                                                             np.float64)
    if not np.linalg.norm(d) > 0:
        raise p.error("dir", "the direction is zero (or the transform makes it so)")
    p.finish()
    d = tuple(float(c) for c in d / np.linalg.norm(d))
    w = loader.textures.add(procedural.Procedural(p.path + ".weight", procedural.DIRECTION, procedural.MAP_UV,
                                                  np.eye(4), planar=(d, (0.0, 1.0, 0.0))))
    return loader.textures.add(Composite(p.path, OP_MIX, y, x, w))


@TEXTURE_TYPES.register("imagemap")
def _imagemap(loader, p, form, emitter, unbounded):
    """``imagemap`` (pbrt-v4's): an image with a MIP pyramid, filtered over the pixel
    footprint (see :mod:`pbr.textures.mipmap`). t is flipped (image row 0 at t = 1).

    =============  =========  ==========  ================================================
    name           type       default     meaning
    =============  =========  ==========  ================================================
    filename       string     -           the image (or ``data``)
    data           array      -           an (H, W, C) array (linear values) instead
    filter         string     'bilinear'  'point', 'bilinear', 'trilinear' or 'ewa'
    maxanisotropy  float      8           'ewa': longest ratio of the footprint's axes
    wrap           string     'repeat'    'repeat', 'black' or 'clamp'
    scale          float      1           factor on the values
    invert         bool       false       1 - value (after the scale)
    encoding       string     -           'sRGB' (default for 8-bit files) or 'linear'
    mapping        string     'uv'        2D mapping (see ``dots``), with ``uscale``,
                                          ``vscale``, ``udelta``, ``vdelta``, ``v1``,
                                          ``v2``, ``to_world``
    =============  =========  ==========  ================================================

    The texels are not differentiable parameters (use Mitsuba's ``bitmap`` for that).
    """
    filt = p.string("filter", "bilinear", choices=mipmap.FILTERS)
    max_aniso = p.float("maxanisotropy", 8.0, min=1.0)
    wrap = p.string("wrap", "repeat", choices=(*mipmap.WRAPS, "octahedralsphere"))
    if wrap == "octahedralsphere":
        raise p.error("wrap", "'octahedralsphere' is not supported (supported: repeat, black, clamp)")
    scale = p.float("scale", 1.0)
    invert = p.bool("invert", False)
    if p.has("data"):
        rgb = np.asarray(p.raw("data"), dtype=np.float32)
        if rgb.ndim == 2:
            rgb = rgb[..., None]
        if rgb.ndim != 3 or rgb.shape[2] not in (1, 3, 4):
            raise p.error("data", f"expected an (H, W, 1|3|4) array, got shape {rgb.shape}")
        eight_bit = False
    else:
        fname = loader.resolve_path(p.string("filename"), p.key("filename"))
        try:
            rgb = read_image(fname)
        except Exception as e:  # unreadable file
            raise p.error("filename", f"cannot read image {fname!r}: {e}") from None
        eight_bit = os.path.splitext(fname)[1].lower() in (".png", ".jpg", ".jpeg", ".tga", ".bmp")
    encoding = p.string("encoding", "sRGB" if eight_bit else "linear", choices=("sRGB", "linear"))
    if eight_bit and encoding == "linear":
        rgb = linear_to_srgb(rgb).astype(np.float32)   # read_image decoded sRGB: keep the stored values
    kw = _mapping_2d(p)
    p.finish()
    if rgb.ndim == 2:
        rgb = rgb[..., None]
    rgb = np.repeat(rgb[..., :1], 3, axis=2) if rgb.shape[2] == 1 else rgb[..., :3]
    FINITE.check(rgb, p.key("filename" if p.has("filename") else "data"))
    mapping = procedural.Procedural(p.path + ".mapping", procedural.CHECKER2D, **kw)
    return loader.textures.add(mipmap.MipMap(p.path, rgb, filt, wrap, max_aniso, scale, invert, form, mapping))


@TEXTURE_TYPES.register("scale")
def _scale(loader, p, form, emitter, unbounded, scalar=False):
    """``scale`` (pbrt-v4's): tex * scale. The factor is a plain (unbounded, never
    illuminant) spectrum, so that an emitter's scaled radiance carries D65 once.

    =====  =======  =======  ===========
    name   type     default  meaning
    =====  =======  =======  ===========
    tex    texture  1        the texture
    scale  texture  1        the factor
    =====  =======  =======  ===========
    """
    # pbrt-v4's ``scale``: tex * scale. The factor is a plain (unbounded, never
    # illuminant) spectrum, so that an emitter's scaled radiance carries D65 once.
    x = load_spectrum(loader, p.raw("tex", 1.0), p.key("tex"), emitter, unbounded, scalar=scalar)
    m = load_spectrum(loader, p.raw("scale", 1.0), p.key("scale"), emitter=False, unbounded=True,
                      valid=loader.texture_range.factor(), scalar=scalar)
    p.finish()
    return loader.textures.add(Composite(p.path, OP_SCALE, x, m=m))


@TEXTURE_TYPES.register("mix")
def _mix(loader, p, form, emitter, unbounded, scalar=False):
    """``mix`` (pbrt-v4's texture): (1 - amount) tex1 + amount tex2.

    ======  =======  =======  ==============
    name    type     default  meaning
    ======  =======  =======  ==============
    tex1    texture  0        first texture
    tex2    texture  1        second texture
    amount  texture  0.5      blend
    ======  =======  =======  ==============
    """
    # pbrt-v4's ``mix``: (1 - amount) tex1 + amount tex2 (defaults 0, 1 and 0.5).
    x = load_spectrum(loader, p.raw("tex1", 0.0), p.key("tex1"), emitter, unbounded, scalar=scalar)
    y = load_spectrum(loader, p.raw("tex2", 1.0), p.key("tex2"), emitter, unbounded, scalar=scalar)
    m = load_spectrum(loader, p.raw("amount", 0.5), p.key("amount"), emitter=False, valid=UNIT)
    p.finish()
    return loader.textures.add(Composite(p.path, OP_MIX, x, y, m))


@TEXTURE_TYPES.register("sqrt")
def _sqrt(loader, p, form, emitter, unbounded, scalar=False):
    """``sqrt`` (pbr's): the square root of a texture's value, sqrt(max(tex, 0)), taken
    where the texture is evaluated. The pbrt-v4 reader wraps a roughness texture in it
    when ``remaproughness`` is true (pbrt-v4's TrowbridgeReitzDistribution::
    RoughnessToAlpha, alpha = sqrt(roughness), applied to the texture's value at each
    lookup), so that ``roughconductor``/``roughdielectric`` get alpha.

    ====  =======  =======  =====================
    name  type     default  meaning
    ====  =======  =======  =====================
    tex   texture  -        the texture (required)
    ====  =======  =======  =====================
    """
    if not p.has("tex"):
        raise p.error("tex", "sqrt needs a texture 'tex'")
    x = load_spectrum(loader, p.raw("tex"), p.key("tex"), emitter, unbounded, scalar=scalar)
    p.finish()
    return loader.textures.add(Composite(p.path, OP_SQRT, x))


@TEXTURE_TYPES.register("bitmap")
def _bitmap(loader, p, form, emitter, unbounded):
    """``bitmap`` (Mitsuba's): an image, upsampled per texel; the spectra of the four
    nearest texels are interpolated (bilinear).

    ===========  =========  ========  ==============================================
    name         type       default   meaning
    ===========  =========  ========  ==============================================
    filename     string     -         the image (or data)
    data         array      -         an (H, W, C) array instead
    filter_type  string     bilinear  'bilinear' or 'nearest'
    wrap_mode    string     repeat    'repeat', 'mirror' or 'clamp'
    raw          bool       false     keep 8-bit values as stored (no sRGB decoding)
    to_uv        transform  identity  texture-coordinate transform
    accel        bool       true      accepted for Mitsuba scenes, no effect (below)
    ===========  =========  ========  ==============================================

    pbr always interpolates in float32. Mitsuba's ``accel`` (default true) lets its CUDA
    variants filter with the GPU's texture units, whose bilinear weights have 8 fractional
    bits: its lookups differ from pbr's (and from its own LLVM variants) by up to ~1/256
    of neighbouring texels' difference. Compare with ``accel`` false on CUDA.
    """
    p.bool("accel", True)
    filter_type = p.string("filter_type", "bilinear", choices=("bilinear", "nearest"))
    wrap_mode = p.string("wrap_mode", "repeat", choices=("repeat", "mirror", "clamp"))
    raw = p.bool("raw", False)
    to_uv = p.transform("to_uv")
    p.mark("format")
    if p.has("data"):
        rgb = np.asarray(p.raw("data"), dtype=np.float32)
        if rgb.ndim == 2:
            rgb = rgb[..., None]
        if rgb.ndim != 3:
            raise p.error("data", f"expected an (H, W, C) array, got shape {rgb.shape}")
    else:
        fname = loader.resolve_path(p.string("filename"), p.key("filename"))
        try:
            rgb = read_image(fname)
        except Exception as e:  # unreadable file
            raise p.error("filename", f"cannot read image {fname!r}: {e}") from None
    p.finish()
    if rgb.ndim == 2:
        rgb = rgb[..., None]
    rgb = rgb[..., :3] if rgb.shape[2] >= 3 else rgb[..., :1]
    if raw and not p.has("data") and os.path.splitext(fname)[1].lower() in (".png", ".jpg", ".jpeg"):
        # read_image decodes 8-bit sRGB; raw data (normal/bump maps) keeps the stored values.
        rgb = linear_to_srgb(rgb).astype(np.float32)
    raw_values = np.array(rgb, dtype=np.float32)
    if form == "albedo":
        rgb = np.clip(rgb, 0.0, 1.0)
    return loader.textures.add(Bitmap(p.path, rgb, filter_type, wrap_mode, to_uv, form, raw_values))


@TEXTURE_TYPES.register("rawconstant")
def _rawconstant(loader, p, form, emitter, unbounded):
    """``rawconstant`` (Mitsuba's): a constant used as stored, without colour conversion
    or range checks: one value (a plain spectrum equal to it) or a 3-vector (e.g. a normal
    map's flat normal (0.5, 0.5, 1); evaluated as a colour, pbr upsamples it, where
    Mitsuba's spectral variants refuse).

    =====  ============  =======  ==========================
    name   type          default  meaning
    =====  ============  =======  ==========================
    value  float|vector  -        the value(s) (required)
    =====  ============  =======  ==========================
    """
    v = p.raw("value")
    if isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool):
        p.float("value")
        p.finish()
        return loader.textures.add(ConstantSpectrum(p.path, BASE_ONE, value=mi.Float(float(v))))
    vec = p.vector3("value").astype(np.float32)
    p.finish()
    texel = vec.reshape(1, 1, 3)
    rgb = np.clip(texel, 0.0, 1.0) if form == "albedo" else texel
    return loader.textures.add(Bitmap(p.path, rgb, "nearest", "clamp", np.eye(4), form, texel.copy()))


@TEXTURE_TYPES.register("volume")
def _volume(loader, p, form, emitter, unbounded):
    """``volume`` (Mitsuba's): a ``gridvolume``'s value at the surface point's world
    position (see :mod:`pbr.textures.volume`; clamped outside the grid's box).

    ======  ======  ========  =====================================================
    name    type    default   meaning
    ======  ======  ========  =====================================================
    volume  volume  -         a ``gridvolume`` (``filename``, ``data`` or ``grid``, ``to_world``,
                              ``use_grid_bbox``) or a ``constvolume`` (required)
    ======  ======  ========  =====================================================
    """
    v = p.raw("volume", None)
    if not isinstance(v, dict) or v.get("type") not in ("gridvolume", "constvolume"):
        raise p.error("volume", f"expected a gridvolume or constvolume, got "
                                f"{v.get('type') if isinstance(v, dict) else v!r}")
    vp = Props(v, p.key("volume"), loader)
    if vp.type == "constvolume":   # a constant: the texture is its value
        vp.transform("to_world")
        slot = load_spectrum(loader, vp.raw("value", 1.0), vp.key("value"), emitter, unbounded)
        vp.finish()
        p.finish()
        return slot
    data, to_world = load_gridvolume(loader, vp)
    p.finish()
    try:
        grid_from_world = np.linalg.inv(to_world)
    except np.linalg.LinAlgError:
        raise vp.error("to_world", "the grid transform is singular") from None
    return loader.textures.add(volume.VolumeTexture(p.path, data, grid_from_world, form))


@TEXTURE_TYPES.register("mesh_attribute")
def _mesh_attribute(loader, p, form, emitter, unbounded):
    """``mesh_attribute`` (Mitsuba's): a mesh's per-vertex or per-face attribute at the hit.

    =====  ======  =======  ===========================================
    name   type    default  meaning
    =====  ======  =======  ===========================================
    name   string  -        'vertex_*' or 'face_*' attribute (required)
    scale  float   1        factor
    =====  ======  =======  ===========================================
    """
    return loader.textures.add(meshattr.load(p, form))
