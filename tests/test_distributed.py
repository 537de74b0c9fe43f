"""pbr.distributed (issue 24): renders, maps and gradient steps on a Dask LocalCluster of
two worker processes give what one process gives, bit for bit where the sums are the
same, also when a worker dies mid-render."""

import os
import sys
import threading
import time

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import pbr

distributed = pytest.importorskip("distributed")
cloudpickle = pytest.importorskip("cloudpickle")
from pbr import distributed as pd  # noqa: E402

# The workers cannot import this test module: send its functions by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def client():
    c = pd.local_client(2, threads=1)
    yield c
    cluster = c.cluster
    c.close()
    assert cluster.status.name == "closed", "local_client's client owns its cluster"


def _scene(res=24, spp=16, integrator="path"):
    d = pbr.cornell_box(res, spp)
    d["integrator"] = {"type": integrator, "max_depth": 4}
    return d


def _local(d, spp, per_pass, seed=0, monkeypatch=None):
    """pbr.render of ``d`` in this process with passes of ``per_pass`` samples per pixel."""
    w, h = d["sensor"]["film"]["width"], d["sensor"]["film"]["height"]
    monkeypatch.setenv("PBR_MAX_SAMPLES_PER_PASS", str(w * h * per_pass))
    return np.asarray(pbr.render(pbr.load_dict(d), spp=spp, seed=seed, progress=False))


def test_distributed_render_is_bit_identical_to_the_local_multipass_render(client, monkeypatch):
    d = _scene()
    img = np.asarray(pd.render(d, spp=16, chunks=4, seed=7, client=client, backend=pbr.get_backend(),
                               progress=False))
    assert img.shape == (24, 24, 3) and img.mean() > 0.05
    assert np.array_equal(img, _local(d, 16, 4, seed=7, monkeypatch=monkeypatch))
    # The comparison sees the summation order: passes of 8 samples give other float32 sums.
    assert not np.array_equal(img, _local(d, 16, 8, seed=7, monkeypatch=monkeypatch))
    # client=None renders the same passes in this process.
    assert np.array_equal(img, np.asarray(pd.render(d, spp=16, chunks=4, seed=7, progress=False)))


def test_a_scene_file_with_overrides_renders_on_the_workers(client, monkeypatch):
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes", "cornell_box.xml")
    img = np.asarray(pd.render(path, overrides={"res": 16, "spp": 8}, chunks=2, seed=3, client=client,
                               backend=pbr.get_backend(), progress=False))
    monkeypatch.setenv("PBR_MAX_SAMPLES_PER_PASS", str(16 * 16 * 2))
    assert np.array_equal(img, np.asarray(pbr.render(pbr.load_file(path, res=16, spp=8), seed=3, progress=False)))


def test_passes_spread_over_both_workers_and_scenes_are_cached(client):
    d = _scene(16, 8)
    stats = []
    pd.render(d, spp=8, chunks=1, client=client, backend=pbr.get_backend(), progress=False, stats=stats)
    assert [s["pass"] for s in stats] == list(range(8))
    assert len({s["pid"] for s in stats}) == 2
    # each worker loaded the scene at most once (the first pass it rendered)
    loads = [s for s in stats if s["load_seconds"] > 0]
    assert len(loads) <= 2 and all(s["first"] for s in loads)


def test_aov_and_volpath_split_into_passes_as_one_render(monkeypatch):
    """The pass split of integrators with their own film channels or post-processing."""
    for integ in ({"type": "aov", "aovs": "dd:depth,nn:sh_normal"}, {"type": "volpath", "max_depth": 4}):
        d = _scene(16, 8)
        d["integrator"] = integ
        img = np.asarray(pd.render(d, spp=8, chunks=2, progress=False))
        assert np.array_equal(img, _local(d, 8, 2, monkeypatch=monkeypatch)), integ["type"]


def _die_when_busy(dask_worker):
    """Kill this worker process as soon as it runs a task (a lost worker mid-render)."""
    def watch():
        while dask_worker.state.executing_count == 0:
            time.sleep(0.001)
        os._exit(1)
    threading.Thread(target=watch, daemon=True).start()


def test_a_worker_killed_mid_render_still_gives_the_exact_image(client, monkeypatch):
    d = _scene(24, 32)
    pd.render(d, spp=2, chunks=1, client=client, backend=pbr.get_backend(), progress=False)  # warm up
    before = client.run(os.getpid)
    victim = sorted(before)[0]
    client.run(_die_when_busy, workers=[victim])
    img = np.asarray(pd.render(d, spp=32, chunks=1, client=client, backend=pbr.get_backend(), progress=False))
    client.wait_for_workers(2, timeout=60)
    after = client.run(os.getpid)
    assert before[victim] not in after.values(), "the worker was not killed"
    assert np.array_equal(img, _local(d, 32, 1, monkeypatch=monkeypatch))


