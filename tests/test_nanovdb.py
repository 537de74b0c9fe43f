"""pbrt-v4's ``nanovdb`` medium: .nvdb files read through NVIDIA Warp (an optional
dependency). The files are written by Warp itself (``wp.Volume.load_from_numpy`` +
``save_to_nvdb``) from known NumPy fields, and Warp's own trilinear sampler
(``wp.volume_sample_f``) is the independent oracle of NanoVDB's lookups."""
import os
import struct
import sys
import tempfile
import types

import numpy as np
import pytest

wp = pytest.importorskip("warp")

import pbr  # noqa: E402
from pbr.scene.xml import XMLError  # noqa: E402

wp.config.log_level = wp.LOG_ERROR


def warp_volume(values, min_world, voxel):
    """A Warp float volume of ``values`` indexed [x, y, z] (voxel (i, j, k) at
    min_world + voxel * (i, j, k)); Warp pads the array to multiples of 8 with zeros."""
    return wp.Volume.load_from_numpy(np.ascontiguousarray(values, np.float32), min_world=min_world,
                                     voxel_size=voxel, bg_value=0.0, device="cpu")


def write_nvdb(path, grids):
    """One .nvdb file of the named Warp volumes ``[(name, volume)]``: Warp serialises each
    grid (``save_to_nvdb``); this names them (the grid header's name field, offset 40)
    and chains them in one file (file header's grid count, each grid's index/count)."""
    metas, datas = [], []
    for i, (name, v) in enumerate(grids):
        buf = v.array().numpy()           # aliases the CPU volume's grid buffer
        nb = name.encode() + b"\0"
        buf[40:40 + len(nb)] = np.frombuffer(nb, np.uint8)
        with tempfile.TemporaryDirectory() as d:
            f = os.path.join(d, "g.nvdb")
            v.save_to_nvdb(f)
            with open(f, "rb") as fh:
                raw = fh.read()
        name_size = struct.unpack_from("<I", raw, 16 + 136)[0]
        metas.append(raw[16:16 + 176 + name_size])
        g = bytearray(raw[16 + 176 + name_size:])
        struct.pack_into("<II", g, 24, i, len(grids))
        datas.append(bytes(g))
    with open(path, "wb") as f:
        f.write(raw[:12] + struct.pack("<HH", len(grids), 0))
        for m in metas:
            f.write(m)
        for g in datas:
            f.write(g)
    return str(path)


