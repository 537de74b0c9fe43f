"""Films: the image the camera develops. Mitsuba's ``hdrfilm`` (linear sRGB) and
``specfilm`` (channels of sensor response functions), pbrt-v4's ``rgb`` (with its pixel
sensor: ``iso``, exposure time, ``whitebalance``, ``maxcomponentvalue``), ``gbuffer``
(RGB and the geometry camera rays see) and ``spectral`` (RGB and radiance in wavelength
buckets).

Each camera sample contributes  w * XYZ(L)  and  w  to its pixel (w: the filter weight of
filter importance sampling), and w times each of the film's extra per-sample channels
(:meth:`HDRFilm.sample_channels`; the integrator adds the gbuffer's surface channels);
the developed pixel is the ratio, XYZ converted (through :attr:`HDRFilm.xyz_matrix`, the
sensor's) to sRGB. Samples whose filter offset lands outside the image get w = 0, so
border pixels average over the image only, as Mitsuba's film does."""

from __future__ import annotations

import functools
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from . import backend
from . import spectrum as spec
from .filters import FILTERS, GaussianFilter
from .plugins.props import Props, did_you_mean
from .plugins.registry import Registry
from .textures import read_spectrum_file, table_from_pairs

FILMS = Registry("film")


@FILMS.register("hdrfilm")
class HDRFilm:
    """``hdrfilm``: the image the camera develops (linear sRGB, float). Nested: a
    reconstruction filter (default ``gaussian``).

    ================  ======  =========  ===================================================
    name              type    default    meaning
    ================  ======  =========  ===================================================
    width             int     768        image width (pixels)
    height            int     576        image height (pixels)
    crop_offset_x     int     0          left column of the crop window
    crop_offset_y     int     0          top row of the crop window
    crop_width        int     width      crop window width: the rendered image's width
    crop_height       int     height     crop window height: the rendered image's height
    pixel_format      string  'rgb'      only 'rgb'
    component_format  string  'float32'  accepted: 'float16', 'float32' (images are float32)
    file_format       string  'openexr'  accepted: 'openexr', 'exr'
    sample_border     bool    false      only false
    ================  ======  =========  ===================================================

    With a crop window, the camera keeps the full film's view (aspect ratio and field of
    view) and the image holds the window's pixels only, as in Mitsuba: ``size`` is the
    window's (crop_width, crop_height), ``full_size`` the film's (width, height).
    """

    # The sensor: XYZ -> XYZ before sRGB (None: identity), the largest sensor-RGB
    # component a sample may have (pbrt-v4's maxcomponentvalue), whether the image starts
    # with R, G, B, and the surface channels (gbuffer) the integrator adds.
    xyz_matrix = None
    max_component = math.inf
    size_keys = ("width", "height", 768, 576)   # the parameters (and defaults) of the image size
    diagonal = 35.0      # physical film diagonal (mm; pbrt-v4's ``realistic`` camera)
    keeps_rgb = True
    surface_channels = ()

    name = "hdrfilm"

    def __init__(self, props: Props):
        self._size(props)
        self._reconstruction_filter(props)
        props.finish()

    def _size(self, props: Props) -> None:
        self._window(props)
        self.pixel_format = props.string("pixel_format", "rgb", choices=("rgb",))
        props.string("component_format", "float32", choices=("float16", "float32"))
        props.string("file_format", "openexr", choices=("openexr", "exr"))
        if props.bool("sample_border", False):
            raise props.error("sample_border", "sample_border=true is not supported: pbr's films drop "
                              "samples whose filter offset leaves the image (Mitsuba's default, "
                              "sample_border=false); remove the entry (only pixels within the "
                              "filter's radius of the image's edge differ)")

    def _window(self, props: Props) -> None:
        """Mitsuba's ``width``/``height`` and crop window (which must lie inside the film)."""
        self.width = props.int("width", 768, min=1)
        self.height = props.int("height", 576, min=1)
        self.crop_offset = (props.int("crop_offset_x", 0, min=0), props.int("crop_offset_y", 0, min=0))
        self.crop_size = (props.int("crop_width", self.width, min=1), props.int("crop_height", self.height, min=1))
        for k, o, c, n in (("crop_width", self.crop_offset[0], self.crop_size[0], self.width),
                           ("crop_height", self.crop_offset[1], self.crop_size[1], self.height)):
            if o + c > n:
                raise props.error(k, f"the crop window (offset {o} + size {c}) exceeds the film's {n} pixels")

    def _reconstruction_filter(self, props: Props) -> None:
        self.rfilter = GaussianFilter(Props({"type": "gaussian"}, props.key("rfilter")))
        for key, child in props.children():
            if child["type"] in FILTERS:
                self.rfilter = FILTERS[child["type"]](props.child(key))
            else:
                raise props.error(key, f"unsupported reconstruction filter {child['type']!r}"
                                       f"{did_you_mean(child['type'], FILTERS)} (supported: {', '.join(FILTERS)})")

    def set_exposure(self, seconds: float) -> None:
        """The camera's shutter interval (pbrt-v4's films scale by it; Mitsuba's do not)."""

    def to_xyz(self, L, wl):
        """A sample's values that ``xyz_matrix`` (identity: None) takes to XYZ."""
        return spec.to_xyz(L, wl)

    @property
    def splattable(self) -> bool:
        """Whether light tracers can splat into the film: RGB with no extra channels (a
        camera sensor, ``iso`` and ``maxcomponentvalue`` included)."""
        return self.keeps_rgb and not self.surface_channels and not self.n_extra

    @property
    def plain(self) -> bool:
        """Whether the film is an RGB image with no extra channels and no sensor (what
        light tracers splat into)."""
        return self.keeps_rgb and self.xyz_matrix is None and not self.surface_channels and not self.n_extra

    n_extra = 0          # channels of sample_channels

    def sample_channels(self, L, wl) -> list:
        """Extra per-sample channels (list of ``mi.Float``) from the sample's spectrum."""
        return []

    def channel_names(self) -> list:
        """Names of the developed image's channels."""
        names = ["R", "G", "B"] if self.keeps_rgb else []
        return names + list(self._extra_names())

    def _extra_names(self):
        return []

    @property
    def size(self):
        """(width, height) of the rendered image: the crop window's."""
        return self.crop_size

    @property
    def full_size(self):
        """(width, height) of the whole film (which sets the camera's view)."""
        return self.width, self.height


