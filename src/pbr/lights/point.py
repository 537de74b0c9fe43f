"""``point``: an isotropic point light (Mitsuba's ``point``), and helpers shared by the
other delta-position lights (``spot``, ``projector``/``projection``, ``goniometric``) and
by ``directional``.

Parameters: ``intensity`` (W/sr; a spectrum, RGB in the illuminant form as Mitsuba),
``position`` or ``to_world`` (only its translation), and pbrt-v4's photometric
``scale`` (a multiplier) and ``power`` (total emitted power: the intensity is rescaled
so that ``4 pi I_v = power``, where ``I_v`` is the luminance of the intensity spectrum
without its RGB multiplier, exactly as pbrt-v4's ``SpectrumToPhotometric``; unlike
pbrt-v4 the spectrum is *not* normalised when ``power`` is absent, as in Mitsuba).

Every delta light samples the single direction toward the light with ``pdf = 1``
(``delta = True``: the integrator skips MIS and multiplies by the light sampler's
probability); radiance ``L = I(w) / d^2``; lanes where the light sends nothing get
``pdf = 0`` so that no shadow ray is traced. ``pdf_Li`` is 0 (BSDF sampling never hits
a delta light).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..textures import (load_spectrum, ConstantSpectrum, Checkerboard, Bitmap, Composite,
                        BASE_ONE, BASE_SIGMOID, BASE_TABLE, OP_CHECKER)
from .base import LIGHT_TYPES, LightType, LightSample, LeSample


# ------------------------------------------------------------------ shared helpers

def spatially_varying(textures, slot: int) -> bool:
    """True when texture ``slot`` depends on the surface coordinates."""
    t = textures.items[slot]
    if isinstance(t, (Checkerboard, Bitmap)):
        return True
    if isinstance(t, Composite):
        if t.op == OP_CHECKER:
            return True
        return any(spatially_varying(textures, s) for s in (t.x, t.y, t.m))
    return False


def load_constant_emission(loader, props, name: str, default=1.0) -> int:
    """An emission spectrum that must not vary spatially (Mitsuba's ``intensity`` /
    ``irradiance`` of point, spot and directional lights)."""
    slot = load_spectrum(loader, props.raw(name, default), props.key(name), emitter=True)
    if spatially_varying(loader.textures, slot):
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


def vec_table(rows) -> mi.Float:
    """Per-instance 3-vectors, flattened (gather them with ``gather3``)."""
    return mi.Float(np.asarray(rows, dtype=np.float64).reshape(-1).astype(np.float32))


def gather3(tp, table, idx, active):
    return dr.gather(tp, table, idx, active)


def mat_rows(mats) -> list:
    """Three flat tables, the rows of each instance's 3x3 matrix."""
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
    """Common machinery: per-instance position, spectrum slot and scale factor."""

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
        return self.textures.eval(slot, mi.Point2f(0.5), wl.lambda_, active) * dr.gather(mi.Float, self.factor, idx, active)

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
        ref = _Ref(p + d)
        ls = self.sample_Li(idx, ref, u_pos, wl, active)
        ok = active & (ls.pdf > 0)
        return dr.select(ok, ls.L * dr.squared_norm(ls.p - ref.p), 0.0), ok

    def pdf_Le(self, idx, p, n, d, active):
        """(1: the delta in position, as ``sample_Le`` reports it; density of ``d``)."""
        return mi.Float(1.0), dr.select(active, UNIFORM_SPHERE_PDF, 0.0)


UNIFORM_SPHERE_PDF = 1.0 / (4.0 * math.pi)


class _Ref:
    """A bare reference point for ``sample_Li`` (only ``p`` and ``time`` are read)."""

    def __init__(self, p):
        self.p = p
        self.time = 0.0
        self.n = mi.Normal3f(0.0)


# ------------------------------------------------------------------------ point

@LIGHT_TYPES.register("point")
class PointLight(DeltaPositionLight):
    name = "point"

    def add(self, loader, props, shape_index=None) -> int:
        slot = load_constant_emission(loader, props, "intensity")
        m = light_frame(props, allow_position=True)
        factor = power_factor(props, loader.textures, slot, 4.0 * math.pi)
        props.finish()
        self.instances.append({"slot": slot, "to_world": m, "factor": factor})
        return len(self.instances) - 1

    def build(self, scene) -> None:
        self._base_tables()

    def power(self, i: int, scene) -> float:
        inst = self.instances[i]
        return 4.0 * math.pi * inst["factor"] * luminance(scene.textures, inst["slot"])

    def bounds(self, i: int, scene):
        inst = self.instances[i]
        phi = 4.0 * math.pi * inst["factor"] * max_value(scene.textures, inst["slot"])
        return point_bounds(self._position(i), (0, 0, 1), phi, -1.0, 0.0)

    def sample_Li(self, idx, ref, u, wl, active) -> LightSample:
        p, wi, inv_dist2, ok = self._toward(idx, ref, active)
        L = self._intensity(idx, wl, ok) * inv_dist2
        return LightSample(dr.select(ok, L, 0.0), wi, dr.select(ok, 1.0, 0.0), p, mi.Bool(True))
