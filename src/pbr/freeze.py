"""``pbr.freeze``: ``dr.freeze`` for functions that take pbr scenes.

``dr.freeze`` records the kernels a function launches and replays them on later calls
without tracing the Python code again. It sees the Dr.Jit arrays of its arguments only
when they are PyTrees (containers, dataclasses, ``DRJIT_STRUCT``) or traversable C++
objects; a :class:`pbr.scene.scene.Scene` is neither, and every array it holds would be
read as a constant created outside the recording (an error). ``pbr.freeze`` passes
``dr.freeze`` a ``state_fn`` that lists them: the tables reachable from each scene
argument (texture, BSDF, light, medium, sensor tables), the scene's parameter values,
its Mitsuba geometry, and pbr's spectral tables.

Within a frozen function, ``params.update()`` must take its values-only path (a BSDF's
constant or bitmap texture, or its ``eta``; see :meth:`pbr.SceneParameters.update`): a full rebuild reads
parameters on the host, which a recording cannot replay. Geometry is the exception:
moved vertices or transforms are assigned inside the recording, and ``pbr.freeze``
rebuilds Mitsuba's acceleration structure (Embree's BVH is built on the host) after each
call, recorded or replayed, for every shape whose geometry arrays the call replaced
(compared by Dr.Jit variable index: a replay writes its outputs back into the shapes).
The next call's recording reads the new acceleration handle and arrays as inputs
(Mitsuba's scene is traversable: its Embree/OptiX handle is a ``UInt64`` variable). So a
frozen step renders first and moves the geometry last (after ``opt.step()``); a ray
traced after the update within the same call raises an error. A recording's gradients
stop at its inputs, so ``pbr.render`` inside one derives the tables that depend on
parameters with gradients again (vertex normals, BSDF value tables:
``SceneParameters.attach_in_recording``). Seeds are passed as
``mi.UInt32`` (``dr.opaque(mi.UInt32, i)``), not Python ints, which would be recorded as
constants (one recording per seed). ``dr.freeze``'s inputs also include every live
Mitsuba shape of the process (the registry its ray-tracing calls can reach): another
scene released between two calls changes them and causes one more recording
(docs/inverse.md).
"""

from __future__ import annotations

import functools
import gc
import weakref

import drjit as dr
import numpy as np

from . import samplers, spectrum
from .scene.params import SceneParameters, geometry_deferred, traverse
from .scene.scene import Scene
from .plugins.tables import map_tables
from .integrators.base import SamplingIntegrator


def scene_state(scene: Scene) -> list:
    """The Dr.Jit state a frozen function may read or change through ``scene``: its table
    arrays, the containers in which an update re-binds arrays (the texture tables, the
    parameter values: a replay assigns the new values there) and the Mitsuba scene
    (traversable by Dr.Jit), and those of its moving shapes."""
    arrays = []

    def keep(x):
        arrays.append(x)
        return x

    map_tables(scene, keep)
    # Attribute dicts of the BSDF families whose tables an update re-binds (``eta``).
    refreshed = [vars(f) for f in scene.bsdfs.families.values() if hasattr(f, "refresh_params")]
    return [arrays, scene.textures.tables, refreshed, [owner.params for owner in scene.param_owners()],
            scene.mi_scene, [mover for mover, _ in scene.geometry.movers],
            [camera_signature(c) for c in scene.sensors]]


def camera_signature(camera) -> tuple:
    """A camera's pose and intrinsics as hashable Python values. Cameras keep them on the
    host (NumPy, floats) and kernels read them as constants, so a recording holds the
    camera it saw; in the state, a camera moved between calls makes ``dr.freeze`` record
    again instead of replaying the old view (measured: pixel errors up to 0.12)."""
    out = []
    for k, v in sorted(vars(camera).items()):
        if isinstance(v, np.ndarray):
            out.append((k, v.shape, v.tobytes()))
        elif isinstance(v, (bool, int, float, str)) or (isinstance(v, tuple) and
                                                        all(isinstance(x, (bool, int, float, str)) for x in v)):
            out.append((k, v))
    return tuple(out)


