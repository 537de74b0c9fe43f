"""pbrt-v4's procedural textures against an independent NumPy evaluation of pbrt-v4's
formulas (Perlin noise with pbrt-v4's permutation table, FBm, Turbulence, windy, marble,
polka dots, the filtered checkerboard), the pixel footprint of the camera, and the
textures in renders."""

import math

import numpy as np
import pytest
import drjit as dr
import mitsuba as mi

import pbr
from pbr.cameras import SENSORS
from pbr.plugins.props import Props, SceneError
from pbr.textures import procedural as P

PERM = P.NOISE_PERM.astype(np.int64)


# ------------------------------------------------------------ NumPy reference (float64)

def np_noise(x, y, z):
    x, y, z = (np.fmod(np.asarray(c, np.float64), float(1 << 30)) for c in (x, y, z))
    ix, iy, iz = (np.floor(c).astype(np.int64) for c in (x, y, z))
    dx, dy, dz = x - ix, y - iy, z - iz
    ix, iy, iz = ix & 255, iy & 255, iz & 255

    def grad(a, b, c, fx, fy, fz):
        h = PERM[PERM[PERM[a] + b] + c] & 15
        u = np.where((h < 8) | (h == 12) | (h == 13), fx, fy)
        v = np.where((h < 4) | (h == 12) | (h == 13), fy, fz)
        return np.where(h & 1, -u, u) + np.where(h & 2, -v, v)

    def wgt(t):
        return 6 * t ** 5 - 15 * t ** 4 + 10 * t ** 3

    def lerp(t, a, b):
        return (1 - t) * a + t * b
    w = {(a, b, c): grad(ix + a, iy + b, iz + c, dx - a, dy - b, dz - c) for a in (0, 1) for b in (0, 1) for c in (0, 1)}
    wx, wy, wz = wgt(dx), wgt(dy), wgt(dz)
    x00, x10 = lerp(wx, w[0, 0, 0], w[1, 0, 0]), lerp(wx, w[0, 1, 0], w[1, 1, 0])
    x01, x11 = lerp(wx, w[0, 0, 1], w[1, 0, 1]), lerp(wx, w[0, 1, 1], w[1, 1, 1])
    return lerp(wz, lerp(wy, x00, x10), lerp(wy, x01, x11))


def np_smoothstep(x, a, b):
    t = np.clip((x - a) / (b - a), 0, 1)
    return t * t * (3 - 2 * t)


def np_octaves(dpdx, dpdy, max_oct):
    len2 = np.maximum((dpdx ** 2).sum(0), (dpdy ** 2).sum(0))
    with np.errstate(divide="ignore"):
        n = np.clip(-1 - np.log2(len2) / 2, 0, max_oct)
    return n, np.floor(n).astype(np.int64)


def np_fbm(p, dpdx, dpdy, omega, max_oct):
    n, n_int = np_octaves(dpdx, dpdy, max_oct)
    out = np.zeros(p.shape[1])
    for k in range(p.shape[1]):
        s, lam, o = 0.0, 1.0, 1.0
        for _ in range(n_int[k]):
            s += o * np_noise(*(lam * p[:, k]))
            lam *= 1.99
            o *= omega
        s += o * np_smoothstep(n[k] - n_int[k], .3, .7) * np_noise(*(lam * p[:, k]))
        out[k] = s
    return out


def np_turbulence(p, dpdx, dpdy, omega, max_oct):
    n, n_int = np_octaves(dpdx, dpdy, max_oct)
    out = np.zeros(p.shape[1])
    for k in range(p.shape[1]):
        s, lam, o = 0.0, 1.0, 1.0
        for _ in range(n_int[k]):
            s += o * abs(np_noise(*(lam * p[:, k])))
            lam *= 1.99
            o *= omega
        t = np_smoothstep(n[k] - n_int[k], .3, .7)
        s += o * ((1 - t) * 0.2 + t * abs(np_noise(*(lam * p[:, k]))))
        for _ in range(n_int[k], max_oct):
            s += o * 0.2
            o *= omega
        out[k] = s
    return out


