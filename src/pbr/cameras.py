"""Cameras: Mitsuba 3's ``perspective`` (pinhole; with pbrt-v4's ``lensradius`` a thin
lens), ``thinlens`` (depth of field) and ``orthographic``, with the same parameters and
conventions, and pbrt-v4's ``spherical`` (equal-area and equirectangular).

Every camera takes a shutter interval (Mitsuba's ``shutter_open``/``shutter_close``,
pbrt-v4's ``shutteropen``/``shutterclose``) and may move during it: with ``to_world_end``
the camera-to-world transform is interpolated (translation and scale linearly, rotation
by quaternion slerp, as pbrt-v4's ``AnimatedTransform``) between ``to_world`` at
``transform_times[0]`` and ``to_world_end`` at ``transform_times[1]`` (pbrt-v4's
``TransformTimes``/``ActiveTransform``), at each ray's time, drawn uniformly in the
shutter interval (camera motion blur).

Camera space looks down +z with +y up; image x grows toward camera -x (Mitsuba's
convention), so ``to_world = look_at(origin, target, up)`` gives the expected view.
``fov`` is in degrees along ``fov_axis`` (x, y, diagonal, smaller, larger). A film crop
window (``crop_offset_x/y``, ``crop_width/height``) renders that part of the full image:
film positions in [0, 1]^2 of the crop window map to ``pos * crop_size / size +
crop_offset / size`` of the full film, as in Mitsuba's projection transforms."""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .backend import Struct
from .films import FILMS, HDRFilm
from .lens import LensSystem, read_lens_file
from .geometry import read_motion
from .samplers import SAMPLERS, IndependentSampler
from .sampling import square_to_uniform_disk_concentric
from .plugins.props import Props, Range
from .plugins.registry import Registry

SENSORS = Registry("sensor")


def _x_fov(props: Props, aspect: float) -> float:
    """Horizontal field of view (degrees) from ``fov``/``fov_axis`` or ``focal_length``
    (a 35 mm equivalent: the diagonal of a 36 x 24 mm film); neither: Mitsuba's default
    focal length, 50 mm."""
    if props.has("fov") and props.has("focal_length"):
        raise props.error("fov", "give either 'fov' or 'focal_length', not both")
    if not props.has("fov"):
        if props.has("fov_axis"):
            raise props.error("fov_axis", "fov_axis needs 'fov'")
        fl = props.raw("focal_length", "50mm")
        try:
            f = float(str(fl).rstrip("m").rstrip("m")) if isinstance(fl, str) else float(fl)
        except ValueError:
            raise props.error("focal_length", f"expected e.g. '50mm', got {fl!r}") from None
        fov = math.degrees(2.0 * math.atan(math.sqrt(36 ** 2 + 24 ** 2) / (2.0 * f)))
        axis = "diagonal"
    else:
        fov = props.float("fov", min=1e-4, max=179.99)
        axis = props.string("fov_axis", "x", choices=("x", "y", "diagonal", "smaller", "larger"))
    if axis == "smaller":
        axis = "x" if aspect <= 1 else "y"
    elif axis == "larger":
        axis = "x" if aspect > 1 else "y"
    t = math.tan(math.radians(fov) / 2)
    if axis == "y":
        t = t * aspect
    elif axis == "diagonal":
        t = t * aspect / math.sqrt(aspect * aspect + 1.0)
    return 2.0 * math.degrees(math.atan(t))


