"""The bridge to Mitsuba's ray tracer (Embree on the CPU, OptiX on CUDA).

pbr hands its shapes to Mitsuba (``optimize=False`` keeps one Mitsuba shape per pbr
shape) and uses only intersection, surface-interaction and shape-sampling queries.
OBJ and serialized meshes are read by Mitsuba's own loaders (so that vertices split per
distinct position/uv/normal corner, normals and uv flips are exactly Mitsuba's); PLY
files are read with trimesh (their attributes hold the file's values); both become
``mi.Mesh`` objects.

A hit is mapped to pbr's shape (which indexes pbr's material, light and medium tables)
through the hit's shape pointer, which both ray tracers fill in: in Mitsuba's JIT
variants it holds the shape's Dr.Jit registry id. ``PreliminaryIntersection.shape_index``
is not used: Embree fills it in, OptiX leaves it 0 (Mitsuba 3.9's
``scene_optix.inl``). Registry ids follow the order in which Mitsuba objects were
created (shapes built on several threads, meshes read before the scene, slots freed by
earlier scenes), not the scene's shape order, so the map is a table built from
``Scene.shapes_dr()``.
"""

from __future__ import annotations

import os

import drjit as dr
import mitsuba as mi
import numpy as np

from . import dispatch
from .motion import AnimatedTransform, inverse3
from .plugins.props import Props, SceneError, did_you_mean
from .textures.meshattr import attach, file_attributes

# Parameters each shape type understands (beyond bsdf/emitter/id).
SHAPE_PARAMS = {
    "rectangle": ("to_world", "flip_normals"),
    "disk": ("to_world", "flip_normals"),
    "cube": ("to_world", "flip_normals"),
    "sphere": ("to_world", "flip_normals", "center", "radius"),
    "cylinder": ("to_world", "flip_normals", "p0", "p1", "radius"),
    "obj": ("to_world", "flip_normals", "filename", "face_normals", "flip_tex_coords"),
    "ply": ("to_world", "flip_normals", "filename", "face_normals", "flip_tex_coords"),
    # Mitsuba's compressed mesh format (zlib-deflated streams, several meshes per file).
    "serialized": ("to_world", "flip_normals", "filename", "face_normals", "shape_index"),
    # Mitsuba's curves (round tubes; a text file of "x y z radius" lines, a blank line
    # between curves). Their shading frame has s around the tube and t along it.
    "bsplinecurve": ("to_world", "filename"),
    "linearcurve": ("to_world", "filename"),
    # Mitsuba's signed-distance grid (a .vol file of distances on [0, 1]^3).
    "sdfgrid": ("to_world", "flip_normals", "filename", "normals"),
}
MESH_FILES = ("obj", "ply", "serialized")
CURVE_FILES = ("bsplinecurve", "linearcurve")


def _to_mi_transform(m: np.ndarray):
    return mi.ScalarTransform4f(m.astype(np.float64))


def read_motion(props: Props, m0: np.ndarray, end: str = "to_world_end"):
    """The :class:`~.motion.AnimatedTransform` from ``m0`` (the plugin's ``to_world``) at
    ``transform_times[0]`` to ``end`` at ``transform_times[1]`` (pbrt-v4's
    ``TransformTimes``; default [0, 1]; in XML a string "t0 t1"), or None where ``end``
    is not given or equals ``m0``. Cameras, shapes and instances read their motion here."""
    times = props.raw("transform_times", [0.0, 1.0])
    if isinstance(times, str):         # from XML: <string name="transform_times" value="0 1"/>
        times = times.replace(",", " ").split()
    try:
        t0, t1 = (float(t) for t in np.asarray(times, np.float64).reshape(2))
    except (TypeError, ValueError):
        raise props.error("transform_times", f"expected two times [start, end], got {times!r}") from None
    if not t1 > t0:
        raise props.error("transform_times", f"the end time must exceed the start time, got {times!r}")
    if not props.has(end):
        return None
    m1 = props.transform(end)
    if abs(np.linalg.det(m1[:3, :3])) < 1e-300 or np.any(m1[3] != (0.0, 0.0, 0.0, 1.0)):
        raise props.error(end, "expected an invertible affine transform")
    return None if np.allclose(m1, m0) else AnimatedTransform(m0, m1, t0, t1)