def np_checker_bump(x, r):
    def d(t):
        y = t / 2 - np.floor(t / 2) - 0.5
        return t / 2 + y * (1 - 2 * np.abs(y))
    plain = 1 - 2 * (np.floor(x).astype(np.int64) & 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        filt = (d(x + r) - 2 * d(x) + d(x - r)) / r ** 2
    return np.where(np.floor(x - r) == np.floor(x + r), plain, filt)


def np_polka(s, t):
    sc, tc = np.floor(s + .5), np.floor(t + .5)
    z = np.zeros_like(s)
    s0 = sc + 0.15 * np_noise(sc + 1.5, tc + 2.8, z)
    t0 = tc + 0.15 * np_noise(sc + 4.5, tc + 9.8, z)
    return (np_noise(sc + .5, tc + .5, z) > 0) & ((s - s0) ** 2 + (t - t0) ** 2 < 0.35 ** 2)


def np_marble(p, dpdx, dpdy, omega, octaves, scale, variation):
    p = p * scale
    m = p[1] + variation * np_fbm(p, dpdx * scale, dpdy * scale, omega, octaves)
    t = .5 + .5 * np.sin(m)
    c = np.array(P.MARBLE_COLORS)
    first = np.minimum(np.floor(t * 6).astype(np.int64), 5)
    t = t * 6 - first
    b = [(1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2, t ** 3]
    return 1.5 * sum(b[j][:, None] * c[first + j] for j in range(4))


# ------------------------------------------------------------------------- helpers

def _points(n=2000, seed=0, spread=40.0):
    rng = np.random.default_rng(seed)
    return (rng.random((3, n)) - 0.5) * spread


def _perm():
    return mi.UInt32(P.NOISE_PERM)


def _v(a):
    return mi.Vector3f(*[mi.Float(np.asarray(r, np.float32)) for r in a])


def test_noise_matches_pbrt():
    p = _points().astype(np.float32)
    got = np.array(P.noise(_perm(), *[mi.Float(c) for c in p]))
    ref = np_noise(*p.astype(np.float64))
    assert np.abs(got - ref).max() < 2e-5
    assert np.abs(ref).max() <= 1.0 and ref.std() > 0.1
    # integer lattice points are zeros of gradient noise
    q = np.floor(p)
    assert np.abs(np.array(P.noise(_perm(), *[mi.Float(c) for c in q]))).max() < 1e-6


@pytest.mark.parametrize("footprint", [0.0, 0.01, 0.3])
def test_fbm_and_turbulence_match_pbrt(footprint):
    """With a footprint, the octaves past its frequency fade out (fbm) or count 0.2
    (turbulence), as pbrt-v4's FBm/Turbulence."""
    p = _points(500, seed=1, spread=8.0).astype(np.float32)
    rng = np.random.default_rng(2)
    dpdx = (rng.standard_normal((3, 500)) * footprint).astype(np.float32)
    dpdy = (rng.standard_normal((3, 500)) * footprint).astype(np.float32)
    f, t = P.octave_sums(_perm(), _v(p), _v(dpdx), _v(dpdy), mi.Float(0.6), mi.UInt32(7), 7, True, True)
    assert np.abs(np.array(f) - np_fbm(p.astype(np.float64), dpdx, dpdy, 0.6, 7)).max() < 2e-4
    assert np.abs(np.array(t) - np_turbulence(p.astype(np.float64), dpdx, dpdy, 0.6, 7)).max() < 2e-4


def test_marble_dots_and_checkerboard_match_pbrt():
    p = _points(400, seed=3, spread=6.0).astype(np.float32)
    z = np.zeros_like(p)
    rgb = P.marble_rgb(_perm(), _v(p), _v(z), _v(z), mi.Float(0.5), mi.UInt32(8), mi.Float(2.0), mi.Float(0.4), 8)
    ref = np_marble(p.astype(np.float64), z, z, 0.5, 8, 2.0, 0.4)
    assert np.abs(np.array(rgb).T - ref).max() < 1e-4
    st = p[:2] * 3
    inside = np.array(P.inside_polka_dot(_perm(), mi.Point2f(*[mi.Float(c) for c in st])))
    ref_in = np_polka(*st.astype(np.float64))
    assert np.mean(inside != ref_in) < 0.005 and 0.1 < ref_in.mean() < 0.5
    x = (p[0] * 0.7).astype(np.float32)
    r = np.abs(p[1] * 0.1).astype(np.float32)
    got = np.array(P._checker_bump(mi.Float(x), mi.Float(r)))
    assert np.abs(got - np_checker_bump(x.astype(np.float64), r.astype(np.float64))).max() < 1e-3


def test_camera_footprint_on_a_facing_plane():
    """pbrt-v4's Approximate_dp_dxy: the smallest one-pixel direction change over the
    film's diagonal (for a pinhole, at the corners: cos^2 of the corner angle times the
    centre's) applied at the hit: on a plane facing the camera at distance z on its
    axis, |dp/dx| = z * that change, times max(1/8, 1/sqrt(spp)); a plane seen at 60
    degrees stretches it by 1 / cos 60."""
    w, h, fov, z = 200, 100, 60.0, 3.0
    cam = SENSORS["perspective"](Props({"type": "perspective", "fov": fov,
                                        "film": {"type": "hdrfilm", "width": w, "height": h}}, "sensor"))
    tx = math.tan(math.radians(fov) / 2)
    t = np.linspace(0, 1, 512)
    x, y = (1 - 2 * t) * tx, (1 - 2 * t) * tx * h / w
    d0 = np.stack([x, y, np.ones_like(x)])
    d1 = np.stack([x - 2 * tx / w, y, np.ones_like(x)])
    diff = d1 / np.linalg.norm(d1, axis=0) - d0 / np.linalg.norm(d0, axis=0)
    smallest = np.linalg.norm(diff, axis=0).min()
    assert smallest < 0.8 * 2 * tx / w           # the corners' pixels subtend less
    dpdx, dpdy = cam.approximate_dp_dxy(mi.Point3f(0.0, 0.0, z), mi.Normal3f(0.0, 0.0, -1.0), 16)
    assert float(dr.norm(dpdx)[0]) == pytest.approx(z * smallest / 4, rel=2e-3)
    assert abs(float(dpdx.z[0])) < 1e-6 and abs(float(dpdy.z[0])) < 1e-6
    n = mi.Normal3f(math.sin(math.radians(60)), 0.0, -math.cos(math.radians(60)))
    dpdx, _ = cam.approximate_dp_dxy(mi.Point3f(0.0, 0.0, z), n, 1)
    assert float(dr.norm(dpdx)[0]) == pytest.approx(z * smallest / math.cos(math.radians(60)), rel=0.05)


def _plane_scene(tex, res=32, spp=16, dist=2.0, grazing=False):
    look = (mi.ScalarTransform4f().look_at([0, -1.2, 0.12], [0, 0.5, 0], [0, 0, 1]) if grazing else
            mi.ScalarTransform4f().look_at([0, 0, dist], [0, 0, 0], [0, 1, 0]))
    return {"type": "scene", "integrator": {"type": "direct"},
            "cam": {"type": "perspective", "fov": 40.0, "to_world": look,
                    "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": spp}},
            "plane": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": tex}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}}


def test_textures_render_and_antialias():
    """Every pattern renders finite; a checkerboard far finer than the pixels renders
    its mean 0.5 (filtered), and the 3D checkerboard too."""
    for tex in [{"type": "fbm"}, {"type": "wrinkled", "octaves": 4}, {"type": "windy"},
                {"type": "marble", "scale": 3.0}, {"type": "dots", "uscale": 6, "vscale": 6},
                {"type": "dots", "mapping": "cylindrical"}, {"type": "checkerboard", "mapping": "spherical"},
                {"type": "checkerboard", "mapping": "planar", "v1": [3, 0, 0], "v2": [0, 3, 0], "udelta": 0.5}]:
        img = np.asarray(pbr.render(pbr.load_dict(_plane_scene(tex)), spp=4))
        assert np.isfinite(img).all() and img.max() > 0, tex
    # Same seed, same paths: the filtered pattern equals a constant 0.5 albedo.
    grey = np.asarray(pbr.render(pbr.load_dict(_plane_scene(0.5)), spp=1, seed=1))[8:24, 8:24]
    fine = {"type": "checkerboard", "uscale": 2000.0, "vscale": 2000.0, "tex1": 0.8, "tex2": 0.2}
    img = np.asarray(pbr.render(pbr.load_dict(_plane_scene(fine)), spp=1, seed=1))[8:24, 8:24]
    assert np.abs(img - grey).max() < 0.01 * grey.max()
    fine3 = {"type": "checkerboard", "dimension": 3, "to_world": mi.ScalarTransform4f().scale(1e-3),
             "tex1": 0.8, "tex2": 0.2}
    img = np.asarray(pbr.render(pbr.load_dict(_plane_scene(fine3)), spp=1, seed=1))[8:24, 8:24]
    assert np.abs(img - grey).max() < 0.01 * grey.max()


def test_pbrt_checkerboard_pattern_and_errors():
    """tex1 where floor(s) + floor(t) is even (pbrt-v4), seen where the squares are big."""
    big = {"type": "checkerboard", "tex1": 0.8, "tex2": 0.2}
    img = np.asarray(pbr.render(pbr.load_dict(_plane_scene(big, res=16)), spp=4, seed=2))[4:12, 4:12]
    ref = np.asarray(pbr.render(pbr.load_dict(_plane_scene(0.8, res=16)), spp=4, seed=2))[4:12, 4:12]
    # the rectangle's uv covers [0, 1)^2, one square (even): all tex1
    assert np.abs(img - ref).max() < 1e-3
    with pytest.raises(SceneError, match="reflectance.color0: Mitsuba's checkerboard parameter mixed"):
        pbr.load_dict(_plane_scene({"type": "checkerboard", "tex1": 0.5, "color0": 0.3}))
    with pytest.raises(SceneError, match="reflectance.dimension: expected 2 or 3"):
        pbr.load_dict(_plane_scene({"type": "checkerboard", "dimension": 4}))
    with pytest.raises(SceneError, match="reflectance.mapping: expected one of"):
        pbr.load_dict(_plane_scene({"type": "dots", "mapping": "sphere"}))
    with pytest.raises(SceneError, match="reflectance.uscale: unknown parameter"):
        pbr.load_dict(_plane_scene({"type": "checkerboard", "dimension": 3, "uscale": 2.0}))


# ------------------------------------------------------------------ imagemap (MIP maps)

from pbr.textures import mipmap as MM  # noqa: E402


def _checker(n=256, square=1):
    i = np.arange(n) // square
    return ((i[:, None] + i[None, :]) % 2).astype(np.float32)


def _lookups(tex, res=32, spp=1, seed=1, **kw):
    """Per-pixel texture values seen by 1-sample pixels: the render over a grey (0.5)
    render with the same seed (same paths, diffuse plane, direct lighting)."""
    grey = np.asarray(pbr.render(pbr.load_dict(_plane_scene(0.5, res=res, **kw)), spp=spp, seed=seed))
    img = np.asarray(pbr.render(pbr.load_dict(_plane_scene(tex, res=res, **kw)), spp=spp, seed=seed))
    return (img / grey * 0.5).mean(axis=2)[4:res - 4, 4:res - 4]


def test_pyramid_is_pbrts():
    """Powers of two: 2x2 box steps down to 1x1 (the top is the mean); other sizes are
    first resampled up to the next powers of two (values >= 0, the mean kept)."""
    rng = np.random.default_rng(0)
    img = rng.random((8, 16, 3)).astype(np.float32)
    lv = MM.generate_pyramid(img, "repeat")
    assert [x.shape[:2] for x in lv] == [(8, 16), (4, 8), (2, 4), (1, 2), (1, 1)]
    assert np.allclose(lv[1][1, 2], img[2:4, 4:6].mean(axis=(0, 1)), atol=1e-6)
    assert np.allclose(lv[-1][0, 0], img.mean(axis=(0, 1)), atol=1e-5)
    odd = rng.random((5, 7, 3)).astype(np.float32)
    lv = MM.generate_pyramid(odd, "repeat")
    assert lv[0].shape[:2] == (8, 8) and lv[0].min() >= 0
    assert np.allclose(lv[-1][0, 0], odd.mean(axis=(0, 1)), atol=0.02)


def np_ewa(level, st, d0, d1, wrap="repeat"):
    """pbrt-v4's MIPMap::EWA on one level image (h, w, 3), NumPy, one lookup."""
    h, w = level.shape[:2]
    s, t = st[0] * w - 0.5, st[1] * h - 0.5
    a0, a1, b0, b1 = d0[0] * w, d0[1] * h, d1[0] * w, d1[1] * h
    A, B, C = a1 ** 2 + b1 ** 2 + 1, -2 * (a0 * a1 + b0 * b1), a0 ** 2 + b0 ** 2 + 1
    f = 1 / (A * C - B * B / 4)
    A, B, C = A * f, B * f, C * f
    det = 4 * A * C - B * B
    us, vs = math.sqrt(det * C), math.sqrt(A * det)
    total, wsum = np.zeros(3), 0.0
    for it in range(math.ceil(t - 2 / det * vs), math.floor(t + 2 / det * vs) + 1):
        for i_s in range(math.ceil(s - 2 / det * us), math.floor(s + 2 / det * us) + 1):
            r2 = A * (i_s - s) ** 2 + B * (i_s - s) * (it - t) + C * (it - t) ** 2
            if r2 < 1:
                wt = MM.EWA_LUT[min(int(r2 * 128), 127)]
                total += wt * level[it % h, i_s % w]
                wsum += wt
    return total / wsum


def test_ewa_and_bilerp_match_pbrt():
    rng = np.random.default_rng(5)
    img = rng.random((32, 64, 3)).astype(np.float32)
    tex = MM.MipMap("t", img, "ewa", "repeat", 8.0, 1.0, False, "albedo",
                    P.Procedural("t.m", P.CHECKER2D, P.MAP_UV, np.eye(4)))
    T = MM.build_table([tex])
    n = 64
    st = rng.random((2, n)).astype(np.float32)
    ang = rng.random(n) * math.pi
    d0 = np.stack([np.cos(ang), np.sin(ang)]) * 0.05
    d1 = np.stack([-np.sin(ang), np.cos(ang)]) * 0.012
    for level in (0, 1, 2):
        lv = MM._Level(T, mi.UInt32(0), mi.Int32(level), mi.UInt32(0), mi.Bool(True))
        got = np.array(lv.ewa(mi.Point2f(*st), mi.Vector2f(*d0.astype(np.float32)),
                              mi.Vector2f(*d1.astype(np.float32)), T.ewa_lut)).T
        ref = np.array([np_ewa(tex.levels[level], st[:, k], d0[:, k], d1[:, k]) for k in range(n)])
        assert np.abs(got - ref).max() < 1e-4, level
        bil = np.array(lv.bilerp(mi.Point2f(*st))).T
        L = tex.levels[level].astype(np.float64)
        h, w = L.shape[:2]
        x, y = st[0] * w - 0.5, st[1] * h - 0.5
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        ref = ((1 - fx) * (1 - fy) * L[y0 % h, x0 % w] + fx * (1 - fy) * L[y0 % h, (x0 + 1) % w]
               + (1 - fx) * fy * L[(y0 + 1) % h, x0 % w] + fx * fy * L[(y0 + 1) % h, (x0 + 1) % w])
        assert np.abs(bil - ref).max() < 1e-5


@pytest.mark.parametrize("filt", ["point", "bilinear", "trilinear", "ewa"])
def test_minified_checker_renders_its_mean(filt):
    """A 256^2 checker of 1-texel squares seen ~8 texels per pixel: the MIP-mapped lookups
    give its mean 0.5 at one sample per pixel; Mitsuba's bitmap (no MIP map) samples
    texels and aliases (0 or 1 per pixel)."""
    r = _lookups({"type": "imagemap", "data": _checker(), "filter": filt})
    assert np.abs(r - 0.5).max() < 0.02
    if filt == "point":
        raw = _lookups({"type": "bitmap", "data": _checker(), "filter_type": "nearest", "raw": True})
        assert raw.std() > 0.4


def test_ewa_keeps_detail_that_trilinear_blurs():
    """Stripes across s seen at a grazing angle (t minified ~16x more than s): EWA's
    footprint ellipse keeps the stripes (its level follows the minor axis), trilinear's
    isotropic width blurs them to grey; with maxanisotropy 1 EWA blurs too."""
    n = 256
    stripes = np.repeat(((np.arange(n) // 8) % 2).astype(np.float32)[None, :], n, axis=0)
    def contrast(**tex):
        r = _lookups({"type": "imagemap", "data": stripes, "vscale": 16.0, **tex}, res=48, grazing=True)
        return r.std()
    ewa, tri, iso = contrast(filter="ewa"), contrast(filter="trilinear"), contrast(filter="ewa", maxanisotropy=1.0)
    assert ewa > 0.15 and tri < 0.05 and iso < 0.05, (ewa, tri, iso)


def test_imagemap_errors_and_flip(tmp_path):
    with pytest.raises(SceneError, match="reflectance.filter: expected one of"):
        pbr.load_dict(_plane_scene({"type": "imagemap", "data": _checker(4), "filter": "cubic"}))
    with pytest.raises(SceneError, match="reflectance.wrap: 'octahedralsphere' is not supported"):
        pbr.load_dict(_plane_scene({"type": "imagemap", "data": _checker(4), "wrap": "octahedralsphere"}))
    # t is flipped: the image's top row is seen at t = 1 (the rectangle's top edge).
    top_white = np.zeros((16, 16), np.float32)
    top_white[:8] = 1.0
    r = _lookups({"type": "imagemap", "data": top_white, "filter": "point"}, res=16)
    assert r[:2].mean() > 0.9 and r[-2:].mean() < 0.1


def test_frozen_render_with_filtered_textures_and_a_tabulated_filter():
    """``pbr.freeze`` replays renders with MIP-mapped and procedural textures, a Mitchell
    filter and a spectral film exactly (their tables are made outside the recording)."""
    d = pbr.cornell_box(16, 16)
    d["sensor"]["film"] = {"type": "spectral", "xresolution": 16, "yresolution": 16, "nbuckets": 3,
                           "rfilter": {"type": "mitchell"}}
    d["back"]["bsdf"] = {"type": "diffuse", "reflectance": {
        "type": "imagemap", "data": np.random.default_rng(0).random((16, 16, 3)), "filter": "ewa"}}
    d["floor"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "marble", "scale": 3.0}}
    scene = pbr.load_dict(d)
    frozen = pbr.freeze(lambda scene, seed: pbr.render(scene, spp=4, seed=seed))
    for s in range(3):
        ref = np.asarray(pbr.render(scene, spp=4, seed=s))
        assert np.array_equal(np.asarray(frozen(scene, dr.opaque(mi.UInt32, s))), ref)


# ------------------------------------------------------------------ bilerp, directionmix

def _texture_values(tex, uv, n=None):
    """Values (first wavelength) of ``tex`` as a diffuse reflectance, looked up at surface
    coordinates ``uv`` (2, N) with geometric normals ``n`` (3, N)."""
    from pbr import backend
    scene = pbr.load_dict(_plane_scene(tex))
    with backend.pbr_variant():
        T = scene.textures
        slot = next(i for i, t in enumerate(T.items) if t.path == "plane.bsdf.reflectance")
        si = mi.SurfaceInteraction3f()
        si.uv = mi.Point2f(*uv)
        si.p = mi.Point3f(2 * uv[0] - 1, 2 * uv[1] - 1, 0.0)
        si.dp_du, si.dp_dv = mi.Vector3f(2.0, 0.0, 0.0), mi.Vector3f(0.0, 2.0, 0.0)
        si.n = mi.Normal3f(*(n if n is not None else np.tile([[0.0], [0.0], [1.0]], uv.shape[1])))
        return np.array(T.eval(slot, si, mi.Spectrum(550.0), True, illuminant=False)[0], np.float64)


def test_bilerp_matches_pbrt_formula():
    """pbrt-v4's Bilerp over the uv mapping (s = uscale u + udelta, t = vscale v + vdelta):
    (1-s)(1-t) v00 + s(1-t) v10 + (1-s) t v01 + s t v11, extrapolated outside [0, 1]^2;
    pbrt-v4's defaults (0, 0, 1, 1) make t itself."""
    uv = np.random.default_rng(3).random((2, 500))
    tex = {"type": "bilerp", "v00": 0.1, "v10": 0.9, "v01": 0.4, "v11": 0.25, "uscale": 1.5, "vdelta": -0.2}
    s, t = 1.5 * uv[0], uv[1] - 0.2
    ref = (1 - s) * (1 - t) * 0.1 + s * (1 - t) * 0.9 + (1 - s) * t * 0.4 + s * t * 0.25
    assert np.abs(_texture_values(tex, uv) - ref).max() < 1e-5
    assert np.abs(_texture_values({"type": "bilerp"}, uv) - uv[1]).max() < 1e-6
    with pytest.raises(SceneError, match="reflectance.mapping: expected one of"):
        pbr.load_dict(_plane_scene({"type": "bilerp", "mapping": "polar"}))


def test_directionmix_matches_pbrt_formula():
    """pbrt-v4's DirectionMix: a = |n . dir| (dir normalised after the texture transform),
    a tex1 + (1 - a) tex2; defaults dir (0, 1, 0), tex1 0, tex2 1."""
    rng = np.random.default_rng(4)
    n = rng.normal(size=(3, 400))
    n /= np.linalg.norm(n, axis=0)
    uv = rng.random((2, 400))
    rot = mi.ScalarTransform4f().rotate([1, 0, 0], 90)     # (0, 2, 0) -> (0, 0, 2)
    tex = {"type": "directionmix", "tex1": 0.7, "tex2": {"type": "bilerp"}, "dir": [0, 2, 0], "to_world": rot}
    a = np.abs(n[2])
    ref = a * 0.7 + (1 - a) * uv[1]
    assert np.abs(_texture_values(tex, uv, n) - ref).max() < 1e-5
    assert np.abs(_texture_values({"type": "directionmix"}, uv, n) - (1 - np.abs(n[1]))).max() < 1e-5
    with pytest.raises(SceneError, match="reflectance.dir: the direction is zero"):
        pbr.load_dict(_plane_scene({"type": "directionmix", "dir": [0, 0, 0]}))