class ProjectiveCamera:
    """What Mitsuba's projective cameras share: a film (with its crop window), a sampler,
    the medium the camera sits in, ``to_world`` (possibly moving: a :class:`~.motion.AnimatedTransform`),
    the shutter interval and the clip distances. Subclasses read their own parameters in
    ``_parameters(props)`` and call ``props.finish()``."""

    medium = 0  # index + 1 of the medium the camera sits in (0: vacuum)
    rigid = True  # the camera-to-world transform must be rigid
    clips = True  # reads near_clip / far_clip
    # An attached camera-to-world matrix (mi.Matrix4f) when ``<sensor>.to_world`` was
    # assigned a value with gradients (``to_world`` then holds its detached value): the
    # projective integrators differentiate the camera pose through it.
    to_world_ad = None
    needs_aperture_sample = False  # sample_ray takes a 2D aperture sample (thinlens)
    motion = None  # AnimatedTransform of a moving camera (None: static)

    def __init__(self, props: Props):
        self.film = HDRFilm(Props({"type": "hdrfilm"}, props.key("film")))
        self.sampler = IndependentSampler()
        for key, child in props.children():
            t = child["type"]
            if t in FILMS:
                self.film = FILMS[t](props.child(key))
            elif t in SAMPLERS:
                self.sampler = SAMPLERS[t](props.child(key))
            elif props.loader is not None and props.loader.is_medium(child):
                props.mark(key)  # the camera's medium: resolved by the loader
            else:
                raise props.error(key, f"unexpected {t!r} inside a sensor (expected a film or a sampler)")
        w, h = self.film.full_size
        self.aspect = w / h
        self.to_world = props.transform("to_world")
        self._shutter(props)
        self.film.set_exposure(self.shutter_close - self.shutter_open)
        for name in ("to_world", "to_world_end") if self.motion else ("to_world",):
            m = props.transform(name)
            lin = m[:3, :3]
            if self.rigid and not np.allclose(lin.T @ lin, np.eye(3), atol=1e-4):
                raise props.error(name, "the camera-to-world transform must be rigid (no scale or shear)")
        if self.clips:
            self.near_clip = props.float("near_clip", 1e-2, min=0.0)
            self.far_clip = props.float("far_clip", 1e4, min=0.0)
            if self.near_clip <= 0.0:
                raise props.error("near_clip", "must be greater than zero")
            if self.far_clip <= self.near_clip:
                raise props.error("far_clip", "must exceed near_clip")
        (cw, ch), (ox, oy) = self.film.size, self.film.crop_offset
        self._crop = (cw / w, ch / h, ox / w, oy / h)   # relative size and offset
        self._parameters(props)
        props.mark("srf")
        props.finish()

    def _shutter(self, props: Props) -> None:
        """The shutter interval (Mitsuba's or pbrt-v4's names; pbrt-v4's defaults [0, 1])
        and the camera's motion (``to_world_end``, ``transform_times``)."""
        for mi_name, pbrt_name in (("shutter_open", "shutteropen"), ("shutter_close", "shutterclose")):
            if props.has(mi_name) and props.has(pbrt_name):
                raise props.error(pbrt_name, f"give either {mi_name!r} (Mitsuba's) or {pbrt_name!r} (pbrt-v4's)")
        o = props.float("shutteropen" if props.has("shutteropen") else "shutter_open", 0.0)
        c = props.float("shutterclose" if props.has("shutterclose") else "shutter_close", 1.0)
        if c < o:
            raise props.error("shutterclose" if props.has("shutterclose") else "shutter_close",
                              f"the shutter closes ({c}) before it opens ({o})")
        self.shutter_open, self.shutter_close = o, c
        motion = read_motion(props, self.to_world)
        if motion is not None and c > o:
            self.motion = motion

    @property
    def pinhole(self) -> bool:
        """Whether this camera is a static pinhole."""
        return False

    def sample_time(self, u):
        """A ray time in the shutter interval from a uniform ``u``."""
        return dr.fma(u, self.shutter_close - self.shutter_open, self.shutter_open)

    def _frame(self, time=None):
        """(rows of the camera-to-world linear part, origin) at ray time ``time``: Python
        floats for a static camera (numpy scalars would pull arrays into numpy), Dr.Jit
        Floats for a moving one."""
        if self.motion is not None and time is not None:
            return self.motion.at(time)
        m = self.to_world.tolist()
        return [row[:3] for row in m[:3]], [m[0][3], m[1][3], m[2][3]]

    def _to_world(self, v, time=None, point=False):
        """Camera-space vector (or point) ``v`` in world space at ``time``."""
        lin, o = self._frame(time)
        r = [lin[k][0] * v.x + lin[k][1] * v.y + lin[k][2] * v.z for k in range(3)]
        return mi.Point3f(*[r[k] + o[k] for k in range(3)]) if point else mi.Vector3f(*r)

    # -- footprints of camera rays (MIP-mapped textures): pbrt-v4's Approximate_dp_dxy --
    def min_differentials(self):
        """pbrt-v4's ``FindMinimumDifferentials``: the smallest position and direction
        changes (camera space; directions in a frame whose z is the ray) of a one-pixel
        step along x and y, over 512 points on the film's diagonal, lens at its centre.
        Computed once (it evaluates rays: call it outside render kernels)."""
        if getattr(self, "_min_diff", None) is None:
            n = 512
            cw, ch = self.film.size
            t = np.linspace(0.0, 1.0, n)
            pos = mi.Point2f(mi.Float(t), mi.Float(t))
            ap = mi.Point2f(0.5, 0.5)
            tm = mi.Float(0.5 * (self.shutter_open + self.shutter_close))
            rays = [self.sample_ray(mi.Point2f(pos.x + dx, pos.y + dy), ap, tm)
                    for dx, dy in ((0.0, 0.0), (1.0 / cw, 0.0), (0.0, 1.0 / ch))]
            inv = np.linalg.inv(self.to_world)
            o = [np.broadcast_to(inv[:3, :3] @ np.array(r.o, np.float64).reshape(3, -1) + inv[:3, 3:], (3, n)).copy()
                 for r in rays]
            d = [np.broadcast_to(inv[:3, :3] @ np.array(r.d, np.float64).reshape(3, -1), (3, n)).copy() for r in rays]
            d = [x / np.linalg.norm(x, axis=0) for x in d]
            for oi, di in zip(o, d):     # origins back from the near plane to the lens plane z = 0
                ok = np.abs(di[2]) > 1e-6
                oi -= np.where(ok, di * (oi[2] / np.where(ok, di[2], 1.0)), 0.0)
            out = []
            for k in (1, 2):
                dpos = (o[k] - o[0]).T
                out.append(dpos[np.argmin(np.linalg.norm(dpos, axis=1))])
            for k in (1, 2):
                best = None
                for i in range(n):
                    loc = np.array(_rotate_z_to(d[0][:, i].tolist(), d[k][:, i].tolist(), inverse=True))
                    diff = loc / np.linalg.norm(loc) - np.array([0.0, 0.0, 1.0])
                    if best is None or np.linalg.norm(diff) < np.linalg.norm(best):
                        best = diff
                out.append(best)
            self._min_diff = [v.tolist() for v in out]   # pos x, pos y, dir x, dir y
        return self._min_diff

    def approximate_dp_dxy(self, p, n, spp: int):
        """(dp/dx, dp/dy): the change of the surface point ``p`` (normal ``n``, world
        space) under a one-pixel step of the camera ray, estimated from the camera's
        minimum differentials, scaled by max(1/8, 1/sqrt(spp)) (pbrt-v4's
        ``Approximate_dp_dxy``: no differentials are carried along paths). A moving camera
        is taken at its start transform."""
        pdx, pdy, ddx, ddy = self.min_differentials()
        lin, o = self._frame(None)
        inv = np.linalg.inv(np.asarray(self.to_world, np.float64)[:3, :3]).tolist()
        q = p - mi.Point3f(*o)
        pc = mi.Vector3f(*[inv[k][0] * q.x + inv[k][1] * q.y + inv[k][2] * q.z for k in range(3)])
        # Normals go to camera space with the transpose of the camera-to-world matrix.
        nc = mi.Vector3f(*[lin[0][k] * n.x + lin[1][k] * n.y + lin[2][k] * n.z for k in range(3)])
        dist = dr.norm(pc)
        w = list(pc / dr.maximum(dist, 1e-30))                # "down z": z along the camera ray
        nz = mi.Vector3f(*_rotate_z_to(w, list(nc), inverse=True))
        d = nz.z * dist
        scale = max(0.125, 1.0 / math.sqrt(max(spp, 1)))
        out = []
        for po, dd in ((pdx, ddx), (pdy, ddy)):
            ro = mi.Vector3f(*po)
            rd = mi.Vector3f(dd[0], dd[1], 1.0 + dd[2])
            t = -(dr.dot(nz, ro) - d) / dr.dot(nz, rd)
            hit = ro + rd * t - mi.Vector3f(0.0, 0.0, dist)
            v = mi.Vector3f(*_rotate_z_to(w, list(hit))) * scale
            out.append(mi.Vector3f(*[lin[k][0] * v.x + lin[k][1] * v.y + lin[k][2] * v.z for k in range(3)]))
        return out[0], out[1]

    def _parameters(self, props: Props) -> None:
        raise NotImplementedError

    def full_film(self, pos: mi.Point2f) -> mi.Point2f:
        """Position in the full film of crop-window position ``pos`` (both in [0, 1]^2)."""
        sx, sy, ox, oy = self._crop
        if (sx, sy, ox, oy) == (1.0, 1.0, 0.0, 0.0):
            return pos
        return mi.Point2f(dr.fma(pos.x, sx, ox), dr.fma(pos.y, sy, oy))

    def crop_film(self, pos: mi.Point2f) -> mi.Point2f:
        """Inverse of :meth:`full_film`."""
        sx, sy, ox, oy = self._crop
        if (sx, sy, ox, oy) == (1.0, 1.0, 0.0, 0.0):
            return pos
        return mi.Point2f((pos.x - ox) / sx, (pos.y - oy) / sy)

    @property
    def connectable(self) -> bool:
        """Whether light paths can connect to this camera (``sample_Wi``, ``pdf_We``):
        a static perspective camera, pinhole or thin lens."""
        return False

    # Light tracing needs the camera's importance; the perspective camera defines these.
    def We(self, ray):
        raise self._unsupported("importance evaluation (We)")

    def pdf_We(self, ray):
        raise self._unsupported("importance densities (pdf_We)")

    def sample_Wi(self, ref_p, u=None):
        raise self._unsupported("connections to the camera (sample_Wi)")

    def _unsupported(self, what: str):
        return NotImplementedError(f"the {self.name!r} camera does not support {what} (light-tracing "
                                   "integrators such as ptracer, lightpath, bdpt and mlt need a static "
                                   "'perspective' or 'thinlens' camera)")