def _built_to_world(props: Props, object_space: bool) -> np.ndarray:
    """The ``to_world`` a shape is built with: its own, or the identity for a moving shape
    (built in its object space; its motion moves it)."""
    m = props.transform("to_world")
    return np.eye(4) if object_space else m


def _mitsuba_mesh(props: Props, path: str, object_space: bool = False) -> "mi.Mesh":
    """An OBJ or serialized mesh read by Mitsuba's own loader, in world space. OBJ vertex
    colours (``v x y z r g b``, which Mitsuba ignores) become ``vertex_color``.
    ``object_space``: without ``to_world`` (a moving shape)."""
    to_world = _built_to_world(props, object_space)
    d = {"type": props.type, "filename": path, "face_normals": props.bool("face_normals", False),
         "flip_normals": props.bool("flip_normals", False), "to_world": _to_mi_transform(to_world)}
    if props.type == "obj":
        d["flip_tex_coords"] = props.bool("flip_tex_coords", True)
    else:
        d["shape_index"] = props.int("shape_index", 0, min=0)
    try:
        mesh = mi.load_dict(d)
    except Exception as e:
        raise props.error("filename", f"cannot read mesh {path!r}: {str(e).strip().splitlines()[-1]}") from None
    if props.type == "obj":
        attach(mesh, _obj_vertex_colours(mesh, path, d, props))
    return mesh


def _obj_vertex_colours(mesh, path: str, d: dict, props: Props) -> dict:
    """``vertex_color`` of the vertices of ``mesh`` (Mitsuba's OBJ mesh) from an OBJ file's
    ``v x y z r g b`` lines, or nothing. Mitsuba splits a file vertex into one vertex per
    distinct corner; each is matched to its file vertex by position (read without
    ``to_world``)."""
    with open(path, "rb") as f:
        if not any(line.startswith(b"v ") and len(line.split()) >= 7 for line in f):
            return {}
    import trimesh
    try:
        tmesh = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    except Exception as e:
        raise props.error("filename", f"cannot read mesh {path!r}: {e}") from None
    colours = file_attributes(tmesh, "obj", props.key("filename")).get("vertex_color")
    if colours is None:
        return {}
    plain = mi.load_dict({**d, "to_world": mi.ScalarTransform4f(), "flip_normals": False})
    pos = np.array(mi.traverse(plain)["vertex_positions"], dtype=np.float32).reshape(-1, 3)
    index = {tuple(v): i for i, v in enumerate(np.asarray(tmesh.vertices, dtype=np.float32))}
    rows = [index.get(tuple(v)) for v in pos]
    if len(pos) != mesh.vertex_count() or any(r is None for r in rows):
        raise props.error("filename", f"{path!r}: cannot match the OBJ vertex colours to Mitsuba's vertices")
    return {"vertex_color": colours[rows]}


