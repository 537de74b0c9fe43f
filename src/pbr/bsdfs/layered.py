"""Layered BSDFs (pbrt-v4's ``coateddiffuse`` and ``coatedconductor``): a dielectric
coating over a diffuse or conductor base, with an optional homogeneous medium between,
evaluated and sampled by stochastic random walks. The model and its costs:
docs/layered.md.
"""

from __future__ import annotations

import numbers
import os

import drjit as dr
import mitsuba as mi

from .. import dispatch
from ..phase import hg, hg_pdf, hg_sample
from ..plugins.params import ParamOwner, param_table
from ..plugins.props import HG_ASYMMETRY, IOR, NONNEGATIVE, ROUGHNESS
from ..sampling import cosine_hemisphere_pdf, mix32, power_heuristic, square_to_cosine_hemisphere
from ..spectrum import clamp_keep_grad, read_spd
from ..textures import add_tabulated, load_spectrum
from .base import BSDF_TYPES, BSDFSample, BSDFType, DIFFUSE, GLOSSY, REFLECTION, SPECULAR, TRANSMISSION
from .conductor import _IOR_DIR   # Mitsuba's measured metal data
from .dielectric import (BOTH, _ior_spectrum, rough_dielectric_eval, rough_dielectric_sample,
                         smooth_dielectric_sample)
from .fresnel import fresnel_conductor, reflect, reflect_about
from .microfacet import GGX, Microfacet

_NONE = 0xFFFFFFFF
_FLT_MIN = 1.1754944e-38
_SMOOTH_ALPHA = 1e-3        # pbrt-v4's "effectively smooth" threshold
SMOOTH, ROUGH, MIXED = "smooth", "rough", "mixed"


# ----------------------------------------------------------------------- helpers

def _hash(*values, salt=0x9E3779B9):
    """Hash of the float bits of ``values`` (per lane)."""
    h = mi.UInt32(salt)
    for v in values:
        h = mix32(h ^ dr.reinterpret_array(mi.UInt32, mi.Float(v)) ^ 0x85EBCA6B)
    return h


def _rng(a, b):
    """A PCG32 stream per lane, determined by the two value tuples ``a`` and ``b``."""
    ha, hb = _hash(*a), _hash(*b, salt=0x632BE5AB)
    rng = mi.PCG32()
    rng.seed((mi.UInt64(ha) << 32) | mi.UInt64(hb), mi.UInt64(_hash(*b, *a, salt=0x1B873593)))
    return rng


def _tr(dz, w):
    """Transmittance of the unit-extinction slab over height ``dz`` along ``w``."""
    return dr.select(dr.abs(dz) <= _FLT_MIN, 1.0, dr.exp(-dr.abs(dz / w.z)))


class _Sample:
    """An interface sample: direction, f |cos| / pdf, pdf, validity, reflected mask."""

    def __init__(self, w, weight, pdf, ok, refl):
        self.w, self.weight, self.pdf, self.ok, self.refl = w, weight, pdf, ok, refl


def _select(mask, a: _Sample, b: _Sample) -> _Sample:
    return _Sample(*(dr.select(mask, x, y) for x, y in
                     zip((a.w, a.weight, a.pdf, a.ok, a.refl), (b.w, b.weight, b.pdf, b.ok, b.refl))))


class _Flight:
    """The outcome of one step of a layered random walk (see :func:`_free_flight`)."""

    def __init__(self, cur, z, beta, zp, dz_top, inside, ps: _Sample):
        self.cur, self.z, self.beta, self.zp, self.dz_top, self.inside, self.ps = cur, z, beta, zp, dz_top, inside, ps


def _free_flight(cur, z, w, beta, thick, g, in_medium, u_dz, u, medium: bool, ad: bool) -> _Flight:
    """One step of a layered random walk from height ``z`` along ``w`` (lanes ``cur``).

    Without a medium (or where ``in_medium`` is false) the walk crosses the slab to the
    other interface, attenuated by its transmittance. In a medium an exponential free
    flight either stops inside (``inside``; the presampled HG direction ``ps`` scatters
    where ``ps.ok``) or reaches an interface. A zero free flight (u = 0) is neither: it
    is drawn again at the next event (pbrt-v4 fails it, a 2^-24 chance per event and an
    energy loss). Returns the lanes now at an interface (``cur``), their height ``z``,
    ``beta``, the flight's end ``zp`` and its signed height below the top ``dz_top``.

    With ``ad`` (reverse mode) the heights are those of the detached thickness (the walk
    is fixed in units of the slab's height, as a path replay fixes its samples), and the
    weights carry the derivatives: the slab is then one of unit height and extinction
    ``thickness``, whose flight densities T exp(-T s) (collision) and exp(-T s) (escape)
    are divided by their detached values; ``dz_top`` scales with the thickness."""
    thick0 = dr.detach(thick) if ad else thick
    flip_z = dr.select(z == thick0, 0.0, thick0)
    if not medium:
        z = dr.select(cur, flip_z, z)
        beta = dr.select(cur, beta * _tr(thick, w), beta)
        no = mi.Bool(False)
        return _Flight(cur, z, beta, z, z - thick, no, _Sample(mi.Vector3f(w), mi.Float(1.0), mi.Float(0.0), no, no))
    med = cur & in_medium
    tau = -dr.log(1.0 - u_dz)
    dz = tau * dr.abs(w.z)
    zp = dr.select(w.z > 0, z + dz, z - dz)
    same = med & (zp == z)
    inside = med & ~same & (zp > 0) & (zp < thick0)
    ps = _hg_sample(-w, g, u, ad)
    ps.ok = inside & (ps.pdf > 0) & (ps.w.z != 0)
    cur = cur & ~(same | inside)
    z_new = dr.select(cur, dr.select(med, dr.clip(zp, 0.0, thick0), flip_z), z)
    beta = dr.select(cur & ~med, beta * _tr(thick, w), beta)
    dz_top = zp - thick
    if ad:
        r = thick / thick0                                  # 1, with d/d thickness
        escape = dr.exp((1.0 - r) * dr.abs(z_new - z) / dr.abs(w.z))
        beta = dr.select(inside, beta * (r * dr.exp((1.0 - r) * tau)), dr.select(cur & med, beta * escape, beta))
        dz_top = (zp - thick0) * r
    return _Flight(cur, z_new, beta, zp, dz_top, inside, ps)