# --------------------------------------------------------------- pbrt-v4's films

def _daylight_xy(t: float):
    """Chromaticity of CIE daylight at correlated colour temperature ``t`` (4000-25000 K)."""
    if not 4000.0 <= t <= 25000.0:
        raise ValueError(t)
    s = 1e3 / t
    x = (-4.6070 * s ** 3 + 2.9678 * s ** 2 + 0.09911 * s + 0.244063 if t <= 7000.0 else
         -2.0064 * s ** 3 + 1.9018 * s ** 2 + 0.24748 * s + 0.237040)
    return x, -3.0 * x * x + 2.87 * x - 0.275


_BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])


def white_balance(src_xy, dst_xy) -> np.ndarray:
    """XYZ -> XYZ von Kries adaptation (Bradford cone space) taking white ``src_xy`` to
    ``dst_xy`` (pbrt-v4's ``WhiteBalance``)."""
    def xyz(xy):
        x, y = xy
        return np.array([x / y, 1.0, (1.0 - x - y) / y])
    lms_s, lms_d = _BRADFORD @ xyz(src_xy), _BRADFORD @ xyz(dst_xy)
    return np.linalg.inv(_BRADFORD) @ np.diag(lms_d / lms_s) @ _BRADFORD


# ------------------------------------------------ pbrt-v4's camera sensors