def load_mesh_file(props: Props, path: str, object_space: bool = False) -> "mi.Mesh":
    """Read a mesh file into an ``mi.Mesh`` in world space: OBJ and serialized files with
    Mitsuba's loaders, PLY files with trimesh.

    Conventions follow Mitsuba's own loaders: OBJ texture coordinates are flipped
    vertically (``flip_tex_coords``, default true); missing vertex normals are
    recomputed (smooth) unless ``face_normals`` is true. ``object_space``: without
    ``to_world`` (a moving shape)."""
    if props.type in ("obj", "serialized"):
        return _mitsuba_mesh(props, path, object_space)
    import trimesh
    to_world = _built_to_world(props, object_space)
    face_normals = props.bool("face_normals", False)
    flip_tc = props.bool("flip_tex_coords", props.type == "obj")
    flip_normals = props.bool("flip_normals", False)
    try:
        # A single mesh is used as read: merging (force="mesh") copies its colours, which
        # trimesh cannot do for PLY face colours without scipy.
        mesh = trimesh.load(path, process=False, maintain_order=True)
        if not isinstance(mesh, trimesh.Trimesh):
            mesh = trimesh.load(path, process=False, force="mesh", maintain_order=True)
    except Exception as e:
        raise props.error("filename", f"cannot read mesh {path!r}: {e}") from None
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.uint32)
    if len(f) == 0:
        raise props.error("filename", f"mesh {path!r} has no faces")
    has_n = "vertex_normals" in mesh._cache.cache or getattr(mesh, "_vertex_normals_from_file", False)
    n = np.asarray(mesh.vertex_normals, dtype=np.float64) if (has_n and not face_normals) else None
    uv = None
    vis = getattr(mesh, "visual", None)
    if vis is not None and getattr(vis, "uv", None) is not None and len(vis.uv) == len(v):
        uv = np.asarray(vis.uv, dtype=np.float64).copy()
        if flip_tc:
            uv[:, 1] = 1.0 - uv[:, 1]
    vw = v @ to_world[:3, :3].T + to_world[:3, 3]
    m = mi.Mesh(os.path.basename(path), len(vw), len(f),
                has_vertex_normals=not face_normals, has_vertex_texcoords=uv is not None)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(vw.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(f.ravel())
    if n is not None:
        nt = np.linalg.inv(to_world[:3, :3]).T
        nw = n @ nt.T
        nw /= np.maximum(np.linalg.norm(nw, axis=1, keepdims=True), 1e-30)
        params["vertex_normals"] = mi.Float(nw.astype(np.float32).ravel())
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(uv.astype(np.float32).ravel())
    params.update()
    if n is None and not face_normals:
        m.recompute_vertex_normals()
    if flip_normals:
        fl = np.asarray(f)[:, ::-1].copy()
        params["faces"] = mi.UInt32(fl.ravel())
        params.update()
        if n is None and not face_normals:
            m.recompute_vertex_normals()
    attach(m, file_attributes(mesh, props.type, props.key("filename")))
    return m


def shape_to_mitsuba(props: Props, resolve_path, object_space: bool = False):
    """The Mitsuba object or dict for one shape (geometry only, no BSDF/emitter);
    ``object_space``: built without its ``to_world`` (a moving shape)."""
    t = props.type
    if t not in SHAPE_PARAMS:
        raise props.error(None, f"unsupported shape type {t!r}{did_you_mean(t, SHAPE_PARAMS)} "
                                        f"(supported: {', '.join(SHAPE_PARAMS)})")
    if t in MESH_FILES:
        path = resolve_path(props.string("filename"), props.key("filename"))
        return load_mesh_file(props, path, object_space)
    d = {"type": t}
    for k in SHAPE_PARAMS[t]:
        if not props.has(k):
            continue
        if k == "to_world":
            d[k] = _to_mi_transform(_built_to_world(props, object_space))
        elif k == "flip_normals":
            d[k] = props.bool(k)
        elif k in ("center", "p0", "p1"):
            d[k] = mi.ScalarPoint3f(*props.vector3(k))
        elif k == "radius":
            d[k] = props.float(k, min=0.0)
        elif k == "filename":
            d[k] = resolve_path(props.string(k), props.key(k))
        elif k == "normals":
            d[k] = props.string(k, choices=("smooth", "analytic"))
    if t in CURVE_FILES:
        # Loaded here so that a malformed curve file is reported under its key.
        try:
            return mi.load_dict(d)
        except Exception as e:
            raise props.error("filename", f"Mitsuba could not load the curves: {e}") from None
    return d


def build_shape(shape):
    """A Mitsuba shape object for ``shape`` (an object already, or a ``load_dict`` dict)."""
    return mi.load_dict(shape) if isinstance(shape, dict) else shape


def registry_id(shape) -> int:
    """The Dr.Jit registry id of a Mitsuba shape object (what a hit's shape pointer holds)."""
    return int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])


#: pbr shape index of registry ids that belong to no shape of the scene (0 is a miss).
NO_SHAPE = 0xFFFFFFFF