def _reweighted(s: _Sample, f) -> _Sample:
    """``s``, drawn with detached parameters, with a weight whose derivative is that of
    ``f``, the attached f |cos| (or phase function) at its direction, over its detached
    density. Reverse mode differentiates the walks this way, as a path replay does its
    path: with the sampling fixed and the integrand moving (attached sampling would move
    directions whose effect further along is not differentiated)."""
    ratio = type(f)(dr.select(f != 0, f / dr.detach(f), 0.0))
    s.weight = type(s.weight)(s.weight * dr.replace_grad(type(f)(1.0), ratio))
    return s


def _hg_sample(wo, g, u, ad: bool) -> _Sample:
    """Henyey-Greenstein sample for a walk arriving along ``-wo``; weight 1."""
    if ad:
        with dr.suspend_grad():
            s = _hg_sample(wo, g, u, False)
        return _reweighted(s, hg_pdf(wo, s.w, g))
    w, pdf = hg_sample(wo, g, u)
    return _Sample(w, mi.Float(1.0), pdf, mi.Bool(True), mi.Bool(False))


def _kind(kinds):
    kinds = set(kinds)
    return kinds.pop() if len(kinds) == 1 else MIXED


def _number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


# ---------------------------------------------------------------- the interfaces

class _Top:
    """The dielectric coating (interior below, z < 0), per lane: relative IOR ``eta``,
    GGX roughness; ``kind`` (a Python constant) says which code the kernel needs."""

    def __init__(self, eta, au, av, kind):
        self.eta, self.kind = eta, kind
        self.rough = kind != SMOOTH
        if kind == MIXED:
            self.smooth = (eta == 1) | (dr.maximum(au, av) < _SMOOTH_ALPHA)
        else:
            self.smooth = mi.Bool(kind == SMOOTH)
        if self.rough:
            self.md = Microfacet(GGX, au, av, True)

    def sample(self, wo, uc, u, lobes=BOTH, ad=False) -> _Sample:
        """Sample from ``wo``; the weight is for radiance transport. ``ad``: see
        :func:`_reweighted` (a smooth lane's value is its lobe's weight times choice
        probability: the Fresnel term)."""
        if ad:
            with dr.suspend_grad():
                s = self.sample(wo, uc, u, lobes)
            f = None
            if self.kind != ROUGH:
                _, pdf, weight, _, _, _ = smooth_dielectric_sample(wo, self.eta, uc, lobes)
                f = weight * pdf
            if self.rough:
                fr = self.eval_pdf(wo, s.w, lobes)[0]
                f = fr if f is None else dr.select(self.smooth, f, fr)
            return _reweighted(s, f)
        out = None
        if self.kind != ROUGH:
            w, pdf, weight, refl, _, _ = smooth_dielectric_sample(wo, self.eta, uc, lobes)
            out = _Sample(w, weight, pdf, (wo.z != 0) & (weight > 0) & (pdf > 0), refl)
        if self.rough:
            md = self.md
            w, pdf, weight, refl, _, ok = rough_dielectric_sample(
                wo, self.eta, md.sample, lambda wo_, m, d_i: md.G1(wo_, m), uc, u, lobes)
            r = _Sample(w, weight, pdf, ok & (weight > 0), refl)
            out = r if out is None else _select(self.smooth, out, r)
        return out

    def eval_pdf(self, wo, wi, lobes=BOTH):
        """(f |cos wi|, density of sampling wi restricted to ``lobes``): 0 where smooth."""
        if not self.rough:
            return mi.Float(0.0), mi.Float(0.0)
        md = self.md

        def micro(m):
            return md.D(m) * md.G(wo, wi, m), md.pdf(dr.mulsign(wo, wo.z), m)

        val, pdf, _, ok = rough_dielectric_eval(wo, wi, self.eta, micro, lobes)
        ok = ok & ~self.smooth
        return dr.select(ok, val, 0.0), dr.select(ok, pdf, 0.0)