def _rotate_z_to(w, v, inverse: bool = False):
    """``v`` rotated by the smallest rotation taking +z to unit ``w`` (pbrt-v4's
    ``RotateFromTo``), or by its inverse; components as lists (floats, NumPy or Dr.Jit)."""
    kx, ky, c = -w[1], w[0], w[2]          # k = z x w, c = z . w
    if inverse:
        kx, ky = -kx, -ky
    kv = [ky * v[2], -kx * v[2], kx * v[1] - ky * v[0]]
    kkv = [ky * kv[2], -kx * kv[2], kx * kv[1] - ky * kv[0]]
    inv = 1.0 / (1.0 + c) if isinstance(c, float) else dr.rcp(dr.maximum(1.0 + c, 1e-12))
    return [v[i] + kv[i] + kkv[i] * inv for i in range(3)]


@SENSORS.register("perspective")
class PerspectiveCamera(ProjectiveCamera):
    """``perspective``: Mitsuba 3's pinhole camera (same parameters and conventions); with
    pbrt-v4's ``lensradius`` > 0 a thin lens focused at ``focaldistance`` (the code of
    ``thinlens``). Nested: an ``hdrfilm``, an ``independent`` sampler and the medium the
    camera sits in.

    ========================  =========  ========  ==================================================
    name                      type       default   meaning
    ========================  =========  ========  ==================================================
    fov                       float      -         field of view (degrees) along fov_axis
    fov_axis                  string     'x'       'x', 'y', 'diagonal', 'smaller' or 'larger'
    focal_length              string     '50mm'    without fov: a 35 mm equivalent (Mitsuba's default)
    to_world                  transform  identity  camera-to-world (rigid; the camera looks down +z)
    near_clip                 float      0.01      near clip distance
    far_clip                  float      10000     far clip distance
    principal_point_offset_x  float      0         shift of the image centre (fraction of the width)
    principal_point_offset_y  float      0         shift of the image centre (fraction of the height)
    lensradius                float      0         pbrt-v4's thin-lens aperture radius (0: a pinhole)
    focaldistance             float      1e6       pbrt-v4's distance of the plane in focus
    shutter_open              float      0         shutter opening time (pbrt-v4: ``shutteropen``)
    shutter_close             float      1         shutter closing time (pbrt-v4: ``shutterclose``)
    to_world_end              transform  -         camera-to-world at transform_times[1] (motion blur)
    transform_times           float[2]   [0, 1]    times of to_world and to_world_end
    ========================  =========  ========  ==================================================
    """

    name = "perspective"

    def _parameters(self, props: Props) -> None:
        self.x_fov = _x_fov(props, self.aspect)
        self.pp = (props.float("principal_point_offset_x", 0.0), props.float("principal_point_offset_y", 0.0))
        props.mark("focus_distance")
        self.aperture_radius = props.float("lensradius", 0.0, min=0.0)
        self.focus_distance = props.float("focaldistance", 1e6, min=1e-6)
        self.needs_aperture_sample = self.aperture_radius > 0.0

    @property
    def pinhole(self) -> bool:
        return self.motion is None and not self.needs_aperture_sample

    def _near_point(self, pos: mi.Point2f) -> mi.Vector3f:
        """Camera-space point on the plane z = 1 seen at crop-window position ``pos``."""
        pos = self.full_film(pos)
        tx = math.tan(math.radians(self.x_fov) / 2)
        x = (1.0 - 2.0 * (pos.x + self.pp[0])) * tx
        y = (1.0 - 2.0 * (pos.y + self.pp[1])) * tx / self.aspect
        return mi.Vector3f(x, y, 1.0)

    def _ray(self, o_local, d: mi.Vector3f, time=None) -> mi.Ray3f:
        """World ray at ``time`` from camera-space origin ``o_local`` (None: the pinhole)
        along unit camera-space ``d``, clipped to [near_clip, far_clip] in depth (Mitsuba's)."""
        lin, o = self._frame(time)
        dw = mi.Vector3f(*[lin[r][0] * d.x + lin[r][1] * d.y + lin[r][2] * d.z for r in range(3)])
        inv_z = dr.rcp(d.z)
        near_t, far_t = self.near_clip * inv_z, self.far_clip * inv_z
        o = mi.Point3f(*o)
        if o_local is not None:
            o += mi.Vector3f(*[lin[r][0] * o_local.x + lin[r][1] * o_local.y for r in range(3)])
        return mi.Ray3f(o + dw * near_t, dw, far_t - near_t, 0.0 if time is None else time, mi.Spectrum(0))

    def _lens_ray(self, pos, aperture, time):
        """Thin lens: the ray from a point of the aperture disk (radius ``aperture_radius``)
        through the point of the focus plane (z = ``focus_distance``) the pinhole ray meets."""
        if aperture is None:
            raise self._unsupported("rays without an aperture sample")
        near_p = self._near_point(pos)
        lens = square_to_uniform_disk_concentric(aperture) * self.aperture_radius
        focus = near_p * self.focus_distance
        d = dr.normalize(mi.Vector3f(focus.x - lens.x, focus.y - lens.y, focus.z))
        return self._ray(lens, d, time)

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None, time=None) -> mi.Ray3f:
        """Primary ray through crop-window position ``pos`` in [0,1]^2 (x right, y down) at
        ray time ``time`` (None: the shutter's opening); ``aperture`` (a 2D sample) is used
        with a lens only."""
        if self.needs_aperture_sample:
            return self._lens_ray(pos, aperture, time)
        return self._ray(None, dr.normalize(self._near_point(pos)), time)

    def sample_ray_attached(self, pos: mi.Point2f) -> mi.Ray3f:
        """:meth:`sample_ray` from the attached ``to_world_ad`` (call under
        ``dr.resume_grad``): the ray's origin and direction carry the camera pose's
        derivatives."""
        m = self.to_world_ad
        d = dr.normalize(self._near_point(pos))
        dw = mi.Vector3f(*[m[r][0] * d.x + m[r][1] * d.y + m[r][2] * d.z for r in range(3)])
        inv_z = dr.rcp(d.z)
        near_t, far_t = self.near_clip * inv_z, self.far_clip * inv_z
        o = mi.Point3f(m[0][3], m[1][3], m[2][3])
        return mi.Ray3f(o + dw * near_t, dw, far_t - near_t, 0.0, mi.Spectrum(0))

    # -- importance (light tracing, BDPT): pbrt-v4's We, PDF_We, SampleWi ------------------
    def _tan_x(self) -> float:
        return math.tan(math.radians(self.x_fov) / 2)

    def film_area(self) -> float:
        """Area A of the (cropped) film's image on the plane z = 1 in camera space."""
        t = self._tan_x()
        return 4.0 * t * t / self.aspect * self._crop[0] * self._crop[1]

    def _local(self, v):
        """World vector -> camera space (the frame is rigid: its transpose inverts it)."""
        m = self.to_world.tolist()
        return mi.Vector3f(*[m[0][k] * v.x + m[1][k] * v.y + m[2][k] * v.z for k in range(3)])

    def film_position(self, local_d):
        """(film position in [0,1]^2 (x right, y down) of camera-space direction
        ``local_d``, whether it lies on the film): the inverse of ``sample_ray``."""
        t = self._tan_x()
        inv_z = dr.rcp(local_d.z)
        px = 0.5 * (1.0 - local_d.x * inv_z / t) - self.pp[0]
        py = 0.5 * (1.0 - local_d.y * inv_z * (self.aspect / t)) - self.pp[1]
        pos = self.crop_film(mi.Point2f(px, py))
        inside = (local_d.z > 0) & (pos.x >= 0) & (pos.x <= 1) & (pos.y >= 0) & (pos.y <= 1)
        return pos, inside

    @property
    def connectable(self) -> bool:
        return self.motion is None

    def lens_area(self) -> float:
        """Area of the aperture disk (pbrt-v4's ``lensArea``; 1 for a pinhole, whose
        position is a delta)."""
        return math.pi * self.aperture_radius ** 2 if self.needs_aperture_sample else 1.0

    def _check_connectable(self):
        if not self.connectable:
            raise self._unsupported("importance (a moving camera)")

    def _lens_film(self, o_local, d_local):
        """(film position, on the film) of the camera-space ray from ``o_local`` along
        ``d_local`` through a thin lens: the film point that sees the ray's point on the
        plane in focus (z = ``focus_distance``), which every ray of that film point
        crosses."""
        t = (self.focus_distance - o_local.z) * dr.rcp(d_local.z)
        focus = mi.Vector3f(o_local.x + d_local.x * t, o_local.y + d_local.y * t, self.focus_distance)
        pos, inside = self.film_position(focus)
        return pos, inside & (d_local.z > 0)

    def _ray_film(self, ray):
        """(camera-space unit direction, film position, on the film) of the world ray
        ``ray`` leaving the camera (a pinhole: its direction alone decides)."""
        local = self._local(ray.d)
        if not self.needs_aperture_sample:
            pos, inside = self.film_position(local)
            return local, pos, inside
        m = self.to_world.tolist()
        o_local = self._local(ray.o - mi.Point3f(m[0][3], m[1][3], m[2][3]))
        pos, inside = self._lens_film(o_local, local)
        return local, pos, inside

    def lens_point(self, ray):
        """World point where camera ray ``ray`` (from :meth:`sample_ray`, which starts it at
        the near clip plane) leaves the lens: the pinhole, or its point on the aperture
        disk (camera z = 0)."""
        m = self.to_world.tolist()
        o = mi.Point3f(m[0][3], m[1][3], m[2][3])
        if not self.needs_aperture_sample:
            return o
        back = self._local(ray.o - o).z * dr.rcp(self._local(ray.d).z)
        return mi.Point3f(ray.o - ray.d * back)

    def We(self, ray):
        """(importance We, film position) of a ray leaving the camera along ``ray.d`` (from
        its lens point, or any point of it, with a thin lens).
        Units: the importance is ``1 / (A lens_area cos^4 theta)``, so that int We cos theta
        d omega dA_lens over the film and the lens is 1 and a light-traced image matches the
        camera-traced one (pbrt-v4's normalisation; a pinhole's lens is a delta in position,
        of area 1; Mitsuba returns We cos theta)."""
        self._check_connectable()
        local, pos, inside = self._ray_film(ray)
        cos = local.z * dr.rsqrt(dr.squared_norm(local))
        c2 = cos * cos
        den = self.film_area() * c2 * c2
        if self.needs_aperture_sample:
            den = den * self.lens_area()
        return dr.select(inside, dr.rcp(den), 0.0), pos

    def pdf_We(self, ray):
        """(pdf_pos, pdf_dir) of ``sample_ray`` producing ``ray``: ``1 / lens_area`` (1: the
        pinhole, a delta in position) and the solid-angle density ``1 / (A cos^3 theta)`` of
        a uniform film position (with a lens too: the focus-plane point is uniform over an
        area A focus_distance^2)."""
        self._check_connectable()
        local, _, inside = self._ray_film(ray)
        cos = local.z * dr.rsqrt(dr.squared_norm(local))
        pdf_pos = mi.Float(1.0 / self.lens_area()) if self.needs_aperture_sample else mi.Float(1.0)
        return pdf_pos, dr.select(inside, dr.rcp(self.film_area() * cos * cos * cos), 0.0)

    def sample_Wi(self, ref_p, u=None) -> "CameraWiSample":
        """Connect point ``ref_p`` to the camera (pbrt-v4's ``SampleWi``): a point ``p`` of
        the lens (the pinhole; with a thin lens uniform on the aperture disk from the 2D
        sample ``u``), the importance ``We`` of the ray from ``p`` toward ``ref_p``, unit
        direction ``wi`` from ``ref_p`` to ``p``, ``pdf`` = dist^2 / (cos theta lens_area)
        (solid angle at ``ref_p``), film position ``pos``, and ``valid``: in front of the
        camera, between the clip planes (in depth, as Mitsuba) and on the film. A surface
        vertex's contribution is ``beta * f(wi) |cos| * We / pdf``."""
        self._check_connectable()
        m = self.to_world.tolist()
        p = mi.Point3f(m[0][3], m[1][3], m[2][3])
        lens = self.needs_aperture_sample
        if lens:
            if u is None:
                raise self._unsupported("connections without a lens sample")
            disk = square_to_uniform_disk_concentric(u) * self.aperture_radius
            lens_local = mi.Vector3f(disk.x, disk.y, 0.0)
            p = p + mi.Vector3f(*[m[r][0] * disk.x + m[r][1] * disk.y for r in range(3)])
        d = p - ref_p
        dist2 = dr.squared_norm(d)
        inv_dist = dr.rsqrt(dist2)
        wi = d * inv_dist
        local = self._local(-d)
        if lens:
            pos, inside = self._lens_film(lens_local, local)
        else:
            pos, inside = self.film_position(local)
        valid = inside & (local.z >= self.near_clip) & (local.z <= self.far_clip) & (dist2 > 0)
        cos = local.z * inv_dist
        c2 = cos * cos
        if lens:
            area = self.lens_area()
            We = dr.select(valid, dr.rcp(self.film_area() * area * c2 * c2), 0.0)
            pdf = dr.select(valid, dist2 / (cos * area), 0.0)
        else:
            We = dr.select(valid, dr.rcp(self.film_area() * c2 * c2), 0.0)
            pdf = dr.select(valid, dist2 / cos, 0.0)
        return CameraWiSample(We, wi, pdf, pos, p, valid)