_LAM_1NM = np.arange(spec.LAMBDA_MIN, spec.LAMBDA_MAX + 1.0)    # pbrt-v4's 1 nm sums


def _data(name):
    import os
    return os.path.join(os.path.dirname(__file__), "data", name)


@functools.lru_cache(maxsize=None)
def camera_sensors() -> dict:
    """pbrt-v4's named camera sensors: name -> (wavelengths (nm), r, g, b response curves)
    from ``data/camera_sensors.txt`` (pbrt-v4's measured curves)."""
    out, name, rows = {}, None, []
    with open(_data("camera_sensors.txt")) as fh:
        for ln in list(fh) + ["camera -"]:
            if ln.startswith("#") or not ln.strip():
                continue
            if ln.startswith("camera "):
                if name is not None:
                    out[name] = tuple(np.array(rows).T)
                name, rows = ln.split()[1], []
            else:
                rows.append([float(x) for x in ln.split()])
    return out


def _piecewise(lam, x, y):
    """pbrt-v4's PiecewiseLinearSpectrum: linear between the samples, 0 outside."""
    return np.interp(lam, x, y, left=0.0, right=0.0)


def daylight_spectrum(t: float, lam: np.ndarray) -> np.ndarray:
    """pbrt-v4's ``Spectra::D(t)``: CIE daylight of correlated colour temperature t (with
    pbrt-v4's 1.4388/1.4380 correction of t), a blackbody below 4000 K; relative units."""
    cct = t * 1.4388 / 1.4380
    if cct < 4000.0:
        return spec.blackbody(lam, cct)
    s = 1e3 / cct
    x = (-4.607 * s ** 3 + 2.9678 * s ** 2 + 0.09911 * s + 0.244063 if cct <= 7000.0 else
         -2.0064 * s ** 3 + 1.9018 * s ** 2 + 0.24748 * s + 0.23704)
    y = -3.0 * x * x + 2.870 * x - 0.275
    m = 0.0241 + 0.2562 * x - 0.7341 * y
    m1, m2 = (-1.3515 - 1.7703 * x + 5.9114 * y) / m, (0.0300 - 31.4424 * x + 30.0717 * y) / m
    b = spec.read_table(_data("cie_daylight_s012.spd"))
    return _piecewise(lam, b[:, 0], (b[:, 1] + m1 * b[:, 2] + m2 * b[:, 3]) * 0.01)


@functools.lru_cache(maxsize=None)
def sensor_xyz_matrix(name: str, white: float) -> np.ndarray:
    """pbrt-v4's ``PixelSensor`` XYZ-from-sensor-RGB matrix of camera ``name`` white-balanced
    for daylight ``white`` (K): the least-squares fit, over the 24 ColorChecker swatches lit
    by that daylight, of the sensor's RGB (each normalised by the sensor's g response to the
    light) to the swatches' XYZ under sRGB's D65 (normalised by Y), times white Y / white g."""
    lam = _LAM_1NM
    wl, *rgb = camera_sensors()[name]
    r, g, b = (_piecewise(lam, wl, c) for c in rgb)
    illum = daylight_spectrum(white, lam)
    xyz_tab, d65_tab = spec.cie_tables_np()
    grid = spec.LAMBDA_MIN + 5.0 * np.arange(len(d65_tab))
    cx, cy, cz = (np.interp(lam, grid, xyz_tab[:, k]) for k in range(3))
    d65 = np.interp(lam, grid, d65_tab)
    sw = spec.read_table(_data("colorchecker_swatches.spd"))
    refl = np.stack([_piecewise(lam, sw[:, 0], sw[:, k]) for k in range(1, sw.shape[1])])   # (24, n)
    cam = np.stack([(refl * illum * c).sum(axis=1) for c in (r, g, b)], axis=1) / (g * illum).sum()
    xyz = np.stack([(refl * d65 * c).sum(axis=1) for c in (cx, cy, cz)], axis=1) / (cy * d65).sum()
    xyz *= (illum * cy).sum() / (illum * g).sum()
    mt, *_ = np.linalg.lstsq(cam, xyz, rcond=None)      # cam @ M^T ~ xyz
    return mt.T


