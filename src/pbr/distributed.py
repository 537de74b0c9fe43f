"""``pbr.distributed``: renders, parameter sweeps and gradient steps on a Dask cluster.

Dask (``dask.distributed``, ``pip install 'pbr-render[distributed]'``) schedules the
work: a ``LocalCluster`` on a laptop or a workstation with several GPUs, any Dask
cluster beyond. Three entry points:

* :func:`render`: the passes of one render (``integrators.base.PassJob``), one task
  each; the client adds the passes' float32 film sums in pass order as they arrive and
  develops the image, so the result is bit for bit ``pbr.render`` with the same passes
  (``chunks`` samples per pixel each) on the same backend.
* :func:`map`: any function over items (parameter sweeps, error-vs-time studies).
* :func:`gradient`: a data-parallel optimisation step; one task per view renders, takes
  the loss and backpropagates; the client sums the gradients.

Scenes travel as what built them, never as loaded objects (those hold Dr.Jit arrays): a
scene file's path with ``load_file`` overrides, or a scene dict (Mitsuba transform
objects in it are sent as 4x4 matrices). Each worker process loads a scene once and
keeps it (:func:`cached_scene`); its Dr.Jit kernels are cached in memory and on disk.
Workers pick their backend (``backend=None``: CUDA where a GPU is usable, else LLVM).
A task that raises is re-run up to ``retries`` times; the tasks of a worker that dies
are re-run elsewhere by the scheduler. docs/distributed.md has the measurements.
"""

from __future__ import annotations

import hashlib
import numbers
import os
import pickle
import threading
import time
import warnings
from collections.abc import Mapping

import drjit as dr
import mitsuba as mi
import numpy as np

from . import backend as _backend
from .integrators.base import NonFinite, PassJob, _progress
from .render import _count, _seed, render as _render
from .scene import load_dict, load_file, traverse
from .scene.objects import as_integrator
from .scene.scene import Scene

__all__ = ["render", "map", "gradient", "cached_scene", "local_client", "SceneSpec"]

# Keywords of pbr.render that a view of `gradient` may set.
RENDER_KEYS = ("sensor", "seed", "seed_grad", "spp", "spp_grad", "integrator")


def _dask():
    """The ``distributed`` module (an optional dependency)."""
    try:
        import distributed
    except ImportError as e:   # pragma: no cover
        raise ImportError("pbr.distributed needs Dask's scheduler: pip install 'pbr-render[distributed]' "
                          "(or pip install 'dask[distributed]')") from e
    return distributed


# ----------------------------------------------------------------------------- scenes

def _portable(value, path):
    """``value`` with Mitsuba transform objects (anything with ``.matrix``) replaced by
    4x4 float64 matrices, which ``load_dict`` reads the same way and pickle can send."""
    if isinstance(value, dict):
        return {k: _portable(v, f"{path}.{k}" if path else str(k)) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_portable(v, f"{path}[{i}]") for i, v in enumerate(value))
    if hasattr(value, "matrix") and not isinstance(value, np.ndarray):
        return np.array(value.matrix, dtype=np.float64).reshape(4, 4)
    try:
        pickle.dumps(value)
    except Exception as e:
        raise TypeError(f"pbr.distributed: scene dict entry {path!r} ({type(value).__name__}) cannot be sent to "
                        f"workers ({e}); use plain values, numpy arrays or file names") from None
    return value


class SceneSpec:
    """What a worker needs to load a scene: a scene file (``path``, with ``load_file``
    keyword ``overrides``) or a scene dict (``scene``, read relative to ``base_dir``).
    ``key`` names it (a hash of its content), under which workers cache the loaded scene."""

    def __init__(self, scene, overrides=None):
        if isinstance(scene, SceneSpec):
            self.__dict__.update(scene.__dict__)
            return
        if isinstance(scene, Scene):
            raise TypeError("pbr.distributed: a loaded scene holds Dr.Jit arrays and cannot be sent to workers: "
                            "pass the scene dict or the scene file (with its load_file overrides) it was "
                            "loaded from, or client=None to render it in this process")
        if isinstance(scene, (str, os.PathLike)):
            path = os.path.abspath(os.fspath(scene))
            if not os.path.isfile(path):
                raise FileNotFoundError(f"pbr.distributed: scene file {path!r} does not exist")
            self.kind, self.source, self.options = "file", path, dict(overrides or {})
        elif isinstance(scene, dict):
            if overrides:
                raise ValueError("pbr.distributed: overrides apply to scene files (load_file keywords); edit the "
                                 "dict instead")
            self.kind, self.source, self.options = "dict", _portable(scene, ""), {"base_dir": os.getcwd()}
        else:
            raise TypeError(f"pbr.distributed: scene: expected a scene dict or a scene file's path, "
                            f"got {type(scene).__name__}")
        self.key = hashlib.sha1(pickle.dumps((self.kind, self.source, sorted(self.options.items())))).hexdigest()

    def load(self):
        if self.kind == "file":
            return load_file(self.source, **self.options)
        return load_dict(self.source, base_dir=self.options["base_dir"])


