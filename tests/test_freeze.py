"""``pbr.freeze``: a whole optimisation step (update, render, backward, Adam) recorded
once and replayed, and the values-only parameter update it relies on."""

import os
import sys

import numpy as np
import pytest

import pbr
import drjit as dr
import mitsuba as mi

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples"))
import optimize_albedo_texture as example  # noqa: E402

KEY = example.KEY


def _setup(res=24, spp=4):
    pbr.set_backend("llvm")
    scene = pbr.load_dict(example.scene_dict(8, res, spp))
    ref = pbr.render(scene, spp=spp, seed=1 << 20)
    params = pbr.traverse(scene)
    params[KEY] = mi.TensorXf(example.initial_texture(8))
    opt = dr.opt.Adam(lr=0.05)
    opt[KEY] = params[KEY]
    params.update(opt)
    return scene, opt, mi.TensorXf(np.asarray(ref))


def step(scene, opt, ref, seed):
    params = pbr.traverse(scene)
    params.update(opt)
    img = pbr.render(scene, params, spp=4, seed=seed)
    loss = dr.mean(dr.square(img - ref), axis=None)
    dr.backward(loss)
    opt.step()
    opt[KEY] = dr.clip(opt[KEY], 0.0, 1.0)
    return loss


def _optimise(frozen: bool, n=6):
    scene, opt, ref = _setup()
    f = pbr.freeze(step) if frozen else step
    losses = [float(f(scene, opt, ref, dr.opaque(mi.UInt32, i + 1)).array[0]) for i in range(n)]
    return np.array(losses), np.array(opt[KEY]), f, np.array(scene.textures.T["b_texel"])


def test_frozen_steps_replay_the_unfrozen_ones():
    """Each replay must use its own seed and the updated texture: a replay that reused
    the recording's seed or texture would drift from the unfrozen run by about a step
    (lr 0.05) per iteration."""
    l0, p0, _, t0 = _optimise(False)
    l1, p1, f, t1 = _optimise(True)
    # Recordings: the first call, Adam's first step (it adds its state), and Dr.Jit's
    # auto-opaque pass (literals that changed between calls); the rest are replays.
    assert f.n_recordings <= 3, f.n_recordings
    assert np.allclose(l1, l0, rtol=1e-4), (l0, l1)
    assert np.abs(p1 - p0).max() < 1e-3
    assert np.abs(p1 - np.asarray(example.initial_texture(8))).max() > 0.1   # it did move
    # The scene's texel table after the replays is the last step's (a replay assigns it).
    assert np.abs(t1 - t0).max() < 1e-2 * np.abs(t0).max()


def test_values_only_update_equals_a_rebuild():
    pbr.set_backend("llvm")
    new = mi.TensorXf(example.initial_texture(8))
    images = []
    for full in (False, True):
        scene = pbr.load_dict(example.scene_dict(8, 16, 4))
        params = pbr.traverse(scene)
        params[KEY] = new
        if full:
            scene.build()
        else:
            params.update()
        images.append(np.asarray(pbr.render(scene, spp=4, seed=3)))
    assert np.array_equal(images[0], images[1])


def test_update_needing_a_rebuild_inside_freeze_is_refused():
    """A light's radiance feeds the light sampler's power estimates, computed on the host:
    a clear error, not a crash in the recording."""
    pbr.set_backend("llvm")
    scene = pbr.load_dict(pbr.cornell_box())
    key = "light.emitter.radiance.value"
    value = pbr.traverse(scene)[key] * 2.0

    @pbr.freeze
    def f(scene, v, seed):
        p = pbr.traverse(scene)
        p[key] = v
        p.update()
        return pbr.render(scene, p, spp=1, seed=seed)

    with pytest.raises(RuntimeError) as e:
        f(scene, value, dr.opaque(mi.UInt32, 1))
    cause = e.value.__cause__ or e.value
    assert "light.emitter.radiance.value" in str(cause) and "dr.freeze" in str(cause)


def test_seed_must_be_an_int_or_a_uint32():
    pbr.set_backend("llvm")
    scene = pbr.load_dict(pbr.cornell_box())
    with pytest.raises(TypeError, match="seed"):
        pbr.render(scene, spp=1, seed=mi.Float(1.0))