class _DiffuseBase:
    """Lambertian base (pbrt's DiffuseBxDF: reflects on the side of its argument)."""

    rough = True

    def __init__(self, r):
        self.r = r
        self.specular = mi.Bool(False)

    def sample(self, wo, uc, u, ad=False) -> _Sample:
        # The direction does not depend on the parameters: no reweighting for ``ad``.
        w = square_to_cosine_hemisphere(u)
        ok = (wo.z > 0) & (w.z > 0)
        return _Sample(w, mi.Spectrum(dr.select(ok, self.r, 0.0)), cosine_hemisphere_pdf(w), ok, mi.Bool(True))

    def eval_pdf(self, wo, wi):
        ok = (wo.z > 0) & (wi.z > 0)
        return dr.select(ok, self.r * (wi.z * dr.inv_pi), 0.0), dr.select(ok, cosine_hemisphere_pdf(wi), 0.0)


class _ConductorBase:
    """Conductor base (smooth or GGX), complex IOR relative to the coating."""

    def __init__(self, eta, k, au, av, kind):
        self.eta, self.k, self.kind = eta, k, kind
        self.rough = kind != SMOOTH
        if kind == MIXED:
            self.specular = dr.maximum(au, av) < _SMOOTH_ALPHA
        else:
            self.specular = mi.Bool(kind == SMOOTH)
        if self.rough:
            self.md = Microfacet(GGX, au, av, True)

    def sample(self, wo, uc, u, ad=False) -> _Sample:
        if ad and self.rough:       # see _reweighted; a mirror's direction does not move
            with dr.suspend_grad():
                s = self.sample(wo, uc, u)
            f = self.eval_pdf(wo, s.w)[0]
            if self.kind != ROUGH:
                f = mi.Spectrum(dr.select(self.specular, fresnel_conductor(wo.z, self.eta, self.k), f))
            return _reweighted(s, f)
        out = None
        if self.kind != ROUGH:
            ok = wo.z > 0
            w = fresnel_conductor(wo.z, self.eta, self.k)
            out = _Sample(reflect(wo), mi.Spectrum(dr.select(ok, w, 0.0)), mi.Float(1.0), ok, mi.Bool(True))
        if self.rough:
            md = self.md
            m, pdf_m = md.sample(wo, u)
            w = reflect_about(wo, m)
            d = dr.dot(wo, m)
            pdf = pdf_m / (4.0 * d)
            ok = (wo.z > 0) & (w.z > 0) & (d > 0) & (pdf_m > 0) & dr.isfinite(pdf)
            weight = fresnel_conductor(d, self.eta, self.k) * md.G1(w, m)
            r = _Sample(w, mi.Spectrum(dr.select(ok, weight, 0.0)), dr.select(ok, pdf, 0.0), ok, mi.Bool(True))
            out = r if out is None else _select(self.specular, out, r)
        return out

    def eval_pdf(self, wo, wi):
        if not self.rough:
            return mi.Spectrum(0.0), mi.Float(0.0)
        md = self.md
        m = dr.normalize(wo + wi)
        d = dr.dot(wo, m)
        ok = (wo.z > 0) & (wi.z > 0) & ~self.specular
        f = fresnel_conductor(d, self.eta, self.k) * (md.D(m) * md.G(wo, wi, m) / (4.0 * wo.z))
        pdf = md.pdf(wo, m) / (4.0 * d)
        ok = ok & (pdf > 0) & dr.isfinite(pdf) & dr.all(dr.isfinite(f))
        return mi.Spectrum(dr.select(ok, f, 0.0)), dr.select(ok, pdf, 0.0)


class _Params:
    """Per-lane parameters of one query."""

    def __init__(self, top, base, thick, albedo, g, medium, maxdepth, nsamples, terminate, unroll):
        self.top, self.base, self.thick, self.albedo, self.g = top, base, thick, albedo, g
        self.medium, self.maxdepth, self.nsamples, self.terminate = medium, maxdepth, nsamples, terminate
        # Where a parameter carries gradients (ad), the walks sample with detached
        # parameters (see _reweighted) and their loops are unrolled (see dispatch.loop)
        # to these trip counts (events, walks); else (0, 0): symbolic loops.
        self.unroll_depth, self.unroll_samples = unroll
        self.ad = self.unroll_depth > 0


# ---------------------------------------------------------------- the BSDF family