@FILMS.register("rgb")
class RGBFilm(HDRFilm):
    """``rgb`` (pbrt-v4's): an RGB image (linear sRGB) through pbrt-v4's pixel sensor:
    XYZ matching ('cie1931') times the imaging ratio exposure time * iso / 100 (the
    exposure time is the camera's shutter interval), optionally white balanced (von Kries,
    Bradford) from CIE daylight at ``whitebalance`` kelvin to sRGB's D65 white; each
    sample's sensor values (XYZ, or a camera's RGB) times the imaging ratio are scaled
    down to at most ``maxcomponentvalue`` (pbrt-v4's clamp). Nested: a filter.

    =================  =========  ==========  ================================================
    name               type       default     meaning
    =================  =========  ==========  ================================================
    xresolution        int        1280        image width (pixels)
    yresolution        int        720         image height (pixels)
    cropwindow         float[4]   [0,1,0,1]   x0, x1, y0, y1 of the rendered part (fractions)
    pixelbounds        int[4]     -           x0, x1, y0, y1 of the rendered part (pixels)
    iso                float      100         sensitivity (imaging ratio t * iso / 100)
    whitebalance       float      0           daylight temperature to balance for (0: none)
    sensor             string     'cie1931'   'cie1931' or a camera: 'canon_eos_100d', ...
    maxcomponentvalue  float      inf         largest RGB component of a sample
    filename           string     -           accepted (pbr returns the image)
    diagonal           float      35          accepted (film diagonal, mm: ``realistic``)
    savefp16           bool       true        accepted (images are float32)
    =================  =========  ==========  ================================================
    """

    name = "rgb"
    size_keys = ("xresolution", "yresolution", 1280, 720)

    def __init__(self, props: Props):
        self.name = props.type or "rgb"
        self._pbrt_size(props)
        self._reconstruction_filter(props)
        self._sensor(props)
        self._own(props)
        props.finish()

    def _own(self, props: Props) -> None:
        """Parameters of the subclasses."""

    def _pbrt_size(self, props: Props) -> None:
        self.width = props.int("xresolution", 1280, min=1)
        self.height = props.int("yresolution", 720, min=1)
        self.pixel_format = "rgb"
        x0, x1, y0, y1 = 0, self.width, 0, self.height
        if props.has("pixelbounds"):
            pb = np.asarray(props.raw("pixelbounds"), np.float64).ravel()
            if pb.size != 4:
                raise props.error("pixelbounds", f"expected 4 integers x0 x1 y0 y1, got {props.raw('pixelbounds')!r}")
            x0, x1 = max(0, int(pb[0])), min(self.width, int(pb[1]))
            y0, y1 = max(0, int(pb[2])), min(self.height, int(pb[3]))
        if props.has("cropwindow"):
            cr = np.asarray(props.raw("cropwindow"), np.float64).ravel()
            if cr.size != 4 or not np.all(np.isfinite(cr)):
                raise props.error("cropwindow", f"expected 4 fractions x0 x1 y0 y1, got {props.raw('cropwindow')!r}")
            cx0, cx1 = np.clip(sorted(cr[:2]), 0.0, 1.0)
            cy0, cy1 = np.clip(sorted(cr[2:]), 0.0, 1.0)
            x0, x1 = math.ceil(self.width * cx0), math.ceil(self.width * cx1)
            y0, y1 = math.ceil(self.height * cy0), math.ceil(self.height * cy1)
        if x1 <= x0 or y1 <= y0:
            raise props.error("cropwindow" if props.has("cropwindow") else "pixelbounds",
                              f"the rendered part of the image is empty ({x0}..{x1} x {y0}..{y1})")
        self.crop_offset, self.crop_size = (x0, y0), (x1 - x0, y1 - y0)
        props.mark("filename")
        self.diagonal = props.float("diagonal", 35.0, min=1e-6)
        props.bool("savefp16", True)

    def _sensor(self, props: Props) -> None:
        self.iso = props.float("iso", 100.0, min=0.0)
        self.sensor = props.string("sensor", "cie1931", choices=("cie1931", *camera_sensors()))
        self.max_component = props.float("maxcomponentvalue", math.inf, min=0.0) if props.has(
            "maxcomponentvalue") else math.inf
        wb = props.float("whitebalance", 0.0, min=0.0)
        self.white = np.eye(3)
        self.curves = None
        if self.sensor != "cie1931":
            # pbrt-v4: a camera sensor is white-balanced for 6500 K daylight unless told otherwise.
            if wb == 0.0:
                wb = 6500.0
            self.white = sensor_xyz_matrix(self.sensor, wb)
            wl, *rgb = camera_sensors()[self.sensor]
            self.curves = np.stack([_piecewise(_LAM_1NM, wl, c) for c in rgb])
        elif wb != 0.0:
            try:
                src = _daylight_xy(wb)
            except ValueError:
                raise props.error("whitebalance", f"expected a daylight temperature in [4000, 25000] K, got {wb}")
            d65 = spec.SRGB_TO_XYZ @ np.ones(3)
            self.white = white_balance(src, (d65[0] / d65.sum(), d65[1] / d65.sum()))
        self.set_exposure(1.0)

    def set_exposure(self, seconds: float) -> None:
        self.imaging_ratio = seconds * self.iso / 100.0
        m = self.white * self.imaging_ratio
        self.xyz_matrix = None if np.allclose(m, np.eye(3), atol=0.0, rtol=0.0) and self.curves is None else m

    def to_xyz(self, L, wl):
        """A sample's tristimulus values: XYZ, or with a camera sensor its RGB response
        (the curves' Monte Carlo integral over L, in XYZ's units), which ``xyz_matrix``
        takes to XYZ."""
        if self.curves is None:
            return spec.to_xyz(L, wl)
        tabs = self._curve_tables()
        inv = dr.select(wl.pdf != 0, dr.rcp(wl.pdf), 0.0) * (1.0 / (spec.N_WAVELENGTHS * spec.CIE_Y_INTEGRAL))
        Lw = L * inv
        out = [mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)]
        for k in range(spec.N_WAVELENGTHS):
            lam = wl.lambda_[k]
            inside = (lam >= spec.LAMBDA_MIN) & (lam <= spec.LAMBDA_MAX)
            t = dr.clip(lam - spec.LAMBDA_MIN, 0.0, len(_LAM_1NM) - 1.0)
            i0 = dr.minimum(mi.UInt32(t), len(_LAM_1NM) - 2)
            f = t - mi.Float(i0)
            for c, tab in enumerate(tabs):
                v = dr.lerp(dr.gather(mi.Float, tab, i0, inside), dr.gather(mi.Float, tab, i0 + 1, inside), f)
                out[c] = out[c] + dr.select(inside, v, 0.0) * Lw[k]
        return mi.Array3f(*out)

    def _curve_tables(self):
        key = backend.variant()
        cache = self.__dict__.setdefault("_tables", {})
        if key not in cache:
            cache[key] = [mi.Float(c.astype(np.float32)) for c in self.curves]
        return cache[key]