@SENSORS.register("thinlens")
class ThinLensCamera(PerspectiveCamera):
    """``thinlens``: Mitsuba 3's thin-lens camera: a perspective camera whose rays leave
    a disk-shaped aperture and meet in the plane at ``focus_distance`` (depth of field).
    Nested as in ``perspective``. Light-tracing integrators (``ptracer``, ``bdpt``,
    ``mlt``) connect to it through its lens (``sample_Wi``) when it does not move.

    ========================  =========  ==========  ==============================================
    name                      type       default     meaning
    ========================  =========  ==========  ==============================================
    aperture_radius           float      -           radius of the lens aperture (required)
    focus_distance            float      far_clip    distance of the plane in focus
    fov                       float      -           field of view (degrees) along fov_axis
    fov_axis                  string     'x'         'x', 'y', 'diagonal', 'smaller' or 'larger'
    focal_length              string     '50mm'      without fov: a 35 mm equivalent (Mitsuba's)
    to_world                  transform  identity    camera-to-world (rigid)
    near_clip                 float      0.01        near clip distance
    far_clip                  float      10000       far clip distance
    shutter_open              float      0           shutter opening time
    shutter_close             float      1           shutter closing time
    to_world_end              transform  -           camera-to-world at transform_times[1]
    transform_times           float[2]   [0, 1]      times of to_world and to_world_end
    ========================  =========  ==========  ==============================================
    """

    name = "thinlens"
    needs_aperture_sample = True

    def _parameters(self, props: Props) -> None:
        self.x_fov = _x_fov(props, self.aspect)
        self.pp = (0.0, 0.0)
        self.aperture_radius = props.float("aperture_radius", min=0.0)
        if self.aperture_radius == 0.0:   # Mitsuba warns and uses the float epsilon
            self.aperture_radius = float(np.finfo(np.float32).eps)
        self.focus_distance = props.float("focus_distance", self.far_clip, valid=Range(0.0, open_lo=True))


