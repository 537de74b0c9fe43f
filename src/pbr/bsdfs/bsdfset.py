"""``BSDFSet``: every BSDF of a scene and the per-scene dispatch over their families.

A scene's BSDFs get global ids (entries); ``BSDFSet`` maps an entry to (family, index in
family) and calls the family's vectorised code. With a single family the call is
direct; with several it is a ``dr.switch`` over only the families the scene uses.
Mitsuba's ``twosided``, ``mask``, ``blendbsdf`` (pbrt-v4's ``mix``), ``normalmap`` and
``bumpmap`` are not families but attributes of an entry (:data:`WRAPPERS`).
"""

from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi

from .. import dispatch
from ..plugins.props import UNIT, SceneError, did_you_mean
from ..spectrum import clamp_keep_grad, luminance_rgb
from ..textures import load_spectrum
from . import perturb
from .base import BSDF_TYPES, BSDFSample, BSDFType, DIFFUSE, GLOSSY, TRANSMISSION
from .null import pass_through

NO_BACK = 0xFFFFFFFF


class BSDFSet:
    """All BSDFs of a scene. Entry ``i`` is (family, index in family, back entry, opacity).

    ``twosided`` and ``mask`` (Mitsuba's) are not families but entry attributes:
    ``twosided`` keeps the front BSDF's entry with a back entry (the second nested BSDF, or
    the front one again); where the incident direction lies below the surface the
    dispatcher mirrors both directions and uses the back entry. ``mask`` adds an opacity
    texture: with probability 1 - opacity light passes straight through (``null``)."""

    def __init__(self):
        self.families: dict[str, BSDFType] = {}
        self.entries: list[tuple[str, int, int, int]] = []
        self.blend_of: dict[int, tuple[int, int, int]] = {}   # blend entry -> (a, b, weight slot)
        self.blend_mixed_delta: set[int] = set()   # blends weighting delta samples as Mitsuba 3.9
        self.perturb_of: dict[int, tuple] = {}   # normal/bump-mapped entry -> (kind, slot, scale, flip, shadow)

    def add(self, loader, props) -> int:
        """Parse one BSDF (a family instance or a wrapper); returns its entry."""
        t = props.type
        if t in WRAPPERS:
            return getattr(self, WRAPPERS[t])(loader, props)
        if t not in BSDF_TYPES:
            raise props.error(None, f"unsupported BSDF type {t!r}{did_you_mean(t, bsdf_names())} "
                                        f"(supported: {', '.join(sorted(bsdf_names()))})")
        fam = self.families.setdefault(t, BSDF_TYPES[t]())
        local = fam.add(loader, props)
        self.entries.append((t, local, NO_BACK, NO_BACK))
        return len(self.entries) - 1

    def _add_blend(self, loader, props) -> int:
        """``blendbsdf`` (Mitsuba's) / ``mix`` (pbrt-v4's): f = (1 - w) f_0 + w f_1; sampling
        picks a component with its weight and reports the mixture's pdf and f / pdf.

        ===========  =======  =========  =================================================
        name         type     default    meaning
        ===========  =======  =========  =================================================
        weight       texture  0.5        w (blendbsdf)
        amount       texture  0.5        w (mix)
        delta_lobes  string   'mixture'  blendbsdf: how a sampled Dirac (smooth) lobe is
                                         weighted: 'mixture' (Mitsuba 3.9's: its value and
                                         pdf are mixed with the other component's density
                                         like any sample) or 'separate' (pbr's: it keeps
                                         its own weight, the exact mixture; ``mix`` always)
        (two keys)   BSDF     -          the two nested BSDFs, f_0 first
        ===========  =======  =========  =================================================

        Mitsuba 3.9's 'mixture' treats a delta lobe's discrete probability as a density:
        a blend of a diffuse and a smooth mirror renders up to a few percent darker than
        the exact mixture (measured on the Cornell box: 2.2% under its area light, 4% under
        an environment). It is the default so that Mitsuba scenes give Mitsuba's images.
        """
        wkey = "weight" if props.type == "blendbsdf" else "amount"
        mixed_delta = props.type == "blendbsdf" and props.string(
            "delta_lobes", "mixture", choices=("mixture", "separate")) == "mixture"
        nested = [k for k, v in props.children() if k != wkey]
        if len(nested) != 2:
            raise props.error(None, f"{props.type} takes exactly two nested BSDFs, got {len(nested)}")
        weight = load_spectrum(loader, props.raw(wkey, 0.5), props.key(wkey), emitter=False, valid=UNIT,
                               scalar=props.type == "blendbsdf")   # Mitsuba's: read with eval_1
        ids = [loader.bsdf(props.raw(k), props.key(k)) for k in nested]
        props.finish()
        for i, k in zip(ids, nested):
            if i in self.blend_of:
                raise props.error(k, f"a {props.type} cannot contain another blend")
        # A blend entry points at its first component (used where it is not a blend).
        self.entries.append(self.entries[ids[0]])
        self.blend_of[len(self.entries) - 1] = (ids[0], ids[1], weight)
        if mixed_delta:
            self.blend_mixed_delta.add(len(self.entries) - 1)
        return len(self.entries) - 1

    def _add_perturbed(self, loader, props) -> int:
        """``normalmap`` / ``bumpmap`` (Mitsuba's): the nested BSDF in a perturbed shading frame.

        ======================  =======  =======  ===============================================
        name                    type     default  meaning
        ======================  =======  =======  ===============================================
        normalmap               texture  -        normalmap: a raw bitmap of normals in [0, 1]^3
        (a texture key)         texture  -        bumpmap: the height field h, any texture
                                                  (a raw bitmap: its exact gradient; any
                                                  other: forward differences, pbrt-v4's)
        scale                   float    1        bumpmap: factor on the height gradient
        flip_invalid_normals    bool     true     flip normals facing away from the incident side
        use_shadowing_function  bool     true     Estevez et al.'s shadowing term
        (a BSDF key)            BSDF     -        the nested BSDF
        ======================  =======  =======  ===============================================
        """
        kind, slot, scale, flip, shadow, key = perturb.parse(loader, props, bsdf_names())
        inner = loader.bsdf(props.raw(key), props.key(key))
        props.finish()
        if inner in self.perturb_of or inner in self.blend_of:
            raise props.error(key, f"a {props.type} cannot wrap another normal/bump map or a blend")
        self.entries.append(self.entries[inner])
        self.perturb_of[len(self.entries) - 1] = (kind, slot, scale, flip, shadow)
        return len(self.entries) - 1

    def _add_mask(self, loader, props) -> int:
        """``mask`` (Mitsuba's): light passes straight through with probability 1 - opacity.

        =======  =======  =======  =============================================
        name     type     default  meaning
        =======  =======  =======  =============================================
        opacity  texture  0.5      opacity (first wavelength), clamped to [0, 1]
        (a key)  BSDF     -        the nested BSDF
        =======  =======  =======  =============================================
        """
        nested = [k for k, v in props.children() if k != "opacity"]
        if len(nested) != 1:
            raise props.error(None, f"mask takes exactly one nested BSDF, got {len(nested)}")
        opacity = load_spectrum(loader, props.raw("opacity", 0.5), props.key("opacity"), emitter=False, valid=UNIT,
                                scalar=True)
        inner = loader.bsdf(props.raw(nested[0]), props.key(nested[0]))
        props.finish()
        fam, local, back, op = self.entries[inner]
        if op != NO_BACK:
            raise props.error(nested[0], "a mask cannot contain another mask")
        self.entries.append((fam, local, back, opacity))
        if inner in self.perturb_of:
            self.perturb_of[len(self.entries) - 1] = self.perturb_of[inner]
        return len(self.entries) - 1

    def _add_twosided(self, loader, props) -> int:
        """``twosided`` (Mitsuba's): the back side uses the second nested BSDF, or the first
        one mirrored.

        =================  ====  =======  =============================
        name               type  default  meaning
        =================  ====  =======  =============================
        (one or two keys)  BSDF  -        front BSDF, then the back one
        =================  ====  =======  =============================
        """
        nested = [k for k, v in props.children()]
        if not 1 <= len(nested) <= 2:
            raise props.error(None, f"twosided takes one or two nested BSDFs, got {len(nested)}")
        ids = [loader.bsdf(props.raw(k), props.key(k)) for k in nested]
        props.finish()
        for i, k in zip(ids, nested):
            if self.entries[i][2] != NO_BACK:
                raise props.error(k, "a twosided BSDF cannot contain another twosided BSDF")
        front, back = ids[0], ids[-1]
        fam, local, _, opacity = self.entries[front]
        self.entries.append((fam, local, back, opacity))
        if front in self.perturb_of:
            self.perturb_of[len(self.entries) - 1] = self.perturb_of[front]
        return len(self.entries) - 1

    def build(self, textures) -> None:
        self.order = list(self.families)
        for f in self.families.values():
            f.textures = textures
            f.build()
        self.textures = textures
        self.family_of = mi.UInt32([self.order.index(t) for t, _, _, _ in self.entries])
        self.local_of = mi.UInt32([i for _, i, _, _ in self.entries])
        self.back_of = mi.UInt32([b for _, _, b, _ in self.entries])
        self.opacity_of = mi.UInt32([o for _, _, _, o in self.entries])
        self.opacity_reach = tuple(o for _, _, _, o in self.entries if o != NO_BACK)
        self.twosided = any(b != NO_BACK for _, _, b, _ in self.entries)
        n = len(self.entries)
        blend = [self.blend_of.get(i, (i, i, NO_BACK)) for i in range(n)]
        self.blend_a = mi.UInt32([x[0] for x in blend])
        self.blend_b = mi.UInt32([x[1] for x in blend])
        self.blend_w = mi.UInt32([x[2] for x in blend])
        self.blend_reach = tuple(x[2] for x in blend if x[2] != NO_BACK)
        self.blends = bool(self.blend_of)
        # The families a blend's components (and their twosided back sides) belong to: a
        # blend's evaluations of its other component dispatch over these only, not over
        # every family of the scene (the gallery's blend of a diffuse and a rough
        # conductor traced all 16 families twice more per vertex).
        comp = {e for a, b, _ in self.blend_of.values() for e in (a, b)}
        comp |= {self.entries[e][2] for e in comp if self.entries[e][2] != NO_BACK}
        comp_fams = {self.entries[e][0] for e in comp}
        self.component_families = [t for t in self.order if t in comp_fams]
        self.component_family_of = mi.UInt32([self.component_families.index(t) if t in comp_fams else 0
                                              for t, _, _, _ in self.entries])
        # Which entry attributes blend components have (evaluating a component skips the others).
        self.components_masked = any(self.entries[e][3] != NO_BACK for e in comp)
        self.components_twosided = any(self.entries[e][2] != NO_BACK for e in comp)
        self.components_perturbed = any(e in self.perturb_of for e in comp)
        self.mixed_delta = mi.Bool([i in self.blend_mixed_delta for i in range(n)]) if self.blend_mixed_delta else None
        pert = [self.perturb_of.get(i, (0, NO_BACK, 0.0, True, True)) for i in range(n)]
        self.pert_kind = mi.UInt32([x[0] for x in pert])
        self.pert_slot = mi.UInt32([x[1] for x in pert])
        self.pert_scale = mi.Float([x[2] for x in pert])
        kinds = {x[0] for x in self.perturb_of.values()}
        self.pert_kinds = kinds
        self.pert_differenced = tuple(sorted({x[1] for x in self.perturb_of.values()
                                              if x[0] == perturb.BUMP_DIFFERENCED}))
        self.pert_flip = {x[3] for x in self.perturb_of.values()}
        self.pert_shadow = {x[4] for x in self.perturb_of.values()}
        if len(self.pert_flip) > 1 or len(self.pert_shadow) > 1:
            raise SceneError("scene: normal/bump maps of one scene must share flip_invalid_normals "
                             "and use_shadowing_function (for now)")
        # Entries with a non-delta lobe (light sampling is pointless on the others).
        fam_smooth = {t: bool(f.flags & (DIFFUSE | GLOSSY)) for t, f in self.families.items()}
        smooth = [fam_smooth[t] for t, _, _, _ in self.entries]
        for i, (a, b, _) in self.blend_of.items():
            smooth[i] = smooth[a] or smooth[b]
        self.smooth_of = mi.Bool(smooth)
        self.all_smooth = all(smooth)
        # Entries that regularisation makes glossy (smooth conductors and dielectrics).
        glossy = [self.families[t].regularizes_to_glossy for t, _, _, _ in self.entries]
        for i, (a, b, _) in self.blend_of.items():
            glossy[i] = glossy[a] or glossy[b]
        self.regularized_smooth_of = mi.Bool(glossy)
        self.any_regularizes = any(glossy)
        # Entries whose sample weight is a random estimate (see BSDFType.stochastic).
        stoch = [self.families[t].stochastic or (b != NO_BACK and self.families[self.entries[b][0]].stochastic)
                 for t, _, b, _ in self.entries]
        for i, (a, b, _) in self.blend_of.items():
            stoch[i] = stoch[a] or stoch[b]
        self.stochastic_of = mi.Bool(stoch)
        self.any_stochastic = any(stoch)
        self.masked = any(o != NO_BACK for _, _, _, o in self.entries)
        # Pure ``null`` entries: index-matched medium boundaries, skipped by volpath.
        null = [t == "null" and i not in self.blend_of for i, (t, _, _, _) in enumerate(self.entries)]
        self.null_of = mi.Bool(null)
        self.has_null = any(null)
        # Plain entries of families with a null lobe (thindielectric): see null_transmission.
        lobe = [self.families[t].null_lobe and i not in self.blend_of and i not in self.perturb_of
                and b == NO_BACK and o == NO_BACK for i, (t, _, b, o) in enumerate(self.entries)]
        self.null_lobe_of = mi.Bool(lobe)
        self.has_null_lobes = any(lobe)
        # Plain ``subsurface`` entries: volpath carries light refracted into them to an
        # exit point (integrators/subsurface.py).
        sss = [t == "subsurface" and i not in self.blend_of and i not in self.perturb_of and b == NO_BACK
               and o == NO_BACK for i, (t, _, b, o) in enumerate(self.entries)]
        self.subsurface_of = mi.Bool(sss)
        self.has_subsurface = any(sss)
        if any(t == "subsurface" and not p for (t, _, _, _), p in zip(self.entries, sss)):
            warnings.warn("subsurface inside twosided, mask, a blend or a normal/bump map: rendered as its "
                          "dielectric boundary only (no subsurface transport)", RuntimeWarning, stacklevel=2)

    def smooth(self, bsdf_id, active, regularize=None):
        """True where the entry has a non-delta lobe (worth sampling a light for), and
        where ``regularize`` (a mask: pbrt-v4's BSDF regularisation) makes a smooth
        conductor or dielectric glossy."""
        if self.all_smooth:
            return mi.Bool(True)
        s = dr.gather(mi.Bool, self.smooth_of, bsdf_id, active)
        if regularize is not None and self.any_regularizes:
            s |= regularize & dr.gather(mi.Bool, self.regularized_smooth_of, bsdf_id, active & regularize)
        return s

    def stochastic(self, bsdf_id, active):
        """True where the entry's sample weight is a random estimate that ``eval`` does not
        reproduce (a layered BSDF): gradients differentiate the sample's own weight."""
        if not self.any_stochastic:
            return mi.Bool(False)
        return dr.gather(mi.Bool, self.stochastic_of, bsdf_id, active)

    def is_null(self, bsdf_id, active):
        """True where the entry is a pure ``null`` BSDF (light passes unchanged)."""
        if not self.has_null:
            return mi.Bool(False)
        return dr.gather(mi.Bool, self.null_of, bsdf_id, active)

    def has_null_lobe(self, bsdf_id, active):
        """True where the entry has a lobe passing light straight on (Mitsuba's Null flag,
        e.g. ``thindielectric``'s transmission)."""
        if not self.has_null_lobes:
            return mi.Bool(False)
        return dr.gather(mi.Bool, self.null_lobe_of, bsdf_id, active)

    def null_transmission(self, bsdf_id, ctx, active):
        """Weight of light passing entry ``bsdf_id`` straight on (``ctx.si.wi``: the local
        direction it arrives from): 1 for ``null``, the null lobe's weight for entries
        with one (Mitsuba's ``eval_null_transmission``), 0 elsewhere."""
        out = dr.select(self.is_null(bsdf_id, active), mi.Spectrum(1.0), mi.Spectrum(0.0))
        if not self.has_null_lobes:
            return out
        lanes = active & self.has_null_lobe(bsdf_id, active)
        local = dr.gather(mi.UInt32, self.local_of, bsdf_id, lanes)
        fam_of = dr.gather(mi.UInt32, self.family_of, bsdf_id, lanes)
        for t, fam in self.families.items():
            if fam.null_lobe:
                on = lanes & (fam_of == self.order.index(t))
                out = dr.select(on, fam.null_transmission(ctx, local, on), out)
        return out

    def subsurface(self, bsdf_id, active):
        """(lanes at a plain ``subsurface`` entry, the ``subsurface`` family, its instance
        index on those lanes); only called when :attr:`has_subsurface`."""
        lanes = active & dr.gather(mi.Bool, self.subsurface_of, bsdf_id, active)
        return lanes, self.families["subsurface"], dr.gather(mi.UInt32, self.local_of, bsdf_id, lanes)

    @property
    def dispersive(self) -> bool:
        """Whether some BSDF refracts by a wavelength-dependent IOR."""
        return any(getattr(f, "dispersive", False) for f in self.families.values())

    @property
    def refracts(self) -> bool:
        """Whether some BSDF's samples can have a relative IOR other than 1 (Russian
        roulette then scales by it)."""
        return any(f.refracts for f in self.families.values())

    def has_flag(self, flag: int) -> bool:
        return any(f.flags & flag for f in self.families.values())

    def entry_flags(self) -> list[int]:
        """Lobe flags of every entry (after ``build``): its family's, both components' for
        a blend, plus TRANSMISSION where a mask lets light through."""
        def flags(i):
            t, _, _, opacity = self.entries[i]
            fl = self.families[t].flags | (TRANSMISSION if opacity != NO_BACK else 0)
            if i in self.blend_of:
                a, b, _ = self.blend_of[i]
                fl |= flags(a) | flags(b)
            return fl
        return [flags(i) for i in range(len(self.entries))]

    def shading_normal(self, bsdf_id, ctx, active):
        """World shading normal of entry ``bsdf_id`` at ``ctx.si``, after its normal or
        bump map (Mitsuba's ``BSDF::sh_frame``)."""
        n = ctx.si.sh_frame.n
        pert = self._perturb(bsdf_id, ctx, active)
        if pert is None:
            return n
        _, frame, has = pert
        return dr.select(has, ctx.si.to_world(frame.n), n)

    def _dispatch(self, method, bsdf_id, ctx, active, *args, components=False):
        """``method`` of each lane's family; ``components``: the active lanes hold blend
        components only, so only their families are dispatched over."""
        local = dr.gather(mi.UInt32, self.local_of, bsdf_id, active)
        order, family_of = ((self.component_families, self.component_family_of) if components
                            else (self.order, self.family_of))
        fams = [self.families[t] for t in order]
        if len(fams) == 1:
            return _cast(getattr(fams[0], method)(ctx, local, *args, active))
        fam = dr.gather(mi.UInt32, family_of, bsdf_id, active)
        return dispatch.switch(fam, [_typed(getattr(f, method)) for f in fams], ctx, local, *args, active)

    def _side(self, bsdf_id, ctx, active, components=False):
        """(entry to use, context, flip mask) after applying two-sidedness."""
        if not self.twosided or (components and not self.components_twosided):
            return bsdf_id, ctx, None
        back = dr.gather(mi.UInt32, self.back_of, bsdf_id, active)
        flip = (back != NO_BACK) & (ctx.si.wi.z < 0)
        si = mi.SurfaceInteraction3f(ctx.si)
        si.wi = _flip(si.wi, flip)
        return dr.select(flip, back, bsdf_id), ctx.at(si), flip

    def _opacity(self, bsdf_id, ctx, active, components=False):
        """Opacity of masked entries (1 elsewhere), or None if the scene has no mask
        (``components``: among the entries that blends contain)."""
        if not self.masked or (components and not self.components_masked):
            return None
        slot = dr.gather(mi.UInt32, self.opacity_of, bsdf_id, active)
        has = active & (slot != NO_BACK)

        def lookup():
            o = self.textures.eval(slot, ctx.si, ctx.wl.lambda_, has, illuminant=False, reach=self.opacity_reach)[0]
            return mi.Float(dr.select(has, dr.clip(o, 0.0, 1.0), 1.0))
        return dispatch.when_any(has, lookup, otherwise=mi.Float(1.0), label="opacity")

    def _perturb(self, bsdf_id, ctx, active, components=False):
        """(context in the perturbed frame, local frame, mask) for normal/bump-mapped
        entries, or None if the scene has none."""
        if not self.perturb_of or (components and not self.components_perturbed):
            return None
        kinds = self.pert_kinds
        kind = dr.gather(mi.UInt32, self.pert_kind, bsdf_id, active)
        has = active & (kind != 0)
        slot = dr.gather(mi.UInt32, self.pert_slot, bsdf_id, has)
        flip = next(iter(self.pert_flip))
        si = mi.SurfaceInteraction3f(ctx.si)
        frame = mi.Frame3f(mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0), mi.Vector3f(0, 0, 1))
        if kinds & {perturb.NORMAL, perturb.BUMP}:
            raw = has & (kind != perturb.BUMP_DIFFERENCED) if perturb.BUMP_DIFFERENCED in kinds else has
            value, du, dv = self.textures.eval_raw(slot, ctx.si.uv, raw)
        if perturb.NORMAL in kinds:
            fn = perturb.normalmap_frame(value, si.wi, flip)
            frame = dr.select(has & (kind == perturb.NORMAL), fn, frame)
        if kinds & {perturb.BUMP, perturb.BUMP_DIFFERENCED}:
            bump = has & ((kind == perturb.BUMP) | (kind == perturb.BUMP_DIFFERENCED))
            scale = dr.gather(mi.Float, self.pert_scale, bsdf_id, bump)
            if perturb.BUMP in kinds:
                gu, gv = luminance_rgb(du), luminance_rgb(dv)
            if perturb.BUMP_DIFFERENCED in kinds:
                diff = has & (kind == perturb.BUMP_DIFFERENCED)
                hu, hv = perturb.height_gradient(self.textures, slot, ctx.si, ctx.wl.lambda_, diff,
                                                 reach=self.pert_differenced)
                gu, gv = (hu, hv) if perturb.BUMP not in kinds else (dr.select(diff, hu, gu), dr.select(diff, hv, gv))
            fb = perturb.bumpmap_frame(si, gu * scale, gv * scale, flip)
            frame = dr.select(bump, fb, frame)
        si.wi = frame.to_local(ctx.si.wi)
        return ctx.at(si), frame, has

    def _resolve(self, bsdf_id, ctx, wo, active, components=False):
        """Apply the entry attributes that change the frame: the side (twosided, with
        ``wo`` mirrored alongside) and the normal/bump perturbation. Returns (entry,
        context, wo, flip mask or None, perturbation or None)."""
        bsdf_id, ctx, flip = self._side(bsdf_id, ctx, active, components)
        if flip is not None and wo is not None:
            wo = _flip(wo, flip)
        return bsdf_id, ctx, wo, flip, self._perturb(bsdf_id, ctx, active, components)

    @staticmethod
    def _to_perturbed(frame, has, wo):
        """``wo`` in the perturbed frame, and where it lies on the same side of both
        surfaces (elsewhere a normal/bump map would leak light)."""
        wo_p = frame.to_local(wo)
        return wo_p, ~has | (wo.z * wo_p.z > 0)

    def _perturbed_value(self, frame, has, wo, ok, f, pdf=None):
        """Apply the shadow-terminator term and the leak mask to values toward ``wo``."""
        if next(iter(self.pert_shadow)):
            f = f * dr.select(has, perturb.shadow_terminator(frame.n, wo), 1.0)
        return dr.select(ok, f, 0.0), (None if pdf is None else dr.select(ok, pdf, 0.0))

    def _entry_eval_pdf(self, bsdf_id, ctx, wo, active, components=False):
        opacity = self._opacity(bsdf_id, ctx, active, components)
        bsdf_id, ctx, wo, flip, pert = self._resolve(bsdf_id, ctx, wo, active, components)
        if pert is not None:
            ctx, frame, has = pert
            wo_p, ok = self._to_perturbed(frame, has, wo)
            f, pdf = self._dispatch("eval_pdf", bsdf_id, ctx, active & ok, wo_p, components=components)
            f, pdf = self._perturbed_value(frame, has, wo, ok, f, pdf)
        else:
            f, pdf = self._dispatch("eval_pdf", bsdf_id, ctx, active, wo, components=components)
        if opacity is not None:
            f, pdf = f * opacity, pdf * opacity
        return f, pdf

    def _dispatch_eval_pdf_sample(self, bsdf_id, ctx, active, wo, u1, u2):
        """The families' ``eval_pdf_sample``, or their ``sample`` alone (f, pdf None)
        when there is no ``wo`` to evaluate."""
        if wo is None:
            return None, None, self._dispatch("sample", bsdf_id, ctx, active, u1, u2)
        return self._dispatch("eval_pdf_sample", bsdf_id, ctx, active, wo, u1, u2)

    def _entry_eval_pdf_sample(self, bsdf_id, ctx, wo, u1, u2, active):
        opacity = self._opacity(bsdf_id, ctx, active)
        wi_world_side = ctx.si.wi
        if opacity is not None:
            # Pass straight through with probability 1 - opacity; reuse u1 otherwise.
            through = u1 >= opacity
            u1 = dr.select(through, u1, u1 / dr.maximum(opacity, 1e-12))
        bsdf_id, ctx, wo, flip, pert = self._resolve(bsdf_id, ctx, wo, active)
        if pert is not None:
            ctx, frame, has = pert
            wo_p, ok = (None, None) if wo is None else self._to_perturbed(frame, has, wo)
            f, pdf, bs = self._dispatch_eval_pdf_sample(bsdf_id, ctx, active, wo_p, u1, u2)
            if wo is not None:
                f, pdf = self._perturbed_value(frame, has, wo, ok, f, pdf)
            wo_s = dr.select(has, frame.to_world(bs.wo), bs.wo)
            ok_s = ~has | (bs.wo.z * wo_s.z > 0)
            bs.wo = wo_s
            bs.weight = self._perturbed_value(frame, has, wo_s, ok_s, bs.weight)[0]
            bs.pdf = dr.select(ok_s, bs.pdf, 0.0)
        else:
            f, pdf, bs = self._dispatch_eval_pdf_sample(bsdf_id, ctx, active, wo, u1, u2)
        if flip is not None:
            bs.wo = _flip(bs.wo, flip)
        if opacity is not None:
            if wo is not None:
                f, pdf = f * opacity, pdf * opacity
            bs.pdf = bs.pdf * opacity
            null = pass_through(wi_world_side, 1.0 - opacity, active & through)
            bs = dr.select(through, _cast(null), _cast(bs))
        return f, pdf, bs

    # -- public interface: handles blends over the entry-level methods above --------------
    def _blend(self, bsdf_id, ctx, active):
        """(component a, component b, weight of b, is-blend mask) per lane."""
        slot = dr.gather(mi.UInt32, self.blend_w, bsdf_id, active)
        is_blend = active & (slot != NO_BACK)

        def lookup():
            w = self.textures.eval(slot, ctx.si, ctx.wl.lambda_, is_blend, illuminant=False, reach=self.blend_reach)[0]
            a = dr.select(is_blend, dr.gather(mi.UInt32, self.blend_a, bsdf_id, is_blend), bsdf_id)
            b = dr.gather(mi.UInt32, self.blend_b, bsdf_id, is_blend)
            # (the clip keeps w's derivative: at a weight of 0 or 1, dr.clip's is 0 and an
            # optimiser starting from one component alone could never leave it)
            return a, b, mi.Float(dr.select(is_blend, clamp_keep_grad(w, 0.0, 1.0), 0.0))
        a, b, w = dispatch.when_any(is_blend, lookup, otherwise=(mi.UInt32(bsdf_id), mi.UInt32(0), mi.Float(0.0)),
                                    label="blend weight")
        return a, b, w, is_blend

    def eval_pdf(self, bsdf_id, ctx, wo, active):
        """(f |cos theta_o|, pdf) of entry ``bsdf_id`` for local direction ``wo``."""
        if not self.blends:
            return self._entry_eval_pdf(bsdf_id, ctx, wo, active)
        a, b, w, is_blend = self._blend(bsdf_id, ctx, active)
        fa, pa = self._entry_eval_pdf(a, ctx, wo, active)
        fb, pb = self._entry_eval_pdf(b, ctx, wo, is_blend, components=True)
        return dr.fma(w, fb - fa, fa), dr.fma(w, pb - pa, pa)

    def sample(self, bsdf_id, ctx, u1, u2, active) -> BSDFSample:
        """A sampled direction of entry ``bsdf_id`` (no evaluation toward another ``wo``)."""
        return self.eval_pdf_sample(bsdf_id, ctx, None, u1, u2, active)[2]

    def eval_pdf_sample(self, bsdf_id, ctx, wo, u1, u2, active):
        """``eval_pdf(wo)`` and a sampled direction at once (``wo`` None: the sample only,
        f and pdf None). For a blend, one component is sampled (chosen with its weight) but
        a non-delta sample reports the mixture's pdf and f / pdf, so that MIS sees the
        density the direction really has."""
        if not self.blends:
            return self._entry_eval_pdf_sample(bsdf_id, ctx, wo, u1, u2, active)
        a, b, w, is_blend = self._blend(bsdf_id, ctx, active)
        take_b = is_blend & (u1 < w)
        u1 = dr.select(is_blend, dr.select(take_b, u1 / dr.maximum(w, 1e-12), (u1 - w) / dr.maximum(1.0 - w, 1e-12)), u1)
        chosen = dr.select(take_b, b, a)
        f, pdf, bs = self._entry_eval_pdf_sample(chosen, ctx, wo, u1, u2, active)
        # The other component (toward wo and toward the sampled direction), in a
        # conditional: vector packets without a blend lane skip it.
        if wo is None:
            keep = (mi.Float(bs.pdf), mi.Spectrum(bs.weight))
        else:
            keep = (_cast(f), _cast(pdf), mi.Float(bs.pdf), mi.Spectrum(bs.weight))
        r = dispatch.when_any(is_blend, lambda: self._mix_other(bsdf_id, ctx, wo, a, b, w, take_b, is_blend, *keep,
                                                                bs.wo, bs.delta), otherwise=keep, label="blend")
        if wo is None:
            bs.pdf, bs.weight = r
        else:
            f, pdf, bs.pdf, bs.weight = r
        return f, pdf, bs

    def _mix_other(self, bsdf_id, ctx, wo, a, b, w, take_b, is_blend, *values):
        """A blend's mixture on ``is_blend`` lanes, given its chosen component's values
        ((f, pdf) toward ``wo`` unless it is None, then the sample's pdf and weight,
        direction and delta flag): the other component evaluated toward ``wo`` and toward
        the sampled direction. Returns the mixed values in the order given."""
        *fp, bs_pdf, bs_weight, bs_wo, bs_delta = values
        other = dr.select(take_b, a, b)
        wc = dr.select(take_b, w, 1.0 - w)
        if wo is not None:
            f, pdf = fp
            fo, po = self._entry_eval_pdf(other, ctx, wo, is_blend, components=True)
            fp = [mi.Spectrum(dr.select(is_blend, wc * f + (1.0 - wc) * fo, f)),
                  mi.Float(dr.select(is_blend, wc * pdf + (1.0 - wc) * po, pdf))]
        # The sampled direction: mixture density and weight unless the lobe was a delta
        # (which Mitsuba's blendbsdf mixes as well: ``delta_lobes``).
        mix = is_blend & (bs_pdf > 0)
        if self.mixed_delta is None:
            mix &= ~bs_delta
        else:
            mix &= ~bs_delta | dr.gather(mi.Bool, self.mixed_delta, bsdf_id, is_blend)
        f2, p2 = self._entry_eval_pdf(other, ctx, bs_wo, mix, components=True)
        p_mix = wc * bs_pdf + (1.0 - wc) * p2
        f_mix = wc * bs_weight * bs_pdf + (1.0 - wc) * f2
        weight = mi.Spectrum(dr.select(mix, f_mix / dr.maximum(p_mix, 1e-30), bs_weight))
        pdf_s = mi.Float(dr.select(mix, p_mix, dr.select(is_blend, bs_pdf * wc, bs_pdf)))
        return (*fp, pdf_s, weight)


