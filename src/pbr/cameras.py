"""Mitsuba 3's cameras: ``perspective`` (pinhole), ``thinlens`` (depth of field) and
``orthographic``, with the same parameters and conventions.

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
from .films import HDRFilm
from .samplers import SAMPLERS, IndependentSampler
from .sampling import square_to_uniform_disk_concentric
from .plugins.props import Props
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
    the medium the camera sits in, ``to_world`` and the clip distances. Subclasses read
    their own parameters in ``_parameters(props)`` and call ``props.finish()``."""

    medium = 0  # index + 1 of the medium the camera sits in (0: vacuum)
    rigid = True  # the camera-to-world transform must be rigid
    # An attached camera-to-world matrix (mi.Matrix4f) when ``<sensor>.to_world`` was
    # assigned a value with gradients (``to_world`` then holds its detached value): the
    # projective integrators differentiate the camera pose through it.
    to_world_ad = None
    needs_aperture_sample = False  # sample_ray takes a 2D aperture sample (thinlens)

    def __init__(self, props: Props):
        self.film = HDRFilm(Props({"type": "hdrfilm"}, props.key("film")))
        self.sampler = IndependentSampler()
        for key, child in props.children():
            t = child["type"]
            if t == "hdrfilm":
                self.film = HDRFilm(props.child(key))
            elif t in SAMPLERS:
                self.sampler = SAMPLERS[t](props.child(key))
            elif props.loader is not None and props.loader.is_medium(child):
                props.mark(key)  # the camera's medium: resolved by the loader
            elif t in ("independent", "stratified", "multijitter", "orthogonal", "ldsampler"):
                raise props.error(key, f"sampler {t!r} is not supported yet (supported: independent)")
            else:
                raise props.error(key, f"unexpected {t!r} inside a sensor (expected a film or a sampler)")
        w, h = self.film.full_size
        self.aspect = w / h
        self.to_world = props.transform("to_world")
        if self.rigid:
            lin = self.to_world[:3, :3]
            if not np.allclose(lin.T @ lin, np.eye(3), atol=1e-4):
                raise props.error("to_world", "the camera-to-world transform must be rigid (no scale or shear)")
        self.near_clip = props.float("near_clip", 1e-2, min=0.0)
        self.far_clip = props.float("far_clip", 1e4, min=0.0)
        if self.near_clip <= 0.0:
            raise props.error("near_clip", "must be greater than zero")
        if self.far_clip <= self.near_clip:
            raise props.error("far_clip", "must exceed near_clip")
        (cw, ch), (ox, oy) = self.film.size, self.film.crop_offset
        self._crop = (cw / w, ch / h, ox / w, oy / h)   # relative size and offset
        self._parameters(props)
        props.mark("shutter_open", "shutter_close", "srf")
        props.finish()

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

    # Light tracing needs a pinhole's importance; the pinhole camera defines these.
    def We(self, ray):
        raise self._unsupported("importance evaluation (We)")

    def pdf_We(self, ray):
        raise self._unsupported("importance densities (pdf_We)")

    def sample_Wi(self, ref_p, u=None):
        raise self._unsupported("connections to the camera (sample_Wi)")

    def _unsupported(self, what: str):
        return NotImplementedError(f"the {self.name!r} camera does not support {what} (light-tracing "
                                   "integrators such as ptracer, lightpath and bdpt need a 'perspective' camera)")