@FILMS.register("spectral")
class SpectralFilm(RGBFilm):
    """``spectral`` (pbrt-v4's): the ``rgb`` film's image followed by ``nbuckets``
    channels of spectral radiance averaged over equal wavelength buckets of
    [lambdamin, lambdamax] (each a Monte Carlo estimate of (1 / width) * integral of
    L over the bucket; pbr's radiance units, without pbrt-v4's photometric factor).

    =================  =====  =======  ==============================================
    name               type   default  meaning
    =================  =====  =======  ==============================================
    nbuckets           int    16       spectral channels
    lambdamin          float  360      shortest wavelength (nm)
    lambdamax          float  830      longest wavelength (nm)
    (rgb's)            -      -        every parameter of ``rgb``
    =================  =====  =======  ==============================================
    """

    def _own(self, props: Props) -> None:
        self.n_extra = props.int("nbuckets", 16, min=1)
        self.lambda_min = props.float("lambdamin", spec.LAMBDA_MIN, min=spec.LAMBDA_MIN, max=spec.LAMBDA_MAX)
        self.lambda_max = props.float("lambdamax", spec.LAMBDA_MAX, min=spec.LAMBDA_MIN, max=spec.LAMBDA_MAX)
        if self.lambda_max <= self.lambda_min:
            raise props.error("lambdamax", "must exceed lambdamin")

    def sample_channels(self, L, wl) -> list:
        n, lo, hi = self.n_extra, self.lambda_min, self.lambda_max
        width = (hi - lo) / n
        inv = dr.select(wl.pdf != 0, dr.rcp(wl.pdf), 0.0) * (1.0 / (spec.N_WAVELENGTHS * width))
        out = []
        for b in range(n):
            a, c = lo + b * width, lo + (b + 1) * width
            inside = (wl.lambda_ >= a) & ((wl.lambda_ < c) if b < n - 1 else (wl.lambda_ <= c))
            out.append(dr.sum(dr.select(inside, L * inv, 0.0)))
        return out

    def _extra_names(self):
        w = (self.lambda_max - self.lambda_min) / self.n_extra
        return [f"S.{self.lambda_min + (b + 0.5) * w:.1f}nm" for b in range(self.n_extra)]