# Wrapper type name -> the BSDFSet method that parses it.
WRAPPERS = {"twosided": "_add_twosided", "mask": "_add_mask", "blendbsdf": "_add_blend", "mix": "_add_blend",
            "normalmap": "_add_perturbed", "bumpmap": "_add_perturbed"}


def bsdf_names() -> set:
    """Every type name that describes a BSDF (families and wrappers)."""
    return set(BSDF_TYPES) | set(WRAPPERS)


def _flip(v, mask):
    """Mirror a local direction through the surface where ``mask``."""
    return mi.Vector3f(v.x, v.y, dr.select(mask, -v.z, v.z))


def _cast(v):
    """Identical types for values of any family (``dr.switch``/``dr.select`` need them):
    spectra as ``mi.Spectrum``, densities as ``mi.Float``."""
    if isinstance(v, BSDFSample):
        return BSDFSample(mi.Vector3f(v.wo), mi.Float(v.pdf), mi.Float(v.eta), mi.Bool(v.delta),
                          mi.Spectrum(v.weight), mi.Bool(v.terminate), mi.Bool(v.null))
    if isinstance(v, tuple):
        return tuple(_cast(x) for x in v)
    if dr.size_v(v) == 4:
        return mi.Spectrum(v)
    return mi.Float(v)


def _typed(fn):
    """Wrap a family method so that every family returns identical types."""
    def wrapped(*args):
        return _cast(fn(*args))
    return wrapped