@SENSORS.register("perspective")
class PerspectiveCamera(ProjectiveCamera):
    """``perspective``: Mitsuba 3's pinhole camera (same parameters and conventions). Nested:
    an ``hdrfilm``, an ``independent`` sampler and the medium the camera sits in.

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
    ========================  =========  ========  ==================================================
    """

    name = "perspective"

    def _parameters(self, props: Props) -> None:
        self.x_fov = _x_fov(props, self.aspect)
        self.pp = (props.float("principal_point_offset_x", 0.0), props.float("principal_point_offset_y", 0.0))
        props.mark("focus_distance")

    def _near_point(self, pos: mi.Point2f) -> mi.Vector3f:
        """Camera-space point on the plane z = 1 seen at crop-window position ``pos``."""
        pos = self.full_film(pos)
        tx = math.tan(math.radians(self.x_fov) / 2)
        x = (1.0 - 2.0 * (pos.x + self.pp[0])) * tx
        y = (1.0 - 2.0 * (pos.y + self.pp[1])) * tx / self.aspect
        return mi.Vector3f(x, y, 1.0)

    def _ray(self, o_local, d: mi.Vector3f) -> mi.Ray3f:
        """World ray from camera-space origin ``o_local`` (None: the pinhole) along unit
        camera-space ``d``, clipped to [near_clip, far_clip] in depth (Mitsuba's)."""
        m = self.to_world.tolist()  # Python floats: numpy scalars would pull arrays into numpy
        dw = mi.Vector3f(*[m[r][0] * d.x + m[r][1] * d.y + m[r][2] * d.z for r in range(3)])
        inv_z = dr.rcp(d.z)
        near_t, far_t = self.near_clip * inv_z, self.far_clip * inv_z
        o = mi.Point3f(m[0][3], m[1][3], m[2][3])
        if o_local is not None:
            o += mi.Vector3f(*[m[r][0] * o_local.x + m[r][1] * o_local.y for r in range(3)])
        return mi.Ray3f(o + dw * near_t, dw, far_t - near_t, 0.0, mi.Spectrum(0))

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None) -> mi.Ray3f:
        """Primary ray through crop-window position ``pos`` in [0,1]^2 (x right, y down);
        ``aperture`` (a 2D sample) is unused by a pinhole."""
        return self._ray(None, dr.normalize(self._near_point(pos)))

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

    def We(self, ray):
        """(importance We, film position) of a ray leaving the camera along ``ray.d``.
        Units: the pinhole's importance is a delta in position (density 1) times
        ``1 / (A cos^4 theta)``, so that int We cos theta d omega over the film is 1 and a
        light-traced image matches the camera-traced one (pbrt-v4's normalisation; Mitsuba
        returns We cos theta)."""
        local = self._local(ray.d)
        cos = local.z * dr.rsqrt(dr.squared_norm(local))
        pos, inside = self.film_position(local)
        c2 = cos * cos
        return dr.select(inside, dr.rcp(self.film_area() * c2 * c2), 0.0), pos

    def pdf_We(self, ray):
        """(pdf_pos, pdf_dir) of ``sample_ray`` producing ``ray``: 1 (the pinhole, a delta in
        position) and the solid-angle density ``1 / (A cos^3 theta)`` of a uniform film position."""
        local = self._local(ray.d)
        cos = local.z * dr.rsqrt(dr.squared_norm(local))
        _, inside = self.film_position(local)
        return mi.Float(1.0), dr.select(inside, dr.rcp(self.film_area() * cos * cos * cos), 0.0)

    def sample_Wi(self, ref_p, u=None) -> "CameraWiSample":
        """Connect point ``ref_p`` to the camera (pbrt-v4's ``SampleWi``): importance ``We``
        of the ray from the pinhole toward ``ref_p``, unit direction ``wi`` from ``ref_p`` to
        the pinhole, ``pdf`` = dist^2 / cos theta (solid angle at ``ref_p``), film position
        ``pos``, the pinhole ``p``, and ``valid``: in front of the camera, between the
        clip planes (in depth, as Mitsuba) and on the film. ``u`` is unused (a pinhole).
        A surface vertex's contribution is ``beta * f(wi) |cos| * We / pdf``."""
        m = self.to_world.tolist()
        p = mi.Point3f(m[0][3], m[1][3], m[2][3])
        d = p - ref_p
        dist2 = dr.squared_norm(d)
        inv_dist = dr.rsqrt(dist2)
        wi = d * inv_dist
        local = self._local(-d)
        pos, inside = self.film_position(local)
        valid = inside & (local.z >= self.near_clip) & (local.z <= self.far_clip) & (dist2 > 0)
        cos = local.z * inv_dist
        c2 = cos * cos
        We = dr.select(valid, dr.rcp(self.film_area() * c2 * c2), 0.0)
        pdf = dr.select(valid, dist2 / cos, 0.0)
        return CameraWiSample(We, wi, pdf, pos, p, valid)


@SENSORS.register("thinlens")
class ThinLensCamera(PerspectiveCamera):
    """``thinlens``: Mitsuba 3's thin-lens camera: a perspective camera whose rays leave
    a disk-shaped aperture and meet in the plane at ``focus_distance`` (depth of field).
    Nested as in ``perspective``. Camera-ray integrators only (light tracing needs a
    pinhole).

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
        self.focus_distance = props.float("focus_distance", self.far_clip, min=0.0)

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None) -> mi.Ray3f:
        """Ray through crop-window position ``pos`` from aperture sample ``aperture``."""
        if aperture is None:
            raise self._unsupported("rays without an aperture sample")
        near_p = self._near_point(pos)
        lens = square_to_uniform_disk_concentric(aperture) * self.aperture_radius
        focus = near_p * self.focus_distance
        d = dr.normalize(mi.Vector3f(focus.x - lens.x, focus.y - lens.y, focus.z))
        return self._ray(lens, d)

    # A lens is not a pinhole: no importance for light tracing (ProjectiveCamera's refusals).
    We, pdf_We, sample_Wi = ProjectiveCamera.We, ProjectiveCamera.pdf_We, ProjectiveCamera.sample_Wi


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
    """

    name = "orthographic"
    rigid = False

    def _parameters(self, props: Props) -> None:
        m = self.to_world
        d = m[:3, 2] / np.linalg.norm(m[:3, 2])
        self._dir = d.tolist()

    def sample_ray(self, pos: mi.Point2f, aperture: mi.Point2f | None = None) -> mi.Ray3f:
        """Ray through crop-window position ``pos`` in [0,1]^2 (x right, y down)."""
        pos = self.full_film(pos)
        x = 1.0 - 2.0 * pos.x
        y = (1.0 - 2.0 * pos.y) / self.aspect
        m = self.to_world.tolist()
        o = mi.Point3f(*[m[r][0] * x + m[r][1] * y + (m[r][2] * self.near_clip + m[r][3]) for r in range(3)])
        return mi.Ray3f(o, mi.Vector3f(*self._dir), self.far_clip - self.near_clip, 0.0, mi.Spectrum(0))


class CameraWiSample(Struct):
    """Result of :meth:`PerspectiveCamera.sample_Wi` (fields documented there)."""

    _fields = {"We": "Float", "wi": "Vector3f", "pdf": "Float", "pos": "Point2f", "p": "Point3f", "valid": "Bool"}