class _Entry:
    """A scene loaded in this process: the lock that serialises its renders, the values
    its parameters had when loaded (of the keys tasks have set), and the keys set now."""

    def __init__(self, scene, load_seconds):
        self.scene, self.load_seconds = scene, load_seconds
        self.lock = threading.RLock()
        self.original, self.applied = {}, set()
        self.passes = 0

    def apply(self, values):
        """Set parameters ``values`` ({key: value}); keys an earlier task set and this one
        does not go back to their loaded values."""
        values = values or {}
        if not values and not self.applied:
            return
        params = traverse(self.scene)
        for k in values:
            if k not in params.keys():
                raise KeyError(f"pbr.distributed: params: no scene parameter {k!r} (see pbr.traverse(scene))")
            if k not in self.original:
                self.original[k] = _host(params[k])
        for k in self.applied - set(values):
            params[k] = _as_param(params[k], self.original[k])
        for k, v in values.items():
            params[k] = _as_param(params[k], v)
        params.update()
        self.applied = set(values)


_CACHE: dict = {}
_CACHE_LOCK = threading.Lock()
_CACHE_SIZE = 4


def _host(v):
    return float(v) if isinstance(v, numbers.Real) else np.array(v)


def _as_param(current, value):
    """``value`` (numpy or Python) as the type of the parameter value ``current``."""
    if isinstance(current, numbers.Real):
        return float(np.asarray(value).ravel()[0])
    return type(current)(np.asarray(value, dtype=np.asarray(current).dtype))


def _use_backend(name):
    """Select backend ``name`` for this process (None: keep pbr's, choosing 'auto' in a
    worker, where nothing chose one)."""
    if name is not None:
        _backend.set_backend(name)
    elif _in_worker() and _backend._backend is None:
        _backend.set_backend("auto")
    return _backend.get_backend()


def _in_worker() -> bool:
    try:
        _dask().get_worker()
        return True
    except (ValueError, ImportError):
        return False


def _entry(spec, backend_name=None) -> _Entry:
    name = _use_backend(backend_name)
    key = (spec.key, name)
    with _CACHE_LOCK:
        entry = _CACHE.get(key)
        if entry is None:
            t0 = time.perf_counter()
            entry = _Entry(spec.load(), 0.0)
            entry.load_seconds = time.perf_counter() - t0
            while len(_CACHE) >= _CACHE_SIZE:
                _CACHE.pop(next(iter(_CACHE)))
            _CACHE[key] = entry
    return entry


def cached_scene(scene, params=None, backend=None):
    """The scene ``scene`` (a dict, a scene file's path or a :class:`SceneSpec`) loaded
    once per process and kept (the last four), with parameters ``params`` ({key: value})
    set, on ``backend`` (None: pbr's; 'auto' in a worker where none was chosen); for
    functions that :func:`map` runs. Returns the loaded ``pbr`` scene."""
    entry = _entry(SceneSpec(scene), backend)
    entry.apply(params)
    return entry.scene


# ---------------------------------------------------------------------------- render

def _integrator(scene, integrator):
    integ = scene.integrator if integrator is None else as_integrator(integrator)
    if not integ.pass_separable:
        raise NotImplementedError(f"pbr.distributed.render: the {integ.name!r} integrator does not render "
                                  f"independent camera-sample passes (its splats, chains or photon statistics "
                                  f"span passes); render it with pbr.render, or use pbr.distributed.map over "
                                  f"seeds and average the images")
    return integ


def _plan(scene, sensor, integrator, spp, chunks):
    """(spp, samples per pass, number of passes) of a render split into passes of
    ``chunks`` samples per pixel (None: the integrator's own plan)."""
    integ = _integrator(scene, integrator)
    if not isinstance(sensor, int) or isinstance(sensor, bool) or not 0 <= sensor < len(scene.sensors):
        raise ValueError(f"pbr.distributed.render: sensor must be an index into the scene's "
                         f"{len(scene.sensors)} sensors, got {sensor!r}")
    with integ.pass_job(PassJob(chunks)):
        _, _, _, spp, per_pass, n_pass = integ._plan(scene, sensor, spp)
    return spp, per_pass, n_pass


