"""pbrt-v4's procedural textures and texture-coordinate mappings.

Patterns (pbrt-v4's names and parameters): ``fbm``, ``wrinkled``, ``windy`` (float
textures: the same value at every wavelength), ``marble`` (an sRGB albedo), ``dots`` and
pbrt-v4's ``checkerboard`` (2D or 3D; both blend two child textures, so they load as a
``mix`` whose amount is the pattern); ``bilerp`` (two ``mix`` levels weighted by the
mapping's s and t) and ``directionmix`` (a ``mix`` weighted by |n . dir|) load the same
way. Noise is Perlin's improved noise with pbrt-v4's
permutation table; ``fbm``/``wrinkled`` sum octaves up to the frequency the pixel
footprint resolves (pbrt-v4's ``FBm``/``Turbulence``), and the checkerboard is
box-filtered over the footprint (pbrt-v4's closed form), so both antialias.

The footprint (dp/dx, dp/dy of a one-pixel step) comes from the camera of the render
(:meth:`pbr.cameras.ProjectiveCamera.approximate_dp_dxy`, pbrt-v4's approximation from
the camera's minimum ray differentials, scaled by max(1/8, 1/sqrt(spp))): the integrator
sets :attr:`TextureSet.footprint` for the render. Without one (textures evaluated
outside a render, or lookups without a surface point) the footprint is 0: every octave,
no filtering.

Mappings (``mapping``): 'uv' (``uscale``, ``vscale``, ``udelta``, ``vdelta``),
'spherical', 'cylindrical', 'planar' (``v1``, ``v2``, ``udelta``, ``vdelta``) for the 2D
patterns; 3D patterns use the texture-space point. Texture space is given by
``to_world`` (texture -> world; pbrt-v4: the transform in effect at the ``Texture``
directive), points map to texture space by its inverse.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from .kinds import PROCEDURAL, key_path
from .tables import ProceduralTable

# pbrt-v4's noise permutation (a permutation of 0..255), repeated once to 512 entries.
NOISE_PERM = np.array([
    151, 160, 137, 91, 90, 15, 131, 13, 201, 95, 96, 53, 194, 233, 7, 225,
    140, 36, 103, 30, 69, 142, 8, 99, 37, 240, 21, 10, 23, 190, 6, 148,
    247, 120, 234, 75, 0, 26, 197, 62, 94, 252, 219, 203, 117, 35, 11, 32,
    57, 177, 33, 88, 237, 149, 56, 87, 174, 20, 125, 136, 171, 168, 68, 175,
    74, 165, 71, 134, 139, 48, 27, 166, 77, 146, 158, 231, 83, 111, 229, 122,
    60, 211, 133, 230, 220, 105, 92, 41, 55, 46, 245, 40, 244, 102, 143, 54,
    65, 25, 63, 161, 1, 216, 80, 73, 209, 76, 132, 187, 208, 89, 18, 169,
    200, 196, 135, 130, 116, 188, 159, 86, 164, 100, 109, 198, 173, 186, 3, 64,
    52, 217, 226, 250, 124, 123, 5, 202, 38, 147, 118, 126, 255, 82, 85, 212,
    207, 206, 59, 227, 47, 16, 58, 17, 182, 189, 28, 42, 223, 183, 170, 213,
    119, 248, 152, 2, 44, 154, 163, 70, 221, 153, 101, 155, 167, 43, 172, 9,
    129, 22, 39, 253, 19, 98, 108, 110, 79, 113, 224, 232, 178, 185, 112, 104,
    218, 246, 97, 228, 251, 34, 242, 193, 238, 210, 144, 12, 191, 179, 162, 241,
    81, 51, 145, 235, 249, 14, 239, 107, 49, 192, 214, 31, 181, 199, 106, 157,
    184, 84, 204, 176, 115, 121, 50, 45, 127, 4, 150, 254, 138, 236, 205, 93,
    222, 114, 67, 29, 24, 72, 243, 141, 128, 195, 78, 66, 215, 61, 156, 180,
] * 2, dtype=np.uint32)

# Pattern ids. COORD_S, COORD_T: the 2D mapping's s or t (the weights of ``bilerp``);
# DIRECTION: |n . dir| (the weight of ``directionmix``).
FBM, WRINKLED, WINDY, MARBLE, DOTS, CHECKER2D, CHECKER3D, COORD_S, COORD_T, DIRECTION = range(10)
MAPPED_2D = (DOTS, CHECKER2D, COORD_S, COORD_T)    # patterns over a 2D mapping
PATTERNS = {"fbm": FBM, "wrinkled": WRINKLED, "windy": WINDY, "marble": MARBLE, "dots": DOTS}
# Mapping ids.
MAP_UV, MAP_SPHERICAL, MAP_CYLINDRICAL, MAP_PLANAR = range(4)
MAPPINGS = {"uv": MAP_UV, "spherical": MAP_SPHERICAL, "cylindrical": MAP_CYLINDRICAL, "planar": MAP_PLANAR}
# pbrt-v4's marble colour spline (sRGB control points of cubic Bezier segments).
MARBLE_COLORS = [(.58, .58, .6), (.58, .58, .6), (.58, .58, .6), (.5, .5, .5), (.6, .59, .58), (.58, .58, .6),
                 (.58, .58, .6), (.2, .2, .33), (.58, .58, .6)]


class Procedural:
    """A procedural pattern (:data:`PATTERNS`, or a checkerboard's blend weight) over a
    mapping. ``texture_from_world``: 4x4; ``uv``: (su, sv, du, dv); ``planar``: (v1, v2)
    (DIRECTION: v1 is the world direction)."""

    kind = PROCEDURAL

    def __init__(self, path: str, pattern: int, mapping: int, texture_from_world: np.ndarray, uv=(1.0, 1.0, 0.0, 0.0),
                 planar=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)), octaves: int = 8, omega: float = 0.5,
                 scale: float = 1.0, variation: float = 0.2):
        self.path = key_path(path)
        self.pattern, self.mapping, self.m = pattern, mapping, np.asarray(texture_from_world, np.float64)
        self.uv, self.planar = tuple(uv), tuple(map(tuple, planar))
        self.octaves, self.omega, self.scale, self.variation = octaves, omega, scale, variation
        self.params = {}


def build_table(items: list) -> ProceduralTable:
    """The table of procedural textures ``items`` (in table order)."""
    f = lambda v: mi.Float([float(x) for x in v])   # noqa: E731
    return ProceduralTable(
        pattern=mi.UInt32([t.pattern for t in items]), mapping=mi.UInt32([t.mapping for t in items]),
        octaves=mi.UInt32([t.octaves for t in items]), omega=f([t.omega for t in items]),
        scale=f([t.scale for t in items]), variation=f([t.variation for t in items]),
        m=[f([t.m[r, c] for t in items]) for r in range(3) for c in range(4)],
        uv=[f([t.uv[k] for t in items]) for k in range(4)],
        v1=[f([t.planar[0][k] for t in items]) for k in range(3)],
        v2=[f([t.planar[1][k] for t in items]) for k in range(3)], perm=mi.UInt32(NOISE_PERM),
        marble=[f([c[k] for c in MARBLE_COLORS]) for k in range(3)])


def static_info(items: list):
    """What the kernels trace: (patterns present, 2D mappings present, most octaves)."""
    return ({t.pattern for t in items}, {t.mapping for t in items if t.pattern in MAPPED_2D},
            max([t.octaves for t in items if t.pattern in (FBM, WRINKLED, MARBLE)] + [0]))


# ---------------------------------------------------------------------- noise

def _grad(perm, ix, iy, iz, dx, dy, dz):
    h = dr.gather(mi.UInt32, perm, dr.gather(mi.UInt32, perm, dr.gather(mi.UInt32, perm, ix) + iy) + iz) & 15
    u = dr.select((h < 8) | (h == 12) | (h == 13), dx, dy)
    v = dr.select((h < 4) | (h == 12) | (h == 13), dy, dz)
    return dr.select((h & 1) != 0, -u, u) + dr.select((h & 2) != 0, -v, v)


def _weight(t):
    t3 = t * t * t
    return t3 * dr.fma(t, dr.fma(t, 6.0, -15.0), 10.0)


def noise(perm, x, y, z):
    """pbrt-v4's ``Noise(x, y, z)``: Perlin's improved gradient noise, in [-1, 1]."""
    big = float(1 << 30)
    x, y, z = (c - dr.trunc(c / big) * big for c in (x, y, z))   # fmod
    fx, fy, fz = dr.floor(x), dr.floor(y), dr.floor(z)
    dx, dy, dz = x - fx, y - fy, z - fz
    ix, iy, iz = (mi.UInt32(mi.Int32(f) & 255) for f in (fx, fy, fz))
    w = {}
    for a in (0, 1):
        for b in (0, 1):
            for c in (0, 1):
                w[a, b, c] = _grad(perm, ix + a, iy + b, iz + c, dx - a, dy - b, dz - c)
    wx, wy, wz = _weight(dx), _weight(dy), _weight(dz)
    x00 = dr.lerp(w[0, 0, 0], w[1, 0, 0], wx)
    x10 = dr.lerp(w[0, 1, 0], w[1, 1, 0], wx)
    x01 = dr.lerp(w[0, 0, 1], w[1, 0, 1], wx)
    x11 = dr.lerp(w[0, 1, 1], w[1, 1, 1], wx)
    return dr.lerp(dr.lerp(x00, x10, wy), dr.lerp(x01, x11, wy), wz)


def _smoothstep(x, a, b):
    t = dr.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _octaves(dpdx, dpdy, max_octaves):
    """(n, floor(n), n - floor(n)) of pbrt-v4's octave count for a footprint."""
    len2 = dr.maximum(dr.squared_norm(dpdx), dr.squared_norm(dpdy))
    n = dr.clip(-1.0 - dr.log2(len2) / 2.0, 0.0, mi.Float(max_octaves))
    n_int = dr.floor(n)
    return n, n_int, n - n_int


# lambda_i = 1.99^i as pbrt-v4 computes it (float32 products).
_LAMBDA = np.cumprod(np.concatenate([[1.0], np.full(32, 1.99)]).astype(np.float32), dtype=np.float32).tolist()


def octave_sums(perm, p, dpdx, dpdy, omega, max_octaves, unroll: int, fbm_sum=True, turbulence=False):
    """pbrt-v4's ``FBm`` and ``Turbulence`` (those asked for, from the same noise values):
    octaves of noise up to the footprint's frequency, the last one faded in (turbulence:
    |noise|, and the octaves beyond the footprint count their mean 0.2); ``max_octaves``
    per lane, ``unroll`` the largest."""
    _, n_int, frac = _octaves(dpdx, dpdy, max_octaves)
    fade = _smoothstep(frac, 0.3, 0.7)
    f_total, t_total = mi.Float(0.0), mi.Float(0.0)
    o = mi.Float(1.0)
    n_max = mi.Float(max_octaves)
    for i in range(unroll + 1):
        lam = _LAMBDA[i]
        nz = noise(perm, p.x * lam, p.y * lam, p.z * lam)
        fi = float(i)
        if fbm_sum:
            f_total += o * dr.select(fi < n_int, nz, dr.select(fi == n_int, fade * nz, 0.0))
        if turbulence:
            a = dr.abs(nz)
            term = dr.select(fi < n_int, a, dr.select(fi == n_int, dr.lerp(0.2, a, fade), 0.0))
            term += dr.select((fi >= n_int) & (fi < n_max), 0.2, 0.0)
            t_total += o * term
        o *= omega
    return f_total, t_total


def fbm(perm, p, dpdx, dpdy, omega, max_octaves, unroll: int):
    """pbrt-v4's ``FBm``."""
    return octave_sums(perm, p, dpdx, dpdy, omega, max_octaves, unroll)[0]


# ------------------------------------------------------------------- mappings

def xform_rows(m, v, point: bool):
    """3x4 rows ``m`` (flat list of 12) applied to ``v`` (a point adds the translation)."""
    out = []
    for r in range(3):
        e = m[4 * r] * v.x + m[4 * r + 1] * v.y + m[4 * r + 2] * v.z
        out.append(e + m[4 * r + 3] if point else e)
    return mi.Vector3f(*out)


def uv_differentials(si, dpdx, dpdy):
    """(du/dx, du/dy, dv/dx, dv/dy) from the footprint by least squares on the surface's
    dp/du, dp/dv (pbrt-v4's ``ComputeDifferentials``); 0 where they are degenerate."""
    a00, a01, a11 = dr.dot(si.dp_du, si.dp_du), dr.dot(si.dp_du, si.dp_dv), dr.dot(si.dp_dv, si.dp_dv)
    det = a00 * a11 - a01 * a01
    inv = dr.select(dr.abs(det) > 1e-20, dr.rcp(det), 0.0)
    out = []
    for d in (dpdx, dpdy):
        b0, b1 = dr.dot(si.dp_du, d), dr.dot(si.dp_dv, d)
        du = (a11 * b0 - a01 * b1) * inv
        dv = (a00 * b1 - a01 * b0) * inv
        out.append((dr.clip(du, -1e8, 1e8), dr.clip(dv, -1e8, 1e8)))
    (dudx, dvdx), (dudy, dvdy) = out
    return dudx, dudy, dvdx, dvdy


def map_2d(T, i, mapping_ids, uv, si, p, dpdx, dpdy, active):
    """(st, dsdx, dsdy, dtdx, dtdy) of pbrt-v4's 2D mappings (those in ``mapping_ids``)."""
    mapping = dr.gather(mi.UInt32, T.mapping, i, active) if len(mapping_ids) > 1 else None
    m = [dr.gather(mi.Float, a, i, active) for a in T.m]
    res = None

    def pick(mid, val):
        nonlocal res
        if res is None or mapping is None:
            res = val
        else:
            res = [dr.select(mapping == mid, a, b) for a, b in zip(val, res)]

    if MAP_UV in mapping_ids:
        su, sv, du, dv = (dr.gather(mi.Float, a, i, active) for a in T.uv)
        if si is not None:
            dudx, dudy, dvdx, dvdy = uv_differentials(si, dpdx, dpdy)
        else:
            dudx = dudy = dvdx = dvdy = mi.Float(0.0)
        pick(MAP_UV, [dr.fma(su, uv.x, du), dr.fma(sv, uv.y, dv), su * dudx, su * dudy, sv * dvdx, sv * dvdy])
    if mapping_ids & {MAP_SPHERICAL, MAP_CYLINDRICAL, MAP_PLANAR}:
        pt = xform_rows(m, p, True)
        tx, ty = xform_rows(m, dpdx, False), xform_rows(m, dpdy, False)
        x2y2 = dr.maximum(pt.x * pt.x + pt.y * pt.y, 1e-30)
        dsdp = mi.Vector3f(-pt.y, pt.x, 0.0) / (2.0 * math.pi * x2y2)
        if MAP_SPHERICAL in mapping_ids:
            r = dr.sqrt(x2y2)
            dtdp = mi.Vector3f(pt.x * pt.z / r, pt.y * pt.z / r, -r) / (math.pi * (x2y2 + pt.z * pt.z))
            v = dr.normalize(pt)
            theta = dr.safe_acos(dr.clip(v.z, -1.0, 1.0))
            phi = dr.atan2(v.y, v.x)
            phi = dr.select(phi < 0.0, phi + 2.0 * math.pi, phi)
            pick(MAP_SPHERICAL, [theta / math.pi, phi / (2.0 * math.pi), dr.dot(dsdp, tx), dr.dot(dsdp, ty),
                                 dr.dot(dtdp, tx), dr.dot(dtdp, ty)])
        if MAP_CYLINDRICAL in mapping_ids:
            pick(MAP_CYLINDRICAL, [(math.pi + dr.atan2(pt.y, pt.x)) / (2.0 * math.pi), pt.z,
                                   dr.dot(dsdp, tx), dr.dot(dsdp, ty), tx.z, ty.z])
        if MAP_PLANAR in mapping_ids:
            v1 = mi.Vector3f(*(dr.gather(mi.Float, a, i, active) for a in T.v1))
            v2 = mi.Vector3f(*(dr.gather(mi.Float, a, i, active) for a in T.v2))
            du, dv = dr.gather(mi.Float, T.uv[2], i, active), dr.gather(mi.Float, T.uv[3], i, active)
            pick(MAP_PLANAR, [du + dr.dot(pt, v1), dv + dr.dot(pt, v2), dr.dot(v1, tx), dr.dot(v1, ty),
                              dr.dot(v2, tx), dr.dot(v2, ty)])
    return mi.Point2f(res[0], res[1]), res[2], res[3], res[4], res[5]


# ------------------------------------------------------------------- patterns

def _checker_bump(x, r):
    """pbrt-v4's filtered 1D checkerboard: +1 on even cells, -1 on odd ones, filtered
    over [x - r, x + r] where an edge lies inside (pbrt-v4's closed form: the second
    difference of the integral of the integral, d(x + r) - 2 d(x) + d(x - r), / r^2).
    d's linear part x / 2 has no second difference, so only its periodic part is
    evaluated, at x reduced modulo 2 (float32 would cancel catastrophically at large
    |x|); the result is clamped to [-1, 1], where the exact value lies."""
    x0 = x - 2.0 * dr.floor(x / 2.0)

    def g(t):
        y = t / 2.0 - dr.floor(t / 2.0) - 0.5
        return y * (1.0 - 2.0 * dr.abs(y))
    plain = dr.select((mi.Int32(dr.floor(x)) & 1) != 0, -1.0, 1.0)
    rr = dr.maximum(r, 1e-20)
    filtered = dr.clip((g(x0 + rr) - 2.0 * g(x0) + g(x0 - rr)) / (rr * rr), -1.0, 1.0)
    return dr.select(dr.floor(x - r) == dr.floor(x + r), plain, filtered)


def inside_polka_dot(perm, st):
    """pbrt-v4's ``InsidePolkaDot``: a dot of radius 0.35 in cells where noise > 0,
    shifted by noise."""
    sc, tc = dr.floor(st.x + 0.5), dr.floor(st.y + 0.5)
    zero = mi.Float(0.0)
    has = noise(perm, sc + 0.5, tc + 0.5, zero) > 0.0
    radius = 0.35
    shift = 0.5 - radius
    s0 = sc + shift * noise(perm, sc + 1.5, tc + 2.8, zero)
    t0 = tc + shift * noise(perm, sc + 4.5, tc + 9.8, zero)
    return has & ((st.x - s0) ** 2 + (st.y - t0) ** 2 < radius * radius)


def _bezier(t, c0, c1, c2, c3):
    s = 1.0 - t
    return s * s * s * c0 + 3.0 * s * s * t * c1 + 3.0 * s * t * t * c2 + t * t * t * c3


def marble_rgb(perm, p, dpdx, dpdy, omega, octaves, scale, variation, unroll, table=None):
    """pbrt-v4's marble: sin of y perturbed by fbm, through its colour spline (x 1.5);
    ``table``: the spline's control points (3 Floats; made here when not given)."""
    p = p * scale
    m = p.y + variation * fbm(perm, p, dpdx * scale, dpdy * scale, omega, octaves, unroll)
    t = 0.5 + 0.5 * dr.sin(m)
    n_seg = len(MARBLE_COLORS) - 3
    first = dr.minimum(mi.UInt32(dr.floor(t * n_seg)), n_seg - 1)
    t = t * n_seg - mi.Float(first)
    table = table or [mi.Float([c[k] for c in MARBLE_COLORS]) for k in range(3)]
    return mi.Color3f(*[1.5 * _bezier(t, *[dr.gather(mi.Float, table[k], first + j) for j in range(4)])
                        for k in range(3)])


def footprint(textures, si, active):
    """(dp/dx, dp/dy) at the hit ``si`` for the render's camera (0 without one)."""
    fp = getattr(textures, "footprint", None)
    if fp is None or si is None:
        return mi.Vector3f(0.0), mi.Vector3f(0.0)
    camera, spp = fp
    return camera.approximate_dp_dxy(si.p, si.n, spp)


def evaluate(textures, i, uv, si, lam, active) -> mi.Spectrum:
    """Spectrum of procedural texture ``i`` (index in its table) at ``si`` (or at the
    surface coordinates ``uv``, the point (u, v, 0), without one)."""
    T = textures.tables.procedurals
    pats, mappings, max_octaves = textures.procedural_info
    perm = T.perm
    pattern = dr.gather(mi.UInt32, T.pattern, i, active)
    p = si.p if si is not None else mi.Point3f(uv.x, uv.y, 0.0)
    dpdx, dpdy = footprint(textures, si, active)
    value = mi.Float(0.0)
    rgb = None
    if pats & {FBM, WRINKLED, WINDY, MARBLE, CHECKER3D}:
        m = [dr.gather(mi.Float, a, i, active) for a in T.m]
        pt, tx, ty = xform_rows(m, p, True), xform_rows(m, dpdx, False), xform_rows(m, dpdy, False)
        omega = dr.gather(mi.Float, T.omega, i, active)
        octaves = dr.gather(mi.UInt32, T.octaves, i, active)
        if FBM in pats or WRINKLED in pats:
            f, t = octave_sums(perm, pt, tx, ty, omega, octaves, max_octaves, FBM in pats, WRINKLED in pats)
            value = dr.select(pattern == FBM, f, dr.select(pattern == WRINKLED, t, value))
        if WINDY in pats:
            wind = fbm(perm, pt * 0.1, tx * 0.1, ty * 0.1, 0.5, 3, 3)
            wave = fbm(perm, pt, tx, ty, 0.5, 6, 6)
            value = dr.select(pattern == WINDY, dr.abs(wind) * wave, value)
        if MARBLE in pats:
            rgb = marble_rgb(perm, pt, tx, ty, omega, octaves, dr.gather(mi.Float, T.scale, i, active),
                             dr.gather(mi.Float, T.variation, i, active), max_octaves, T.marble)
        if CHECKER3D in pats:
            r = [1.5 * dr.maximum(dr.abs(tx[k]), dr.abs(ty[k])) for k in range(3)]
            w = 0.5 - 0.5 * _checker_bump(pt.x, r[0]) * _checker_bump(pt.y, r[1]) * _checker_bump(pt.z, r[2])
            value = dr.select(pattern == CHECKER3D, w, value)
    if pats & set(MAPPED_2D):
        st, dsdx, dsdy, dtdx, dtdy = map_2d(T, i, mappings, uv, si, p, dpdx, dpdy, active)
        if COORD_S in pats:
            value = dr.select(pattern == COORD_S, st.x, value)
        if COORD_T in pats:
            value = dr.select(pattern == COORD_T, st.y, value)
        if DOTS in pats:
            value = dr.select(pattern == DOTS, dr.select(inside_polka_dot(perm, st), 0.0, 1.0), value)
        if CHECKER2D in pats:
            ds = 1.5 * dr.maximum(dr.abs(dsdx), dr.abs(dsdy))
            dt = 1.5 * dr.maximum(dr.abs(dtdx), dr.abs(dtdy))
            w = 0.5 - 0.5 * _checker_bump(st.x, ds) * _checker_bump(st.y, dt)
            value = dr.select(pattern == CHECKER2D, w, value)
    if DIRECTION in pats:   # pbrt-v4's DirectionMix weight: |n . dir|, n the geometric normal
        n = si.n if si is not None else mi.Vector3f(0.0, 0.0, 1.0)
        d = mi.Vector3f(*(dr.gather(mi.Float, a, i, active) for a in T.v1))
        value = dr.select(pattern == DIRECTION, dr.abs(dr.dot(n, d)), value)
    out = mi.Spectrum(value)
    if rgb is not None:
        marble = spec.sigmoid_polynomial(spec.rgb_to_coeffs(rgb), lam)
        out = dr.select(pattern == MARBLE, marble, out)
    return out