@SENSORS.register("orthographic")
class OrthographicCamera(ProjectiveCamera):
    """``orthographic``: Mitsuba 3's orthographic camera: parallel rays along the camera's
    +z through the rectangle [-1, 1] x [-1/aspect, 1/aspect] of the near plane, mapped by
    ``to_world`` (which may scale, to size the view). Nested as in ``perspective``.
    Camera-ray integrators only (light tracing needs a pinhole).

    =========  =========  ========  ==========================================================
    name       type       default   meaning
    =========  =========  ========  ==========================================================
    to_world   transform  identity  camera-to-world (scale sets the extent of the view)
    near_clip  float      0.01      near clip distance (rays start on this plane)
    far_clip   float      10000     far clip distance
    =========  =========  ========  ==========================================================

    The shutter and motion parameters of ``perspective`` (``shutter_open``,
    ``shutter_close``, ``to_world_end``, ``transform_times``) apply too.
    """

    name = "orthographic"
    rigid = False

    def _parameters(self, props: Props) -> None:
        pass

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None, time=None) -> mi.Ray3f:
        """Ray through crop-window position ``pos`` in [0,1]^2 (x right, y down) at ``time``."""
        pos = self.full_film(pos)
        x = 1.0 - 2.0 * pos.x
        y = (1.0 - 2.0 * pos.y) / self.aspect
        lin, t = self._frame(time)
        o = mi.Point3f(*[lin[r][0] * x + lin[r][1] * y + (lin[r][2] * self.near_clip + t[r]) for r in range(3)])
        d = dr.normalize(mi.Vector3f(*[lin[r][2] for r in range(3)]))
        return mi.Ray3f(o, d, self.far_clip - self.near_clip, 0.0 if time is None else time, mi.Spectrum(0))