def _flaky(x, marker):
    """Fails the first time it sees ``marker`` missing (a task lost once), then works."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        raise ConnectionError("simulated lost task")
    return x * x


def test_map_runs_in_order_and_retries_a_failed_task(client, tmp_path):
    assert pd.map(_flaky, range(6), client=client, marker=str(tmp_path / "m"), progress=False) == \
        [x * x for x in range(6)]
    assert pd.map(lambda x: x + 1, [1, 2], progress=False) == [2, 3]
    with pytest.raises(ConnectionError, match="simulated"):
        pd.map(_flaky, [1], client=client, retries=0, marker=str(tmp_path / "n"), progress=False)


def _render_mean(seed, scene):
    return float(np.asarray(pbr.render(pd.cached_scene(scene), spp=2, seed=seed, progress=False)).mean())


def test_map_with_a_cached_scene_renders_a_seed_sweep(client):
    d = _scene(16, 2)
    d = pd.SceneSpec(d)    # a scene dict as workers can receive it (transforms as matrices)
    out = pd.map(_render_mean, [0, 1, 2], client=client, scene=d, progress=False)
    assert out == pd.map(_render_mean, [0, 1, 2], scene=d, progress=False)
    assert len(set(out)) == 3


KEY = "red.reflectance.value"


def _loss(img, view):
    return dr.mean(dr.square(img - mi.TensorXf(view["target"])), axis=None)


def _grad_setup():
    d = _scene(16, 4, "prb")
    target = np.full((16, 16, 3), 0.3, np.float32)
    views = [{"seed": s, "spp": 4, "target": target} for s in (1, 2, 3)]
    value = np.array([[0.6], [0.2], [0.1]], np.float32)
    return d, views, value


@pytest.fixture
def one_thread():
    """Dr.Jit on one thread in this process, as on the workers: the adjoint pass adds into
    a parameter's gradient with float32 atomics, whose order (and so rounding) depends on
    the threads; on 2 threads the same gradient varied by up to 1e-4 (relative) run to run."""
    n = dr.thread_count()
    dr.set_thread_count(1)
    yield
    dr.set_thread_count(n)


def test_gradients_summed_across_workers_equal_the_single_process_gradient(client, one_thread):
    d, views, value = _grad_setup()
    loss, grads = pd.gradient(d, {KEY: value}, _loss, views, client=client, backend=pbr.get_backend(),
                              progress=False)
    # the same tasks in this process: the same numbers, bit for bit
    loss0, grads0 = pd.gradient(d, {KEY: value}, _loss, views, progress=False)
    assert loss == loss0 and np.array_equal(grads[KEY], grads0[KEY])
    # one process, one backward pass through the sum of the views' losses
    scene = pbr.load_dict(d)
    params = pbr.traverse(scene)
    x = mi.Color3f(value)
    dr.enable_grad(x)
    params[KEY] = x
    params.update()
    total = 0
    for v in views:
        total = total + _loss(pbr.render(scene, params, seed=v["seed"], spp=4), v)
    dr.backward(total)
    ref = np.array(dr.grad(x))
    assert np.abs(ref).max() > 1e-3
    assert np.allclose(grads[KEY], ref, rtol=1e-6, atol=0), (grads[KEY], ref)   # float32 vs float64 sums
    assert np.isclose(loss, float(np.asarray(dr.detach(total)).ravel()[0]), rtol=1e-6)
    # a parameter's value reaches the workers: another value, another gradient
    _, other = pd.gradient(d, {KEY: value * 0.5}, _loss, views, client=client, backend=pbr.get_backend(),
                           progress=False)
    assert not np.allclose(other[KEY], grads[KEY], rtol=1e-3)


def test_params_set_on_workers_change_the_render_and_are_undone(client):
    d = _scene(16, 4)
    kw = dict(spp=4, chunks=2, client=client, backend=pbr.get_backend(), progress=False)
    plain = np.asarray(pd.render(d, **kw))
    red = np.asarray(pd.render(d, params={KEY: np.array([[0.9], [0.0], [0.0]])}, **kw))
    assert not np.array_equal(plain, red)
    assert np.array_equal(plain, np.asarray(pd.render(d, **kw)))


def test_bad_arguments_are_clear_errors(client, tmp_path):
    d = _scene(16, 4)
    with pytest.raises(TypeError, match="loaded scene holds Dr.Jit arrays"):
        pd.render(pbr.load_dict(d), client=client)
    with pytest.raises(ValueError, match="4 samples per pass do not divide the 6"):
        pd.render(d, spp=6, chunks=4)
    with pytest.raises(ValueError, match="chunks"):
        pd.render(d, chunks=0)
    with pytest.raises(ValueError, match="spp must be a non-negative integer"):
        pd.render(d, spp=-1)
    with pytest.raises(ValueError, match="sensor must be an index"):
        pd.render(d, sensor=3)
    with pytest.raises(TypeError, match="client must be a dask.distributed.Client"):
        pd.render(d, client="localhost:8786")
    with pytest.raises(NotImplementedError, match="'sppm' integrator does not render independent"):
        pd.render(d, integrator={"type": "sppm"})
    bad = _scene(16, 4)
    bad["red"]["lock"] = threading.Lock()
    with pytest.raises(TypeError, match="'red.lock'"):
        pd.render(bad, client=client)
    with pytest.raises(FileNotFoundError, match="no_such.xml"):
        pd.render(str(tmp_path / "no_such.xml"), client=client)
    with pytest.raises(KeyError, match="no scene parameter 'red.nope'"):
        pd.render(d, params={"red.nope": 1.0})
    with pytest.raises(ValueError, match="views must be a non-empty list"):
        pd.gradient(d, {KEY: 0.5}, _loss, [])


def test_distributed_notebook_runs(tmp_path, monkeypatch):
    from mitsuba_scenes import run_notebook
    monkeypatch.chdir(tmp_path)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ns = run_notebook(os.path.join(root, "notebooks", "distributed.ipynb"),
                      {"resolution=128": "resolution=24", "spp=64, chunks=8": "spp=16, chunks=4",
                       "N_ITER = 8": "N_ITER = 3", '"spp": 8': '"spp": 2', "range(4)": "range(2)"})
    assert np.array_equal(np.asarray(ns["img"]), np.asarray(ns["local"]))
    assert ns["errors"][0] > ns["errors"][-1]
    assert ns["value"][0, 0] > 0.25 and ns["value"][1, 0] < 0.2   # towards the red wall's albedo
    assert ns["client"].status == "closed"