def _render_pass(spec, backend_name, values, sensor, integrator, seed, spp, per_pass, p):
    """A worker's task: pass ``p`` of a render. Returns its film sums (numpy float32),
    its count of non-finite samples, the warnings it raised, and timings."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    _use_backend(backend_name)
    t_backend = time.perf_counter() - t0
    entry = _entry(spec, backend_name)
    with entry.lock:
        entry.apply(values)
        first = entry.passes == 0
        integ = _integrator(entry.scene, integrator)
        t1 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught, integ.pass_job(PassJob(per_pass, run=[p])) as job:
            warnings.simplefilter("always")
            _render(entry.scene, sensor=sensor, integrator=integ, seed=seed, spp=spp, progress=False,
                    on_nonfinite="ignore")
            nonfinite = int(integ.nonfinite.count[0])
        entry.passes += 1
    return {"pass": p, "sums": job.sums[p], "nonfinite": nonfinite,
            "warnings": [(type(w.message), str(w.message)) for w in caught],
            "seconds": time.perf_counter() - t0, "render_seconds": time.perf_counter() - t1,
            "cpu_seconds": time.process_time() - cpu0,
            "load_seconds": entry.load_seconds if first else 0.0, "backend_seconds": t_backend, "first": first,
            "pid": os.getpid(),
            "backend": _backend.get_backend()}


class _Arrivals(Mapping):
    """Pass sums by pass index, fetched from the futures as the film asks for them (in
    pass order); results that arrive early wait here, so memory holds only those."""

    def __init__(self, futures, bar):
        self.n, self.bar, self.ready, self.results = len(futures), bar, {}, []
        self.index = {f.key: p for p, f in enumerate(futures)}
        self.arrivals = _dask().as_completed(futures)

    def __getitem__(self, p):
        while p not in self.ready:
            f = next(self.arrivals)
            r = f.result()
            f.release()
            self.ready[self.index[f.key]] = r
            self.results.append({k: v for k, v in r.items() if k != "sums"})
            if self.bar:
                self.bar.update(1)
        return self.ready.pop(p)["sums"]

    def __contains__(self, p):
        return isinstance(p, int) and 0 <= p < self.n

    def __iter__(self):
        return iter(range(self.n))

    def __len__(self):
        return self.n


def _check_client(client):
    if client is not None and not isinstance(client, _dask().Client):
        raise TypeError(f"pbr.distributed: client must be a dask.distributed.Client or None (this process), "
                        f"got {type(client).__name__}")


def render(scene, spp=0, client=None, seed=0, chunks=None, sensor=0, integrator=None, params=None,
           backend=None, overrides=None, retries=2, progress=None, on_nonfinite="warn", stats=None):
    """Render ``scene`` in passes of ``chunks`` samples per pixel, one Dask task each,
    on ``client``'s workers (``client=None``: in this process). Returns ``mi.TensorXf``
    (H, W, 3), as ``pbr.render``: bit for bit the image ``pbr.render`` gives with the
    same passes (``chunks``; None: ``pbr.render``'s own plan) on the backend of this process.

    ``scene``: a scene dict or a scene file's path (``overrides``: ``load_file``
    keywords), or with ``client=None`` also a loaded scene. ``spp``: samples per pixel
    (0: the sensor's). ``sensor``: an index. ``integrator``: None (the scene's) or an
    integrator dict. ``params``: {key: value} scene parameters (``pbr.traverse`` keys)
    to set first. ``backend``: the workers' (None: CUDA where usable, else LLVM).
    ``retries``: re-runs of a task that raised. ``progress``: a bar of passes done
    (False: none). ``on_nonfinite``: as ``pbr.render``. ``stats``: a list that receives
    each pass's timings (seconds in the task, cpu_seconds (of the worker process), render_seconds, load_seconds, backend_seconds,
    first: the worker's first pass of this scene, pid)."""
    _check_client(client)
    values = _hosted(params)
    spp, seed = _count("spp", spp), _seed("seed", seed)
    if not isinstance(seed, int):
        raise ValueError(f"pbr.distributed.render: seed must be an integer in [0, 2^32), got {seed!r}")
    if chunks is not None and (isinstance(chunks, bool) or not isinstance(chunks, numbers.Integral) or chunks < 1):
        raise ValueError(f"pbr.distributed.render: chunks (samples per pixel per pass) must be a positive "
                         f"integer or None, got {chunks!r}")
    if on_nonfinite not in ("warn", "raise", "ignore"):
        NonFinite(on_nonfinite)        # raises the usual message
    if isinstance(integrator, dict):
        integrator = _portable(integrator, "integrator")
    elif integrator is not None:
        raise TypeError(f"pbr.distributed.render: integrator must be None (the scene's) or an integrator dict, "
                        f"got {type(integrator).__name__}")
    if client is None and isinstance(scene, Scene):
        entry = _Entry(scene, 0.0)
    else:
        spec = SceneSpec(scene, overrides)
        entry = _entry(spec, None if client is not None else backend)
    with entry.lock:
        try:
            entry.apply(values)
            spp, per_pass, n_pass = _plan(entry.scene, sensor, integrator, spp, chunks)
            integ = _integrator(entry.scene, integrator)
            if client is None:
                t0 = time.perf_counter()
                with integ.pass_job(PassJob(per_pass, run=range(n_pass))):
                    img = _render(entry.scene, sensor=sensor, integrator=integ, seed=seed, spp=spp,
                                  progress=progress, on_nonfinite=on_nonfinite)
                if stats is not None:
                    stats.append({"seconds": time.perf_counter() - t0, "passes": n_pass, "pid": os.getpid()})
                return img
            spec_f = client.scatter(spec, broadcast=True, hash=False)
            token = hashlib.sha1(pickle.dumps((spec.key, seed, spp, per_pass, sensor,
                                               time.time_ns()))).hexdigest()[:12]
            futures = [client.submit(_render_pass, spec_f, backend, values, sensor, integrator, seed, spp,
                                     per_pass, p, retries=retries, pure=False, key=f"pbr-pass-{token}-{p}")
                       for p in range(n_pass)]
            bar = _progress(n_pass, progress, desc="pbr.distributed render")
            arrivals = _Arrivals(futures, bar)
            try:
                with integ.pass_job(PassJob(per_pass, given=arrivals)):
                    img = _render(entry.scene, sensor=sensor, integrator=integ, seed=seed, spp=spp, progress=False,
                                  on_nonfinite="ignore")
            finally:
                if bar:
                    bar.close()
                for f in futures:
                    f.cancel()
        finally:
            if client is None and isinstance(scene, Scene):
                entry.apply({})
    if stats is not None:
        stats.extend(sorted(arrivals.results, key=lambda r: r["pass"]))
    seen = set()
    for cls, msg in (w for r in arrivals.results for w in r["warnings"]):
        if msg not in seen:
            seen.add(msg)
            warnings.warn(f"pbr.distributed.render (a worker): {msg}", cls, stacklevel=2)
    counter = NonFinite(on_nonfinite)
    counter.count = mi.UInt32(sum(r["nonfinite"] for r in arrivals.results))
    counter.report("pbr.distributed.render")
    return img


