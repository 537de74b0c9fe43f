"""Building blocks shared by the integrators that trace paths from the lights
(``ptracer``, ``bdpt``, ``sppm``).

* :class:`SplatFilm`: contributions at arbitrary film positions, scatter-added into an
  image with the film's reconstruction filter (as Mitsuba's particle tracer splats), and
  developed as ``sum / spp``; :class:`LightTracingIntegrator` renders the ordinary
  camera-sample image and adds the splatted one (BDPT's t = 1 strategies, a particle
  tracer's camera connections).
* Importance transport (pbrt-v4's ``TransportMode::Importance``): pbr's BSDFs compute the
  radiance-transport values; :func:`eval_importance` and :func:`sample_importance` turn
  them into the adjoint BSDF used along light paths, and :func:`shading_correction` is
  Veach's factor for shading normals.
* :func:`start_light_path`, :func:`connect_to_camera`: the first and the last step of a
  light path, with the sampling routines of the lights (``LightSet.sample_Le``) and of the
  camera (``PerspectiveCamera.sample_Wi``: a pinhole or a point of a thin lens).

Conventions: directions are world-space unit vectors unless named ``*_local``; along a
light path ``si.wi`` points back toward the light (where the particle came from) and
``wo`` toward where it goes next.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..bsdfs.base import TRANSMISSION, ShadingContext
from .base import NonFinite, SamplingIntegrator, clamp_sample, nonzero_estimate

# Mitsuba's ray offset (math::RayEpsilon): rays leaving a surface start this far (relative
# to the magnitude of the point) along its normal.
RAY_EPSILON = 1500.0 * 2.0 ** -24


# ----------------------------------------------------------------------------- splatting

class SplatFilm:
    """An image of contributions splatted at film positions (XYZ sums, float64).

    ``splat(pos, L, wl, active)`` adds the spectrum ``L`` (converted to XYZ with the
    wavelengths' densities, or to a camera sensor's values and clamped to the film's
    ``maxcomponentvalue``, as the camera film does) at film position ``pos`` in
    [0,1]^2 (x right, y down), spread over the pixels the film's reconstruction filter
    covers with weights normalised to sum to 1 over the full (unclipped) footprint, as
    Mitsuba's ``ImageBlock(normalize=True)``: what falls outside the image is lost. It is a
    scatter-add, so it may be called inside a render kernel (also inside its symbolic
    loops); the sums are computed with that kernel. ``develop(scale)`` returns the linear
    sRGB image ``scale * sum`` (H, W, 3) through the film's sensor matrix, numpy float64; ``scale = 1 / spp`` when every
    pixel's ``spp`` samples traced one light path each (``W H spp`` paths in all).
    Contributions that are not finite are splatted as 0 and counted in ``nonfinite`` (the
    integrator's :class:`~pbr.integrators.base.NonFinite`).
    """

    def __init__(self, camera, nonfinite: NonFinite | None = None):
        self.film = camera.film
        self.width, self.height = camera.film.size
        self.rfilter = camera.film.rfilter
        # Float64 sums: float atomics add in whatever order threads arrive, and float32
        # sums then differ between runs (by ~1e-7); in float64 that difference is far
        # below the float32 image's rounding, so the same seed gives the same image.
        self.buf = dr.zeros(mi.Float64, self.width * self.height * 3)
        self.nonfinite = nonfinite or NonFinite()

    def splat(self, pos, L, wl, active):
        xyz, = self.nonfinite.replace([clamp_sample(self.film, self.film.to_xyz(L, wl))], active)
        self.splat_xyz(pos, xyz, active)

    def splat_xyz(self, pos, xyz, active):
        w, h = self.width, self.height
        fx, fy = self.rfilter, self.rfilter.y
        r = max(float(fx.radius), float(fy.radius))
        # Pixel i covers [i, i + 1): its centre is at i + 1/2.
        cx, cy = pos.x * w - 0.5, pos.y * h - 0.5
        x0, y0 = dr.ceil(cx - r), dr.ceil(cy - r)
        n = max(1, int(math.ceil(2.0 * r)))
        wx = [fx.eval(x0 + i - cx) for i in range(n)]
        wy = [fy.eval(y0 + j - cy) for j in range(n)]
        sx, sy = wx[0], wy[0]
        for i in range(1, n):
            sx, sy = sx + wx[i], sy + wy[i]
        norm = sx * sy
        active = active & (norm != 0)
        inv = dr.select(active, dr.rcp(norm), 0.0)
        ix0, iy0 = mi.Int32(x0), mi.Int32(y0)
        for j in range(n):
            iy = iy0 + j
            ok_y = active & (iy >= 0) & (iy < h) & (wy[j] != 0)
            for i in range(n):
                ix = ix0 + i
                ok = ok_y & (ix >= 0) & (ix < w) & (wx[i] != 0)
                wgt = wx[i] * wy[j] * inv
                idx = mi.UInt32(iy * w + ix) * 3
                for c in range(3):
                    dr.scatter_reduce(dr.ReduceOp.Add, self.buf, mi.Float64(xyz[c] * wgt), idx + c, ok)

    def develop(self, scale: float) -> np.ndarray:
        xyz = np.array(self.buf, dtype=np.float64).reshape(self.height, self.width, 3) * scale
        if self.film.xyz_matrix is not None:
            xyz = xyz @ np.asarray(self.film.xyz_matrix, np.float64).T
        return spec.xyz_to_srgb(xyz)


class LightTracingIntegrator(SamplingIntegrator):
    """A sampling integrator whose ``sample`` may also splat (into ``self.splats``, with
    ``self.camera`` the sensor being rendered): ``render`` = the camera-sample image plus
    the splatted image over ``spp``. Primal only."""

    pass_separable = False    # the splat film (float64 sums) spans passes

    needs_camera_importance = True  # connects paths to the camera (sample_Wi / its own camera rays)
    traces_light_paths = True
    supports_films = False        # splats RGB (RGB films only)
    supports_sensor_films = True  # with a camera sensor (pbrt-v4's rgb film: iso, maxcomponentvalue)

    def render(self, scene, sensor=0, seed=0, spp=0, progress=None):
        cam, w, h, spp, _, _ = self._plan(scene, sensor, spp)
        self.camera = cam
        self.splats = SplatFilm(cam, self.counter())
        try:
            img = np.array(super().render(scene, sensor, seed, spp, progress), dtype=np.float64)
            img[..., :3] += self.splats.develop(1.0 / spp)
        finally:
            self.splats = None
        return mi.TensorXf(img.astype(np.float32))


# ----------------------------------------------------------------- importance transport

def shading_correction(si, wi, wo):
    """Veach's adjoint factor for shading normals, ``|wi.ns| |wo.ng| / (|wi.ng| |wo.ns|)``
    (pbrt-v4's and Mitsuba's), and where both directions lie on the same side of the
    geometric and the shading surface (elsewhere shading normals would leak light)."""
    ng, ns = si.n, si.sh_frame.n
    i_g, i_s = dr.dot(wi, ng), dr.dot(wi, ns)
    o_g, o_s = dr.dot(wo, ng), dr.dot(wo, ns)
    ok = (i_g * i_s > 0) & (o_g * o_s > 0)
    corr = dr.abs((i_s * o_g) / (i_g * o_s))
    return dr.select(ok, corr, 0.0), ok


def eval_importance(bsdfs, bsdf_id, ctx, wo_local, active):
    """(adjoint BSDF value f* |cos theta_o|, density of sampling ``wo_local``) at a light-path
    vertex (``ctx.si.wi``: toward the light side). pbr's BSDFs give the radiance-transport
    value, which for a transmission across an IOR change carries ``1 / eta^2`` (the
    radiance scaling); importance transport does not (pbrt-v4, Mitsuba). For reflection the
    value is used as it is (as Mitsuba does); for transmission it is the exact adjoint, the
    radiance-transport value with the directions swapped: f*(wi, wo) = f(wo, wi), which
    needs no IOR (only computed when the scene has a transmitting BSDF)."""
    f, pdf = bsdfs.eval_pdf(bsdf_id, ctx, wo_local, active)
    if not bsdfs.has_flag(TRANSMISSION):
        return f, pdf
    wi_local = ctx.si.wi
    trans = active & (wi_local.z * wo_local.z < 0)
    si = mi.SurfaceInteraction3f(ctx.si)
    si.wi = wo_local
    f_swap, _ = bsdfs.eval_pdf(bsdf_id, ShadingContext(si, ctx.wl), wi_local, trans)
    ratio = dr.abs(wo_local.z) / dr.maximum(dr.abs(wi_local.z), 1e-20)
    return dr.select(trans, f_swap * ratio, f), pdf


def sample_importance(bsdfs, bsdf_id, ctx, u1, u2, active):
    """A BSDF sample at a light-path vertex with the importance-transport weight: the
    radiance weight times ``bs.eta^2`` (``bs.eta``: the relative IOR crossed, 1 for
    reflection), which removes the radiance scaling of refraction."""
    bs = bsdfs.sample(bsdf_id, ctx, u1, u2, active)
    if bsdfs.has_flag(TRANSMISSION):
        bs.weight = bs.weight * (bs.eta * bs.eta)
    return bs


# --------------------------------------------------------------------- light-path steps

def spawn_from(p, n, d):
    """A ray from ``p`` along ``d``, its origin moved off the surface of normal ``n`` (to
    the side ``d`` points to) as Mitsuba's ``spawn_ray``; ``n = 0`` leaves it in place."""
    mag = (1.0 + dr.max(dr.abs(p))) * RAY_EPSILON
    off = dr.mulsign(mi.Vector3f(n) * mag, dr.dot(n, d))
    return mi.Ray3f(p + off, d)


def start_light_path(scene, sampler, rng, wl, active):
    """Pick a light with ``sampler`` and sample a ray leaving it (4 random numbers): (``LeSample``, the
    ray, the initial throughput ``beta``: the sample's weight, W/m^2/sr-free units such
    that the expected sum of contributions reaching the film equals the image)."""
    u_light = rng.next_float32()
    u_pos = mi.Point2f(rng.next_float32(), rng.next_float32())
    u_dir = mi.Point2f(rng.next_float32(), rng.next_float32())
    ls = scene.lights.sample_Le(sampler, u_light, u_pos, u_dir, wl, active)
    ray = spawn_from(ls.o, ls.n, ls.d)
    return ls, ray, mi.Spectrum(ls.weight)


def lens_sample(camera, rng):
    """The 2D sample of a camera connection's lens point (``sample_Wi``) from ``rng``, or
    None for a pinhole (which draws nothing, so that its random streams stay as they were)."""
    if not camera.needs_aperture_sample:
        return None
    return mi.Point2f(rng.next_float32(), rng.next_float32())


def connect_to_camera(scene, camera, si, bsdf_id, wl, beta, active, cs=None):
    """Connect a light-path surface vertex ``si`` (reached with throughput ``beta``) to the
    camera through ``cs``, its ``camera.sample_Wi(si.p, u)`` (default: the pinhole's):
    (contribution to splat, film position, valid mask). The contribution is
    ``beta f*(wi, wo) |cos| corr We / pdf`` with the adjoint BSDF toward the camera,
    Veach's shading-normal factor and the camera's importance, zero where the shadow ray
    to the lens point is blocked."""
    if cs is None:
        cs = camera.sample_Wi(si.p)
    ok = active & cs.valid
    wo_local = si.to_local(cs.wi)
    ctx = ShadingContext(si, wl)
    f, _ = eval_importance(scene.bsdfs, bsdf_id, ctx, wo_local, ok)
    corr, side_ok = shading_correction(si, si.to_world(si.wi), cs.wi)
    ok &= side_ok & (cs.pdf > 0)
    contrib = beta * f * (corr * cs.We / dr.select(ok, cs.pdf, 1.0))
    # The shadow ray only where the contribution is not zero (base.light_reaches' rule).
    ok = nonzero_estimate(contrib, ok)
    ok &= scene.geometry.unoccluded(si, cs.p, ok)
    return dr.select(ok, contrib, 0.0), cs.pos, ok
