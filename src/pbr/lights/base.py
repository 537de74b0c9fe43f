"""The light interface (one family per module, vectorised over its instances).

``sample_Li(idx, ref, u, wl, active)`` returns a :class:`LightSample`: radiance ``L``
arriving at ``ref`` from a sampled point of the light, the world direction ``wi`` toward it,
its solid-angle density ``pdf`` (excluding the light sampler's pick probability), the
point ``p`` to trace a shadow ray to, and ``delta`` for lights that are Dirac deltas in
position or direction (no MIS with BSDF sampling). ``pdf_Li`` gives the same density for a
surface point (area lights) or a direction (infinite lights) found by BSDF sampling.
``L`` is the radiance an area light emits at a surface hit; ``Le`` the radiance an
infinite light sends along an escaped ray.

Below the interface: the helpers several families share (emission spectra, photometric
``scale``/``power``, light frames, per-instance vector tables, pbrt-v4 light bounds) and
:class:`DeltaPositionLight`, the base of the lights at a point.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..backend import Struct
from ..plugins.registry import Registry
from ..textures import BASE_ONE, BASE_SIGMOID, BASE_TABLE, ConstantSpectrum, load_spectrum

# Type name -> light family (each family registers itself in its module).
LIGHT_TYPES = Registry("emitter")


class LightSample(Struct):
    _fields = {"L": "Spectrum", "wi": "Vector3f", "pdf": "Float", "p": "Point3f", "delta": "Bool"}


class LightType:
    """A light family: its instances and their parameter table."""

    name = ""
    delta = False      # Dirac delta in position or direction (no MIS needed)
    infinite = False   # emits along rays that leave the scene (Le)
    textures = None    # the scene's TextureSet, set by LightSet.build
    traces_rays_in = ()  # methods that trace rays: LightSet calls them outside its dr.switch

    def __init__(self):
        self.instances: list = []

    def add(self, loader, props, shape_index=None) -> int:
        raise NotImplementedError

    def build(self, scene) -> None:
        pass

    def power(self, i: int, scene) -> float:
        """Approximate emitted power of instance ``i`` (W; for the power/BVH samplers)."""
        raise NotImplementedError

    def bounds(self, i: int, scene):
        """pbrt-v4 LightBounds of instance ``i`` for the BVH sampler (None: infinite)."""
        return None

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        raise NotImplementedError

    def pdf_Li(self, idx, ref_p, si, active):
        return mi.Float(0.0)

    def Le(self, idx, d, wl, active):
        """Radiance along direction ``d`` of a ray that left the scene (infinite lights)."""
        return mi.Spectrum(0.0)

    def pdf_Le_dir(self, idx, d, active):
        """Solid-angle density of ``sample_Li`` choosing direction ``d`` (infinite lights)."""
        return mi.Float(0.0)

    # -- emission, for light tracing (see LeSample) -----------------------------------------
    emits_rays = False  # whether the family implements sample_Le / pdf_Le

    def sample_Le(self, idx, u_pos, u_dir, wl, active) -> "LeSample":
        """A ray leaving the light (``pmf``, ``weight`` and ``light`` are filled in by
        ``LightSet.sample_Le``)."""
        raise NotImplementedError

    def pdf_Le(self, idx, p, n, d, active):
        """(pdf_pos, pdf_dir) with which ``sample_Le`` produces the ray (p, d); ``n``: the
        surface normal at ``p`` (area lights)."""
        raise NotImplementedError


class LeSample(Struct):
    """A ray leaving a light (pbrt-v4's ``SampleLe``, Mitsuba's ``sample_ray``), for light
    tracing, BDPT and photon mapping.

    ``o``, ``d``: the ray (origin on the light, unit direction away from it); ``L``: the
    radiance (area, infinite lights), intensity (W/sr, point-like lights) or irradiance
    (W/m^2, directional) carried along it at the sampled wavelengths; ``pdf_pos``: area
    density of ``o`` (1/m^2; 1 for delta-position lights); ``pdf_dir``: solid-angle density
    of ``d`` (1/sr; 1 for delta-direction lights); ``pmf``: the probability of having
    picked this light; ``n``: the light's surface normal at ``o`` on its emitting side
    (area lights), the ray direction (directional and infinite lights: the normal of the
    disk ``o`` lies on), 0 for point-like lights; ``weight`` = ``L |n . d| / (pmf pdf_pos
    pdf_dir)`` with ``|n . d|`` read as 1 for point-like lights: the throughput a light
    path starts with (Mitsuba's ray weight). Flags: ``delta_pos``, ``delta_dir``,
    ``infinite``; ``light``: the light's index (as in ``LightSet``)."""

    _fields = {"o": "Point3f", "d": "Vector3f", "L": "Spectrum", "pdf_pos": "Float", "pdf_dir": "Float",
               "pmf": "Float", "n": "Normal3f", "weight": "Spectrum", "delta_pos": "Bool", "delta_dir": "Bool",
               "infinite": "Bool", "light": "UInt32"}


# --------------------------------------------- helpers shared by light families

def load_constant_emission(loader, props, name: str, default=1.0) -> int:
    """An emission spectrum that must not vary spatially (Mitsuba's ``intensity`` /
    ``irradiance`` of point, spot and directional lights)."""
    slot = load_spectrum(loader, props.raw(name, default), props.key(name), emitter=True)
    if loader.textures.spatially_varying(slot):
        raise props.error(name, "expected a spectrum that does not vary spatially (e.g. not a bitmap)")
    return slot


def luminance(textures, slot: int) -> float:
    """Luminance (pbr's units: a unit-luminance D65 is 1) of an emission spectrum, for
    power estimates. RGB values count with their luminance; tabulated spectra
    (``spectrum``, ``blackbody``) are integrated against the CIE Y curve."""
    t = textures.items[slot]
    if isinstance(t, ConstantSpectrum) and t.base in (BASE_ONE, BASE_TABLE):
        v = t.params.get("value")
        vv = 1.0 if v is None else float(np.asarray(v).reshape(-1)[0])
        if t.form == "illuminant":
            return vv * t.scale
        xyz, _ = spec.cie_tables_np()
        grid = spec.LAMBDA_MIN + spec._CIE_STEP * np.arange(len(xyz))
        if t.base == BASE_TABLE:
            s = np.interp(grid, spec.LAMBDA_MIN + np.arange(len(t.table)), t.table)
        else:
            s = np.ones_like(grid)
        return float(np.trapezoid(s * xyz[:, 1], grid) / spec.CIE_Y_INTEGRAL) * vv * t.scale
    return textures.constant_value(slot)


def photometric(textures, slot: int) -> float:
    """pbrt-v4's ``SpectrumToPhotometric`` in pbr's units: the luminance of the spectrum,
    where an RGB illuminant spectrum counts only its (unit-luminance) D65 part."""
    t = textures.items[slot]
    if isinstance(t, ConstantSpectrum) and t.base == BASE_SIGMOID and t.form == "illuminant":
        return t.scale
    return luminance(textures, slot)


def power_factor(props, textures, slot: int, k_e: float) -> float:
    """pbrt-v4's ``scale`` and photometric ``power``: the factor applied to the light's
    spectrum. ``k_e`` is the power emitted per unit (photometric) intensity."""
    sc = props.float("scale", 1.0)
    p = props.float("power", -1.0)
    if p > 0:
        ph = photometric(textures, slot)
        if not (ph > 0 and k_e > 0):
            raise props.error("power", "cannot reach a target power with a black spectrum or an empty emission profile")
        sc *= p / (k_e * ph)
    return sc


def light_frame(props, allow_position: bool = False) -> np.ndarray:
    """The light-to-world matrix from ``to_world`` (or Mitsuba's ``position``)."""
    if allow_position and props.has("position"):
        if props.has("to_world"):
            raise props.error("position", "give either 'position' or 'to_world', not both")
        m = np.eye(4)
        m[:3, 3] = props.vector3("position")
        return m
    m = props.transform("to_world")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise props.error("to_world", "the transform is singular")
    return m


def vec_table(rows) -> mi.Vector3f:
    """Per-instance 3-vectors, one array per component (gather them with ``gather3``).
    A family with one instance thus has width-1 components, which Dr.Jit reads as
    constants instead of gathering them (a flat table of 3 values took 3 gathers per
    lookup: 18 per light sample of a projector)."""
    a = np.asarray(rows, dtype=np.float64).reshape(-1, 3).astype(np.float32)
    return mi.Vector3f(*[mi.Float(np.ascontiguousarray(a[:, k])) for k in range(3)])


def gather3(tp, table, idx, active):
    return tp(dr.gather(mi.Vector3f, table, idx, active))


def mat_rows(mats) -> list:
    """Three tables (see ``vec_table``), the rows of each instance's 3x3 matrix."""
    return [vec_table([m[r] for m in mats]) for r in range(3)]


def apply_rows(rows, idx, v, active) -> mi.Vector3f:
    r = [gather3(mi.Vector3f, row, idx, active) for row in rows]
    return mi.Vector3f(dr.dot(r[0], v), dr.dot(r[1], v), dr.dot(r[2], v))


def point_bounds(p, w, phi, cos_theta_o, cos_theta_e) -> dict:
    """pbrt-v4's ``LightBounds`` of a light at point ``p`` as a plain dict."""
    p = np.asarray(p, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    n = np.linalg.norm(w)
    return {"p_min": p.copy(), "p_max": p.copy(), "phi": float(phi), "w": w / n if n > 0 else np.array([0, 0, 1.0]),
            "cos_theta_o": float(cos_theta_o), "cos_theta_e": float(cos_theta_e), "two_sided": False}


def max_value(textures, slot: int) -> float:
    """An upper-bound-like magnitude of an emission spectrum (pbrt's ``MaxValue``)."""
    t = textures.items[slot]
    if isinstance(t, ConstantSpectrum) and t.base == BASE_SIGMOID:
        v = np.maximum(np.array(t.params["value"], dtype=np.float64).reshape(-1), 0.0)
        return float(v.max()) * t.scale
    return textures.constant_value(slot)


class DeltaPositionLight(LightType):
    """Common machinery of the lights at a point (``point``, ``spot``, ``projector``,
    ``projection``, ``goniometric``): per-instance position, spectrum slot and scale factor.

    Every such light samples the single direction toward the light with ``pdf = 1``
    (``delta = True``: the integrator skips MIS and multiplies by the light sampler's
    probability); radiance ``L = I(w) / d^2``; lanes where the light sends nothing get
    ``pdf = 0`` so that no shadow ray is traced. ``pdf_Li`` is 0 (BSDF sampling never hits
    a delta light).
    """

    delta = True

    def _base_tables(self):
        self.pos = vec_table([i["to_world"][:3, 3] for i in self.instances])
        self.slot = mi.UInt32([i["slot"] for i in self.instances])
        self.factor = mi.Float([i["factor"] for i in self.instances])

    def _toward(self, idx, ref, active):
        """(light position, unit direction to it, 1/d^2, lanes with d > 0)."""
        p = gather3(mi.Point3f, self.pos, idx, active)
        d = p - ref.p
        dist2 = dr.squared_norm(d)
        ok = active & (dist2 > 0)
        inv_dist2 = dr.select(ok, dr.rcp(dist2), 0.0)
        return p, d * dr.sqrt(inv_dist2), inv_dist2, ok

    def _intensity(self, idx, wl, active):
        slot = dr.gather(mi.UInt32, self.slot, idx, active)
        return self.textures.eval(slot, mi.Point2f(0.5), wl.lambda_, active,
                                  reach=tuple(int(i["slot"]) for i in self.instances)) * dr.gather(mi.Float, self.factor, idx, active)

    def _position(self, i):
        return self.instances[i]["to_world"][:3, 3]

    # -- emission (light tracing) ----------------------------------------------------------
    emits_rays = True

    def sample_Le(self, idx, u_pos, u_dir, wl, active) -> LeSample:
        """A uniformly distributed direction; its intensity is what ``sample_Li`` delivers to
        a point at distance 1 along it (times that distance^2, exactly). Families with a
        narrower emission profile (``spot``) override this with a better density."""
        d = mi.warp.square_to_uniform_sphere(u_dir)
        p = gather3(mi.Point3f, self.pos, idx, active)
        I, ok = self._intensity_along(idx, p, d, u_pos, wl, active)
        return LeSample(o=p, d=d, L=I, pdf_pos=mi.Float(1.0),
                        pdf_dir=dr.select(ok, UNIFORM_SPHERE_PDF, 0.0), delta_pos=mi.Bool(True))

    def _intensity_along(self, idx, p, d, u_pos, wl, active):
        """(intensity leaving the light at ``p`` along unit ``d``, lanes where it is
        non-zero): what ``sample_Li`` delivers at distance 1, times that distance^2
        (exactly, so the light's falloff conventions are not restated here)."""
        ref = ReferencePoint(p + d)
        ls = self.sample_Li(idx, ref, u_pos, wl, active)
        ok = active & (ls.pdf > 0)
        return dr.select(ok, ls.L * dr.squared_norm(ls.p - ref.p), 0.0), ok

    def pdf_Le(self, idx, p, n, d, active):
        """(1: the delta in position, as ``sample_Le`` reports it; density of ``d``)."""
        return mi.Float(1.0), dr.select(active, UNIFORM_SPHERE_PDF, 0.0)


UNIFORM_SPHERE_PDF = 1.0 / (4.0 * math.pi)


class ReferencePoint:
    """A bare reference point for ``sample_Li`` (only ``p`` and ``time`` are read)."""

    def __init__(self, p):
        self.p = p
        self.time = 0.0
        self.n = mi.Normal3f(0.0)