@FILMS.register("gbuffer")
class GBufferFilm(RGBFilm):
    """``gbuffer`` (pbrt-v4's): the ``rgb`` film's image followed by what camera rays
    see first: albedo (the BSDF's sampled reflectance, sRGB), position P, geometric
    normal N and shading normal Ns (camera space, or world space), and the surface's
    u, v (0 where rays escape). pbrt-v4's dz/dx, dz/dy and variance channels are left out.

    =================  ======  ========  ==============================================
    name               type    default   meaning
    =================  ======  ========  ==============================================
    coordinatesystem   string  'camera'  'camera' or 'world': the frame of P, N, Ns
    (rgb's)            -       -         every parameter of ``rgb``
    =================  ======  ========  ==============================================
    """

    CHANNELS = ["Albedo.R", "Albedo.G", "Albedo.B", "P.X", "P.Y", "P.Z", "N.X", "N.Y", "N.Z", "Ns.X", "Ns.Y",
                "Ns.Z", "u", "v"]

    def _own(self, props: Props) -> None:
        self.world_space = props.string("coordinatesystem", "camera", choices=("camera", "world")) == "world"
        self.surface_channels = ("albedo", "position", "geo_normal", "sh_normal", "uv")

    def _extra_names(self):
        return list(self.CHANNELS)