class _Layered(BSDFType):
    flags = REFLECTION | DIFFUSE | GLOSSY | SPECULAR
    stochastic = True
    _prefix = ""          # parameter prefix of the coating ("interface." for coatedconductor)

    # -- parsing ---------------------------------------------------------------------
    def _roughness(self, loader, props, prefix, remap):
        """Texture slots (u, v) and the kind (smooth/rough/mixed) of a GGX roughness given
        as ``roughness`` or ``uroughness``/``vroughness`` (pbrt-v4's names)."""
        base = props.raw(prefix + "roughness", 0.0)
        vals = [props.raw(prefix + n, base) if props.has(prefix + n) else base for n in ("uroughness", "vroughness")]
        keys = [prefix + n if props.has(prefix + n) else prefix + "roughness" for n in ("uroughness", "vroughness")]
        slots = []
        for v, k in zip(vals, keys):
            # Both axes from ``roughness``: one slot, so that the parameter moves both.
            slots.append(slots[0] if slots and k == keys[0] else
                         load_spectrum(loader, v, props.key(k), emitter=False, unbounded=True, valid=ROUGHNESS))
        if all(_number(v) for v in vals):
            alpha = max((float(v) ** 0.5 if remap else float(v)) for v in vals)
            kind = SMOOTH if alpha < _SMOOTH_ALPHA else ROUGH
        else:
            kind = MIXED
        return slots, kind

    def _add_common(self, loader, props) -> dict:
        p = self._prefix
        inst: dict = {}
        remap = props.bool("remaproughness", True)
        inst["remap"] = remap
        eta, slot = _ior_spectrum(loader, props, p + "eta", 1.5)
        if eta is not None and eta == 0:
            eta = 1.0          # pbrt-v4: an IOR of 0 means index-matched
        inst["eta"], inst["eta_slot"] = (1.0 if eta is None else eta), (_NONE if slot is None else slot)
        # A constant IOR is a scene parameter (``<bsdf>.eta``, ``<bsdf>.interface.eta``);
        # a spectral one is a texture, a parameter of its own.
        inst["owner"] = (ParamOwner(props.path, valid={p + "eta": IOR}, **{p + "eta": mi.Float(inst["eta"])})
                         if slot is None else None)
        (inst["top_u"], inst["top_v"]), kind = self._roughness(loader, props, p, remap)
        if slot is not None:
            kind = MIXED       # a wavelength-dependent IOR may be 1
        elif eta == 1.0:
            kind = SMOOTH
        inst["top_kind"] = kind
        inst["thickness"] = load_spectrum(loader, props.raw("thickness", 0.01), props.key("thickness"), emitter=False,
                                          unbounded=True, valid=NONNEGATIVE)
        a = props.raw("albedo", 0.0)
        inst["medium"] = not (_number(a) and a == 0)
        inst["albedo"] = load_spectrum(loader, a, props.key("albedo"), emitter=False)
        inst["g"] = load_spectrum(loader, props.raw("g", 0.0), props.key("g"), emitter=False, unbounded=True,
                                  valid=HG_ASYMMETRY)
        inst["maxdepth"] = props.int("maxdepth", 10, min=1)
        inst["nsamples"] = props.int("nsamples", 1, min=1)
        return inst

    def refresh_params(self) -> None:
        """Recompute the table of the coat IOR parameters (see ``SceneParameters.update``)."""
        p = self._prefix + "eta"
        self.eta = param_table([i["owner"].params[p] if i["owner"] else i["eta"] for i in self.instances])

    def build(self) -> None:
        I = self.instances  # noqa: E741
        u32 = lambda k: mi.UInt32([i[k] for i in I])  # noqa: E731
        self.refresh_params()
        self.dispersive = any(i["eta_slot"] != _NONE for i in I)
        self.eta_slot = u32("eta_slot")
        self.remap = mi.Bool([i["remap"] for i in I])
        self.top_u, self.top_v = u32("top_u"), u32("top_v")
        self.top_kind = _kind(i["top_kind"] for i in I)
        self.thickness, self.albedo, self.g = u32("thickness"), u32("albedo"), u32("g")
        self.medium = any(i["medium"] for i in I)
        self.maxdepth, self.nsamples = u32("maxdepth"), u32("nsamples")
        self.maxdepth_max = max(i["maxdepth"] for i in I)
        self.nsamples_max = max(i["nsamples"] for i in I)

    def param_owners(self) -> list:
        return [i["owner"] for i in self.instances if i["owner"] is not None]

    # -- per-hit parameters ---------------------------------------------------------
    def _tex(self, ctx, idx, active):
        """A lookup of the parameter ``name`` (its slot table is ``self.<name>``, its
        instances' slots ``inst[name]``): only the texture kinds those slots reach are
        traced (a walk evaluates it at every step, unrolled for derivatives)."""
        tex, uv, lam = self.textures, ctx.si, ctx.wl.lambda_

        def ev(name):
            reach = tuple(i[name] for i in self.instances)
            return tex.eval(dr.gather(mi.UInt32, getattr(self, name), idx, active), uv, lam, active,
                            illuminant=False, reach=reach)
        return ev

    def _alpha(self, ev, idx, tu, tv, active):
        remap = dr.gather(mi.Bool, self.remap, idx, active)
        au, av = dr.maximum(ev(tu)[0], 0.0), dr.maximum(ev(tv)[0], 0.0)
        return dr.select(remap, dr.sqrt(au), au), dr.select(remap, dr.sqrt(av), av)

    def _params(self, ctx, idx, active) -> _Params:
        ev = self._tex(ctx, idx, active)
        eta = dr.gather(mi.Float, self.eta, idx, active)
        terminate = mi.Bool(False)
        if self.dispersive:
            slot = dr.gather(mi.UInt32, self.eta_slot, idx, active)
            disp = active & (slot != _NONE)
            e = self.textures.eval(slot, ctx.si, ctx.wl.lambda_, disp, illuminant=False,
                                   reach=tuple(i["eta_slot"] for i in self.instances if i["eta_slot"] != _NONE))[0]
            eta = dr.select(disp, dr.select(e == 0, 1.0, e), eta)
            terminate = disp
        top = _Top(eta, *self._alpha(ev, idx, "top_u", "top_v", active), self.top_kind)
        # Numerical clamps of checked values: the derivative at a bound passes.
        thick = clamp_keep_grad(ev("thickness")[0], _FLT_MIN)
        if self.medium:
            albedo = clamp_keep_grad(ev("albedo"), 0.0, 1.0)
            g = clamp_keep_grad(ev("g")[0], -1.0, 1.0)
            medium = dr.any(albedo > 0)
        else:
            albedo, g, medium = mi.Spectrum(0.0), mi.Float(0.0), mi.Bool(False)
        base = self._base(ev, idx, eta, active)
        parts = (top, getattr(top, "md", None), base, getattr(base, "md", None))
        ad = dr.grad_enabled(thick, albedo, g, *(vars(p) for p in parts if p is not None))
        unroll = (self.maxdepth_max, self.nsamples_max) if ad else (0, 0)
        return _Params(top, base, thick, albedo, g, medium, dr.gather(mi.UInt32, self.maxdepth, idx, active),
                       dr.gather(mi.UInt32, self.nsamples, idx, active), terminate, unroll)

    # -- the three estimators -------------------------------------------------------
    def _f(self, P: _Params, wv, wl, active):
        """pbrt-v4's LayeredBxDF::f times |cos wl|, for view ``wv`` and light ``wl``
        (both above the surface)."""
        top, base = P.top, P.base
        thick, albedo, g = P.thick, P.albedo, P.g
        medium, ad = self.medium, P.ad
        f_top = top.eval_pdf(wv, wl)[0]
        rng = _rng((wv.x, wv.y, wv.z), (wl.x, wl.y, wl.z))
        zero = mi.Spectrum(0.0)

        def walk(s, acc, acc_cos, rng):
            on = active & (s < P.nsamples)
            # Into the coating from the camera side, and (the virtual light) from the
            # light side; the latter for importance transport (the adjoint: undo 1/eta^2).
            wos = top.sample(wv, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()),
                             TRANSMISSION, ad)
            wis = top.sample(wl, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()),
                             TRANSMISSION, ad)
            v = wis.w
            ok = on & wos.ok & wis.ok & (wos.w.z != 0) & (v.z != 0)
            f_wis = wis.weight * (top.eta * top.eta) / dr.abs(v.z)      # f / pdf of the light-side sample
            pdf_wis = wis.pdf

            def event(depth, alive, beta, w, z, acc, acc_cos, rng):
                u_rr, u_dz, uc = rng.next_float32(), rng.next_float32(), rng.next_float32()
                u = mi.Point2f(rng.next_float32(), rng.next_float32())
                # Russian roulette.
                mb = dr.max(beta)
                rr = alive & (depth > 3) & (mb < 0.25)
                q = dr.maximum(0.0, 1.0 - dr.detach(mb))   # a probability: no derivative
                alive = alive & (~(rr & (u_rr < q)))
                beta = dr.select(rr, beta / (1.0 - q), beta)
                fl = _free_flight(mi.Bool(alive), z, w, beta, thick, g, P.medium, u_dz, u, medium, ad)
                cur, z, beta, inside, scat = fl.cur, fl.z, fl.beta, fl.inside, fl.ps.ok
                at_top = cur & (z == thick)
                at_bot = cur & (z != thick)

                # Connection to the light through the top along the presampled -v: from
                # a scattering point in the medium or from the base (unless specular).
                fb, pb = base.eval_pdf(-w, -v)
                val, p_conn, dzz = fb, pb, mi.Float(thick)
                conn = at_bot & ~base.specular
                if medium:
                    ph = hg(dr.dot(w, v), g)
                    val = dr.select(inside, albedo * ph, val)
                    p_conn = dr.select(inside, ph, p_conn)
                    dzz = dr.select(inside, fl.dz_top, dzz)
                    conn = conn | inside
                # MIS weights are detached (their derivatives cancel between strategies).
                wt = dr.select(top.smooth, 1.0, power_heuristic(pdf_wis, dr.detach(p_conn)))
                acc = acc + dr.select(conn, beta * val * (wt * _tr(dzz, v) * f_wis), zero)

                # Continue: reflect inside the top, at the base, or scatter in the medium.
                st = top.sample(-w, uc, u, REFLECTION, ad)
                sb = base.sample(-w, uc, u, ad)
                ok_t, ok_b = at_top & st.ok, at_bot & sb.ok
                new_w = dr.select(at_top, st.w, sb.w)
                new_beta = beta * dr.select(at_top, mi.Spectrum(st.weight), sb.weight)
                new_pdf = sb.pdf
                cont = ok_t | ok_b
                if medium:
                    new_w = dr.select(scat, fl.ps.w, new_w)
                    new_beta = dr.select(scat, beta * albedo * fl.ps.weight, new_beta)
                    new_pdf = dr.select(scat, fl.ps.pdf, new_pdf)
                    cont = cont | scat

                # Connection along the new direction where it leaves through a rough top
                # (MIS against the light-side sample above).
                if top.rough:
                    leave = ok_b
                    dzz2 = mi.Float(thick)
                    if medium:
                        leave = leave | (scat & (new_w.z > 0))
                        dzz2 = dr.select(scat, fl.dz_top, dzz2)
                    leave = leave & ~top.smooth
                    # Evaluated from the light side: pe is the density with which the
                    # light-side sample would have produced this direction (the weights
                    # of the two strategies then sum to one; pbrt-v4 uses the reverse
                    # density here), and reciprocity f(a, b) eta^2 = f(b, a) (a outside)
                    # gives the value for leaving toward wl.
                    fr, pe = top.eval_pdf(wl, -new_w, TRANSMISSION)
                    fe = fr * (top.eta * top.eta) * dr.abs(wl.z) / dr.abs(new_w.z)
                    wt2 = dr.select(ok_b & base.specular, 1.0, power_heuristic(new_pdf, dr.detach(pe)))
                    acc_cos = acc_cos + dr.select(leave & (fe > 0), new_beta * (_tr(dzz2, new_w) * fe * wt2), zero)

                alive = alive & (~((at_top & ~st.ok) | (at_bot & ~sb.ok)))
                beta = dr.select(cont, new_beta, beta)
                w = dr.select(cont, new_w, w)
                if medium:
                    z = dr.select(scat, fl.zp, z)
                return depth + 1, alive, beta, w, z, acc, acc_cos, rng

            state = (mi.UInt32(0), mi.Bool(ok), mi.Spectrum(wos.weight), mi.Vector3f(wos.w),
                     mi.Float(dr.detach(thick) if ad else thick), acc, acc_cos, rng)
            _, _, _, _, _, acc, acc_cos, rng = dispatch.loop(
                state, lambda depth, alive, *_: alive & (depth < P.maxdepth), event, P.unroll_depth, "layered_f_walk")
            return s + 1, acc, acc_cos, rng

        _, acc, acc_cos, _ = dispatch.loop((mi.UInt32(0), mi.Spectrum(0.0), mi.Spectrum(0.0), rng),
                                           lambda s, *_: active & (s < P.nsamples), walk, P.unroll_samples,
                                           "layered_f_samples")
        inv_n = dr.rcp(mi.Float(P.nsamples))
        return f_top + (acc * dr.abs(wl.z) + acc_cos) * inv_n

    def _pdf(self, P: _Params, wv, wl, active):
        """pbrt-v4's LayeredBxDF::PDF (reflection: both directions above)."""
        top, base = P.top, P.base
        p_top = top.eval_pdf(wv, wl, REFLECTION)[1]
        rng = _rng((wl.x, wl.y, wl.z), (wv.x, wv.y, wv.z))

        def body(s, acc, rng):
            r = rng.next_float32
            wos = top.sample(wv, r(), mi.Point2f(r(), r()), TRANSMISSION)
            wis = top.sample(wl, r(), mi.Point2f(r(), r()), TRANSMISSION)
            ok = wos.ok & wis.ok
            # Through a smooth top the base's own density of the connecting pair.
            pb = base.eval_pdf(-wos.w, -wis.w)[1]
            term = pb
            if top.rough:
                rs = base.sample(-wos.w, r(), mi.Point2f(r(), r()))
                pt = top.eval_pdf(-rs.w, wl)[1]
                mis = power_heuristic(wis.pdf, pb) * pb + power_heuristic(rs.pdf, pt) * pt
                term = dr.select(top.smooth, pb, dr.select(base.specular, pt, mis))
                ok = ok & (top.smooth | rs.ok)
            return s + 1, acc + dr.select(ok, term, 0.0), rng

        _, acc, _ = dispatch.loop((mi.UInt32(0), mi.Float(0.0), rng), lambda s, *_: active & (s < P.nsamples),
                                  body, P.unroll_samples, "layered_pdf")
        est = p_top + acc / mi.Float(P.nsamples)
        return dr.lerp(1.0 / (4.0 * dr.pi), est, 0.9)

    def _sample(self, P: _Params, wv, uc, u, active) -> BSDFSample:
        """pbrt-v4's LayeredBxDF::Sample_f from view ``wv`` (above the surface)."""
        top, base = P.top, P.base
        thick, albedo, g = P.thick, P.albedo, P.g
        medium, ad = self.medium, P.ad
        s0 = top.sample(wv, uc, u, BOTH, ad)
        ok0 = active & s0.ok & (s0.w.z != 0)
        refl0 = s0.refl
        rng = _rng((wv.x, wv.y, wv.z), (uc, u.x, u.y))

        def event(depth, alive, exited, spec, beta, pdf, w, z, rng):
            u_rr, u_dz, uc = rng.next_float32(), rng.next_float32(), rng.next_float32()
            u = mi.Point2f(rng.next_float32(), rng.next_float32())
            mb = dr.max(beta)
            rr = alive & (depth > 3) & (mb < 0.25)
            q = dr.maximum(0.0, 1.0 - dr.detach(mb))
            alive = alive & (~(rr & (u_rr < q)) & (w.z != 0))
            beta = dr.select(rr, beta / (1.0 - q), beta)
            pdf = dr.select(rr, pdf * (1.0 - q), pdf)
            fl = _free_flight(mi.Bool(alive), z, w, beta, thick, g, P.medium, u_dz, u, medium, ad)
            cur, z, beta, scat = fl.cur, fl.z, fl.beta, fl.ps.ok
            if medium:
                alive = alive & (~(fl.inside & ~scat))
            at_top = cur & (z == thick)
            at_bot = cur & (z != thick)
            st = top.sample(-w, uc, u, BOTH, ad)
            sb = base.sample(-w, uc, u, ad)
            ok_t, ok_b = at_top & st.ok & (st.w.z != 0), at_bot & sb.ok
            alive = alive & (~((at_top & ~ok_t) | (at_bot & ~ok_b)))
            beta = dr.select(ok_t, beta * st.weight, dr.select(ok_b, beta * sb.weight, beta))
            pdf = dr.select(ok_t, pdf * st.pdf, dr.select(ok_b, pdf * sb.pdf, pdf))
            spec = spec & (dr.select(ok_t, top.smooth, dr.select(ok_b, base.specular, True)))
            w = dr.select(ok_t, st.w, dr.select(ok_b, sb.w, w))
            if medium:
                beta = dr.select(scat, beta * albedo * fl.ps.weight, beta)
                pdf = dr.select(scat, pdf * fl.ps.pdf, pdf)
                spec = spec & ~scat
                w = dr.select(scat, fl.ps.w, w)
                z = dr.select(scat, fl.zp, z)
            out = ok_t & ~st.refl
            exited = exited | out
            alive = alive & ~out
            return depth + 1, alive, exited, spec, beta, pdf, w, z, rng

        state = (mi.UInt32(0), ok0 & ~refl0, mi.Bool(False), top.smooth & ok0, mi.Spectrum(s0.weight),
                 mi.Float(s0.pdf), mi.Vector3f(s0.w), mi.Float(dr.detach(thick) if ad else thick), rng)
        _, _, exited, spec, beta, pdf, w, _, _ = dispatch.loop(
            state, lambda depth, alive, *_: alive & (depth < P.maxdepth), event, P.unroll_depth, "layered_sample")
        ok = ok0 & (refl0 | exited)
        wo = dr.select(refl0, s0.w, w)
        delta = dr.select(refl0, top.smooth, spec)
        weight = dr.select(refl0, mi.Spectrum(s0.weight), beta)
        path_pdf = dr.select(refl0, s0.pdf, pdf)
        # The stochastic density (non-delta) is detached: the path replay differentiates
        # weight * pdf (BSDFType.stochastic), i.e. the walk's weight alone (with ``ad``
        # every density is detached and the weights carry the derivatives).
        pdf = dr.select(delta, path_pdf, dr.detach(self._pdf(P, wv, wo, ok & ~delta)))
        ok = ok & (pdf > 0) & (wo.z > 0)
        return BSDFSample(wo, dr.select(ok, pdf, 0.0), mi.Float(1.0), ok & delta, dr.select(ok, weight, 0.0),
                          P.terminate & active)

    # -- interface --------------------------------------------------------------------
    @staticmethod
    def _flip(v, mask):
        return mi.Vector3f(v.x, v.y, dr.select(mask, -v.z, v.z))

    def _eval_pdf(self, ctx, P, wo, active):
        wi = ctx.si.wi
        down = wi.z < 0        # two-sided: mirror both directions
        wv, wl = self._flip(wi, down), self._flip(wo, down)
        on = active & (wv.z > 0) & (wl.z > 0)
        f = self._f(P, wv, wl, on)
        pdf = self._pdf(P, wv, wl, on)
        ok = on & dr.all(dr.isfinite(f)) & dr.isfinite(pdf)
        return dr.select(ok, f, 0.0), dr.select(ok, pdf, 0.0)

    def _sample_dir(self, ctx, P, uc, u, active):
        wi = ctx.si.wi
        down = wi.z < 0
        wv = self._flip(wi, down)
        bs = self._sample(P, wv, uc, u, active & (wv.z > 0))
        ok = dr.all(dr.isfinite(bs.weight)) & dr.isfinite(bs.pdf)
        bs.wo = self._flip(bs.wo, down)
        bs.weight = dr.select(ok, bs.weight, 0.0)
        bs.pdf = dr.select(ok, bs.pdf, 0.0)
        return bs

    def eval_pdf(self, ctx, idx, wo, active):
        return self._eval_pdf(ctx, self._params(ctx, idx, active), wo, active)

    def sample(self, ctx, idx, u1, u2, active) -> BSDFSample:
        return self._sample_dir(ctx, self._params(ctx, idx, active), u1, u2, active)

    def eval_pdf_sample(self, ctx, idx, wo, u1, u2, active):
        P = self._params(ctx, idx, active)
        f, pdf = self._eval_pdf(ctx, P, wo, active)
        return f, pdf, self._sample_dir(ctx, P, u1, u2, active)