def equal_area_square_to_sphere(u, v):
    """Clarberg's equal-area map of the unit square onto the sphere (pbrt-v4's
    ``EqualAreaSquareToSphere``), as (x, y, z) Dr.Jit Floats: the square's centre maps to
    +z, its corners to -z; equal areas of the square are equal solid angles."""
    a, b = 2.0 * u - 1.0, 2.0 * v - 1.0
    ap, bp = dr.abs(a), dr.abs(b)
    sd = 1.0 - (ap + bp)
    r = 1.0 - dr.abs(sd)
    phi = dr.select(r == 0.0, 1.0, (bp - ap) / dr.maximum(r, 1e-30) + 1.0) * (math.pi / 4.0)
    z = dr.copysign(1.0 - r * r, sd)
    cos_phi, sin_phi = dr.copysign(dr.cos(phi), a), dr.copysign(dr.sin(phi), b)
    s = r * dr.safe_sqrt(2.0 - r * r)
    return cos_phi * s, sin_phi * s, z


def wrap_equal_area_square(u, v):
    """pbrt-v4's ``WrapEqualAreaSquare``: positions just outside the unit square (filter
    offsets past the film's edge) mirrored back to the neighbouring part of the sphere."""
    flip_x = (u < 0.0) | (u > 1.0)
    u = dr.select(u < 0.0, -u, dr.select(u > 1.0, 2.0 - u, u))
    v = dr.select(flip_x, 1.0 - v, v)
    flip_y = (v < 0.0) | (v > 1.0)
    v = dr.select(v < 0.0, -v, dr.select(v > 1.0, 2.0 - v, v))
    u = dr.select(flip_y, 1.0 - u, u)
    return u, v