@FILMS.register("specfilm")
class SpecFilm(HDRFilm):
    """``specfilm`` (Mitsuba's): one channel per sensor response function, the
    integral of srf(lambda) L(lambda) d lambda (Mitsuba's convention), estimated with
    pbr's wavelength samples (so only the part of a response inside 360-830 nm counts).
    Every nested spectrum (``spectrum`` with ``value`` pairs or ``filename``,
    ``regular``, ``irregular``) is a response function, its key the channel's name; no
    R, G, B channels. Nested also: a filter.

    ================  ======  =========  ==============================================
    name              type    default    meaning
    ================  ======  =========  ==============================================
    width             int     768        image width (pixels)
    height            int     576        image height (pixels)
    crop_offset_x     int     0          left column of the crop window
    crop_offset_y     int     0          top row of the crop window
    crop_width        int     width      crop window width
    crop_height       int     height     crop window height
    component_format  string  'float16'  accepted: 'float16', 'float32', 'uint32'
    (any key)         srf     -          a sensor response function (channel name)
    ================  ======  =========  ==============================================
    """

    keeps_rgb = False
    name = "specfilm"

    def __init__(self, props: Props):
        self._window(props)
        self.pixel_format = "spectral"
        props.string("component_format", "float16", choices=("float16", "float32", "uint32"))
        props.mark("compensate")
        self.rfilter = GaussianFilter(Props({"type": "gaussian"}, props.key("rfilter")))
        self.srf_names, tables = [], []
        for key, child in props.children():
            t = child["type"]
            if t in FILTERS:
                self.rfilter = FILTERS[t](props.child(key))
            elif t in ("spectrum", "regular", "irregular"):
                self.srf_names.append(key)
                tables.append(_srf_table(props.child(key)))
            else:
                raise props.error(key, f"expected a sensor response function (spectrum, regular, irregular) or a "
                                       f"filter, got {t!r}")
        if not tables:
            raise props.error(None, "a specfilm needs at least one sensor response function (a nested spectrum)")
        props.finish()
        self.n_extra = len(tables)
        self._n_tab = len(tables[0])
        self._tables = mi.Float(np.stack(tables).astype(np.float32).ravel())   # not inside a frozen render

    def sample_channels(self, L, wl) -> list:
        n_tab, tab = self._n_tab, self._tables
        ts = [dr.clip(wl.lambda_[k] - spec.LAMBDA_MIN, 0.0, n_tab - 1.0) for k in range(spec.N_WAVELENGTHS)]
        i0 = [dr.minimum(mi.UInt32(t), n_tab - 2) for t in ts]
        f = [t - mi.Float(i) for t, i in zip(ts, i0)]
        inv = dr.select(wl.pdf != 0, dr.rcp(wl.pdf), 0.0) * (1.0 / spec.N_WAVELENGTHS)
        out = []
        for j in range(self.n_extra):
            srf = mi.Spectrum([dr.lerp(dr.gather(mi.Float, tab, j * n_tab + i0[k]),
                                       dr.gather(mi.Float, tab, j * n_tab + i0[k] + 1), f[k])
                               for k in range(spec.N_WAVELENGTHS)])
            out.append(dr.sum(srf * L * inv))
        return out

    def _extra_names(self):
        return list(self.srf_names)


def _numbers(p: Props, name: str) -> np.ndarray:
    """A list of numbers given as a sequence or a string ('1, 2, 3')."""
    v = p.raw(name)
    try:
        return np.asarray([float(x) for x in v.replace(",", " ").split()] if isinstance(v, str) else v,
                          np.float64).ravel()
    except (TypeError, ValueError, AttributeError):
        raise p.error(name, f"expected a list of numbers, got {v!r}") from None


def _srf_table(p: Props) -> np.ndarray:
    """A response function (the Props of its dict) -> values at 1 nm steps over
    [LAMBDA_MIN, LAMBDA_MAX] (piecewise linear, 0 outside its range)."""
    t, where = p.type, p.path
    if t == "spectrum" and p.has("filename"):
        wl, vals = read_spectrum_file(p)
    elif t == "spectrum":
        v = p.raw("value")
        if isinstance(v, str):
            try:
                v = [tuple(float(x) for x in item.split(":")) for item in v.replace(",", " ").split()]
            except ValueError:
                raise p.error("value", f"expected 'wavelength:value' pairs, got {v!r}") from None
        a = np.asarray(v, np.float64)
        if a.ndim != 2 or a.shape[1] != 2:
            raise p.error("value", "a response function needs (wavelength, value) pairs")
        wl, vals = a[:, 0], a[:, 1]
    elif t == "regular":
        vals = _numbers(p, "values")
        wl = np.linspace(p.float("wavelength_min"), p.float("wavelength_max"), vals.size)
    else:
        wl, vals = _numbers(p, "wavelengths"), _numbers(p, "values")
    p.finish()
    return table_from_pairs(wl, vals, where)
