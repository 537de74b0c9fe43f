"""pbrt-v4's ``imagemap``: an RGB image with a MIP pyramid, filtered over the pixel
footprint ('point', 'bilinear', 'trilinear' or 'ewa', pbrt-v4's ``MIPMap::Filter``).

The pyramid is pbrt-v4's: an image whose sides are not powers of two is first resampled
up to the next powers of two (separable windowed sinc, radius 2, tau 2, weights
normalised, negative results clamped to 0), then each level averages 2x2 texels of the
one below, down to 1x1. Lookups filter RGB (as pbrt-v4 does) and upsample the result to
a spectrum (albedo, unbounded or illuminant form, as the parameter asks).

The footprint is the camera's (see :mod:`.procedural`: dp/dx, dp/dy from pbrt-v4's
``Approximate_dp_dxy``) mapped to (ds, dt) by the texture's 2D mapping. Filters:
'point' and 'bilinear' read the level whose texel spacing matches the footprint's width
(2 max |d(s,t)|); 'trilinear' blends the two levels around it; 'ewa' filters with
pbrt-v4's elliptically weighted average (its Gaussian weight table, the ellipse's minor
axis at most ``maxanisotropy`` times shorter than the major) on the two levels around
the minor axis's width. Like pbrt-v4, t is flipped (image row 0 at t = 1); unlike
pbrt-v4, whose lookups pass dt/dx unflipped, the footprint's t derivatives are flipped
too (an anisotropic footprint is not mirrored).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from .kinds import MIPMAP, key_path
from .procedural import build_table as build_mapping_table
from .procedural import footprint, map_2d
from .tables import MipmapTable

FILTERS = ("point", "bilinear", "trilinear", "ewa")
WRAPS = ("repeat", "black", "clamp")
FORMS = ("albedo", "unbounded", "illuminant")

# pbrt-v4's EWA weight table (MIPFilterLUT: 128 entries, Gaussian exp(-2 r^2) - exp(-2)).
EWA_LUT = np.array([
    0.864664733, 0.849040031, 0.83365953, 0.818519294, 0.80361563, 0.788944781, 0.774503231, 0.760287285,
    0.746293485, 0.732518315, 0.718958378, 0.705610275, 0.692470789, 0.679536581, 0.666804492, 0.654271305,
    0.641933978, 0.629789352, 0.617834508, 0.606066525, 0.594482362, 0.583079159, 0.571854174, 0.560804546,
    0.549927592, 0.539220572, 0.528680861, 0.518305838, 0.50809288, 0.498039544, 0.488143265, 0.478401601,
    0.468812168, 0.45937258, 0.450080454, 0.440933526, 0.431929469, 0.423066139, 0.414341331, 0.405752778,
    0.397298455, 0.388976216, 0.380784035, 0.372719884, 0.364781618, 0.356967449, 0.34927541, 0.341703475,
    0.334249914, 0.32691282, 0.319690347, 0.312580705, 0.305582166, 0.298692942, 0.291911423, 0.285235822,
    0.278664529, 0.272195935, 0.265828371, 0.259560347, 0.253390193, 0.247316495, 0.241337672, 0.235452279,
    0.229658857, 0.223955944, 0.21834214, 0.212816045, 0.207376286, 0.202021524, 0.196750447, 0.191561714,
    0.186454013, 0.181426153, 0.176476851, 0.171604887, 0.166809067, 0.162088141, 0.157441005, 0.152866468,
    0.148363426, 0.143930718, 0.139567271, 0.135272011, 0.131043866, 0.126881793, 0.122784719, 0.11875169,
    0.114781633, 0.11087364, 0.107026696, 0.103239879, 0.0995122194, 0.0958427936, 0.0922307223, 0.0886750817,
    0.0851749927, 0.0817295909, 0.0783380121, 0.0749994367, 0.0717130303, 0.0684779733, 0.0652934611,
    0.0621587038, 0.0590728968, 0.0560353249, 0.0530452281, 0.0501018465, 0.0472044498, 0.0443523228,
    0.0415447652, 0.0387810767, 0.0360605568, 0.0333825648, 0.0307464004, 0.0281514227, 0.0255970061,
    0.0230824798, 0.0206072628, 0.0181707144, 0.0157722086, 0.013411209, 0.0110870898, 0.0087992847,
    0.0065472275, 0.00433036685, 0.0021481365, 0.0], dtype=np.float32)


class MipMap:
    """An ``imagemap``: its pyramid (``levels``: float32 (h, w, 3) arrays, finest first),
    filter, wrap mode, ``scale``, ``invert``, spectrum ``form`` and 2D mapping (a
    :class:`~.procedural.Procedural` holding the mapping's parameters)."""

    kind = MIPMAP

    def __init__(self, path: str, rgb: np.ndarray, filter_name: str, wrap: str, max_aniso: float, scale: float,
                 invert: bool, form: str, mapping):
        self.path = key_path(path)
        self.levels = generate_pyramid(rgb, wrap)
        self.filter, self.wrap, self.max_aniso = filter_name, wrap, max_aniso
        self.scale, self.invert, self.form, self.mapping = scale, invert, form, mapping
        self.params = {}

    def mean_luminance(self) -> float:
        top = self.levels[-1].reshape(3).astype(np.float64) * self.scale
        return float(spec.luminance_rgb(np.clip(1.0 - top if self.invert else top, 0, None)))


# ------------------------------------------------------------------ the pyramid

def _windowed_sinc(x, radius, tau):
    x = np.abs(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(x < 1e-5, 1.0, np.sin(np.pi * x) / (np.pi * x))
        w = np.where(x / tau < 1e-5, 1.0, np.sin(np.pi * x / tau) / (np.pi * x / tau))
    return np.where(x > radius, 0.0, s * w)


def _wrap_index(i, n, wrap):
    if wrap == "repeat":
        return np.mod(i, n), np.ones_like(i, bool)
    if wrap == "clamp":
        return np.clip(i, 0, n - 1), np.ones_like(i, bool)
    return np.clip(i, 0, n - 1), (i >= 0) & (i < n)      # black


def _resize_axis(img: np.ndarray, new: int, axis: int, wrap: str) -> np.ndarray:
    """Resample axis ``axis`` of ``img`` to ``new`` samples (pbrt-v4's ResampleWeights:
    4 taps of a windowed sinc, radius 2, tau 2, normalised)."""
    old = img.shape[axis]
    centre = (np.arange(new) + 0.5) * old / new
    first = np.floor(centre - 2.0 + 0.5).astype(np.int64)
    taps = first[:, None] + np.arange(4)[None, :]
    wts = _windowed_sinc(taps + 0.5 - centre[:, None], 2.0, 2.0)
    wts /= wts.sum(axis=1, keepdims=True)
    idx, ok = _wrap_index(taps, old, wrap)
    src = np.moveaxis(img, axis, 0)
    out = np.einsum("nk,nk...->n...", wts * ok, src[idx])
    return np.moveaxis(out, 0, axis)


def generate_pyramid(rgb: np.ndarray, wrap: str) -> list:
    """pbrt-v4's ``GeneratePyramid``: resample up to powers of two, then 2x2 box steps."""
    img = np.asarray(rgb, np.float64)
    h, w = img.shape[:2]
    pw, ph = 1 << max(0, math.ceil(math.log2(w))), 1 << max(0, math.ceil(math.log2(h)))
    if (pw, ph) != (w, h):
        img = np.maximum(_resize_axis(_resize_axis(img, pw, 1, wrap), ph, 0, wrap), 0.0)
    levels = [img.astype(np.float32)]
    while img.shape[0] > 1 or img.shape[1] > 1:
        h, w = img.shape[:2]
        nh, nw = max(1, h // 2), max(1, w // 2)
        y0, x0 = np.arange(nh) * 2, np.arange(nw) * 2
        y1, x1 = np.minimum(y0 + 1, h - 1), np.minimum(x0 + 1, w - 1)
        img = (img[y0][:, x0] + img[y0][:, x1] + img[y1][:, x0] + img[y1][:, x1]) / 4.0
        levels.append(img.astype(np.float32))
    return levels


def build_table(items: list) -> MipmapTable:
    """The table of ``imagemap`` textures ``items`` (in table order)."""
    offs, sizes, first, n_levels, pool = [], [], [], [], []
    n = 0
    for t in items:
        first.append(len(offs))
        n_levels.append(len(t.levels))
        for lv in t.levels:
            offs.append(n)
            sizes.append((lv.shape[1], lv.shape[0]))
            pool.append(lv.reshape(-1, 3))
            n += lv.shape[0] * lv.shape[1]
    texels = np.concatenate(pool)
    return MipmapTable(
        texel=mi.Array3f(*[mi.Float(texels[:, k]) for k in range(3)]), level_offset=mi.UInt32(offs),
        level_size=mi.Array2i([s[0] for s in sizes], [s[1] for s in sizes]), first_level=mi.UInt32(first),
        n_levels=mi.UInt32(n_levels), filter=mi.UInt32([FILTERS.index(t.filter) for t in items]),
        wrap=mi.UInt32([WRAPS.index(t.wrap) for t in items]), max_aniso=mi.Float([t.max_aniso for t in items]),
        scale=mi.Float([t.scale for t in items]), invert=mi.Bool([t.invert for t in items]),
        form=mi.UInt32([FORMS.index(t.form) for t in items]),
        mapping=build_mapping_table([t.mapping for t in items]), ewa_lut=mi.Float(EWA_LUT))


def static_info(items: list):
    """What the kernels trace: (filters present, wrap modes present, 2D mappings present,
    forms present)."""
    return ({t.filter for t in items}, {t.wrap for t in items}, {t.mapping.mapping for t in items},
            {t.form for t in items})


# ------------------------------------------------------------------ lookups

class _Level:
    """Addressing of one pyramid level per lane."""

    def __init__(self, T, first, level, wrap, active):
        k = first + mi.UInt32(level)
        self.off = dr.gather(mi.UInt32, T.level_offset, k, active)
        self.size = dr.gather(mi.Array2i, T.level_size, k, active)
        self.T, self.wrap, self.active = T, wrap, active

    def texel(self, x, y, active=True):
        """RGB texel (x, y) (Int32) with the wrap mode (black: 0 outside)."""
        w, h = self.size.x, self.size.y
        inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        rx = x - w * mi.Int32(dr.floor(mi.Float(x) / mi.Float(w)))
        ry = y - h * mi.Int32(dr.floor(mi.Float(y) / mi.Float(h)))
        cx, cy = dr.clip(x, 0, w - 1), dr.clip(y, 0, h - 1)
        rep = self.wrap == 0
        xx, yy = dr.select(rep, rx, cx), dr.select(rep, ry, cy)
        on = self.active & active & (inside | (self.wrap != 1))
        v = dr.gather(mi.Array3f, self.T.texel, self.off + mi.UInt32(yy * w + xx), on)
        return dr.select(on, v, mi.Array3f(0.0))

    def bilerp(self, st):
        x = st.x * mi.Float(self.size.x) - 0.5
        y = st.y * mi.Float(self.size.y) - 0.5
        fx, fy = dr.floor(x), dr.floor(y)
        dx, dy = x - fx, y - fy
        ix, iy = mi.Int32(fx), mi.Int32(fy)
        return ((1 - dx) * (1 - dy) * self.texel(ix, iy) + dx * (1 - dy) * self.texel(ix + 1, iy)
                + (1 - dx) * dy * self.texel(ix, iy + 1) + dx * dy * self.texel(ix + 1, iy + 1))

    def point(self, st):
        return self.texel(mi.Int32(dr.round(st.x * mi.Float(self.size.x) - 0.5)),
                          mi.Int32(dr.round(st.y * mi.Float(self.size.y) - 0.5)))

    def ewa(self, st, d0, d1, lut):
        """pbrt-v4's EWA: Gaussian-weighted texels inside the footprint ellipse."""
        rx, ry = mi.Float(self.size.x), mi.Float(self.size.y)
        s, t = st.x * rx - 0.5, st.y * ry - 0.5
        a0, a1, b0, b1 = d0.x * rx, d0.y * ry, d1.x * rx, d1.y * ry
        A = a1 * a1 + b1 * b1 + 1.0
        B = -2.0 * (a0 * a1 + b0 * b1)
        C = a0 * a0 + b0 * b0 + 1.0
        inv_f = dr.rcp(A * C - B * B * 0.25)
        A, B, C = A * inv_f, B * inv_f, C * inv_f
        det = 4.0 * A * C - B * B
        inv_det = dr.rcp(det)
        us, vs = dr.safe_sqrt(det * C), dr.safe_sqrt(A * det)
        s0, s1 = mi.Int32(dr.ceil(s - 2.0 * inv_det * us)), mi.Int32(dr.floor(s + 2.0 * inv_det * us))
        t0, t1 = mi.Int32(dr.ceil(t - 2.0 * inv_det * vs)), mi.Int32(dr.floor(t + 2.0 * inv_det * vs))
        ns = dr.maximum(s1 - s0 + 1, 0)
        count = mi.UInt32(ns * dr.maximum(t1 - t0 + 1, 0))
        count = dr.select(self.active, dr.minimum(count, 4096), 0)

        def body(k, total, wsum):
            ki = mi.Int32(k)
            i_s = s0 + ki % dr.maximum(ns, 1)
            i_t = t0 + ki // dr.maximum(ns, 1)
            ss, tt = mi.Float(i_s) - s, mi.Float(i_t) - t
            r2 = A * ss * ss + B * ss * tt + C * tt * tt
            inside = r2 < 1.0
            wt = dr.gather(mi.Float, lut, mi.UInt32(dr.minimum(mi.Int32(r2 * 128.0), 127)), inside)
            wt = dr.select(inside, wt, 0.0)
            total += wt * self.texel(i_s, i_t, inside)
            wsum += wt
            return k + 1, total, wsum

        _, total, wsum = dr.while_loop((mi.UInt32(0), mi.Array3f(0.0), mi.Float(0.0)),
                                       lambda k, total, wsum: k < count, body, label="ewa texels")
        return dr.select(wsum > 0.0, total / dr.maximum(wsum, 1e-30), self.bilerp(st))


def evaluate(textures, i, uv, si, lam, active, illuminant=True) -> mi.Spectrum:
    """Spectrum of ``imagemap`` texture ``i`` (index in its table) at ``si`` (or at the
    surface coordinates ``uv`` without one: no footprint, the finest level)."""
    T = textures.tables.mipmaps
    filters, wraps, mappings, forms = textures.mipmap_info
    p = si.p if si is not None else mi.Point3f(uv.x, uv.y, 0.0)
    dpdx, dpdy = footprint(textures, si, active)
    st, dsdx, dsdy, dtdx, dtdy = map_2d(T.mapping, i, mappings, uv, si, p, dpdx, dpdy, active)
    st = mi.Point2f(st.x, 1.0 - st.y)                   # image row 0 at t = 1 (pbrt-v4)
    d0, d1 = mi.Vector2f(dsdx, -dtdx), mi.Vector2f(dsdy, -dtdy)
    first = dr.gather(mi.UInt32, T.first_level, i, active)
    n_lev = mi.Int32(dr.gather(mi.UInt32, T.n_levels, i, active))
    wrap = dr.gather(mi.UInt32, T.wrap, i, active) if len(wraps) > 1 else mi.UInt32(WRAPS.index(next(iter(wraps))))
    filt = dr.gather(mi.UInt32, T.filter, i, active) if len(filters) > 1 else None
    top = mi.Float(n_lev - 1)
    rgb = mi.Array3f(0.0)

    def is_filter(name):
        return (filt == FILTERS.index(name)) if filt is not None else mi.Bool(True)

    if filters & {"point", "bilinear", "trilinear"}:
        width = 2.0 * dr.maximum(dr.maximum(dr.abs(d0.x), dr.abs(d0.y)), dr.maximum(dr.abs(d1.x), dr.abs(d1.y)))
        level = top + dr.log2(dr.maximum(width, 1e-8))
        i_level = dr.maximum(mi.Int32(dr.floor(level)), 0)
        i_level = dr.minimum(i_level, n_lev - 1)
        lv = _Level(T, first, i_level, wrap, active)
        v = mi.Array3f(0.0)
        if "point" in filters:
            v = dr.select(is_filter("point"), lv.point(st), v)
        if filters & {"bilinear", "trilinear"}:
            bil = lv.bilerp(st)
            v = dr.select(is_filter("bilinear"), bil, v)
            if "trilinear" in filters:
                up = _Level(T, first, dr.minimum(i_level + 1, n_lev - 1), wrap, active & (i_level > 0))
                tri = dr.select(i_level == 0, bil, dr.lerp(bil, up.bilerp(st), level - mi.Float(i_level)))
                v = dr.select(is_filter("trilinear"), tri, v)
        coarsest = _Level(T, first, n_lev - 1, wrap, active).texel(mi.Int32(0), mi.Int32(0))
        rgb = dr.select(level >= top, coarsest, v)
    if "ewa" in filters:
        on = active & is_filter("ewa")
        swap = dr.squared_norm(d0) < dr.squared_norm(d1)
        a, b = dr.select(swap, d1, d0), dr.select(swap, d0, d1)
        longer, shorter = dr.norm(a), dr.norm(b)
        max_aniso = dr.gather(mi.Float, T.max_aniso, i, on)
        clamp = (shorter * max_aniso < longer) & (shorter > 0)
        k = dr.select(clamp, longer / dr.maximum(shorter * max_aniso, 1e-30), 1.0)
        b, shorter = b * k, shorter * k
        lod = dr.maximum(0.0, top + dr.log2(dr.maximum(shorter, 1e-30)))
        ilod = mi.Int32(dr.floor(lod))
        lo = _Level(T, first, dr.minimum(ilod, n_lev - 1), wrap, on)
        hi = _Level(T, first, dr.minimum(ilod + 1, n_lev - 1), wrap, on)
        e0, e1 = lo.ewa(st, a, b, T.ewa_lut), hi.ewa(st, a, b, T.ewa_lut)
        coarsest = _Level(T, first, n_lev - 1, wrap, on).texel(mi.Int32(0), mi.Int32(0))
        e0 = dr.select(ilod >= n_lev, coarsest, e0)
        e1 = dr.select(ilod + 1 >= n_lev, coarsest, e1)
        ewa = dr.lerp(e0, e1, lod - mi.Float(ilod))
        ewa = dr.select(shorter == 0.0, _Level(T, first, 0, wrap, on).bilerp(st), ewa)
        rgb = dr.select(is_filter("ewa"), ewa, rgb)
    rgb = rgb * dr.gather(mi.Float, T.scale, i, active)
    rgb = dr.select(dr.gather(mi.Bool, T.invert, i, active), 1.0 - rgb, rgb)
    rgb = dr.maximum(rgb, 0.0)
    form = dr.gather(mi.UInt32, T.form, i, active) if len(forms) > 1 else None
    out = mi.Spectrum(0.0)
    if "albedo" in forms:
        alb = spec.sigmoid_polynomial(spec.rgb_to_coeffs(mi.Color3f(dr.minimum(rgb, 1.0))), lam)
        out = alb if form is None else dr.select(form == 0, alb, out)
    if forms & {"unbounded", "illuminant"}:
        cf, sc = spec.rgb_unbounded(mi.Color3f(rgb))
        unb = spec.sigmoid_polynomial(cf, lam) * sc
        if "illuminant" in forms and illuminant:
            unb = dr.select(form == 2 if form is not None else True, unb * spec.d65(lam), unb)
        out = unb if form is None else dr.select(form != 0, unb, out)
    return out
