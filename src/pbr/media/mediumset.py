"""Participating media and :class:`MediumSet`, the per-scene table of them.

Model (pbrt-v4's): at a point ``p`` a medium has absorption and scattering coefficients
``sigma_a``, ``sigma_s`` (1/length, spectral), emitted radiance ``Le`` (scaled by
``sigma_a`` in the RTE) and a phase function. Each medium is described by two factors,
each a constant spectrum times an optional voxel grid:

- Mitsuba form (``homogeneous``, ``heterogeneous``): ``sigma_t = scale * S1 * G1(p)``,
  ``albedo = S2 * G2(p)``, ``sigma_s = albedo * sigma_t``, ``sigma_a = sigma_t - sigma_s``;
- pbrt-v4 form (``homogeneous`` given ``sigma_a``/``sigma_s``, ``uniformgrid``,
  ``rgbgrid``): ``sigma_a = scale * S1 * G1(p)``, ``sigma_s = scale * S2 * G2(p)``.

Free-flight sampling is against a majorant ``sigma_maj >= sigma_t``: exactly ``sigma_t``
in homogeneous media; in grid media a piecewise-constant bound over a coarse 16^3 grid
of cells (pbrt-v4's ``MajorantGrid``), walked with a DDA (:mod:`.majorant`), so sparse
media are not sampled against their global maximum.

Media attach to shapes as ``interior``/``exterior`` and to the sensor (``medium``), as in
Mitsuba: a ray crossing a shape that has media enters ``interior`` when it goes against
the shape's normal, ``exterior`` otherwise; a side without a medium is vacuum.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import spectrum as spec
from ..backend import Struct
from ..phase import HG, PHASE_TYPES, G_MAX, phase_eval, phase_sample
from ..plugins.params import ParamOwner, param_table
from ..plugins.props import ALBEDO, HG_ASYMMETRY, NONNEGATIVE, Props, Range, SceneError, did_you_mean
from ..plugins.registry import Registry
from ..textures import CONSTANT, load_spectrum
from ..textures.grid import GridTable, as_grid, load_gridvolume
from .cloud import cloud_density
from .grid import MAJORANT_RES, cell_maxima

# Type name -> the MediumSet method that parses a medium of that type.
MEDIUM_TYPES = Registry("medium")
MEDIUM_TYPES.update(homogeneous="_homogeneous", heterogeneous="_heterogeneous", uniformgrid="_uniformgrid",
                    rgbgrid="_rgbgrid", cloud="_cloud", nanovdb="_nanovdb")

TA, AS = 0, 1          # parameter forms: (sigma_t, albedo) or (sigma_a, sigma_s)
NO_GRID = 0xFFFFFFFF

# The range of a medium coefficient (sigma_t, sigma_a, sigma_s).
_COEFF = Range(0.0, what="a medium coefficient")


class MediumProperties(Struct):
    """Coefficients of a medium at a point, for the sampled wavelengths."""

    _fields = {"sigma_a": "Spectrum", "sigma_s": "Spectrum", "Le": "Spectrum"}


class _Medium:
    """One medium as parsed: two (spectrum slot, grid) factors, scale, emission, phase."""

    def __init__(self, path):
        self.path = path
        self.form = TA
        self.s1 = self.s2 = None
        self.g1 = self.g2 = NO_GRID
        self.scale = 1.0
        self.le = None
        self.ge = NO_GRID
        self.le_scale = 1.0
        self.to_local = None          # (4, 4) world -> unit cube, grid media only
        self.phase = (HG, 0.0)
        self.cloud = None             # (density, wispiness, frequency, p0, p1): pbrt-v4's cloud
        self.gt = NO_GRID             # temperature grid (nanovdb): blackbody emission
        self.temp = (0.0, 1.0)        # its (offset, scale): T = (grid - offset) * scale


class MediumSet:
    def __init__(self):
        self.media: list[_Medium] = []
        self.grids = GridTable()

    def param_owners(self) -> list:
        """Differentiable medium parameters besides the constant spectra (textures):
        single-channel voxel grids (``<medium>.<sigma_t|albedo>.data``) and ``scale``."""
        return [o for _, o in self.grids.owners] + [m.owner for m in self.media]

    def __len__(self):
        return len(self.media)

    # -- loading ---------------------------------------------------------------------
    def add(self, loader, props: Props) -> int:
        """Parse one medium (its type's method in :data:`MEDIUM_TYPES`); returns its index.
        Every type also takes:

        ===============  =========  ========  =========================================================
        name             type       default   meaning
        ===============  =========  ========  =========================================================
        Le               spectrum   -         pbrt-v4's emitted radiance (scaled by sigma_a in the RTE)
        Lescale          float      1         factor on Le
        g                float      -         pbrt-v4's Henyey-Greenstein asymmetry (or a nested phase
                                              function: isotropic, hg, rayleigh; default isotropic)
        to_world         transform  identity  frame of the grid bounds (grid media)
        sample_emitters  bool       true      only true is supported (NEE from media)
        ===============  =========  ========  =========================================================
        """
        m = _Medium(props.path)
        if props.type not in MEDIUM_TYPES:
            raise props.error(None, f"unknown medium type {props.type!r}{did_you_mean(props.type, MEDIUM_TYPES)} "
                                        f"(supported: {MEDIUM_TYPES.supported()})")
        first_slot = len(loader.textures.items)
        getattr(self, MEDIUM_TYPES[props.type])(loader, props, m)
        self._emission(loader, props, m)
        m.owner = ParamOwner(props.path, valid={"scale": NONNEGATIVE}, scale=mi.Float(m.scale))
        m.phase = self._phase(props)
        if m.phase[0] == HG and (props.has("g") or any(c["type"] == "hg" for _, c in props.children())):
            m.owner.params["phase_function.g"] = mi.Float(m.phase[1])
        self._traverse_keys(loader.textures, first_slot, m)
        if props.has("sample_emitters") and not props.bool("sample_emitters"):
            raise props.error("sample_emitters", "only sample_emitters=true is supported")
        props.mark("has_spectral_extinction")
        props.finish()
        self.media.append(m)
        return len(self.media) - 1

    @staticmethod
    def _traverse_keys(textures, first_slot: int, m) -> None:
        """Name medium ``m``'s constant coefficients as ``mi.traverse`` does: in Mitsuba's
        form a constant coefficient is a constant volume holding a spectrum
        (``<medium>.sigma_t.value.value``; grids are ``<medium>.sigma_t.data``). The
        medium's own prefix (``<shape>.interior_medium``...) is the scene's business
        (:func:`pbr.scene.params.mitsuba_key_paths`). The constant factor (1) by which pbr
        multiplies a grid is internal (``traversed = False``)."""
        if m.form != TA:
            return
        prefix = m.path.split(".", 1)[1] if m.path.startswith("scene.") else m.path
        for slot, name in ((m.s1, "sigma_t"), (m.s2, "albedo")):
            tex = textures.items[slot]
            if slot >= first_slot and tex.path == f"{prefix}.{name}":
                tex.path = f"{prefix}.{name}.value"

    @staticmethod
    def _unit_factor(loader, path, emitter=False) -> int:
        """A constant 1 slot that multiplies a grid: internal, not a scene parameter."""
        slot = load_spectrum(loader, 1.0, path, emitter=emitter)
        loader.textures.items[slot].traversed = False
        return slot

    def _spectrum(self, loader, props, name, default, bounded=False):
        """A constant spectrum slot (float, rgb, spectrum, or Mitsuba's constvolume)."""
        v = props.raw(name, default)
        path = props.key(name)
        if isinstance(v, dict) and v.get("type") == "constvolume":
            p = Props(v, path, loader)
            v = p.raw("value", 1.0)
            path = p.key("value")
            p.transform("to_world")   # every Mitsuba volume takes one; a constant ignores it
            p.finish()
        if isinstance(v, dict) and v.get("type") not in ("rgb", "spectrum", "blackbody", "d65", "ref"):
            raise SceneError(f"{path}: expected a float, rgb, spectrum or constvolume, got type {v.get('type')!r}")
        unbounded = False
        if isinstance(v, dict) and v.get("type") == "rgb" and not bounded:
            # RGB values within [0, 1] use the reflectance upsampling (as Mitsuba does);
            # larger ones pbrt-v4's unbounded form (Mitsuba would squash them).
            unbounded = bool(np.any(np.asarray(v.get("value", 0.0), np.float64) > 1))
        slot = load_spectrum(loader, v, path, emitter=False, unbounded=unbounded, valid=ALBEDO if bounded else _COEFF)
        if loader.textures.kind_of(slot) != CONSTANT:
            raise SceneError(f"{path}: a medium coefficient must be a constant spectrum (not a texture)")
        return slot

    def _volume(self, loader, props, name, default, m, form):
        """A Mitsuba volume parameter: (spectrum slot, grid index or NO_GRID)."""
        v = props.raw(name, default)
        if isinstance(v, dict) and v.get("type") == "gridvolume":
            gid, to_local = self._gridvolume(loader, Props(v, props.key(name), loader), form, props.key(name))
            self._set_bounds(m, to_local, props.key(name))
            return self._unit_factor(loader, props.key(name)), gid
        return self._spectrum(loader, props, name, default, bounded=(form == "albedo")), NO_GRID

    def _gridvolume(self, loader, p: Props, form, path):
        data, to_world = load_gridvolume(loader, p)
        try:
            to_local = np.linalg.inv(to_world)
        except np.linalg.LinAlgError:
            raise p.error("to_world", "the grid transform is singular") from None
        return self.grids.add(data, form, path), to_local

    @staticmethod
    def _set_bounds(m, to_local, where):
        if m.to_local is not None and not np.allclose(m.to_local, to_local, atol=1e-6):
            raise SceneError(f"{where}: all grids of one medium must share the same to_world")
        m.to_local = to_local

    def _homogeneous(self, loader, props, m):
        """``homogeneous`` (Mitsuba's; or pbrt-v4's with sigma_a / sigma_s). Also the
        parameters every medium takes (see :meth:`add`).

        =======  ========  =======  ====================================
        name     type      default  meaning
        =======  ========  =======  ====================================
        sigma_t  spectrum  1        extinction (1/length)
        albedo   spectrum  0.75     single-scattering albedo, in [0, 1]
        sigma_a  spectrum  -        absorption, instead (pbrt-v4's form)
        sigma_s  spectrum  -        scattering, with sigma_a
        scale    float     1        factor on the coefficients
        =======  ========  =======  ====================================
        """
        if props.has("sigma_a") or props.has("sigma_s"):
            if props.has("sigma_t") or props.has("albedo"):
                raise props.error("sigma_t" if props.has("sigma_t") else "albedo",
                                  "give either sigma_t/albedo (Mitsuba) or sigma_a/sigma_s (pbrt-v4), not both")
            m.form = AS
            m.s1 = self._spectrum(loader, props, "sigma_a", 1.0)
            m.s2 = self._spectrum(loader, props, "sigma_s", 1.0)
        else:
            m.s1 = self._spectrum(loader, props, "sigma_t", 1.0)
            m.s2 = self._spectrum(loader, props, "albedo", 0.75, bounded=True)
        m.scale = props.float("scale", 1.0, min=0.0)

    def _heterogeneous(self, loader, props, m):
        """``heterogeneous`` (Mitsuba's): coefficients times voxel grids. Also the parameters
        every medium takes (see :meth:`add`).

        =======  ======  =======  =============================================================
        name     type    default  meaning
        =======  ======  =======  =============================================================
        sigma_t  volume  1        extinction: a spectrum, constvolume or gridvolume (filename,
                                  data or grid, to_world, use_grid_bbox)
        albedo   volume  0.75     single-scattering albedo (grids of one medium share to_world)
        scale    float   1        factor on the coefficients
        =======  ======  =======  =============================================================

        As in Mitsuba, the medium fills the box of its ``sigma_t`` volume only (the unit
        cube mapped by the volume's ``to_world``), also where ``sigma_t`` is a constant or
        a ``constvolume`` (then by default the unit cube [0, 1]^3); outside it, the shape
        holding the medium is empty.
        """
        m.s1, m.g1 = self._volume(loader, props, "sigma_t", 1.0, m, "unbounded")
        if m.g1 == NO_GRID:
            v = props.raw("sigma_t", 1.0)
            cv = isinstance(v, dict) and v.get("type") == "constvolume"
            to_world = Props(v, props.key("sigma_t"), loader).transform("to_world") if cv else np.eye(4)
            try:
                self._set_bounds(m, np.linalg.inv(to_world), props.key("sigma_t"))
            except np.linalg.LinAlgError:
                raise props.error("sigma_t", "the volume's to_world is singular") from None
        m.s2, m.g2 = self._volume(loader, props, "albedo", 0.75, m, "albedo")
        m.scale = props.float("scale", 1.0, min=0.0)

    def _bounds(self, props, m):
        """pbrt-v4's p0/p1 grid bounds (default the unit cube)."""
        p0 = props.vector3("p0", (0.0, 0.0, 0.0))
        p1 = props.vector3("p1", (1.0, 1.0, 1.0))
        if np.any(p1 <= p0):
            raise props.error("p1", f"must exceed p0 in every coordinate, got p0={p0.tolist()} p1={p1.tolist()}")
        to_world = props.transform("to_world") @ np.array(
            [[p1[0] - p0[0], 0, 0, p0[0]], [0, p1[1] - p0[1], 0, p0[1]], [0, 0, p1[2] - p0[2], p0[2]], [0, 0, 0, 1]])
        self._set_bounds(m, np.linalg.inv(to_world), props.path)

    def _uniformgrid(self, loader, props, m):
        """``uniformgrid`` (pbrt-v4's): sigma_a and sigma_s times one density grid. Also the
        parameters every medium takes (see :meth:`add`).

        =======  ========  =======  =========================================================
        name     type      default  meaning
        =======  ========  =======  =========================================================
        sigma_a  spectrum  1        absorption at density 1
        sigma_s  spectrum  1        scattering at density 1
        density  array     -        (nz, ny, nx) densities (required)
        p0, p1   point     0; 1     grid bounds (default the unit cube) in the to_world frame
        scale    float     1        factor on the coefficients
        =======  ========  =======  =========================================================
        """
        self._pbrt_coefficients(loader, props, m)
        dens = as_grid(props.raw("density"), props.key("density")) if props.has("density") else None
        if dens is None or dens.shape[3] != 1:
            raise props.error("density", "expected a (nz, ny, nx) density grid")
        m.g1 = m.g2 = self.grids.add(dens, "unbounded", props.key("density"))
        self._bounds(props, m)

    def _rgbgrid(self, loader, props, m):
        """``rgbgrid`` (pbrt-v4's): RGB grids of sigma_a and sigma_s. Also the parameters every
        medium takes (see :meth:`add`; here ``Le`` is an (nz, ny, nx, 3) grid, times D65).

        =======  =====  =======  =========================================================
        name     type   default  meaning
        =======  =====  =======  =========================================================
        sigma_a  array  -        (nz, ny, nx, 3) absorption (required)
        sigma_s  array  -        (nz, ny, nx, 3) scattering (required)
        p0, p1   point  0; 1     grid bounds (default the unit cube) in the to_world frame
        scale    float  1        factor on the coefficients
        =======  =====  =======  =========================================================
        """
        m.form = AS
        for k in ("sigma_a", "sigma_s"):
            if not props.has(k):
                raise props.error(k, "an rgbgrid needs sigma_a and sigma_s grids of shape (nz, ny, nx, 3)")
        ga = as_grid(props.raw("sigma_a"), props.key("sigma_a"))
        gs = as_grid(props.raw("sigma_s"), props.key("sigma_s"))
        if ga.shape[:3] != gs.shape[:3]:
            raise props.error("sigma_s", f"grid shape {gs.shape[:3]} differs from sigma_a's {ga.shape[:3]}")
        m.g1, m.g2 = self.grids.add(ga, "unbounded"), self.grids.add(gs, "unbounded")
        m.s1 = m.s2 = self._unit_factor(loader, props.path)
        m.scale = props.float("scale", 1.0, min=0.0)
        self._bounds(props, m)

    def _cloud(self, loader, props, m):
        """``cloud`` (pbrt-v4's ``CloudMedium``): sigma_a and sigma_s times a procedural
        density in [0, 1] (:mod:`.cloud`: Perlin noise sums, perturbed by the noise's
        gradient, thinning with height y) over the box p0..p1. Also the parameters every
        medium takes (see :meth:`add`), but no ``Le``.

        =========  ========  =======  ==========================================================
        name       type      default  meaning
        =========  ========  =======  ==========================================================
        sigma_a    spectrum  1        absorption at density 1
        sigma_s    spectrum  1        scattering at density 1
        density    float     1        factor on the noise sum
        wispiness  float     1        strength of the gradient perturbation (0: none)
        frequency  float     5        noise frequency (per unit of medium space)
        p0, p1     point     0; 1     the medium's box (medium space: the to_world frame)
        scale      float     1        factor on the coefficients
        =========  ========  =======  ==========================================================
        """
        if props.has("Le"):
            raise props.error("Le", "a cloud medium does not emit (pbrt-v4's CloudMedium)")
        self._pbrt_coefficients(loader, props, m)
        self._bounds(props, m)
        p0 = props.vector3("p0", (0.0, 0.0, 0.0))
        p1 = props.vector3("p1", (1.0, 1.0, 1.0))
        m.cloud = (props.float("density", 1.0, min=0.0), props.float("wispiness", 1.0, min=0.0),
                   props.float("frequency", 5.0), p0, p1)

    def _pbrt_coefficients(self, loader, props, m):
        """pbrt-v4's density-scaled coefficients of its grid media (``uniformgrid``,
        ``cloud``, ``nanovdb``): ``sigma_a`` and ``sigma_s`` (1 by default) times ``scale``."""
        m.form = AS
        m.s1 = self._spectrum(loader, props, "sigma_a", 1.0)
        m.s2 = self._spectrum(loader, props, "sigma_s", 1.0)
        m.scale = props.float("scale", 1.0, min=0.0)

    def _nanovdb(self, loader, props, m):
        """``nanovdb`` (pbrt-v4's ``NanoVDBMedium``): sigma_a and sigma_s times the density
        grid of a NanoVDB file (read with NVIDIA Warp: ``pip install warp-lang``), and
        optionally blackbody emission from its temperature grid. The medium fills the
        grids' world bounding box (the union of both) in the to_world frame; lookups
        interpolate the voxels trilinearly as NanoVDB does (:mod:`.nanovdb`). Also the
        parameters every medium takes (see :meth:`add`) but ``Le``: the emission is
        ``Lescale`` times pbrt-v4's normalised blackbody (peak 1) at
        ``T = (temperature - temperatureoffset) * temperaturescale``, none where T <= 100 K.

        =================  ========  =============  ============================================
        name               type      default        meaning
        =================  ========  =============  ============================================
        filename           string    -              the ``.nvdb`` file (required)
        gridname           string    "density"      the density grid (a float fog volume)
        temperaturename    string    "temperature"  the temperature grid (optional in the file)
        sigma_a            spectrum  1              absorption at density 1
        sigma_s            spectrum  1              scattering at density 1
        scale              float     1              factor on the coefficients
        temperatureoffset  float     0              subtracted from the temperature grid
                                                    (pbrt-v4 also reads it as temperaturecutoff)
        temperaturescale   float     1              factor on the temperature, after the offset
        =================  ========  =============  ============================================
        """
        from .nanovdb import dense_samples, read_nvdb
        if props.has("Le"):
            raise props.error("Le", "a nanovdb medium emits from its temperature grid, not Le (pbrt-v4's)")
        self._pbrt_coefficients(loader, props, m)
        if not props.has("filename"):
            raise props.error("filename", "a nanovdb medium needs the .nvdb file's 'filename'")
        where = props.key("filename")
        path = loader.resolve_path(props.string("filename"), where)
        dname = props.string("gridname", "density")
        tname = props.string("temperaturename", "temperature")
        grids, every = read_nvdb(path, (dname, tname), where)
        if grids[dname] is None:
            raise SceneError(f"{where}: {path!r} has no grid {dname!r} (its grids: {every}); "
                             "set 'gridname' to use another")
        dens, temp = grids[dname], grids[tname]
        bounds = dens.world_bbox.copy()
        if temp is not None:
            bounds = np.stack([np.minimum(bounds[0], temp.world_bbox[0]), np.maximum(bounds[1], temp.world_bbox[1])])
        values, sc, off = dense_samples(dens, bounds, where)
        m.g1 = m.g2 = self.grids.add(values[..., None], "unbounded", affine=(sc, off))
        off = props.float("temperatureoffset") if props.has("temperatureoffset") else None
        cutoff = props.float("temperaturecutoff", 0.0)    # pbrt-v4's other name for the offset
        m.temp = (cutoff if off is None else off, props.float("temperaturescale", 1.0))
        if temp is not None:
            tv, tsc, toff = dense_samples(temp, bounds, where, nonnegative=False)
            m.gt = self.grids.add(tv[..., None], "unbounded", affine=(tsc, toff))
        box = np.diag([*(bounds[1] - bounds[0]), 1.0])
        box[:3, 3] = bounds[0]
        self._set_bounds(m, np.linalg.inv(props.transform("to_world") @ box), props.path)

    def _emission(self, loader, props, m):
        """pbrt-v4's ``Le`` (an illuminant spectrum, or an RGB grid for ``rgbgrid``) and
        ``Lescale``; for uniformgrid the emission is scaled by the density grid."""
        m.le_scale = props.float("Lescale", 1.0, min=0.0)
        if not props.has("Le"):
            return
        v = props.raw("Le")
        if props.type == "rgbgrid" and not isinstance(v, (dict, int, float)):
            # RGB emission: unbounded per-voxel spectra times the illuminant (D65).
            m.ge = self.grids.add(as_grid(v, props.key("Le")), "unbounded")
            m.le = self._unit_factor(loader, props.key("Le"), emitter=True)
            return
        m.le = load_spectrum(loader, v, props.key("Le"), emitter=True)
        if loader.textures.kind_of(m.le) != CONSTANT:
            raise props.error("Le", "medium emission must be a constant spectrum")
        if props.type == "uniformgrid":
            m.ge = m.g1

    @staticmethod
    def _phase(props):
        kids = [(k, c) for k, c in props.children() if c["type"] in PHASE_TYPES]
        if props.has("g"):  # pbrt-v4: Henyey-Greenstein asymmetry on the medium
            if kids:
                raise props.error("g", "give either 'g' or a phase function, not both")
            return HG, props.float("g", valid=HG_ASYMMETRY)
        if not kids:
            return HG, 0.0
        if len(kids) > 1:
            raise props.error(kids[1][0], "a medium takes at most one phase function")
        k, _ = kids[0]
        p = props.child(k)
        props.mark(k)
        out = PHASE_TYPES[p.type](p)
        p.finish()
        return out

    # -- tables ----------------------------------------------------------------------
    def build(self, textures) -> None:
        self.textures = textures
        ms = self.media
        if not ms:
            return
        self.grids.build()
        self.forms = {m.form for m in ms}
        self.has_grid = any(m.to_local is not None for m in ms)
        self.has_temp = any(m.gt != NO_GRID for m in ms)
        self.has_le = any(m.le is not None for m in ms) or self.has_temp
        self.phase_kinds = {m.phase[0] for m in ms}
        u32 = lambda xs: mi.UInt32([int(x) for x in xs])  # noqa: E731
        self.form = u32(m.form for m in ms)
        self.s1 = u32(m.s1 for m in ms)
        self.s2 = u32(m.s2 for m in ms)
        self.s_reach = (tuple(int(m.s1) for m in ms), tuple(int(m.s2) for m in ms))
        self.g1 = u32(m.g1 for m in ms)
        self.g2 = u32(m.g2 for m in ms)
        self.scale = param_table([m.owner.params["scale"] for m in ms])
        self.le = u32(m.le if m.le is not None else 0 for m in ms)
        self.has_le_of = mi.Bool([m.le is not None for m in ms])
        self.ge = u32(m.ge for m in ms)
        self.le_scale = mi.Float([m.le_scale for m in ms])
        if self.has_temp:
            self.gt = u32(m.gt for m in ms)
            self.temp = mi.Array2f([m.temp[0] for m in ms], [m.temp[1] for m in ms])
        self.phase_kind = u32(m.phase[0] for m in ms)
        self.phase_g = param_table([dr.clip(m.owner.params["phase_function.g"], -G_MAX, G_MAX)
                                    if "phase_function.g" in m.owner.params
                                    else float(np.clip(m.phase[1], -G_MAX, G_MAX)) for m in ms])
        if self.has_grid:
            self._build_majorants()
        self.has_cloud = any(m.cloud is not None for m in ms)
        if self.has_cloud:
            from ..textures.procedural import NOISE_PERM
            c = [m.cloud or (0.0, 0.0, 0.0, np.zeros(3), np.ones(3)) for m in ms]
            self.is_cloud = mi.Bool([m.cloud is not None for m in ms])
            self.cloud_par = mi.Array3f(*([x[k] for x in c] for k in range(3)))
            self.cloud_p0 = mi.Array3f(*([float(x[3][k]) for x in c] for k in range(3)))
            self.cloud_ext = mi.Array3f(*([float(x[4][k] - x[3][k]) for x in c] for k in range(3)))
            self.perm = mi.UInt32(NOISE_PERM)

    def _build_majorants(self):
        """Per medium: world -> unit-cube rows and the majorant grid (two cell maxima
        per cell: one per factor; homogeneous media have none)."""
        ms = self.media
        rows = np.zeros((3, len(ms), 4))
        maj, offs = [], []
        off = 0
        for i, m in enumerate(ms):
            offs.append(off)
            if m.to_local is None:
                rows[:, i] = np.eye(4)[:3]
                continue
            rows[:, i] = m.to_local[:3]
            cells = []
            for g in (m.g1, m.g2):
                bound = self.grids.max_bound(g) if g != NO_GRID else np.ones((1, 1, 1))
                aff = self.grids.affine[g] if g != NO_GRID else None
                cells.append(cell_maxima(bound, MAJORANT_RES, aff).ravel())
            maj.append(np.stack(cells, axis=1).ravel())
            off += 2 * MAJORANT_RES ** 3
        self.rows = [mi.Array4f(*(rows[r, :, k].tolist() for k in range(4))) for r in range(3)]
        self.is_grid = mi.Bool([m.to_local is not None for m in ms])
        self.maj = mi.Float(np.concatenate(maj).astype(np.float32))
        self.maj_off = mi.UInt32(offs)

    # -- kernels -------------------------------------------------------------------------
    def to_local(self, m, p, active, vector=False):
        """World point (or vector) -> the medium's unit-cube grid space."""
        w = 0.0 if vector else 1.0
        ph = mi.Array4f(p.x, p.y, p.z, w)
        return mi.Vector3f(*(dr.dot(dr.gather(mi.Array4f, r, m, active), ph) for r in self.rows))

    def _factors(self, m, wl, active):
        """The constant spectra S1, S2 and the scale of medium ``m``."""
        uv = mi.Point2f(0.0)
        s1 = self.textures.eval(dr.gather(mi.UInt32, self.s1, m, active), uv, wl.lambda_, active,
                                reach=self.s_reach[0])
        s2 = self.textures.eval(dr.gather(mi.UInt32, self.s2, m, active), uv, wl.lambda_, active,
                                reach=self.s_reach[1])
        return s1, s2, dr.gather(mi.Float, self.scale, m, active)

    def _combine(self, m, x, y, scale, active):
        """(sigma_a, sigma_s) from the two factors in the medium's form."""
        sa_as, ss_as = scale * x, scale * y
        if self.forms == {AS}:
            return sa_as, ss_as
        st = scale * x
        ss_ta = st * y
        sa_ta = st - ss_ta
        if self.forms == {TA}:
            return sa_ta, ss_ta
        is_as = dr.gather(mi.UInt32, self.form, m, active) == AS
        return dr.select(is_as, sa_as, sa_ta), dr.select(is_as, ss_as, ss_ta)

    def eval(self, m, p: mi.Point3f, wl, active) -> MediumProperties:
        """sigma_a, sigma_s and Le of medium ``m`` (index) at world point ``p``."""
        x, y, scale = self._factors(m, wl, active)
        if self.has_grid:
            grid = active & dr.gather(mi.Bool, self.is_grid, m, active)
            pl = self.to_local(m, p, grid)
            g1 = dr.gather(mi.UInt32, self.g1, m, grid)
            g2 = dr.gather(mi.UInt32, self.g2, m, grid)
            x = dr.select(grid & (g1 != NO_GRID), x * self.grids.lookup(g1, pl, wl.lambda_, grid & (g1 != NO_GRID)), x)
            y = dr.select(grid & (g2 != NO_GRID), y * self.grids.lookup(g2, pl, wl.lambda_, grid & (g2 != NO_GRID)), y)
            if self.has_cloud:
                cl = grid & dr.gather(mi.Bool, self.is_cloud, m, grid)
                par = dr.gather(mi.Array3f, self.cloud_par, m, cl)
                pm = dr.gather(mi.Array3f, self.cloud_p0, m, cl) + pl * dr.gather(mi.Array3f, self.cloud_ext, m, cl)
                d = cloud_density(self.perm, mi.Point3f(pm), par.x, par.y, par.z)
                d = dr.select(dr.all((pl >= 0.0) & (pl <= 1.0)), d, 0.0)     # bounded by its box
                x, y = dr.select(cl, x * d, x), dr.select(cl, y * d, y)
        sa, ss = self._combine(m, x, y, scale, active)
        Le = mi.Spectrum(0.0)
        if self.has_le:
            em = active & dr.gather(mi.Bool, self.has_le_of, m, active)
            Le = self.textures.eval(dr.gather(mi.UInt32, self.le, m, em), mi.Point2f(0.0), wl.lambda_, em)
            Le *= dr.gather(mi.Float, self.le_scale, m, em)
            if self.has_grid:
                ge = dr.gather(mi.UInt32, self.ge, m, em)
                eg = em & (ge != NO_GRID)
                Le = dr.select(eg, Le * self.grids.lookup(ge, self.to_local(m, p, eg), wl.lambda_, eg), Le)
            Le = dr.select(em, Le, 0.0)
            if self.has_temp:
                Le += self._temperature_emission(m, p, wl, active)
        return MediumProperties(mi.Spectrum(sa), mi.Spectrum(ss), mi.Spectrum(Le))

    def _temperature_emission(self, m, p, wl, active):
        """pbrt-v4's NanoVDB emission: Lescale times the blackbody of peak 1 at the
        temperature ``(T(p) - offset) * scale`` (T trilinear), zero at 100 K or below."""
        gt = dr.gather(mi.UInt32, self.gt, m, active)
        et = active & (gt != NO_GRID)
        tab = dr.gather(mi.Array2f, self.temp, m, et)
        t = (self.grids.lookup(gt, self.to_local(m, p, et), wl.lambda_, et)[0] - tab[0]) * tab[1]
        hot = et & (t > 100.0)
        t = dr.select(hot, t, 1000.0)
        le = spec.blackbody_normalised(wl.lambda_, t) * dr.gather(mi.Float, self.le_scale, m, hot)
        return dr.select(hot, mi.Spectrum(le), 0.0)

    def majorant(self, m, cell, wl, active):
        """sigma_maj of medium ``m`` in majorant cell ``cell`` (ignored for homogeneous
        media, whose majorant is sigma_t itself); detached: it only steers sampling."""
        with dr.suspend_grad():
            return self._majorant(m, cell, wl, active)

    def _majorant(self, m, cell, wl, active):
        x, y, scale = self._factors(m, wl, active)
        if self.has_grid:
            grid = active & dr.gather(mi.Bool, self.is_grid, m, active)
            r = MAJORANT_RES
            idx = dr.gather(mi.UInt32, self.maj_off, m, grid) + 2 * mi.UInt32((cell.z * r + cell.y) * r + cell.x)
            x = dr.select(grid, x * dr.gather(mi.Float, self.maj, idx, grid), x)
            y = dr.select(grid, y * dr.gather(mi.Float, self.maj, idx + 1, grid), y)
        if self.forms == {TA}:
            return scale * x
        st_as = scale * (x + y)
        if self.forms == {AS}:
            return st_as
        return dr.select(dr.gather(mi.UInt32, self.form, m, active) == AS, st_as, scale * x)

    def phase_eval(self, m, wo, wi, active):
        kind = dr.gather(mi.UInt32, self.phase_kind, m, active)
        g = dr.gather(mi.Float, self.phase_g, m, active)
        return phase_eval(kind, g, wo, wi, self.phase_kinds)

    def phase_sample(self, m, wo, u, active):
        kind = dr.gather(mi.UInt32, self.phase_kind, m, active)
        g = dr.gather(mi.Float, self.phase_g, m, active)
        return phase_sample(kind, g, wo, u, self.phase_kinds)