@BSDF_TYPES.register("coateddiffuse")
class CoatedDiffuse(_Layered):
    """``coateddiffuse`` (pbrt-v4's): a Lambertian base under a dielectric coating, evaluated
    by random walks between the interfaces (docs/layered.md).

    ==============  =========  =======  =========================================================
    name            type       default  meaning
    ==============  =========  =======  =========================================================
    reflectance     texture    0.5      albedo of the diffuse base
    roughness       texture    0        GGX roughness of the coating (or uroughness / vroughness)
    remaproughness  bool       true     roughness is pbrt-v4's perceptual value (alpha = sqrt)
    eta             float|str  1.5      IOR of the coating (a number, name or spectrum)
    thickness       texture    0.01     thickness of the coating's medium
    albedo          texture    0        single-scattering albedo of the medium in the coating
    g               texture    0        Henyey-Greenstein asymmetry of that medium
    maxdepth        int        10       longest random walk between the interfaces
    nsamples        int        1        walks averaged per evaluation
    ==============  =========  =======  =========================================================
    """

    name = "coateddiffuse"

    def add(self, loader, props) -> int:
        inst = self._add_common(loader, props)
        inst["reflectance"] = load_spectrum(loader, props.raw("reflectance", 0.5), props.key("reflectance"),
                                            emitter=False)
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        super().build()
        self.reflectance = mi.UInt32([i["reflectance"] for i in self.instances])

    def _base(self, ev, idx, eta, active):
        return _DiffuseBase(clamp_keep_grad(ev("reflectance"), 0.0, 1.0))