@wp.kernel
def _sample(volume: wp.uint64, pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = wp.volume_sample_f(volume, wp.volume_world_to_index(volume, pts[t]), wp.Volume.LINEAR)


def warp_sample(volume, pts):
    """Warp's trilinear NanoVDB sample at world points (n, 3)."""
    out = wp.zeros(len(pts), dtype=float, device="cpu")
    wp.launch(_sample, dim=len(pts), inputs=[volume.id, wp.array(pts.astype(np.float32), dtype=wp.vec3,
                                                                  device="cpu"), out], device="cpu")
    return out.numpy()


def medium_eval(scene, pts, lam=550.0):
    """sigma_a, sigma_s and Le (first wavelength) of the scene's first medium at world points."""
    import mitsuba as mi
    wl = types.SimpleNamespace(lambda_=mi.Spectrum(lam))
    pr = scene.media.eval(mi.UInt32(0), mi.Point3f(*pts.T.astype(np.float32)), wl, mi.Bool(True))
    return (np.asarray(pr.sigma_a)[0], np.asarray(pr.sigma_s)[0], np.asarray(pr.Le)[0])


def medium_scene(medium):
    return pbr.load_dict({"type": "scene", "med": medium,
                          "s": {"type": "sphere", "interior": {"type": "ref", "id": "med"}}})


# -- values, bounds and trilinear lookups --------------------------------------------------------

def test_values_at_voxel_centres_and_world_bounds(tmp_path):
    """Voxel (i, j, k) of a Warp-written grid (origin (1, 2, 3), voxels 0.5 x 0.25 x 0.5)
    has its NumPy value times sigma_a / sigma_s (and scale) at its world point; the
    medium fills the grid's stored world box, (1, 2, 3) .. + 8 voxels (Warp pads 5x6x7 to
    8^3), and is empty outside it; between voxels pbr's trilinear value is Warp's."""
    rng = np.random.default_rng(3)
    a = rng.uniform(0.2, 1.0, (5, 6, 7)).astype(np.float32)
    vol = warp_volume(a, (1.0, 2.0, 3.0), (0.5, 0.25, 0.5))
    path = write_nvdb(tmp_path / "d.nvdb", [("density", vol)])
    scene = medium_scene({"type": "nanovdb", "filename": path, "sigma_a": 2.0, "sigma_s": 0.5, "scale": 1.5})
    ijk = np.stack(np.meshgrid(*(np.arange(n) for n in a.shape), indexing="ij"), -1).reshape(-1, 3)
    pts = np.array([1.0, 2.0, 3.0]) + np.array([0.5, 0.25, 0.5]) * ijk
    sa, ss, le = medium_eval(scene, pts)
    want = a[ijk[:, 0], ijk[:, 1], ijk[:, 2]]
    np.testing.assert_allclose(sa, 3.0 * want, rtol=1e-5)
    np.testing.assert_allclose(ss, 0.75 * want, rtol=1e-5)
    assert np.all(le == 0)
    # Trilinear between voxels: Warp's sampler, everywhere inside the box [1,5]x[2,4]x[3,7].
    lo, hi = np.array([1.0, 2.0, 3.0]), np.array([5.0, 4.0, 7.0])
    p = lo + rng.uniform(0.0, 1.0, (4000, 3)) * (hi - lo)
    ref = warp_sample(vol, p)
    assert ref.std() > 0.1
    np.testing.assert_allclose(medium_eval(scene, p)[0], 3.0 * ref, atol=2e-5)
    # Outside the box the medium is empty, also where NanoVDB's sampler is not (the
    # half voxel below index 0 interpolates towards voxel 0).
    out = np.concatenate([p - [0, 0, 4.1], p + [4.1, 0, 0], lo + [0.2, 0.1, -0.2] + 0 * p])
    assert np.all(medium_eval(scene, out)[0] == 0)
    assert warp_sample(vol, lo + np.array([[0.2, 0.1, -0.2]]))[0] > 0.1


def test_majorant_cells_bound_the_density(tmp_path):
    """Each cell of the medium's 16^3 majorant grid bounds the density at every point in
    it (100k random points) and is not loose (median ratio of the cell's largest sampled
    density to its majorant > 0.75; empty cells are 0): the cells follow the NanoVDB grid's own index map, which does
    not line up with the majorant cells."""
    from pbr.media.grid import MAJORANT_RES as R
    x, y, z = np.meshgrid(*(np.arange(13.0), np.arange(9.0), np.arange(11.0)), indexing="ij")
    a = (1.0 + np.sin(0.7 * x) * np.cos(0.4 * y + 0.2 * z)).astype(np.float32)
    path = write_nvdb(tmp_path / "m.nvdb", [("density", warp_volume(a, (-1.0, 0.5, 2.0), (0.3, 0.2, 0.25)))])
    scene = medium_scene({"type": "nanovdb", "filename": path, "sigma_a": 1.0, "sigma_s": 0.0})
    ms = scene.media
    box = np.array([[-1.0, 0.5, 2.0], [-1.0 + 16 * 0.3, 0.5 + 16 * 0.2, 2.0 + 16 * 0.25]])
    u = np.random.default_rng(5).uniform(0, 1, (100000, 3))
    dens = medium_eval(scene, box[0] + u * (box[1] - box[0]))[0]
    cell = np.minimum((u * R).astype(int), R - 1)
    maj = np.asarray(ms.maj)[0::2][(cell[:, 2] * R + cell[:, 1]) * R + cell[:, 0]]
    assert np.all(dens <= maj * (1 + 1e-5)), (dens - maj).max()
    best = np.zeros(R ** 3)
    np.maximum.at(best, (cell[:, 2] * R + cell[:, 1]) * R + cell[:, 0], dens)
    full = np.asarray(ms.maj)[0::2]
    used = full > 0
    assert np.all(best[~used] == 0) and np.median(best[used] / full[used]) > 0.75


def test_nanovdb_written_file_from_warp_test_assets():
    """Warp's test asset ``test_grid.nvdb`` (written by NanoVDB's own tools, zip-compressed,
    an unnamed float grid of 0.25 voxels, values of both signs, so not a density pbr
    accepts): its stored box is the active voxels' index box -10 .. 10 plus one, times
    0.25 (-2.5 .. 2.75); the dense voxels and affine map pbr builds from it, interpolated
    trilinearly in NumPy, give Warp's sampler's values inside that box."""
    from pbr.media.nanovdb import dense_samples, read_nvdb
    asset = os.path.join(os.path.dirname(wp.__file__), "tests", "assets", "test_grid.nvdb")
    if not os.path.exists(asset):
        pytest.skip("this Warp build has no tests/assets/test_grid.nvdb")
    g = read_nvdb(asset, ("",), "k")[0][""]
    np.testing.assert_allclose(g.world_bbox, [[-2.5] * 3, [2.75] * 3])
    vals, sc, off = dense_samples(g, g.world_bbox, "k", nonnegative=False)
    u = np.random.default_rng(7).uniform(0, 1, (20000, 3))
    x = u * sc + off                                   # array index (x, y, z); vals is [z, y, x]
    i0 = np.floor(x).astype(int)
    f = x - i0
    got = np.zeros(len(u))
    for corner in np.ndindex(2, 2, 2):
        c = np.minimum(i0 + corner, np.array(vals.shape[::-1]) - 1)
        w = np.prod(np.where(np.array(corner) == 1, f, 1 - f), axis=1)
        got += w * vals[c[:, 2], c[:, 1], c[:, 0]]
    ref = warp_sample(g.volume, g.world_bbox[0] + u * (g.world_bbox[1] - g.world_bbox[0]))
    assert ref.std() > 0.01
    np.testing.assert_allclose(got, ref, atol=1e-5 * np.abs(ref).max())


def test_reader_returns_warp_bounds_and_map(tmp_path):
    """read_nvdb: the stored world box of each grid, its voxel size and origin; two grids
    in one file are found by name; a missing name is None and the file's names are listed."""
    from pbr.media.nanovdb import read_nvdb
    a = np.ones((8, 8, 8), np.float32)
    path = write_nvdb(tmp_path / "two.nvdb", [("density", warp_volume(a, (1, 2, 3), 0.5)),
                                              ("temperature", warp_volume(a[:4], (0, 2, 3), (1.0, 0.5, 0.5)))])
    g, names = read_nvdb(path, ("density", "temperature", "heat"), "k")
    assert names == ["density", "temperature"] and g["heat"] is None
    np.testing.assert_allclose(g["density"].world_bbox, [[1, 2, 3], [5, 6, 7]])
    np.testing.assert_allclose(g["temperature"].world_bbox, [[0, 2, 3], [8, 6, 7]])
    np.testing.assert_allclose(g["temperature"].voxel, [1.0, 0.5, 0.5])
    np.testing.assert_allclose(g["temperature"].translation, [0, 2, 3])


# -- pbrt-v4 scenes ----------------------------------------------------------------------------

HEAD = """
LookAt 0.3 -0.2 -6  0.3 -0.2 0  0 1 0
Camera "perspective" "float fov" 28
Film "rgb" "integer xresolution" 24 "integer yresolution" 24
PixelFilter "box"
Sampler "independent" "integer pixelsamples" 16
Integrator "volpath" "integer maxdepth" 6
WorldBegin
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [1 1 1]
  Shape "trianglemesh" "point3 P" [-4 -4 3  -4 4 3  4 4 3  4 -4 3] "integer indices" [0 1 2 0 2 3]
AttributeEnd
LightSource "distant" "point3 from" [1 2 -3] "point3 to" [0 0 0] "rgb L" [2 2 2]
AttributeBegin
Translate -0.4 0.1 0.2
Rotate 25 0 1 0
Scale 1.2 0.8 1.0
MakeNamedMedium "m" {medium}
  "rgb sigma_a" [0.2 0.5 0.9] "rgb sigma_s" [3 2 1] "float scale" 1.5 "float g" 0.3
AttributeEnd
MediumInterface "m" ""
Material "interface"
Shape "sphere" "float radius" 2.5
"""


def _field():
    """An asymmetric smooth density field [x, y, z] on 8^3 voxels, zero on the outer
    layer (so that NanoVDB's box (index 0..8, background beyond) and a uniformgrid's box
    (half a voxel around the voxel centres, clamped) describe the same medium)."""
    x, y, z = np.meshgrid(*(np.arange(8.0),) * 3, indexing="ij")
    d = 5.0 * (x / 7) ** 2 * (1.0 + 0.5 * np.cos(0.8 * y)) + 0.2 * z / 7
    d[[0, -1], :, :] = 0
    d[:, [0, -1], :] = 0
    d[:, :, [0, -1]] = 0
    return d.astype(np.float32)


def _pbrt_pair(tmp_path, break_axes=False):
    d = _field()
    s, o = 0.25, np.array([-1.0, -0.9, -0.8])        # voxel size, origin: box o .. o + 8 s
    path = write_nvdb(tmp_path / "f.nvdb", [("density", warp_volume(d, tuple(o), s))])
    nano = write_tmp(tmp_path, "nano.pbrt", HEAD.format(medium=f'"string type" "nanovdb" "string filename" "{path}"'))
    # uniformgrid: voxel centres (k + 0.5) / 8 of p0 .. p1 = the NanoVDB voxels o + s k.
    dens = d.transpose(2, 1, 0) if not break_axes else d      # x fastest
    p0, p1 = o - 0.5 * s, o + 7.5 * s
    grid = ('"string type" "uniformgrid" "integer nx" 8 "integer ny" 8 "integer nz" 8 '
            f'"point3 p0" [{" ".join(map(str, p0))}] "point3 p1" [{" ".join(map(str, p1))}] '
            f'"float density" [{" ".join(f"{v:.7g}" for v in dens.ravel())}]')
    uni = write_tmp(tmp_path, "uni.pbrt", HEAD.format(medium=grid))
    return nano, uni


def write_tmp(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _compare(nano, uni, spp=64):
    from pbr import validate
    sa, sb = pbr.load_file(nano), pbr.load_file(uni)
    return validate.compare_renders(lambda seed=0, spp=0: np.asarray(pbr.render(sa, seed=seed, spp=spp)),
                                    lambda seed=0, spp=0: np.asarray(pbr.render(sb, seed=seed, spp=spp)),
                                    spp=spp, batches=8, seed_a=5, seed_b=6)


def test_pbrt_nanovdb_matches_uniformgrid(tmp_path):
    """A pbrt-v4 scene whose medium is a Warp-written .nvdb (under a rotated, scaled CTM)
    renders as the same field given to pbr's uniformgrid (validate.compare_renders)."""
    from pbr.scene.pbrt import to_dict
    nano, uni = _pbrt_pair(tmp_path)
    med = [v for v in to_dict(nano).values() if isinstance(v, dict) and v.get("type") == "nanovdb"][0]
    assert med["filename"].endswith("f.nvdb") and med["g"] == 0.3 and med["scale"] == 1.5
    res = _compare(nano, uni)
    print(res.summary())
    assert res.passed, res.summary()


@pytest.mark.slow
def test_nanovdb_comparison_detects_transposed_axes(tmp_path):
    """The comparison above fails when the uniformgrid gets the field with its axes
    swapped (x <-> z): it can tell orientations apart."""
    nano, uni = _pbrt_pair(tmp_path, break_axes=True)
    res = _compare(nano, uni)
    print(res.summary())
    assert not res.passed, res.summary()


# -- temperature: blackbody emission -------------------------------------------------------------

EMIT = """
LookAt 4 4 -5  4 4 0  0 1 0
Camera "orthographic" "float screenwindow" [-0.5 0.5 -0.5 0.5]
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
PixelFilter "box"
Sampler "independent" "integer pixelsamples" 2048
Integrator "volpath" "integer maxdepth" 1
WorldBegin
MakeNamedMedium "m" "string type" "nanovdb" "string filename" "{path}"
  "spectrum sigma_a" [300 0.15 900 0.15] "spectrum sigma_s" [300 0 900 0] "float Lescale" 2.5
  "float temperatureoffset" 100 "float temperaturescale" 2
MediumInterface "m" ""
Material "interface"
AttributeBegin
Translate 4 4 4
Shape "sphere" "float radius" 7
AttributeEnd
"""


def test_temperature_grid_emits_blackbody(tmp_path):
    """A purely absorbing medium (sigma_a 0.15) with density 1 and temperature 2600 K on
    8^3 unit voxels at the origin: along a ray down z through the middle, density and
    temperature are 1 and T0 = (2600 - 100) * 2 K for z <= 7 and fall linearly to the
    background (0) at z = 8 (below 100 K: no emission). The pixels are NumPy's
    integral of sigma_a d(z) Lescale B(T(z)) exp(-tau(z)) dz with B pbrt-v4's blackbody
    of peak 1, through the CIE 1931 matching functions to linear sRGB."""
    from pbr.spectrum import CIE_Y_INTEGRAL, LAMBDA_MIN, cie_tables_np, xyz_to_srgb
    ones = np.ones((8, 8, 8), np.float32)
    path = write_nvdb(tmp_path / "fire.nvdb", [("density", warp_volume(ones, (0, 0, 0), 1.0)),
                                               ("temperature", warp_volume(2600 * ones, (0, 0, 0), 1.0))])
    img = np.asarray(pbr.render(pbr.load_file(write_tmp(tmp_path, "fire.pbrt", EMIT.format(path=path))), seed=3),
                     np.float64)
    z = (np.arange(80000) + 0.5) / 10000                     # 0 .. 8
    dens = np.clip(8.0 - z, 0.0, 1.0)
    temp = (2600.0 * dens - 100.0) * 2.0
    tau = 0.15 * np.cumsum(dens) / 10000
    xyz, _ = cie_tables_np()
    lam = LAMBDA_MIN + 5.0 * np.arange(len(xyz))
    h, c, k = 6.62607004e-34, 2.99792458e8, 1.38064852e-23

    def planck(lam_nm, t):            # Planck's law up to a constant (it cancels in B)
        lm = lam_nm * 1e-9
        return 1.0 / (lm ** 5 * np.expm1(h * c / (lm * k * t)))

    hot = temp > 100
    b = np.zeros((len(lam), len(z)))
    b[:, hot] = planck(lam[:, None], temp[hot]) / planck(2.8977721e-3 / temp[hot] * 1e9, temp[hot])
    L = (0.15 * dens * 2.5 * b * np.exp(-tau)).sum(axis=1) / 10000
    want = xyz_to_srgb(np.trapezoid(L[:, None] * xyz, lam, axis=0) / CIE_Y_INTEGRAL)
    got = img.reshape(-1, 3).mean(axis=0)
    assert want.min() > 0.01, want
    print(got, want)
    np.testing.assert_allclose(got, want, rtol=0.03)


# -- errors ----------------------------------------------------------------------------------------

ERR = """
LookAt 0 0 -5  0 0 0  0 1 0
Camera "perspective" "float fov" 30
Film "rgb" "integer xresolution" 4 "integer yresolution" 4
WorldBegin
MakeNamedMedium "m" "string type" "nanovdb" {params}
MediumInterface "m" ""
Material "interface"
Shape "sphere"
"""


def test_errors_name_file_and_line(tmp_path, monkeypatch):
    ones = np.ones((8, 8, 8), np.float32)
    path = write_nvdb(tmp_path / "d.nvdb", [("density", warp_volume(ones, (0, 0, 0), 1.0))])
    bad = write_tmp(tmp_path, "a.pbrt", ERR.format(params='"string filename" "nothere.nvdb"'))
    with pytest.raises(XMLError, match=r"a\.pbrt:6: MakeNamedMedium: file not found: 'nothere.nvdb'"):
        pbr.load_file(bad)
    bad = write_tmp(tmp_path, "b.pbrt", ERR.format(params=f'"string filename" "{path}" "string gridname" "smoke"'))
    with pytest.raises(Exception, match=r"b\.pbrt:6.*has no grid 'smoke' \(its grids: \['density'\]\)"):
        pbr.load_file(bad)
    bad = write_tmp(tmp_path, "c.pbrt", ERR.format(params='"float scale" 2'))
    with pytest.raises(XMLError, match=r"c\.pbrt:6: MakeNamedMedium: nanovdb needs \"string filename\""):
        pbr.load_file(bad)
    # Mitsuba 3 has no such medium: refused, or a homogeneous stand-in under approximate.
    from pbr.scene.pbrt import convert
    ok = write_tmp(tmp_path, "f.pbrt", ERR.format(params=f'"string filename" "{path}" "rgb Le" [1 1 1]'))
    with pytest.raises(XMLError, match=r"f\.pbrt:6: MakeNamedMedium: medium 'nanovdb' \(NanoVDB files\) is not"):
        convert(ok, mitsuba=True)
    d, notes, _ = convert(ok, mitsuba=True, approximate=True)
    assert [v["type"] for v in d.values() if isinstance(v, dict) and "sigma_a" in v] == ["homogeneous"]
    d, notes, _ = convert(ok)
    assert any("f.pbrt:6" in n and "ignores 'Le'" in n for n in notes), notes
    assert [v for v in d.values() if isinstance(v, dict) and v.get("type") == "nanovdb"][0].get("Le") is None
    junk = tmp_path / "junk.nvdb"
    junk.write_bytes(b"not a nanovdb file at all" * 4)
    bad = write_tmp(tmp_path, "d.pbrt", ERR.format(params=f'"string filename" "{junk}"'))
    with pytest.raises(Exception, match=r"d\.pbrt:6.*junk.nvdb' is not a NanoVDB file Warp can read"):
        pbr.load_file(bad)
    # Without Warp: the file, the line and the command that installs it.
    monkeypatch.setitem(sys.modules, "warp", None)
    monkeypatch.delitem(sys.modules, "pbr.media._nanovdb_warp", raising=False)
    monkeypatch.delattr(pbr.media, "_nanovdb_warp", raising=False)
    ok = write_tmp(tmp_path, "e.pbrt", ERR.format(params=f'"string filename" "{path}"'))
    with pytest.raises(Exception, match=r"e\.pbrt:6.*needs NVIDIA Warp.*pip install warp-lang"):
        pbr.load_file(ok)