def _scenes(args, kwargs) -> list:
    """The pbr scenes among a call's arguments (directly, in containers, or as
    ``SceneParameters``), each once."""
    scenes, seen = [], set()

    def find(x):
        if isinstance(x, SceneParameters):
            x = x.scene
        if isinstance(x, Scene) and id(x) not in seen:
            seen.add(id(x))
            scenes.append(x)
        elif isinstance(x, (list, tuple)):
            for v in x:
                find(v)
        elif isinstance(x, dict):
            for v in x.values():
                find(v)

    find(args)
    find(kwargs)
    return scenes


def _state(args, kwargs) -> list:
    return [scene_state(s) for s in _scenes(args, kwargs)] + [spectrum.tables(), samplers.tables()]


def freeze(fn=None, **kwargs):
    """``dr.freeze(fn, **kwargs)`` that also traverses the pbr scenes among ``fn``'s
    arguments (directly, in containers, or as ``SceneParameters``). Usable as
    ``@pbr.freeze`` or ``pbr.freeze(fn, warn_after=...)``."""
    if fn is None:
        return lambda f: freeze(f, **kwargs)
    user_state = kwargs.pop("state_fn", None)

    def state_fn(*a, **k):
        s = _state(a, k)
        return s + [user_state(*a, **k)] if user_state is not None else s

    return _Frozen(fn, dr.freeze(fn, state_fn=state_fn, **kwargs))


class _Frozen:
    """The frozen function, called with Python's cyclic garbage collector paused: a
    collection during a recording can release arrays made before it (e.g. NumPy buffers
    mapped by an earlier render), whose release Dr.Jit cannot record (it aborts the
    process). After each call, the geometry the call moved is rebuilt (module
    docstring). Other attributes (``n_recordings``, ...) are ``dr.freeze``'s."""

    def __init__(self, fn, frozen):
        self._frozen = frozen
        # scene -> (its SceneParameters, the geometry keys that place its shapes)
        self._params = weakref.WeakKeyDictionary()
        functools.update_wrapper(self, fn)

    def __call__(self, *args, **kwargs):
        # Inside another frozen function, this one is part of its recording (which
        # rebuilds the geometry after its own call).
        scenes = [] if dr.flag(dr.JitFlag.FreezingScope) else _scenes(args, kwargs)
        before = [self._geometry(s) for s in scenes]
        enabled = gc.isenabled()
        gc.disable()
        try:
            with geometry_deferred():
                out = self._frozen(*args, **kwargs)
        except BaseException:
            self._rebuild(scenes, before, restore=True)
            raise
        finally:
            if enabled:
                gc.enable()
        self._rebuild(scenes, before)
        return out

    # The keys whose change needs the acceleration structure rebuilt (normals and uvs are
    # read by the kernels from the shapes' arrays, inputs of the recording).
    PLACING_KEYS = ("vertex_positions", "to_world", "faces")

    def _geometry(self, scene) -> dict:
        """Geometry key -> (the Dr.Jit variable indices of its current value, the value),
        for the keys that place the shapes."""
        if scene not in self._params:
            params = traverse(scene)
            self._params[scene] = params, [k for k, p in params._params.items()
                                           if p.kind == "geometry" and k.rsplit(".", 1)[-1] in self.PLACING_KEYS]
        params, keys = self._params[scene]
        out = {}
        for k in keys:
            v = params._params[k].get()     # (a view of the shape's member: keep a handle of its own)
            out[k] = (tuple(dr.detail.collect_indices(v)), type(v)(v))
        return out

    def _rebuild(self, scenes, before, restore=False) -> None:
        """Let Mitsuba rebuild the shapes whose geometry arrays the call replaced (and its
        acceleration structure), then pbr what depends on them (``params.update()``).
        ``restore``: the call failed (its arrays may be unfinished): put back the
        arrays of before the call instead."""
        for scene, old in zip(scenes, before):
            scene.geometry.stale = ()
            now = self._geometry(scene)
            changed = [k for k, (ids, _) in now.items() if old[k][0] != ids]
            if changed:
                params = self._params[scene][0]
                for k in changed:
                    if restore:
                        params._params[k].mp[k] = old[k][1]
                    params.set_dirty(k)
                params.update()

    def __getattr__(self, name):
        return getattr(self._frozen, name)


# Integrators that replay their own kernels (mlt) record them with this.
SamplingIntegrator.recorder = staticmethod(freeze)