def _metal(loader, name: str, comp: str, path: str) -> int:
    wl, vals = read_spd(os.path.join(_IOR_DIR, f"{name}.{comp}.spd"))
    return add_tabulated(loader, wl, vals, path)


@BSDF_TYPES.register("coatedconductor")
class CoatedConductor(_Layered):
    """``coatedconductor`` (pbrt-v4's): a conductor base under a dielectric coating (random
    walks, docs/layered.md). The coating's parameters are prefixed ``interface.``; the
    conductor's eta and k are divided by the coating's IOR.

    ==============  =======  =======  ================================================================
    name            type     default  meaning
    ==============  =======  =======  ================================================================
    interface.*     -        -        roughness, uroughness, vroughness, eta (1.5) of the coating
    conductor.eta   texture  Cu       the conductor's IOR (a spectrum or a name: 'metal-Cu-eta', 'Au')
    conductor.k     texture  Cu       its absorption
    conductor.*     -        0        roughness, uroughness, vroughness of the conductor
    reflectance     texture  -        an artist reflectance instead of conductor.eta / conductor.k
    remaproughness  bool     true     roughness is pbrt-v4's perceptual value (alpha = sqrt)
    thickness       texture  0.01     thickness of the coating's medium
    albedo          texture  0        single-scattering albedo of the medium in the coating
    g               texture  0        Henyey-Greenstein asymmetry of that medium
    maxdepth        int      10       longest random walk between the interfaces
    nsamples        int      1        walks averaged per evaluation
    ==============  =======  =======  ================================================================
    """

    name = "coatedconductor"
    _prefix = "interface."

    def _metal_spectrum(self, loader, props, name, comp):
        v = props.raw(name)
        if isinstance(v, str):
            # pbrt-v4's named spectra, "metal-Cu-eta", or Mitsuba's material names.
            parts = v.split("-")
            metal = parts[1] if len(parts) == 3 and parts[0] == "metal" and parts[2] == comp else v
            if not os.path.exists(os.path.join(_IOR_DIR, f"{metal}.{comp}.spd")):
                raise props.error(name, f"unknown conductor spectrum {v!r} (e.g. 'metal-Cu-{comp}')")
            return _metal(loader, metal, comp, props.key(name))
        return load_spectrum(loader, v, props.key(name), emitter=False, unbounded=True, valid=NONNEGATIVE)

    def add(self, loader, props) -> int:
        inst = self._add_common(loader, props)
        has_ek = props.has("conductor.eta") or props.has("conductor.k")
        if props.has("reflectance"):
            if has_ek:
                raise props.error("reflectance", "give either 'reflectance' or 'conductor.eta'/'conductor.k'")
            inst["refl"] = load_spectrum(loader, props.raw("reflectance"), props.key("reflectance"), emitter=False)
            inst["ce"] = inst["ck"] = inst["refl"]
        else:
            inst["refl"] = _NONE
            inst["ce"] = (self._metal_spectrum(loader, props, "conductor.eta", "eta") if props.has("conductor.eta")
                          else _metal(loader, "Cu", "eta", props.key("conductor.eta")))
            inst["ck"] = (self._metal_spectrum(loader, props, "conductor.k", "k") if props.has("conductor.k")
                          else _metal(loader, "Cu", "k", props.key("conductor.k")))
        (inst["cu"], inst["cv"]), inst["base_kind"] = self._roughness(loader, props, "conductor.", inst["remap"])
        props.finish()
        self.instances.append(inst)
        return len(self.instances) - 1

    def build(self) -> None:
        super().build()
        I = self.instances  # noqa: E741
        self.ce, self.ck = mi.UInt32([i["ce"] for i in I]), mi.UInt32([i["ck"] for i in I])
        self.cu, self.cv = mi.UInt32([i["cu"] for i in I]), mi.UInt32([i["cv"] for i in I])
        self.use_refl = mi.Bool([i["refl"] != _NONE for i in I])
        self.refl_modes = {i["refl"] != _NONE for i in I}
        self.base_kind = _kind(i["base_kind"] for i in I)

    def _base(self, ev, idx, eta, active):
        if self.refl_modes == {True}:
            ce = ck = None
        else:
            ce, ck = ev("ce"), ev("ck")
        if True in self.refl_modes:
            r = dr.clip(ev("ce"), 0.0, 0.9999)
            rk = 2.0 * dr.sqrt(r) / dr.sqrt(1.0 - r)
            if ce is None:
                ce, ck = mi.Spectrum(1.0), rk
            else:
                use = dr.gather(mi.Bool, self.use_refl, idx, active)
                ce, ck = dr.select(use, 1.0, ce), dr.select(use, rk, ck)
        au, av = self._alpha(ev, idx, "cu", "cv", active)
        return _ConductorBase(ce / eta, ck / eta, au, av, self.base_kind)
