"""Memory a render needs, checked before anything is launched.

A film of ``W x H`` pixels keeps ``W H C`` float sums (``C`` = X, Y, Z, the filter
weight and any AOV channels), a developed ``W H (C - 1)`` image and, where it is read
into NumPy, a copy of that; the megakernel keeps its per-sample state in registers.
Dr.Jit rounds each allocation up to a power of two. Measured on the CPU under a 6 GiB
address-space limit (5.6 GiB left after start-up): 11000^2 at 1 spp renders (5.4 GiB by
this count), 12000^2 ended in a segmentation fault (7.6 GiB by this count; 5.4 GiB
without the rounding). Two limits are checked against that:

- Dr.Jit arrays hold fewer than 2^32 entries (a kernel launches fewer than 2^32 lanes);
- the bytes must fit in the memory available: on the CPU the smaller of the system's
  available memory and the process's address-space limit (``ulimit -v``) left; on the
  GPU the device's free memory (CUDA driver API). Where it cannot be read, only the
  first limit is checked.

Integrators that keep per-path state in memory between kernels (light subpaths, visible
points, photons) say how much (``SamplingIntegrator.bytes_per_lane``, measured as the
growth of the peak resident memory from 1024^2 to 2048^2 pixels at 1 spp, less the
film's): ``bdpt`` 576 bytes, ``sppm`` 416, ``mlt`` 112, ``ptracer`` 48. Without it,
under a 6 GiB limit, ``bdpt`` at 3200^2 and ``sppm`` at 4000^2 passed the film check and
ended in a segmentation fault.

Dr.Jit would otherwise fail deep inside a kernel launch (an internal error about array
sizes, or a segmentation fault when an allocation fails).
"""

from __future__ import annotations

import ctypes
import os
import resource

from . import backend

MAX_ENTRIES = (1 << 32) - 1
SMALL = 1 << 28          # films below 256 MiB are not checked against the memory available
_GiB = float(1 << 30)


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _address_space_left() -> int | None:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/statm") as f:
            used = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return None
    return max(0, soft - used)


def _cuda_free() -> int | None:
    """Free memory of CUDA device 0 (the one Dr.Jit uses by default), by the driver API
    on its primary context; None if the driver cannot tell."""
    try:
        cu = ctypes.CDLL("libcuda.so.1")
        ctx = ctypes.c_void_p()
        if cu.cuDevicePrimaryCtxRetain(ctypes.byref(ctx), 0) != 0:
            return None
        try:
            if cu.cuCtxPushCurrent_v2(ctx) != 0:
                return None
            free, total = ctypes.c_size_t(), ctypes.c_size_t()
            ok = cu.cuMemGetInfo_v2(ctypes.byref(free), ctypes.byref(total)) == 0
            cu.cuCtxPopCurrent_v2(ctypes.byref(ctypes.c_void_p()))
            return free.value if ok else None
        finally:
            cu.cuDevicePrimaryCtxRelease_v2(0)
    except (OSError, AttributeError):
        return None


def available_bytes() -> int | None:
    """Memory a render may still take on the active backend, or None if unknown."""
    if backend.get_backend() == "cuda":
        return _cuda_free()
    known = [b for b in (_meminfo_available(), _address_space_left()) if b is not None]
    return min(known) if known else None


def _pow2(n: int) -> int:
    return 1 << max(0, (n - 1).bit_length())


def film_bytes(width: int, height: int, channels: int) -> int:
    """Bytes of a film's sums (``channels`` per pixel) and its developed image, each
    rounded up to a power of two as Dr.Jit's allocator does, and, on the CPU, where they
    share the memory, the image's copy as a NumPy array."""
    px = width * height
    image = 4 * px * (channels - 1)
    host = image if backend.get_backend() == "llvm" else 0
    return _pow2(4 * px * channels) + _pow2(image) + host


def lane_bytes(lanes: int, per_lane: int) -> int:
    """Bytes of ``per_lane`` bytes of state per lane kept in memory between kernels (4-byte
    arrays, each rounded up to a power of two)."""
    return per_lane * (_pow2(4 * lanes) // 4) if per_lane else 0


def check_render(width: int, height: int, spp_per_pass: int, channels: int, where: str,
                 bytes_per_lane: int = 0, lanes: int | None = None) -> None:
    """Raise a clear error before a render that Dr.Jit could not run: ``where`` names the
    sensor (a key path). ``lanes``: the widest kernel (default: the pixels times
    ``spp_per_pass``); ``bytes_per_lane``: the integrator's state per lane outside
    registers (``SamplingIntegrator.bytes_per_lane``)."""
    lanes = width * height * spp_per_pass if lanes is None else lanes
    entries = width * height * channels
    if max(lanes, entries) > MAX_ENTRIES:
        raise ValueError(
            f"{where}: a {width} x {height} film needs {entries:,} film entries and {lanes:,} samples per "
            f"pass, over Dr.Jit's limit of 2^32 - 1 per array: render a smaller image (or crop it)")
    need = film_bytes(width, height, channels) + lane_bytes(lanes, bytes_per_lane)
    if need < SMALL:
        return
    avail = available_bytes()
    if avail is not None and need > avail:
        raise MemoryError(
            f"{where}: a {width} x {height} film with {channels} channels "
            f"{f'and {lanes:,} paths ' if bytes_per_lane else ''}needs {need / _GiB:.1f} GiB, "
            f"and {avail / _GiB:.1f} GiB are available on the {backend.get_backend()} backend: render a "
            f"smaller image (or crop it)")
