"""``prb_projective`` and ``direct_projective``: derivatives w.r.t. geometry with the
boundary terms that visibility discontinuities contribute.

A pixel is an integral over the film, and the light reflected at a point an integral
over directions; when a shape moves, the silhouettes of the shapes move across these
domains and the integrands jump there. The derivative is then the interior part (the
``prb`` replay with hits that move with the shapes) plus, for each discontinuity, an
integral along the moving boundary of (the jump of the integrand) x (the boundary's
normal velocity) (Li et al. 2018, "Differentiable Monte Carlo Ray Tracing through Edge
Sampling"; Zhang et al. 2023, "Projective Sampling for Differentiable Rendering of
Geometry", whose integrators these follow in name and parameters). pbr estimates two such
boundaries by sampling points on silhouette edges of triangle meshes and on the
silhouette curves of analytic shapes:

* **primary visibility** (``sppp`` samples per pixel): the edges that are silhouettes
  from the pinhole, projected onto the film; an edge is chosen in proportion to its
  projected length inside the film (plus ``OFF_FILM`` of the rest) and a point uniformly
  on it. The jump is the radiance just beside the
  projected edge on either side (two camera rays, the integrator's own estimator with the
  same random numbers), weighted by the pixel filter of each pixel the point falls on.
* **indirect visibility** (``sppi`` samples per pixel): from a vertex x of a camera
  path, a point y on an edge, chosen by resampled importance sampling among
  24 candidates drawn by edge length (target: the edge measure below where the edge is a
  silhouette seen from x, larger toward emitters and where the BSDF at x is large); the
  jump is f(x, w) L_i(x, w) just beside the
  direction w = (y - x) / |y - x| on either side (L_i: the rest of the path, by the
  integrator's estimator, ``max_depth`` counting the segments before x), the normal
  velocity is that of the direction, ((v_y - v_x) . n) / |y - x| (x slides along its
  incoming ray), and the measure along the edge |e x w| / |y - x|. In
  ``direct_projective`` x is the first hit: shadows of area and environment lights. In
  ``prb_projective`` x is a vertex at a random depth k (1 <= k < ``max_depth``, at most
  ``indirect_depth``): the path is traced by BSDF sampling, through delta lobes (mirrors,
  glass: nothing is projected from those), and one vertex with a non-delta lobe is kept
  in proportion to its throughput (:meth:`ProjectivePathIntegrator._projection_vertex`),
  the estimate weighted by the throughput of the k - 1 bounces before x over the
  probability of choosing x. This covers every discontinuity of the light reaching any
  vertex: an object seen in a glossy reflection (k = 1), a shadow seen in a mirror or a
  glossy floor (k = 2), and so on.

Edges (:class:`EdgeSet`): those of every triangle mesh (Mitsuba's ``cube`` included) and the
four sides of every ``rectangle``. Vertices with equal positions are welded first, so a
split-vertex mesh has the silhouettes of the watertight surface it represents (Mitsuba's
own projective integrators count the seams of its ``cube`` as silhouettes and double them);
edges between coplanar faces are never silhouettes and are dropped. An edge is a
silhouette seen from a point p when its two faces' third vertices lie on the same side of
the plane through p and the edge; boundary edges (one face) always are. The welded
positions are the mean of the split copies (attached), so a vertex's gradient is shared
among its copies. Analytic shapes (``sphere``, ``disk``, ``cylinder``; ``silhouettes.py``)
add curves after the edges, whose points depend on the viewpoint (a sphere's circle of
tangency, a cylinder's grazing side lines) or not (rims); each is a boundary ``k`` with
a parameter t in [0, 1), like an edge, so both terms choose among edges and curves alike.

Interior derivatives are ``prb``'s, with light samples in solid angle (the direction
toward an area light is fixed when the shading point moves), which is the measure the
indirect boundary term is written in. Not handled (documented in docs/inverse.md):
boundaries of curves (``linearcurve``, ``bsplinecurve``) and SDF grids (a warning says so),
hard shadows of point and spot lights (their
boundary lies on the receiver, not in a direction), non-pinhole cameras, and guiding
(``guiding`` and its options are accepted and ignored).

A perspective camera's pose (``<sensor>.to_world`` assigned with gradients) is
differentiated too: the replay's first segment follows the attached camera rays, the
primary term projects edges with the attached pose, and the indirect term starts from
the attached first hit. Deeper vertices slide along their detached incoming rays (they
move with their own surface only: a discontinuity seen in a mirror does not move with the
camera or the mirror in this term).
"""

from __future__ import annotations

import math
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import dispatch
from .. import spectrum as spec
from ..bsdfs.base import ShadingContext
from ..plugins.props import SceneError
from ..samplers import IndependentSampler, IndependentStream, seed_array
from ..spectrum import SampledWavelengths
from .base import (BACKWARD, FORWARD, INTEGRATORS, PRIMAL, depth_limit, forward_derivative, loop_ray,
                   max_samples_per_pass, nonzero, ray_state)
from .path import PathIntegrator
from .silhouettes import CurveSet, curve_kinds

# Offset beside an edge at which the two sides' radiance is estimated: a fraction of a
# pixel (primary visibility) and an angle (radians) at the indirect term's vertex.
PIXEL_EPS = 1e-3
# Primary term: weight of a boundary's length outside the film in its probability.
OFF_FILM = 0.01
ANGLE_EPS = 1e-4
# Two faces are coplanar (their edge is never a silhouette) below this |sin| of the angle
# between the fourth vertex and the first face's plane.
COPLANAR = 1e-6
# Relative probability of edges that are silhouettes seen from an emitter's vertices.
LIGHT_BOOST = 16.0
# At most this many of an emitter's vertices (evenly spaced in its vertex list) are the
# viewpoints of that test: each is one silhouette test of every edge in one kernel, and a
# finely tessellated light (the Mitsuba tutorials' 16k-vertex sphere.obj) made that
# kernel too large to trace in minutes. The choice only shapes a sampling probability.
LIGHT_VIEWPOINTS = 32
# Indirect term: candidate edge points per sample (resampled importance sampling), and the
# target's weight of directions that do not point at an emitter (x10 where the rest of the
# path has more than one segment: jumps may come from indirect light).
CANDIDATES = 24
# The target also weighs a candidate by the vertex's BSDF toward it (f |cos|, mean over
# the wavelengths) plus this floor, so that a glossy lobe's directions are preferred.
BSDF_FLOOR = 0.01
CONE_FLOOR = 0.02
# Indirect term: the choice of the camera-path vertex weighs each vertex by its throughput
# times (this floor + its BSDF sample weight), so that black surfaces are seldom chosen
# but never ruled out (a sample weight may be 0 where the BSDF is not).
VERTEX_FLOOR = 0.05