@SENSORS.register("spherical")
class SphericalCamera(ProjectiveCamera):
    """``spherical`` (pbrt-v4's): a camera that sees every direction around its position,
    mapped to the film by ``mapping``: 'equalarea' (Clarberg's equal-area square-sphere
    map: every pixel covers 4 pi / (width height) steradians; a square film) or
    'equirectangular' (latitude-longitude: the film's x is the azimuth phi = 2 pi x, its
    y the polar angle theta = pi y from the camera's +y (up)). Camera space is that of the
    other cameras (+z forward, +y up, image x toward -x): pbrt-v4's directions with x
    negated, so that a pbrt-v4 camera transform converted as for ``perspective`` gives
    pbrt-v4's image. Rays start at the camera (no clip planes). Nested as in
    ``perspective``.

    ===============  =========  ===========  ==============================================
    name             type       default      meaning
    ===============  =========  ===========  ==============================================
    mapping          string     'equalarea'  'equalarea' or 'equirectangular'
    to_world         transform  identity     camera-to-world (rigid)
    shutter_open     float      0            shutter opening time (pbrt-v4: ``shutteropen``)
    shutter_close    float      1            shutter closing time (pbrt-v4: ``shutterclose``)
    to_world_end     transform  -            camera-to-world at transform_times[1]
    transform_times  float[2]   [0, 1]       times of to_world and to_world_end
    ===============  =========  ===========  ==============================================
    """

    name = "spherical"
    clips = False
    near_clip, far_clip = 0.0, float("inf")

    def _parameters(self, props: Props) -> None:
        self.mapping = props.string("mapping", "equalarea", choices=("equalarea", "equirectangular"))
        props.mark("lensradius", "focaldistance", "frameaspectratio", "screenwindow")  # pbrt-v4 ignores them too

    def direction(self, pos: mi.Point2f) -> mi.Vector3f:
        """Camera-space unit direction seen at full-film position ``pos`` in [0,1]^2."""
        if self.mapping == "equirectangular":
            theta, phi = math.pi * pos.y, 2.0 * math.pi * pos.x
            st, ct = dr.sincos(theta)
            sp, cp = dr.sincos(phi)
            x, y, z = st * cp, st * sp, ct
        else:
            x, y, z = equal_area_square_to_sphere(*wrap_equal_area_square(pos.x, pos.y))
        return mi.Vector3f(-x, z, y)     # pbrt-v4 swaps y and z; x negated (see above)

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None, time=None) -> mi.Ray3f:
        """Ray through crop-window position ``pos`` in [0,1]^2 (x right, y down) at ``time``."""
        d = self._to_world(self.direction(self.full_film(pos)), time)
        lin, o = self._frame(time)
        return mi.Ray3f(mi.Point3f(*o), d, dr.inf, 0.0 if time is None else time, mi.Spectrum(0))