class Geometry:
    """Mitsuba scene holding the shapes; ray queries for the integrators.

    ``mi_index[i]`` is pbr shape ``i``'s position in ``mi_scene.shapes()`` (and
    ``shapes_dr()``; -1 for a shape inside a shape group or a moving shape);
    ``shape_of_id`` maps a shape's registry id to its pbr index.

    Instancing (Mitsuba's ``shapegroup``/``instance``): ``groups`` maps pbr shapes to
    the group holding them (built Mitsuba objects, not shapes of the scene themselves);
    ``instances`` lists (group, to_world, motion) triples (motion: an
    :class:`~.motion.AnimatedTransform`, or None). A hit on an instance resolves to the
    group's shape that was hit (``si.shape``; the preliminary intersection's shape
    pointer is empty on instance hits), so every instance has its shapes' BSDFs and
    media, as in Mitsuba.

    Motion blur (pbrt-v4's animated primitives): ``motions`` maps top-level pbr shapes
    to their :class:`~.motion.AnimatedTransform`. Mitsuba 3.9 builds every shape and
    instance at one time, so each moving shape (in its object space) and each shape group
    of a moving instance (in its own space) is a Mitsuba scene of its own, a *mover*
    (moving shapes with the same motion share one):
    a ray is taken into its space at the ray's time, intersected there, and the nearest
    of the static hit and the movers' hits is taken back to world space. A scene without
    movers traces exactly the queries it traced before."""

    #: Geometry keys updated inside the frozen call being recorded, whose acceleration
    #: structure ``pbr.freeze`` rebuilds after the call: ray queries refuse until then.
    stale: tuple = ()

    def __init__(self, shapes: list, groups: dict | None = None, instances: list | None = None,
                 motions: dict | None = None):
        groups, instances, motions = groups or {}, instances or [], motions or {}
        d = {"type": "scene"}
        members: dict[str, dict] = {}
        for i, s in enumerate(shapes):
            if i in groups:
                members.setdefault(groups[i], {})[f"shape_{i:06d}"] = s
            elif i not in motions:
                d[f"shape_{i:06d}"] = s
        for g, m in members.items():
            d[f"group_{g}"] = {"type": "shapegroup", **m}
        for j, (g, to_world, motion) in enumerate(instances):
            if g not in members:
                raise SceneError(f"scene: internal error: instance of unknown shape group {g!r}")
            if motion is None:
                d[f"instance_{j:06d}"] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"group_{g}"},
                                          "to_world": _to_mi_transform(to_world)}
        try:
            self.mi_scene = mi.load_dict(d, optimize=False)
            # Movers: (Mitsuba scene in the moving thing's space, AnimatedTransform).
            self.movers, spaces = [], {}
            moving = [(i, build_shape(shapes[i])) for i in sorted(motions)]
            # Shapes with the same motion (e.g. the meshes of one animated object) share one.
            same: dict[tuple, dict] = {}
            for i, obj in moving:
                same.setdefault(motions[i].key, {})[f"shape_{i:06d}"] = (obj, motions[i])
            for objs in same.values():
                scene = mi.load_dict({"type": "scene", **{k: o for k, (o, _) in objs.items()}}, optimize=False)
                self.movers.append((scene, next(iter(objs.values()))[1]))
            for g, _, motion in instances:
                if motion is not None:
                    if g not in spaces:
                        spaces[g] = mi.load_dict({"type": "scene", **members[g]}, optimize=False)
                    self.movers.append((spaces[g], motion))
        except SceneError:
            raise
        except Exception as e:
            raise SceneError(f"scene: Mitsuba could not build the geometry: {e}") from None
        if self.movers and _traces_with_optix():
            raise SceneError("scene: moving shapes (motion blur of shapes or instances) are not supported on the "
                             "CUDA backend yet: each moving object is traced in a Mitsuba scene of its own, and "
                             "OptiX allows one shader binding table per kernel (Dr.Jit disables the other scenes' "
                             "rays, so the moving objects would be missing from the image); render them with "
                             "pbr.set_backend('llvm') (camera motion blur works on both)")
        mi_shapes = self.mi_scene.shapes()
        # Mitsuba names each shape by its key (objects built beforehand too); its order
        # is the dict's, but the map does not rely on that.
        names = [s.id() for s in mi_shapes]
        if sorted(names) != sorted(k for k in d if k.startswith(("shape_", "instance_"))):
            raise SceneError("scene: internal error: Mitsuba's shapes differ from pbr's")
        to_pbr = np.array([int(n.split("_")[-1]) if n.startswith("shape_") else NO_SHAPE for n in names],
                          dtype=np.int64)
        self.mi_index = np.full(len(shapes), -1, dtype=np.int64)
        listed = to_pbr != NO_SHAPE
        self.mi_index[to_pbr[listed]] = np.arange(len(to_pbr))[listed]
        reg = np.array(dr.reinterpret_array(mi.UInt32, self.mi_scene.shapes_dr()), dtype=np.int64)
        grouped = [(registry_id(shapes[i]), i) for i in groups] + [(registry_id(obj), i) for i, obj in moving]
        size = max([int(reg.max(initial=0))] + [r for r, _ in grouped]) + 1
        table = np.full(size, NO_SHAPE, dtype=np.uint32)
        table[reg] = to_pbr
        for r, i in grouped:
            table[r] = i
        self.shape_of_id = mi.UInt32(table)
        self.instanced = any(m is None for _, _, m in instances)
        top = self.mi_index >= 0
        self._curve_ends([mi_shapes[k] for k in self.mi_index[top]], top)

    @property
    def moving(self) -> bool:
        """Whether shapes or instances move (motion blur)."""
        return bool(self.movers)

    def bbox(self):
        """Bounding box (``mi.ScalarBoundingBox3f``) of the geometry, moving shapes over
        their whole motion included."""
        bb = mi.ScalarBoundingBox3f(self.mi_scene.bbox())
        for sc, motion in self.movers:
            b = sc.bbox()
            if b.valid():
                for c in motion.motion_bounds(np.array(b.min, np.float64), np.array(b.max, np.float64)):
                    bb.expand(mi.ScalarPoint3f(*(float(x) for x in c)))
        return bb

    def mi_shape(self, i: int):
        """Mitsuba's shape object of pbr shape ``i`` (a top-level shape)."""
        if self.mi_index[i] < 0:
            raise SceneError(f"scene: internal error: shape {i} is inside a shape group or moves")
        return self.mi_scene.shapes()[int(self.mi_index[i])]

    def sample_position(self, shapes: list, k, time, u, active):
        """Mitsuba's ``sample_position`` on pbr shape ``shapes[k]`` per lane (``shapes``: a
        list of pbr shape indices): a direct call per listed shape, chosen by a switch. A
        call through shape pointers (``mi.ShapePtr``) would be traced for every shape of
        the variant alive in the process (other scenes' too), and fails on curves, which
        do not implement ``sample_position``."""
        fns = [(lambda t, u_, on, s=self.mi_shape(i): s.sample_position(t, u_, on)) for i in shapes]
        time = mi.Float(time)
        if len(fns) == 1:
            return fns[0](time, u, active)
        return dispatch.switch(k, fns, time, u, active)

    def shape_of(self, shape_ptr, active):
        """pbr shape index of Mitsuba shape pointers (``pi.shape``, ``si.shape``): 0
        where ``active`` is false or there is no shape (a miss)."""
        reg = dr.reinterpret_array(mi.UInt32, shape_ptr)
        return dr.gather(mi.UInt32, self.shape_of_id, reg, active & (reg != 0))

    def _curve_ends(self, shapes, top):
        """Work around a Mitsuba 3.9 ``bsplinecurve`` bug: its shading partials look up
        segment floor(v * N) from the global curve parameter v = (v_local + i) / N, which
        rounds to 1 near the end of the last segment (i = N - 1), and then read past the
        segment table (measured: rare segfaults). Hits on that segment keep v_local below
        1 - N 2^-21, which keeps floor(v N) <= N - 1 in float32 (a shift < 1e-4 of the
        last segment for N < 200 segments). ``shapes``: the top-level ones, in pbr's
        order; ``top``: per pbr shape, whether it is one of them (shapes in groups hold
        no curves: the loader refuses them)."""
        last, vmax = [0xFFFFFFFF] * len(top), [1.0] * len(top)
        for i, s in zip(np.flatnonzero(top), shapes):
            if s.shape_type() == int(mi.ShapeType.BSplineCurve):
                n = s.primitive_count()
                last[i], vmax[i] = n - 1, max(1.0 - n * 2.0 ** -21, 0.0)
        self._curves = any(v < 1.0 for v in vmax)
        if self._curves:
            self.curve_last_segment = mi.UInt32(last)
            self.curve_v_max = mi.Float(vmax)

    def intersect(self, ray: mi.Ray3f, active, attached: bool = False, ray_ad=None, coherent=False):
        """(surface interaction, pbr shape index) of the closest hit (shape 0 on a miss:
        test ``si.is_valid()``).

        ``coherent`` (a mask, or a bool): lanes whose rays are coherent, the camera rays
        (Mitsuba's ``coherent=`` of ``ray_intersect``). Embree traverses a packet whose
        lanes are all coherent with its packet traversal: measured on ``door`` (64x64,
        64 spp, LLVM), Embree's closest-hit time 0.82x for camera rays marked so; marking
        incoherent rays makes it 2.5x slower. The hit is the same either way.

        ``attached``: the surface interaction carries derivatives w.r.t. the shapes'
        differentiable parameters (vertex positions, ``to_world``): Mitsuba recomputes the
        hit on the differentiable triangle (or analytic shape) along the detached ray, so
        that ``p`` slides along the ray and ``n``, ``uv`` and the frame follow the moving
        surface (its ``compute_surface_interaction`` without ``FollowShape``). The ray
        query itself stays detached; ``ray_ad``: the same ray attached to a camera pose
        (the hit is then recomputed along it). Hits on moving shapes carry no derivatives."""
        self.check_current()
        with dr.suspend_grad():
            pi = self.mi_scene.ray_intersect_preliminary(ray, coherent, active)
        hit = active & pi.is_valid()
        shape = self.shape_of(pi.shape, hit)
        if self._curves:
            end = hit & (pi.prim_index == dr.gather(mi.UInt32, self.curve_last_segment, shape, hit))
            v = dr.minimum(pi.prim_uv.x, dr.gather(mi.Float, self.curve_v_max, shape, end))
            pi.prim_uv = mi.Point2f(dr.select(end, v, pi.prim_uv.x), pi.prim_uv.y)
        moved = self._nearest_moving(ray, dr.select(hit, pi.t, ray.maxt), active) if self.movers else None
        static = active if moved is None else active & (moved[1] == 0)
        # RayFlags.All is Mitsuba's default (uv, dp/du, shading frame; no normal partials):
        # the shading frame's tangent follows dp/du, which anisotropic BSDFs rely on.
        with dr.resume_grad(when=attached):
            si = pi.compute_surface_interaction(ray if ray_ad is None else ray_ad, mi.RayFlags.All, static)
        if self.instanced:   # instance hits: pi.shape is empty, si.shape is the group's shape
            shape = self.shape_of(si.shape, hit)
        if moved is not None:
            shape = dr.select(static, shape, 0)
            for k, (r, pk) in enumerate(moved[2]):
                on = active & (moved[1] == k + 1)
                sk = self._to_world(pk.compute_surface_interaction(r, mi.RayFlags.All, on), self.movers[k][1], ray)
                si = dr.select(on, sk, si)
                shape = dr.select(on, self.shape_of(sk.shape, on), shape)
        return si, shape

    def _nearest_moving(self, ray: mi.Ray3f, t_static, active):
        """(nearest distance, which: 0 the static hit or none, k + 1 mover k, per mover
        (its ray in its space, its preliminary intersection)) of ``ray`` among the movers,
        each searched up to the nearest distance so far (``t_static`` to begin with)."""
        best, which, found = mi.Float(t_static), mi.UInt32(0), []
        for k in range(len(self.movers)):
            r = self._ray_into(k, ray, best)
            with dr.suspend_grad():
                pk = self.movers[k][0].ray_intersect_preliminary(r, False, active)
            closer = active & pk.is_valid() & (pk.t < best)
            best = dr.select(closer, pk.t, best)
            which = dr.select(closer, k + 1, which)
            found.append((r, pk))
        return best, which, found

    def _ray_into(self, k: int, ray: mi.Ray3f, maxt) -> mi.Ray3f:
        """``ray`` in mover ``k``'s space at the ray's time, up to ``maxt``. Its direction
        is not normalised, so that distances along it are the world ray's."""
        inv, o = self.movers[k][1].inverse_at(ray.time)
        return mi.Ray3f(_apply(inv, ray.o, o, mi.Point3f), _apply(inv, ray.d, None, mi.Vector3f), maxt,
                        ray.time, ray.wavelengths)

    @staticmethod
    def _to_world(si, motion, ray: mi.Ray3f):
        """Surface interaction ``si`` found in a mover's space taken to world space at
        the ray's time (``motion``: its AnimatedTransform): points and tangents by the
        transform, normals by its inverse transpose, the shading frame rebuilt around the
        shading normal from the transformed tangent, ``wi`` from the world ray."""
        lin, o = motion.at(ray.time)
        inv_t = [list(col) for col in zip(*inverse3(lin))]
        si.p = _apply(lin, si.p, o, mi.Point3f)
        si.n = dr.normalize(_apply(inv_t, si.n, None, mi.Normal3f))
        sn = dr.normalize(_apply(inv_t, si.sh_frame.n, None, mi.Normal3f))
        s = _apply(lin, si.sh_frame.s, None, mi.Vector3f)
        s = dr.normalize(s - sn * dr.dot(sn, s))
        si.sh_frame = mi.Frame3f(s, dr.cross(sn, s), sn)
        si.dp_du = _apply(lin, si.dp_du, None, mi.Vector3f)
        si.dp_dv = _apply(lin, si.dp_dv, None, mi.Vector3f)
        si.dn_du = _apply(inv_t, si.dn_du, None, mi.Vector3f)
        si.dn_dv = _apply(inv_t, si.dn_dv, None, mi.Vector3f)
        si.wi = si.to_local(-ray.d)
        return si

    def occluded(self, ray: mi.Ray3f, active):
        """True where ``ray`` hits something before its ``maxt`` (Mitsuba's ``ray_test``,
        moving shapes included)."""
        self.check_current()
        blocked = self.mi_scene.ray_test(ray, active)
        for k, (sc, _) in enumerate(self.movers):
            blocked |= sc.ray_test(self._ray_into(k, ray, ray.maxt), active & ~blocked)
        return blocked

    def nearest_distance(self, ray: mi.Ray3f, active):
        """(distance to the nearest hit, whether there is one), moving shapes included."""
        self.check_current()
        pi = self.mi_scene.ray_intersect_preliminary(ray, False, active)
        hit = active & pi.is_valid()
        if not self.movers:
            return pi.t, hit
        t, which, _ = self._nearest_moving(ray, dr.select(hit, pi.t, ray.maxt), active)
        hit |= active & (which > 0)
        return t, hit

    def unoccluded(self, si, p: mi.Point3f, active):
        """True where the segment from ``si`` to ``p`` is free of occluders."""
        ray = si.spawn_ray_to(p)
        return ~self.occluded(ray, active)

    def attach_derived(self) -> None:
        """Inside a ``dr.freeze`` recording, before a differentiable render: recompute the
        vertex normals of meshes whose positions have gradients. Mitsuba derived them
        from the positions when the geometry was updated (``parameters_changed``), maybe
        outside the recording, and a recording's gradients stop at its inputs: the
        normals' share of the derivative would not reach the positions. An analytic
        shape's centre and radius are derived on the host, so its ``to_world`` cannot
        be differentiated in a recording (refused)."""
        for s in self.mi_scene.shapes():
            if not s.parameters_grad_enabled():
                continue
            if s.is_mesh():
                if s.has_vertex_normals() and dr.grad_enabled(s.vertex_positions_buffer()):
                    s.recompute_vertex_normals()
            else:
                raise NotImplementedError(
                    f"shape {s.id()!r}: its to_world has gradients enabled inside a dr.freeze / pbr.freeze "
                    "recording, whose gradients stop at its inputs: Mitsuba derives the shape's centre and "
                    "radius from to_world on the host (parameters_changed), outside the recording; "
                    "differentiate a mesh's vertex_positions in a frozen step, or run this step unfrozen")

    def check_current(self):
        if self.stale:
            raise RuntimeError(
                f"a ray is traced after params.update() of {', '.join(self.stale)} inside the same "
                "frozen call: pbr.freeze rebuilds the ray-tracing acceleration structure after the call "
                "(on the host, which a recording cannot replay), so a frozen step must update the "
                "geometry after its last render (e.g. after opt.step()) or before the call")


def _apply(rows, v, offset, cls):
    """``rows`` (a 3x3 matrix's rows) times ``v``, plus ``offset`` (a point's translation;
    None for vectors and normals), as a ``cls``."""
    r = [rows[i][0] * v.x + rows[i][1] * v.y + rows[i][2] * v.z for i in range(3)]
    if offset is not None:
        r = [r[i] + offset[i] for i in range(3)]
    return cls(*r)


def _traces_with_optix() -> bool:
    """Whether rays are traced by OptiX (the CUDA variants), which allows one shader
    binding table, so one Mitsuba scene, per kernel (measured on an H200: a second
    scene's rays in the same kernel are disabled by Dr.Jit and miss)."""
    return mi.variant().startswith("cuda")
