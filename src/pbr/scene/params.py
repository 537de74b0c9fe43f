"""``pbr.traverse``: the differentiable parameters of a scene, under Mitsuba-style keys.

Keys follow ``mi.traverse`` for the same plugins (``red.reflectance.value``,
``light.emitter.radiance.value``, ``<id>.reflectance.data`` for bitmaps). Values are
Dr.Jit arrays: enable gradients on them or assign new values, then call ``update()``
to rebuild the scene's tables (which keeps the AD graph to the parameters).

``tables_as_leaves``: forward-mode differentiation inside a symbolic loop can only start
from variables whose tangents are already known; it may not cross an edge built outside
the loop (Dr.Jit: "outside of the current dr.isolate_grad() scope"). The tables built
from parameters are such edges, so for a forward pass they are replaced by leaves that
carry the tangent the parameters give them.
"""

from __future__ import annotations

import contextlib

import drjit as dr

from ..plugins.params import check_params
from ..plugins.tables import map_tables


class SceneParameters:
    def __init__(self, scene):
        self.scene = scene
        self._owners = {}
        for tex in scene.param_owners():
            for name in tex.params:
                self._owners[f"{tex.path}.{name}"] = (tex, name)
        self._dirty = set()

    def keys(self):
        return self._owners.keys()

    def items(self):
        return [(k, self[k]) for k in self._owners]

    def __contains__(self, key):
        return key in self._owners

    def __len__(self):
        return len(self._owners)

    def __iter__(self):
        return iter(self._owners)

    def _owner(self, key):
        if key not in self._owners:
            raise KeyError(f"{key!r} is not a parameter of this scene; known keys: {', '.join(self._owners)}")
        return self._owners[key]

    def __getitem__(self, key):
        tex, name = self._owner(key)
        return tex.params[name]

    def __setitem__(self, key, value):
        tex, name = self._owner(key)
        old = tex.params[name]
        tp = type(old)
        if type(value) is not tp:
            try:
                value = tp(value)
            except Exception as e:
                raise TypeError(f"{key}: cannot convert {type(value).__name__} to {tp.__name__}: {e}") from None
        if dr.width(value) != dr.width(old) or getattr(value, "shape", None) != getattr(old, "shape", None):
            raise ValueError(f"{key}: shape {getattr(value, 'shape', None)} does not match {getattr(old, 'shape', None)}")
        tex.params[name] = value
        self._dirty.add(key)

    def update(self, values: dict | None = None):
        """Apply ``values`` (if given), then rebuild the tables that depend on parameters.

        Assigned values are checked first: finite, and in the parameter's range (an
        albedo in [0, 1], radiance >= 0, ...), else ``pbr.SceneError`` naming the key (clip
        an optimiser's values into range before the update; not checked inside
        ``dr.freeze``). When every changed key is a BSDF's constant or bitmap texture or a
        BSDF's own scalar (a dielectric's or coating's ``eta``), only those value tables are
        recomputed, with Dr.Jit operations alone (so that an update can be part of a
        ``dr.freeze``-recorded step); otherwise, and when nothing was assigned (e.g. after
        ``dr.enable_grad(params[k])``), the whole scene is rebuilt."""
        for k, v in (values or {}).items():
            self[k] = v
        # The assigned values must be finite and in their ranges (a SceneError names the
        # key). Not inside dr.freeze, which cannot read values.
        if not dr.flag(dr.JitFlag.FreezingScope):
            for k in sorted(self._dirty):
                owner, name = self._owners[k]
                check_params(owner, [name])
        # Values-only refreshes that cover every changed key (None: a rebuild is needed).
        tex = self.scene.textures
        slot_of = {id(t): i for i, t in enumerate(tex.items)}
        family_of = {id(o): f for f in self.scene.bsdfs.families.values()
                     if hasattr(f, "refresh_params") for o in f.param_owners()}
        refreshes = set() if self._dirty else None
        for k in self._dirty:
            o = self._owners[k][0]
            if slot_of.get(id(o)) in self.scene.bsdf_slots and tex.refreshable(o):
                refreshes.add(tex.refresh)
            elif id(o) in family_of:
                refreshes.add(family_of[id(o)].refresh_params)
            else:
                refreshes = None
                break
        if refreshes is not None:
            for refresh in refreshes:
                refresh()
        else:
            if dr.flag(dr.JitFlag.FreezingScope):
                raise RuntimeError(
                    f"params.update(): {', '.join(sorted(self._dirty)) or 'an update with no assigned keys'} "
                    "needs a rebuild of the scene's tables, which reads parameters on the host and "
                    "cannot be recorded by dr.freeze; inside a frozen function only BSDF textures "
                    "(constant or bitmap, e.g. '<bsdf>.reflectance.value' / '.data') and a BSDF's "
                    "'eta' can be updated")
            self.scene.build()
        self._dirty.clear()
        return self

    def __repr__(self):
        rows = [f"  {k}: {type(v).__name__}{list(getattr(v, 'shape', ()))}" for k, v in self.items()]
        return "SceneParameters[\n" + "\n".join(rows) + "\n]"


def traverse(scene) -> SceneParameters:
    return SceneParameters(scene)


@contextlib.contextmanager
def tables_as_leaves(scene, tangents: dict):
    """Within the block, the scene's tables are built from fresh copies of the parameters
    whose tangents are ``tangents`` (key -> tangent), then replaced by leaves holding the
    tangent each table receives; afterwards the parameters and tables are restored."""
    params = traverse(scene)
    originals = {k: params[k] for k in tangents}
    try:
        with dr.resume_grad():
            leaves = []
            for k, t in tangents.items():
                leaf = dr.detach(originals[k])
                dr.enable_grad(leaf)
                dr.set_grad(leaf, t)
                params[k] = leaf
                leaves.append(leaf)
            params.update()
            dr.enqueue(dr.ADMode.Forward, *leaves)
            dr.traverse(dr.ADMode.Forward, flags=dr.ADFlag.ClearEdges)

            def as_leaf(x):
                if not dr.grad_enabled(x):
                    return x
                y = dr.detach(x)
                dr.enable_grad(y)
                dr.set_grad(y, dr.grad(x))
                return y

            map_tables(scene, as_leaf)
        yield
    finally:
        for k, v in originals.items():
            params[k] = v
        params.update()