def _weld(pos: np.ndarray):
    """(welded index per vertex, number of welded vertices, count per welded vertex) for
    vertex positions ``pos`` (n, 3): vertices with bit-equal positions become one."""
    _, inv, counts = np.unique(pos, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    return inv, len(counts), counts


def _mesh_edges(faces: np.ndarray, pos: np.ndarray):
    """Edges of a welded triangle mesh: (a, b, c, d) vertex indices per edge (c, d: the
    third vertices of its faces; d = -1 for a boundary edge), coplanar interior edges
    dropped. Non-manifold edges (3+ faces) are kept once per face, as boundary edges."""
    a = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    b = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    c = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    ok = a != b
    a, b, c = a[ok], b[ok], c[ok]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo.astype(np.int64) * (int(pos.shape[0]) + 1) + hi
    order = np.argsort(key, kind="stable")
    key, lo, hi, c = key[order], lo[order], hi[order], c[order]
    start = np.r_[0, np.flatnonzero(np.diff(key)) + 1]
    count = np.diff(np.r_[start, len(key)])
    two = start[count == 2]
    # boundary edges (one face) and non-manifold ones (3+ faces: each face's copy)
    other = np.repeat(count != 2, count)
    ea = np.concatenate([lo[two], lo[other]]).astype(np.int64)
    eb = np.concatenate([hi[two], hi[other]]).astype(np.int64)
    ec = np.concatenate([c[two], c[other]]).astype(np.int64)
    ed = np.concatenate([c[two + 1], np.full(int(other.sum()), -1)]).astype(np.int64)
    # drop interior edges between coplanar faces
    inner = ed >= 0
    pa, pb, pc = pos[ea], pos[eb], pos[ec]
    pd = pos[np.where(inner, ed, ec)]
    n = np.cross(pb - pa, pc - pa)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    off = np.abs(np.einsum("ij,ij->i", n, pd - pa)) / np.maximum(np.linalg.norm(pd - pa, axis=1), 1e-30)
    keep = ~inner | (off > COPLANAR)
    return ea[keep], eb[keep], ec[keep], ed[keep]


class EdgeSet:
    """The candidate boundaries of a scene (see the module docstring): mesh edges, then
    the analytic shapes' curves (:class:`CurveSet`). Topology built once per geometry;
    positions and frames gathered (attached) from the shapes' current parameters by
    :meth:`state`."""

    def __init__(self, scene):
        geo = scene.geometry
        self.meshes, self.rects = [], []   # (mi shape, target index array, n values) / (mi shape)
        a, b, c, d = [], [], [], []
        n_vert = 0
        counts = []
        emitting = []    # welded vertex ranges of emissive shapes (see edge_weights)
        analytic = []    # spheres, disks, cylinders (silhouettes.CurveSet)
        for i in scene.top_level_shapes():
            shape = geo.mi_shape(i)
            first = n_vert
            if shape.is_mesh():
                pos = np.array(dr.detach(shape.vertex_positions_buffer()), dtype=np.float32).reshape(-1, 3)
                faces = np.array(shape.faces_buffer(), dtype=np.int64).reshape(-1, 3)
                inv, n_w, cnt = _weld(pos)
                wpos = np.zeros((n_w, 3))
                np.add.at(wpos, inv, pos)
                wpos /= cnt[:, None]
                ea, eb, ec, ed = _mesh_edges(inv[faces], wpos)
                target = ((inv + n_vert)[:, None] * 3 + np.arange(3)[None, :]).ravel()
                self.meshes.append((shape, mi.UInt32(target.astype(np.uint32))))
                for lst, e in zip((a, b, c, d), (ea, eb, ec, ed)):
                    lst.append(np.where(e >= 0, e + n_vert, -1))
                counts.append(cnt)
                n_vert += n_w
            elif shape.shape_type() == int(mi.ShapeType.Rectangle):
                # (Mitsuba 3.9's rectangles are meshes and take the branch above; this is
                # for a rectangle without triangles.) Corners (-1,-1), (1,-1), (1,1),
                # (-1,1) of the local square: four boundary edges.
                self.rects.append((shape, n_vert))
                for k in range(4):
                    a.append(np.array([n_vert + k])); b.append(np.array([n_vert + (k + 1) % 4]))
                    c.append(np.array([n_vert + (k + 2) % 4])); d.append(np.array([-1]))
                counts.append(np.ones(4))
                n_vert += 4
            elif curve_kinds(shape):
                analytic.append(shape)
            if scene.shape_emitter[i] and n_vert > first:
                emitting.append((first, n_vert))
        self.n_vertices = n_vert
        self.emitting = emitting
        self.curves = CurveSet(analytic)
        self.n_edges = len(np.concatenate(a)) if a else 0
        self.count = self.n_edges + self.curves.count     # edges, then analytic curves
        if not self.n_edges:
            return
        a, b, c, d = (np.concatenate(x) for x in (a, b, c, d))
        self.a, self.b, self.c = (mi.UInt32(x.astype(np.uint32)) for x in (a, b, c))
        self.has_d = mi.Bool(d >= 0)
        self.d = mi.UInt32(np.maximum(d, 0).astype(np.uint32))
        self.inv_count = mi.Float(np.repeat(1.0 / np.concatenate(counts), 3).astype(np.float32))

    def positions(self) -> mi.Float:
        """Welded vertex positions (flat x, y, z), attached to the shapes' parameters."""
        acc = dr.zeros(mi.Float, 3 * self.n_vertices)
        for shape, target in self.meshes:
            dr.scatter_reduce(dr.ReduceOp.Add, acc, shape.vertex_positions_buffer(), target)
        corners = ((-1, -1), (1, -1), (1, 1), (-1, 1))
        for shape, first in self.rects:
            T = mi.traverse(shape)["to_world"]
            for k, (x, y) in enumerate(corners):
                p = T @ mi.Point3f(x, y, 0.0)
                for j in range(3):
                    dr.scatter(acc, p[j], mi.UInt32(3 * (first + k) + j))
        return acc * self.inv_count

    def gather(self, P, k, active):
        """(a, b, c, d, has_d) of edges ``k`` (< ``n_edges``) from welded positions ``P``."""
        g = lambda idx: dr.gather(mi.Point3f, P, dr.gather(mi.UInt32, idx, k, active), active)  # noqa: E731
        return g(self.a), g(self.b), g(self.c), g(self.d), dr.gather(mi.Bool, self.has_d, k, active)

    def state(self):
        """The geometry the boundary points are made of, attached to the shapes'
        parameters: (welded vertex positions, the analytic shapes' frames)."""
        P = self.positions() if self.n_edges else None
        return P, (self.curves.frames() if self.curves.count else None)

    def point(self, S, k, t, view, active):
        """Boundary ``k`` (an edge, or past ``n_edges`` an analytic curve) at parameter
        ``t`` in [0, 1) seen from ``view``, with geometry ``S`` (:meth:`state`): (the
        point y, dy/dt, whether it is a silhouette from ``view``, a handle for
        :meth:`attached`)."""
        P, F = S
        y, e, sil = mi.Point3f(0.0), mi.Vector3f(0.0), mi.Bool(False)
        on_edge = active & (k < self.n_edges)
        if self.n_edges:
            a, b, c, d, has_d = self.gather(P, k, on_edge)
            y, e = dr.fma(b - a, t, a), b - a
            sil = on_edge & silhouette(view, a, b, c, d, has_d)
        y_l = mi.Vector3f(0.0)
        if self.curves.count:
            on_curve = active & (k >= self.n_edges)
            yc, ec, ok, y_l = self.curves.point(F, k - self.n_edges, t, view, on_curve)
            y, e, sil = dr.select(on_curve, yc, y), dr.select(on_curve, ec, e), dr.select(on_curve, ok, sil)
        return y, e, sil, y_l

    def attached(self, S, k, t, y_l, active):
        """The point of :meth:`point` moving with the shapes (``S`` attached)."""
        P, F = S
        y = mi.Point3f(0.0)
        on_edge = active & (k < self.n_edges)
        if self.n_edges:
            a, b, _, _, _ = self.gather(P, k, on_edge)
            y = dr.fma(b - a, t, a)
        if self.curves.count:
            on_curve = active & (k >= self.n_edges)
            y = dr.select(on_curve, self.curves.attached(F, k - self.n_edges, y_l, on_curve), y)
        return y


def _edge_measure(x, e, y):
    """(|e x w| / |y - x|: the solid-angle length swept per unit of the boundary's
    parameter at its point y seen from x, e = dy/dt; the unit direction w from x to y)."""
    v = y - x
    r = dr.norm(v)
    w = v / r
    meas = dr.norm(dr.cross(w, e)) / r
    return dr.select(r > 0, meas, 0.0), w


def silhouette(p, a, b, c, d, has_d):
    """Whether edge (a, b) with faces' third vertices c, d is a silhouette seen from p."""
    n = dr.cross(a - p, b - p)
    sc, sd = dr.dot(n, c - p), dr.dot(n, d - p)
    return ~has_d | (sc * sd > 0)


@INTEGRATORS.register("prb_projective")
class ProjectivePathIntegrator(PathIntegrator):
    """``prb_projective`` (Mitsuba's name and parameters): ``prb``'s path tracer whose
    derivatives w.r.t. geometry (mesh vertices, shape ``to_world``) include the boundary
    terms of primary visibility and of indirect visibility (from a vertex of the camera
    path at a random depth: shadows, reflections, shadows seen in reflections), estimated by
    sampling silhouette edges of meshes and silhouette curves of spheres, disks and
    cylinders (see docs/inverse.md, "Geometry"). Primal images are ``prb``'s.

    =============  ======  =======  ==============================================================
    name           type    default  meaning
    =============  ======  =======  ==============================================================
    max_depth      int     -1       longest path in segments (Mitsuba's meaning)
    rr_depth       int     5        depth from which Russian roulette may end a path
    hide_emitters  bool    false    camera rays pass through emitting surfaces
    light_sampler  string  bvh      light choice of next-event estimation
    sppc           int     -        samples per pixel of the interior derivative: 0 disables it;
                                    otherwise the render's spp_grad (or spp) wins, then this
                                    value, then the sensor's sample count (Mitsuba's rule)
    sppp           int     -        the same for the primary-visibility boundary term
    sppi           int     -        the same for the indirect-visibility boundary term
    indirect_depth int     -1       deepest camera-path vertex the indirect term projects from
                                    (pbr's: -1 every one max_depth allows, 1 the first hit only)
    guiding        string  octree   Mitsuba's guiding of indirect-boundary samples: accepted and
                                    ignored ('none', 'grid', 'octree'; pbr chooses edges by length)
    guiding_proj   bool    true     accepted and ignored (Mitsuba's guiding option)
    guiding_rounds int     1        accepted and ignored (Mitsuba's guiding option)
    proj_seed_spp  int     0        accepted and ignored (Mitsuba's projection seeds)
    =============  ======  =======  ==============================================================
    """

    supports_moving_shapes = False   # its silhouette edges are the static shapes'
    name = "prb_projective"
    default_max_depth = -1
    hide_through_null = False
    solid_angle_nee = True
    camera_gradients = True   # a perspective camera's pose (sensor to_world)

    def __init__(self, props):
        # prb's parameters, then Mitsuba's projective ones (props finished here)
        PathIntegrator.__init__(self, _Unfinished(props))
        self.spp_c, self.spp_p, self.spp_i = (props.int(k, min=0) if props.has(k) else None
                                              for k in ("sppc", "sppp", "sppi"))
        props.string("guiding", "octree", choices=("none", "grid", "octree"))
        props.bool("guiding_proj", True)
        props.int("guiding_rounds", 1, min=1)
        props.int("proj_seed_spp", 0, min=0)
        self.indirect_depth = props.int("indirect_depth", -1, min=-1)
        if self.indirect_depth == 0:
            raise props.error("indirect_depth", "must be -1 (every vertex max_depth allows) or >= 1, got 0 "
                                                "(sppi = 0 turns the indirect term off)")
        self._extra(props)
        props.finish()

    def _extra(self, props) -> None:
        """Subclasses read their own parameters here."""

    # -- set-up -----------------------------------------------------------------------------
    def prepare(self, scene, sensor: int = 0) -> None:
        super().prepare(scene, sensor)
        key = (id(scene.mi_scene), tuple(len(s.faces_buffer()) if s.is_mesh() else 0 for s in scene.mi_scene.shapes()))
        if getattr(self, "_edges_key", None) != key:
            self.edges = EdgeSet(scene)
            self._edges_key = key

    # -- derivatives: interior + boundaries -------------------------------------------------------
    @staticmethod
    def _scene_emissive_shapes(scene):
        return [i for i in scene.top_level_shapes() if scene.shape_emitter[i]]

    def _warn_uncovered(self, scene) -> None:
        """Warn (once per shape) about shapes with gradients whose silhouettes pbr does
        not sample (shapes other than meshes, rectangles, spheres, disks and cylinders:
        their boundary terms are missing)."""
        warned = self.__dict__.setdefault("_warned", set())
        for shape in scene.mi_scene.shapes():
            covered = (shape.is_mesh() or curve_kinds(shape) is not None
                       or shape.shape_type() == int(mi.ShapeType.Rectangle))
            if shape.parameters_grad_enabled() and not covered and shape.id() not in warned:
                warned.add(shape.id())
                warnings.warn(f"{self.name}: the silhouettes of shape {shape.id()!r} are not sampled (pbr samples "
                              f"those of meshes, rectangles, spheres, disks and cylinders), so the boundary part "
                              f"of its derivative is missing", RuntimeWarning, stacklevel=4)

    def _refuse_recording(self, counts) -> None:
        """The boundary terms choose their edges with weights computed on the host (the
        edges' projected lengths, the edge table's weights), which a ``dr.freeze``
        recording cannot replay: refuse them there, clearly."""
        edges = getattr(self, "edges", None)
        if any(counts[1:]) and (edges is None or edges.count) and dr.flag(dr.JitFlag.FreezingScope):
            raise RuntimeError(
                f"{self.path}: the boundary terms of {self.name!r} cannot be recorded by dr.freeze / "
                "pbr.freeze (they weigh silhouette edges on the host for the current geometry and camera); "
                "freeze a 'prb' step (interior derivatives only), or set sppp and sppi to 0, or run this "
                "step unfrozen")

    def render_backward(self, scene, grad_img, sensor=0, seed=0, spp=0, sample=None):
        self._warn_uncovered(scene)
        n_c, n_p, n_i = self._counts(scene, sensor, spp)
        self._refuse_recording((n_c, n_p, n_i))
        if n_c:
            super().render_backward(scene, grad_img, sensor, seed, n_c)
        else:
            self.prepare(scene, sensor)
        if not self.edges.count:
            return
        g = grad_img.array if isinstance(grad_img, mi.TensorXf) else mi.Float(np.asarray(grad_img, np.float32).ravel())
        if n_p:
            with dispatch.whole_packets():     # as render_backward's replays
                self._primary(scene, sensor, seed, n_p, BACKWARD, g)
        if n_i:
            self._distr = self._edge_distribution(scene, _detached(self.edges.state()))
            super().render_backward(scene, grad_img, sensor, _mix(seed, 2), n_i, sample=self._indirect_boundary)

    def render_forward(self, scene, sensor=0, seed=0, spp=0, sample=None):
        self._warn_uncovered(scene)
        n_c, n_p, n_i = self._counts(scene, sensor, spp)
        self._refuse_recording((n_c, n_p, n_i))
        if n_c:
            img = super().render_forward(scene, sensor, seed, n_c)
        else:
            self.prepare(scene, sensor)
            w, h = scene.sensors[sensor].film.size
            img = dr.zeros(mi.TensorXf, (h, w, 3))
        if not self.edges.count:
            return img
        if n_p:
            img = img + self._primary(scene, sensor, seed, n_p, FORWARD, None)
        if n_i:
            self._distr = self._edge_distribution(scene, _detached(self.edges.state()))
            img = img + super().render_forward(scene, sensor, _mix(seed, 2), n_i, sample=self._indirect_boundary)
        return img

    def _counts(self, scene, sensor, spp):
        """(sppc, sppp, sppi) of a derivative pass, by Mitsuba's rule: a count set to 0
        disables its term; otherwise the render's spp (spp_grad) wins, then the count
        given here, then the sensor's sampler."""
        sampler_spp = scene.sensors[sensor].sampler.sample_count
        out = []
        for n in (self.spp_c, self.spp_p, self.spp_i):
            out.append(0 if n == 0 else (int(spp) if spp else (n if n is not None else sampler_spp)))
        return tuple(out)

    # -- primary visibility -----------------------------------------------------------------------
    def _primary(self, scene, sensor, seed, spp, mode, g):
        """The primary-visibility boundary term: reverse mode propagates it (``g``: the
        image adjoint, flat); forward mode returns its image."""
        self.prepare(scene, sensor)
        cam = scene.sensors[sensor]
        if type(cam).name != "perspective":
            raise SceneError(f"{self.path}: the primary-visibility boundary of {self.name!r} needs a 'perspective' "
                             f"camera (sensor {sensor} is {type(cam).name!r})")
        w, h = cam.film.size
        rf = cam.film.rfilter
        proj = _Projection(cam, w, h)
        edges = self.edges
        with dr.suspend_grad():
            S = _detached(edges.state())
            pmf_w = self._projected_lengths(cam, proj, edges, S)
            total = float(dr.sum(pmf_w)[0])
        if not total > 0.0:
            return None if mode == BACKWARD else dr.zeros(mi.TensorXf, (h, w, 3))
        distr = mi.DiscreteDistribution(pmf_w)
        n = w * h * spp
        fx, fy = _filter_norms(rf, w), _filter_norms(rf, h)
        per_pass = max(1, min(n, max_samples_per_pass()))
        acc = dr.zeros(mi.Float, w * h * 3) if mode == FORWARD else None
        for first in range(0, n, per_pass):      # passes of bounded memory
            acc = self._primary_pass(scene, cam, proj, edges, S, distr, fx, fy, n, first, min(per_pass, n - first),
                                     seed, mode, g, acc)
            dr.eval(acc) if acc is not None else dr.eval()
        if mode == BACKWARD:
            return None
        with dr.suspend_grad():
            pixel = dr.arange(mi.UInt32, w * h)
            rgb = spec.xyz_to_srgb(mi.Array3f([dr.gather(mi.Float, acc, pixel * 3 + ch) for ch in range(3)]))
            out = dr.zeros(mi.Float, w * h * 3)
            for ch in range(3):
                dr.scatter(out, rgb[ch], pixel * 3 + ch)
            return mi.TensorXf(out, (h, w, 3))

    @staticmethod
    def _projected_lengths(cam, proj, edges, S, n_seg=32):
        """Per boundary, its length on the film where it is a silhouette from the pinhole
        in front of the camera (0 elsewhere): the primary term's choice of boundary.
        Analytic curves are measured as polylines of ``n_seg`` segments. Only the part
        inside the film counts (plus ``OFF_FILM`` of the rest: a curve may leave its
        polyline), so that edges reaching far outside it (a floor's) do not take the
        samples of the shapes in view."""
        w, h = cam.film.size
        parts = []
        for first, count, n in ((0, edges.n_edges, 1), (edges.n_edges, edges.curves.count, n_seg)):
            if not count:
                continue
            k = dr.repeat(dr.arange(mi.UInt32, count), n + 1) + first
            j = dr.tile(dr.arange(mi.UInt32, n + 1), count)
            y, _, sil, _ = edges.point(S, k, mi.Float(j) / n, proj.o, True)
            front = sil & (proj.depth(y) > cam.near_clip)
            x = proj.pixel(y)
            seg = dr.arange(mi.UInt32, count * n)
            i0 = seg // n * (n + 1) + seg % n
            x0, x1 = dr.gather(mi.Point2f, x, i0), dr.gather(mi.Point2f, x, i0 + 1)
            full = dr.norm(x1 - x0)
            d = _clipped_fraction(x0, x1, w, h) * full + OFF_FILM * full
            ok = dr.gather(mi.Bool, front, i0) & dr.gather(mi.Bool, front, i0 + 1) & dr.isfinite(d)
            out = dr.zeros(mi.Float, count)
            dr.scatter_reduce(dr.ReduceOp.Add, out, dr.select(ok, d, 0.0), seg // n)
            parts.append(np.array(out, np.float32))
        return mi.Float(np.concatenate(parts))

    def _primary_pass(self, scene, cam, proj, edges, S, distr, fx, fy, n, first, count, seed, mode, g, acc):
        """Samples ``first`` .. ``first + count`` of the ``n`` of the primary term."""
        w, h = cam.film.size
        rf = cam.film.rfilter
        with dr.suspend_grad():
            idx = dr.arange(mi.UInt32, count) + dr.opaque(mi.UInt32, first)
            rng = IndependentStream(rng=IndependentSampler.make_rng(idx, seed_array(_mix(seed, 1))))
            wl = SampledWavelengths.sample_visible(rng.next_float32())
            k, pmf = distr.sample_pmf(rng.next_float32())
            t = rng.next_float32()
            y, e, sil, y_l = edges.point(S, k, t, proj.o, True)
            x, dx = proj.pixel(y), proj.pixel_dt(y, e, 0.0)
            speed = dr.norm(dx)
            nrm = mi.Vector2f(-dx.y, dx.x) / speed
            # the image integrates over the film only (samples outside it are dropped)
            ok = (pmf > 0) & sil & (proj.depth(y) > cam.near_clip) & (speed > 0)
            ok &= (x.x >= 0) & (x.x < w) & (x.y >= 0) & (x.y < h)
            weight = dr.select(ok, speed / (pmf * n), 0.0)
            L = []
            self.face_first_hit = True       # past the rim of interpolated normals (face_the_ray)
            try:
                for sgn in (-1.0, 1.0):
                    q = x + nrm * (sgn * PIXEL_EPS)
                    ray = cam.sample_ray(mi.Point2f(q.x / w, q.y / h))
                    r2 = rng.copy()
                    L.append(self.sample(scene, r2, ray, wl, PRIMAL, None, None, ok)[0])
            finally:
                self.face_first_hit = False
            xyz = spec.to_xyz(L[0] - L[1], wl) * weight
            finite = dr.all(dr.isfinite(xyz))
            xyz, = self.counter().replace([xyz], ok)       # non-finite estimates: counted, then 0
            ok &= finite
            R = int(math.ceil(rf.radius - 0.5))
            base = mi.Int32(dr.floor(x.x)), mi.Int32(dr.floor(x.y))
            taps = []
            for i in range(-R - 1, R + 2):
                for j in range(-R - 1, R + 2):
                    px, py = base[0] + i, base[1] + j
                    inside = ok & (px >= 0) & (px < w) & (py >= 0) & (py < h)
                    norm = dr.gather(mi.Float, fx, mi.UInt32(px), inside) * dr.gather(mi.Float, fy, mi.UInt32(py), inside)
                    fw = rf.eval(x.x - (mi.Float(px) + 0.5)) * rf.eval(x.y - (mi.Float(py) + 0.5)) * dr.rcp(norm)
                    inside &= fw != 0
                    taps.append((mi.UInt32(py * w + px), fw, inside))
        with dr.resume_grad():
            y_a = edges.attached(edges.state(), k, t, y_l, ok)
            proj_ad = _Projection(cam, w, h, attached=True) if cam.to_world_ad is not None else proj
            vn = dr.dot(proj_ad.pixel(y_a), dr.detach(nrm))
        if mode == BACKWARD:
            with dr.suspend_grad():
                g_xyz = mi.Array3f(0.0)
                for pix, fw, inside in taps:
                    gr = mi.Array3f([dr.gather(mi.Float, g, pix * 3 + ch, inside) for ch in range(3)])
                    g_xyz += spec.srgb_to_xyz_adjoint(gr) * dr.select(inside, fw, 0.0)
                s = dr.dot(xyz, g_xyz)
            with dr.resume_grad():
                dr.backward_from(s * vn, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
            return None
        with dr.resume_grad():
            dv = dr.forward_to(vn, flags=dr.ADFlag.ClearInterior | dr.ADFlag.AllowNoGrad)
        with dr.suspend_grad():
            val = xyz * dv
            for pix, fw, inside in taps:
                for ch in range(3):
                    dr.scatter_reduce(dr.ReduceOp.Add, acc, val[ch] * fw, pix * 3 + ch, inside)
        return acc

    # -- indirect visibility: from a vertex of the camera path ------------------------------------
    def _indirect_boundary(self, scene, rng, ray, wl, mode, dL, L_in, active):
        """Per camera sample, the boundary term of the light reflected at one vertex x of
        the camera path (the first hit, or a deeper one: :meth:`_projection_vertex`), an
        estimator with the ``sample`` interface (zero in PRIMAL mode)."""
        if mode == PRIMAL or self._projection_depth() < 1:     # (max_depth 1: no segment to project)
            return mi.Spectrum(0.0), mi.Bool(active)
        edges, geo, bsdfs = self.edges, scene.geometry, scene.bsdfs
        max_depth = depth_limit(self.max_depth)
        if self._projection_depth() == 1:
            # the first hit only (direct_projective, max_depth 2, indirect_depth 1): no walk
            ray_x, depth, beta, found = ray, mi.UInt32(1), mi.Spectrum(1.0), mi.Bool(active)
            r_ad = self.primary_ray_ad
        else:
            with dr.suspend_grad():
                ray_x, depth, beta, found = self._projection_vertex(scene, rng, ray, wl, active)
            r_ad = None
            if self.primary_ray_ad is not None:
                # the camera pose's gradients reach a first hit; deeper vertices slide
                # along their detached incoming ray
                with dr.resume_grad():
                    r_ad = dr.select(depth == 1, self.primary_ray_ad, ray_x)
        si, shape = geo.intersect(ray_x, found, attached=True, ray_ad=r_ad)
        hit = found & si.is_valid()
        bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
        on = hit & bsdfs.smooth(bsdf_id, hit) & (depth < max_depth)
        S = _detached(edges.state())
        x = dr.detach(si.p)
        # Resampled importance sampling (RIS) of the edge point: CANDIDATES points drawn by
        # edge length, one kept in proportion to target / pmf, the target being the edge
        # measure of a silhouette point times (floor + 1 if its direction points at an
        # emitter's bounding sphere) times (BSDF_FLOOR + the BSDF toward it); estimate =
        # h / target * mean(target / pmf). The floor is small where the rest of the path
        # is one segment (only emitters light x).
        floor = dr.select(depth + 1 >= max_depth, CONE_FLOOR, 10 * CONE_FLOOR)
        wsum = mi.Float(0.0)
        k, t, target = mi.UInt32(0), mi.Float(0.0), mi.Float(0.0)
        si_d = dr.detach(si)
        ctx = ShadingContext(si_d, wl)
        for _ in range(CANDIDATES):
            k_i, pmf_i = self._distr.sample_pmf(rng.next_float32())
            t_i = rng.next_float32()
            y, e, sil, _ = edges.point(S, k_i, t_i, x, on)
            meas, wdir = _edge_measure(x, e, y)
            tgt = dr.select(on & sil, meas, 0.0) * (floor + self._toward_light(x, wdir))
            f_i, _ = bsdfs.eval_pdf(bsdf_id, ctx, si_d.to_local(wdir), on & (tgt > 0))
            tgt *= BSDF_FLOOR + dr.mean(f_i)
            w_i = dr.select(pmf_i > 0, tgt / pmf_i, 0.0)
            wsum += w_i
            take = rng.next_float32() * wsum < w_i
            k, t, target = dr.select(take, k_i, k), dr.select(take, t_i, t), dr.select(take, tgt, target)
        on &= target > 0
        y, e, _, y_l = edges.point(S, k, t, x, on)
        r = dr.norm(y - x)
        wdir = (y - x) / r
        cr = dr.cross(wdir, dr.normalize(e))
        nw = cr / dr.norm(cr)
        meas, _ = _edge_measure(x, e, y)
        weight = dr.select(on, meas * wsum / (CANDIDATES * target), 0.0)
        g = []
        for sgn in (-1.0, 1.0):
            # aimed beside the edge point from the spawned ray's origin, which lies off x
            # (along the normal, by about as much as the offset beside the edge: aiming
            # from x put both rays on one side of edges seen at a low angle)
            ray = si_d.spawn_ray(wdir)
            ray.d = dr.normalize(y + nw * (sgn * ANGLE_EPS * r) - ray.o)
            f, _ = bsdfs.eval_pdf(bsdf_id, ctx, si_d.to_local(ray.d), on)
            r2 = rng.copy()
            Li = self._incident(scene, r2, ray, wl, depth, on)
            g.append(f * Li)
        jump = dr.select(on, (g[0] - g[1]) * (beta * weight), 0.0)
        with dr.resume_grad():
            y_a = edges.attached(edges.state(), k, t, y_l, on)
            vn = dr.dot(y_a - si.p, dr.detach(nw)) / dr.detach(r)
            term = jump * vn
            if mode == BACKWARD:
                dr.backward_from(dL * term, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)
                return mi.Spectrum(0.0), mi.Bool(active)
            return forward_derivative(term), mi.Bool(active)

    def _projection_depth(self) -> int:
        """The deepest camera-path vertex the indirect term projects from: the last one
        with a segment left (``max_depth`` - 1), at most ``indirect_depth`` (2^32 - 1:
        unlimited, paths end by Russian roulette)."""
        deepest = depth_limit(self.max_depth) - 1
        if self.indirect_depth > 0:
            deepest = min(deepest, self.indirect_depth)
        return deepest

    @dr.syntax
    def _projection_vertex(self, scene, rng, ray, wl, active):
        """The vertex of the camera path from which the indirect term projects: (the ray
        whose hit it is, its depth k (1: the first hit), the camera subpath's weight,
        whether one was found).

        The path is traced by BSDF sampling (detached) up to :meth:`_projection_depth`;
        it goes on through delta lobes (a mirror, glass), from which nothing is
        projected since their light cannot jump across an edge direction. Among the
        vertices with a non-delta lobe, one is kept by weighted reservoir sampling in
        proportion to w_k = mean(beta_k) (VERTEX_FLOOR + mean(f cos / pdf at x_k)), beta_k
        the throughput of the k - 1 bounces before it: deep vertices of a dim path, and
        black surfaces, are rarely chosen. Its weight is beta_k / P(k), P(k) = w_k / sum w.
        (Mitsuba's prb_projective picks the vertex uniformly among those connected to the
        sensor by a walk from the edge: its weight is the walk's importance times their
        count.)"""
        geo, bsdfs = scene.geometry, scene.bsdfs
        deepest = self._projection_depth()
        ray_var, ray_fixed = ray_state(ray)
        o, d, maxt = mi.Point3f(ray.o), mi.Vector3f(ray.d), mi.Float(ray.maxt)
        depth, chosen = mi.UInt32(0), mi.UInt32(0)
        beta, beta_w = mi.Spectrum(1.0), mi.Spectrum(0.0)
        wsum = mi.Float(0.0)
        active = mi.Bool(active)
        rng_state = rng.loop_state()
        while dr.hint(active, label="projection vertex", exclude=[ray_fixed, rng, wl]):
            r = loop_ray(ray_var, ray_fixed)
            rng.set_loop_state(rng_state)
            si, shape = geo.intersect(r, active)
            hit = active & si.is_valid()
            bsdf_id = dr.gather(mi.UInt32, scene.shape_bsdf, shape, hit)
            bs = bsdfs.sample(bsdf_id, ShadingContext(si, wl), rng.next_float32(), rng.next_2d(), hit)
            depth[hit] = depth + 1
            can = hit & bsdfs.smooth(bsdf_id, hit)
            w = dr.select(can, dr.mean(beta) * (VERTEX_FLOOR + dr.mean(bs.weight)), 0.0)
            wsum += w
            take = (w > 0) & (rng.next_float32() * wsum < w)
            o[take], d[take], maxt[take] = r.o, r.d, r.maxt
            chosen[take] = depth
            beta_w[take] = beta / w
            beta *= bs.weight
            ray_var = ray_state(si.spawn_ray(si.to_world(bs.wo)))[0]
            # Russian roulette (as the path tracer's, from rr_depth on)
            b_max = dr.max(beta)
            q = dr.minimum(b_max, 0.95)
            rr = depth >= self.rr_depth
            survive = rng.next_float32() < q
            beta[rr] = beta * dr.rcp(q)
            active = hit & (bs.pdf > 0) & nonzero(beta) & (~rr | survive) & (depth < deepest)
            rng_state = rng.loop_state()
        rng.set_loop_state(rng_state)
        found = chosen > 0
        return mi.Ray3f(o, d, maxt, ray.time, ray.wavelengths), chosen, dr.select(found, beta_w * wsum, 0.0), found

    def _toward_light(self, x, wdir):
        """1 where direction ``wdir`` from ``x`` points into the bounding sphere of an
        emissive shape (every direction with an environment light), else 0."""
        if self._all_directions:
            return mi.Float(1.0)
        out = mi.Bool(False)
        for cx, cy, cz, rad in self._spheres:
            v = mi.Vector3f(cx, cy, cz) - x
            dist2 = dr.squared_norm(v)
            cos_max = dr.safe_sqrt(dr.maximum(1.0 - rad * rad / dr.maximum(dist2, 1e-30), 0.0))
            out |= (dist2 <= rad * rad) | (dr.dot(v, wdir) >= cos_max * dr.sqrt(dist2))
        return dr.select(out, 1.0, 0.0)

    def _edge_distribution(self, scene, S):
        """Boundaries for the indirect term: in proportion to length, times
        ``LIGHT_BOOST`` for the edges that are silhouettes seen from a vertex or the
        centroid of an emissive shape (those that cast shadow boundaries of small lights)
        and for the analytic curves (silhouettes from almost everywhere). Every boundary
        keeps a nonzero probability, so the estimator stays unbiased; this is a cheap
        stand-in for Mitsuba's guiding structures."""
        edges = self.edges
        P, F = S
        with dr.suspend_grad():
            self._spheres = []
            # emitters the edge table does not hold (environment, other shapes' lights):
            # every direction may see light
            held = len(self._scene_emissive_shapes(scene)) == len(edges.emitting)
            self._all_directions = bool(scene.lights.has_infinite) or not held or not edges.emitting
            weights = []
            if edges.n_edges:
                k_all = dr.arange(mi.UInt32, edges.n_edges)
                a, b, c, d, has_d = edges.gather(P, k_all, True)
                weight = dr.norm(b - a)
                pts = np.array(P, dtype=np.float64).reshape(-1, 3)
                for lo, hi in edges.emitting:
                    q = pts[lo:hi]
                    centre = q.mean(axis=0)
                    self._spheres.append((*centre.tolist(), float(np.linalg.norm(q - centre, axis=1).max()) * 1.001))
                if edges.emitting:
                    lights = [pts[lo:hi][::-(-(hi - lo) // LIGHT_VIEWPOINTS)] for lo, hi in edges.emitting]
                    lights = np.concatenate(lights + [np.mean(x, axis=0, keepdims=True) for x in lights])
                    mark = mi.Bool(False)
                    for q in lights.tolist():
                        mark |= silhouette(mi.Point3f(*q), a, b, c, d, has_d)
                    weight = weight * dr.select(mark, LIGHT_BOOST, 1.0)
                weights.append(np.array(weight, np.float64))
            if edges.curves.count:
                weights.append(LIGHT_BOOST * edges.curves.lengths(F))
            return mi.DiscreteDistribution(mi.Float(np.concatenate(weights).astype(np.float32)))

    def _incident(self, scene, rng, ray, wl, depth, active):
        """Radiance arriving along ``ray`` from camera-path vertex ``depth`` (the rest of the
        path: ``max_depth`` and Russian roulette count the ``depth`` vertices before it;
        emitters visible)."""
        saved = self.hide_emitters
        self.hide_emitters, self.face_first_hit = False, True
        try:
            return PathIntegrator._sample(self, scene, rng, ray, wl, PRIMAL, None, None, active, depth0=depth)[0]
        finally:
            self.hide_emitters = saved
            self.face_first_hit = False


@INTEGRATORS.register("direct_projective")
class DirectProjectiveIntegrator(ProjectivePathIntegrator):
    """``direct_projective`` (Mitsuba's): direct illumination (``prb_projective`` with
    ``max_depth`` 2) with the boundary terms of primary visibility and of shadows
    (silhouettes between the first hit and the emitters).

    =============  ======  =======  ==============================================================
    name           type    default  meaning
    =============  ======  =======  ==============================================================
    max_depth      int     2        accepted and ignored (2: direct illumination, as Mitsuba's)
    rr_depth       int     2        accepted and ignored
    hide_emitters  bool    false    camera rays pass through emitting surfaces
    light_sampler  string  bvh      light choice of next-event estimation
    sppc           int     -        samples per pixel of the interior derivative (0: off; see
                                    prb_projective for which count wins)
    sppp           int     -        the same for the primary-visibility boundary term
    sppi           int     -        the same for the shadow boundary term
    guiding        string  octree   accepted and ignored (Mitsuba's guiding; 'none', 'grid',
                                    'octree')
    guiding_proj   bool    true     accepted and ignored
    guiding_rounds int     1        accepted and ignored
    proj_seed_spp  int     0        accepted and ignored
    project_seed   string  both     accepted and ignored (Mitsuba's: 'both', 'bsdf', 'emitter')
    =============  ======  =======  ==============================================================
    """

    name = "direct_projective"
    default_max_depth = 2

    def _extra(self, props) -> None:
        props.string("project_seed", "both", choices=("both", "bsdf", "emitter"))
        self.max_depth, self.rr_depth = 2, 2   # direct illumination (Mitsuba overrides both too)


class _Unfinished:
    """A view of Props whose ``finish`` does nothing (the subclass reads more keys)."""

    def __init__(self, props):
        self._props = props

    def finish(self):
        pass

    def __getattr__(self, name):
        return getattr(self._props, name)


class _Projection:
    """A perspective camera's map from world points to pixel coordinates of its (cropped)
    film, and the derivative along a segment (for the edge measure)."""

    def __init__(self, cam, w, h, attached=False):
        if attached:     # the camera pose with its gradients (cam.to_world_ad)
            m = cam.to_world_ad
            self.m = [[m[r][c] for c in range(4)] for r in range(4)]
            self.o = mi.Point3f(m[0][3], m[1][3], m[2][3])
        else:
            m = np.asarray(cam.to_world, np.float64)
            self.m = m.tolist()
            self.o = mi.Point3f(*m[:3, 3].tolist())
        tx = math.tan(math.radians(cam.x_fov) / 2)
        sx, sy, ox, oy = cam._crop
        self.kx, self.ky = -0.5 * w / (tx * sx), -0.5 * h * cam.aspect / (tx * sy)
        self.cx = w / sx * (0.5 - cam.pp[0] - ox)
        self.cy = h / sy * (0.5 - cam.pp[1] - oy)

    def local(self, v):
        m = self.m
        return mi.Vector3f(*[m[0][k] * v.x + m[1][k] * v.y + m[2][k] * v.z for k in range(3)])

    def depth(self, p):
        return self.local(p - self.o).z

    def pixel(self, p):
        q = self.local(p - self.o)
        inv = dr.rcp(q.z)
        return mi.Point2f(dr.fma(self.kx, q.x * inv, self.cx), dr.fma(self.ky, q.y * inv, self.cy))

    def pixel_dt(self, a, e, t):
        """d pixel / dt of the point a + t e."""
        A, D = self.local(a - self.o), self.local(e)
        z = dr.fma(D.z, t, A.z)
        X, Y = dr.fma(D.x, t, A.x), dr.fma(D.y, t, A.y)
        inv2 = dr.rcp(z * z)
        return mi.Vector2f(self.kx * (D.x * z - X * D.z) * inv2, self.ky * (D.y * z - Y * D.z) * inv2)


def _clipped_fraction(x0, x1, w, h):
    """The fraction of film segment x0 -> x1 inside [0, w] x [0, h] (Liang-Barsky)."""
    d = x1 - x0
    t0, t1 = mi.Float(0.0), mi.Float(1.0)
    out = mi.Bool(False)
    for p, q in ((-d.x, x0.x), (d.x, w - x0.x), (-d.y, x0.y), (d.y, h - x0.y)):
        r = q / p       # the segment is inside where p t <= q
        t0 = dr.select(p < 0, dr.maximum(t0, r), t0)
        t1 = dr.select(p > 0, dr.minimum(t1, r), t1)
        out |= (p == 0) & (q < 0)
    return dr.select(out | (t1 <= t0), 0.0, t1 - t0)


def _detached(S):
    """:meth:`EdgeSet.state` without its gradients."""
    P, F = S
    return (None if P is None else dr.detach(P)), (None if F is None else tuple(dr.detach(f) for f in F))


def _filter_norms(rf, n: int) -> mi.Float:
    """Per pixel index i < n along one film axis, the integral of the pixel filter over
    the film, int_0^n f(x - i - 1/2) dx: the normalisation of pixel i's value (the film
    drops samples outside it, so pixels at the border integrate a truncated filter)."""
    xs = np.linspace(-rf.radius, rf.radius, 4001)
    with dr.suspend_grad():
        f = np.array(rf.eval(mi.Float(xs.astype(np.float32))), dtype=np.float64)
    centres = np.arange(n) + 0.5
    out = []
    for c in centres:
        inside = (xs + c >= 0) & (xs + c <= n)
        g = np.where(inside, f, 0.0)
        out.append(float(np.sum((g[1:] + g[:-1]) * np.diff(xs)) / 2))
    return mi.Float(np.asarray(out, np.float32))


def _mix(seed, k: int):
    """A seed for the boundary passes, decorrelated from ``seed``."""
    if isinstance(seed, int):
        return (seed * 0x9E3779B1 + 0x632BE5AB * k) & 0xFFFFFFFF
    return seed_array(seed) * 0x9E3779B1 + 0x632BE5AB * k