def _hosted(values):
    """Parameter values as host (numpy / Python) values, which pickle can send."""
    if values is None:
        return None
    if not isinstance(values, Mapping):
        raise TypeError(f"pbr.distributed: params must be a dict {{key: value}}, got {type(values).__name__}")
    return {k: _host(v) for k, v in values.items()}


# ------------------------------------------------------------------------------- map

def map(fn, items, client=None, retries=2, progress=None, **kwargs):
    """``[fn(item, **kwargs) for item in items]``, one Dask task per item on ``client``'s
    workers (None: in this process), in the order of ``items``. ``fn`` must be picklable
    (a module-level function, or a lambda: Dask uses cloudpickle); inside it,
    :func:`cached_scene` loads a scene once per worker. A task that raises is re-run up
    to ``retries`` times before its error is raised here."""
    _check_client(client)
    if not callable(fn):
        raise TypeError(f"pbr.distributed.map: fn must be callable, got {type(fn).__name__}")
    items = list(items)
    bar = _progress(len(items), progress, desc="pbr.distributed map", unit="item")
    try:
        if client is None:
            out = []
            for x in items:
                out.append(fn(x, **kwargs))
                if bar:
                    bar.update(1)
            return out
        futures = client.map(fn, items, retries=retries, pure=False, **kwargs)
        for _ in _dask().as_completed(futures):
            if bar:
                bar.update(1)
        return client.gather(futures)
    finally:
        if bar:
            bar.close()


# -------------------------------------------------------------------------- gradients