@SENSORS.register("realistic")
class RealisticCamera(ProjectiveCamera):
    """``realistic`` (pbrt-v4's): a camera behind a lens system read from a lens file
    (pbrt-v4's format: radius, thickness, index of refraction, aperture diameter per
    interface, in mm), focused at ``focusdistance`` by pbrt-v4's thick-lens approximation;
    rays start on the physical film (its ``diagonal``, 35 mm by default, from the film),
    aim at the exit pupil (bounded per radial film segment) and are traced through the
    elements; each carries pbrt-v4's weight cos^4(theta) / (pdf * rear distance^2)
    (vignetting and the pupil's solid angle: images are brighter or darker than a pinhole's,
    as in pbrt-v4). Camera-ray integrators only; no derivatives. Nested as in
    ``perspective`` (the film may be pbrt-v4's ``rgb`` with ``diagonal``).

    ================  =========  ========  ==================================================
    name              type       default   meaning
    ================  =========  ========  ==================================================
    lensfile          string     -         the lens description file (required)
    aperturediameter  float      1         diameter of the aperture stop (mm), at most the
                                           file's
    focusdistance     float      10        distance of the plane in focus (m)
    to_world          transform  identity  camera-to-world (rigid)
    shutteropen       float      0         shutter opening time (also ``shutter_open``)
    shutterclose      float      1         shutter closing time (also ``shutter_close``)
    to_world_end      transform  -         camera-to-world at transform_times[1]
    transform_times   float[2]   [0, 1]    times of to_world and to_world_end
    ================  =========  ========  ==================================================
    """

    name = "realistic"
    clips = False
    near_clip, far_clip = 0.0, float("inf")
    needs_aperture_sample = True
    weights_rays = True

    def _parameters(self, props: Props) -> None:
        if props.has("aperture"):
            raise props.error("aperture", "custom aperture shapes are not supported (a circular stop only)")
        path = props.string("lensfile")
        if props.loader is not None:
            path = props.loader.resolve_path(path, props.key("lensfile"))
        try:
            rows = read_lens_file(path)
        except (OSError, ValueError) as e:
            raise props.error("lensfile", f"cannot read lens file {path!r}: {e}") from None
        aperture = props.float("aperturediameter", 1.0, min=1e-6)
        focus = props.float("focusdistance", 10.0, min=1e-6)
        self.diagonal = float(getattr(self.film, "diagonal", 35.0)) / 1000.0
        self.lens = LensSystem(rows, aperture)
        try:
            self.lens.focus(focus, self.diagonal)
        except ValueError as e:
            raise props.error("focusdistance", str(e)) from None
        w, h = self.film.full_size
        a = h / w
        x = math.sqrt(self.diagonal ** 2 / (1.0 + a * a))
        self.extent = (x, a * x)
        bounds = self.lens.exit_pupil_bounds(self.diagonal)
        if all(b is None for b in bounds):
            raise props.error("lensfile", "no ray from the film passes the lens system")
        self._n_seg = len(bounds)
        self._bounds = [mi.Float([b[k] if b else 0.0 for b in bounds]) for k in range(4)]
        self._has = mi.Bool([b is not None for b in bounds])

    def sample_ray_weighted(self, pos: mi.Point2f, aperture: mi.Point2f | None = None, time=None):
        """(ray, weight) through crop-window position ``pos`` from the lens sample ``aperture``
        (pbrt-v4's ``GenerateRay``; weight 0 where the lens system stops the ray)."""
        if aperture is None:
            raise self._unsupported("rays without a lens sample")
        s = self.full_film(pos)
        ex, ey = self.extent
        fx, fy = -(-ex / 2.0 + s.x * ex), -ey / 2.0 + s.y * ey     # pbrt-v4's film point (x mirrored)
        r = dr.sqrt(fx * fx + fy * fy)
        seg = dr.minimum(mi.UInt32(r / (self.diagonal / 2.0) * self._n_seg), self._n_seg - 1)
        b = [dr.gather(mi.Float, t, seg) for t in self._bounds]
        ok = dr.gather(mi.Bool, self._has, seg)
        lx, ly = dr.lerp(b[0], b[2], aperture.x), dr.lerp(b[1], b[3], aperture.y)
        area = (b[2] - b[0]) * (b[3] - b[1])
        sin_t = dr.select(r > 0.0, fy / dr.maximum(r, 1e-30), 0.0)
        cos_t = dr.select(r > 0.0, fx / dr.maximum(r, 1e-30), 1.0)
        pupil = mi.Point3f(cos_t * lx - sin_t * ly, sin_t * lx + cos_t * ly, self.lens.rear_z)
        o_film = mi.Point3f(fx, fy, 0.0)
        d_film = pupil - o_film
        o, d, passed = self.lens.trace_from_film(o_film, d_film, ok)
        ok &= passed & (area > 0.0)
        cos = dr.normalize(d_film).z
        c2 = cos * cos
        weight = dr.select(ok, c2 * c2 * area / (self.lens.rear_z ** 2), 0.0)
        # pbrt-v4's camera space -> pbr's (image x toward -x): x mirrored.
        o_cam = dr.select(ok, mi.Vector3f(-o.x, o.y, o.z), mi.Vector3f(0.0))
        d_cam = dr.select(ok, dr.normalize(mi.Vector3f(-d.x, d.y, d.z)), mi.Vector3f(0.0, 0.0, 1.0))
        ray = mi.Ray3f(self._to_world(o_cam, time, point=True), self._to_world(d_cam, time), dr.inf,
                       0.0 if time is None else time, mi.Spectrum(0))
        return ray, weight

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None, time=None) -> mi.Ray3f:
        """The ray of :meth:`sample_ray_weighted` (its weight dropped)."""
        return self.sample_ray_weighted(pos, aperture, time)[0]


class CameraWiSample(Struct):
    """Result of :meth:`PerspectiveCamera.sample_Wi` (fields documented there)."""

    _fields = {"We": "Float", "wi": "Vector3f", "pdf": "Float", "pos": "Point2f", "p": "Point3f", "valid": "Bool"}