def _gradient_task(view, spec, backend_name, values, loss):
    """A worker's task: render ``view`` with the parameters ``values`` differentiable,
    take ``loss(img, view)`` and backpropagate. Returns (loss, {key: gradient})."""
    entry = _entry(spec, backend_name) if isinstance(spec, SceneSpec) else spec
    with entry.lock:
        entry.apply(values)
        params = traverse(entry.scene)
        leaves = {}
        try:
            for k in values:
                x = _as_param(params[k], values[k])
                dr.enable_grad(x)
                params[k] = leaves[k] = x
            params.update()
            kw = {k: view[k] for k in RENDER_KEYS if k in view}
            img = _render(entry.scene, params, progress=False, **kw)
            value = loss(img, view)
            dr.backward(value)
            grads = {k: np.array(dr.grad(x)) for k, x in leaves.items()}
            return float(np.asarray(dr.detach(value)).ravel()[0]), grads
        finally:
            for k, x in leaves.items():
                params[k] = dr.detach(x)
            if leaves:
                params.update()


def gradient(scene, params, loss, views, client=None, backend=None, overrides=None, retries=2, progress=None):
    """One data-parallel gradient evaluation: for each view, a task renders ``scene``
    with parameter values ``params`` ({key: value}, ``pbr.traverse`` keys; these are
    differentiated), computes ``loss(img, view)`` (a Dr.Jit scalar) and backpropagates.
    Returns (sum of the losses, {key: sum of the gradients}) as Python float and numpy
    arrays, summed in the order of ``views`` (float64), so the result is the same
    whichever worker rendered what.

    ``views``: dicts of ``pbr.render`` keywords (sensor, seed, seed_grad, spp, spp_grad,
    integrator) plus anything ``loss`` reads (e.g. the view's target image). ``loss``
    must be picklable (a module-level function or a lambda). ``client=None`` runs the
    views in this process (``scene`` may then be a loaded scene)."""
    _check_client(client)
    if not callable(loss):
        raise TypeError(f"pbr.distributed.gradient: loss must be callable, got {type(loss).__name__}")
    views = list(views)
    if not views or not all(isinstance(v, Mapping) for v in views):
        raise ValueError("pbr.distributed.gradient: views must be a non-empty list of dicts of pbr.render "
                         f"keywords ({', '.join(RENDER_KEYS)}) and what loss reads")
    values = _hosted(params)
    if not values:
        raise ValueError("pbr.distributed.gradient: params must name at least one scene parameter to differentiate")
    if client is None:
        target = _Entry(scene, 0.0) if isinstance(scene, Scene) else SceneSpec(scene, overrides)
        try:
            results = map(_gradient_task, views, progress=progress, spec=target, backend_name=backend, values=values,
                          loss=loss)
        finally:
            if isinstance(target, _Entry):
                target.apply({})
    else:
        spec_f = client.scatter(SceneSpec(scene, overrides), broadcast=True, hash=False)
        results = map(_gradient_task, views, client=client, retries=retries, progress=progress,
                      spec=spec_f, backend_name=backend, values=values, loss=loss)
    total, grads = 0.0, {}
    for value, g in results:
        total += value
        for k, v in g.items():
            grads[k] = grads[k] + v if k in grads else v.astype(np.float64)
    return total, grads


# ------------------------------------------------------------------------- a cluster

class DrJitThreads:
    """A Dask worker plugin: the Dr.Jit thread pool of each worker process gets
    ``threads`` threads (Dr.Jit's default is every core, per process)."""

    name = "pbr-drjit-threads"

    def __init__(self, threads: int):
        self.threads = int(threads)

    def setup(self, worker):
        dr.set_thread_count(self.threads)


def local_client(n_workers: int = 2, threads: int | None = None, **kwargs):
    """A ``dask.distributed.Client`` of a new ``LocalCluster`` of ``n_workers`` worker
    processes, one task at a time each, each with a Dr.Jit pool of ``threads`` threads
    (default: the cores divided among the workers). ``kwargs`` go to ``LocalCluster``.
    The client owns the cluster: ``client.close()`` (or leaving ``with``) stops both."""
    distributed = _dask()
    threads = threads or max(1, (os.cpu_count() or 1) // n_workers)
    kwargs = {"processes": True, "threads_per_worker": 1, "dashboard_address": ":0", **kwargs}
    client = distributed.Client(n_workers=n_workers, **kwargs)
    client.register_plugin(_worker_plugin(threads))
    return client


def _worker_plugin(threads):
    class _Plugin(DrJitThreads, _dask().WorkerPlugin):
        pass
    return _Plugin(threads)
