"""Image input/output: OpenEXR (linear float) and 8-bit sRGB PNG, plus Jupyter display.

Images are plain arrays: anything ``np.asarray`` turns into a float array of shape
(H, W), (H, W, 1), (H, W, 3) or (H, W, 4) -- including Dr.Jit tensors. Pixel values are
linear (scene-referred); the PNG path applies exposure, tone mapping and the sRGB
transfer function, the EXR path stores the values untouched as float32.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = [
    "write_image",
    "read_image",
    "to_png_bytes",
    "srgb_to_linear",
    "linear_to_srgb",
    "register_ipython_display",
    "TONEMAPS",
    "WRITE_EXTENSIONS",
]

#: Tone-mapping operators accepted by :func:`write_image` / :func:`to_png_bytes`.
TONEMAPS = ("clamp", "reinhard")
#: File extensions :func:`write_image` can write.
WRITE_EXTENSIONS = (".exr", ".png")

# Channel names used for EXR files, by channel count.
_EXR_NAMES = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


# --------------------------------------------------------------------------- sRGB curve

def linear_to_srgb(x):
    """Encode linear values with the exact piecewise sRGB OETF (IEC 61966-2-1).

    ``12.92 x`` below 0.0031308, ``1.055 x^(1/2.4) - 0.055`` above. Values are not
    clipped; negative inputs are mirrored (odd extension) so the curve stays monotonic.
    """
    x = np.asarray(x, dtype=np.float64)
    a = np.abs(x)
    y = np.where(a <= 0.0031308, 12.92 * a, 1.055 * np.power(a, 1.0 / 2.4) - 0.055)
    return np.copysign(y, x)


def srgb_to_linear(x):
    """Decode sRGB-encoded values to linear with the exact piecewise inverse OETF.

    ``x / 12.92`` below 0.04045, ``((x + 0.055) / 1.055)^2.4`` above; the inverse of
    :func:`linear_to_srgb` (negative inputs are mirrored the same way).
    """
    x = np.asarray(x, dtype=np.float64)
    a = np.abs(x)
    y = np.where(a <= 0.04045, a / 12.92, np.power((a + 0.055) / 1.055, 2.4))
    return np.copysign(y, x)


# --------------------------------------------------------------------------- helpers

def _as_hwc(img) -> np.ndarray:
    """Return ``img`` as a float32 (H, W, C) array; (H, W) becomes (H, W, 1)."""
    a = np.asarray(img)
    if a.dtype.kind not in "fiub":
        raise ValueError(f"image must be numeric, got dtype {a.dtype}")
    a = a.astype(np.float32, copy=False)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[0] == 0 or a.shape[1] == 0 or a.shape[2] == 0:
        raise ValueError(f"image must have shape (H, W) or (H, W, C), got {a.shape}")
    return a


def _check_finite(a: np.ndarray, allow_nonfinite: bool, what: str) -> None:
    if allow_nonfinite:
        return
    bad = ~np.isfinite(a)
    n = int(bad.sum())
    if n:
        n_nan = int(np.isnan(a).sum())
        raise ValueError(
            f"{what}: image has {n} non-finite value(s) ({n_nan} NaN, {n - n_nan} Inf) "
            f"out of {a.size}; pass allow_nonfinite=True to write it anyway")


def _encode_8bit(a: np.ndarray, tonemap: str, exposure: float) -> np.ndarray:
    """Linear float (H, W, C) -> uint8 sRGB (H, W, C).

    Order: exposure (x 2**exposure), tone mapping, sRGB OETF, round to 8 bits. An alpha
    channel (C == 4) is only clipped and quantised: it is coverage, not radiance.
    NaN maps to 0 and +Inf to white.
    """
    if tonemap not in TONEMAPS:
        raise ValueError(f"unknown tonemap {tonemap!r}; expected one of {', '.join(TONEMAPS)}")
    c = a.shape[2]
    if c not in (1, 3, 4):
        raise ValueError(f"PNG needs 1, 3 or 4 channels, got {c}")
    a = a.astype(np.float64)
    colour = a[:, :, :3] if c == 4 else a
    colour = np.nan_to_num(colour, nan=0.0, posinf=np.finfo(np.float64).max, neginf=0.0)
    colour = np.maximum(colour * (2.0 ** float(exposure)), 0.0)
    if tonemap == "reinhard":
        # Per channel: x / (1 + x). Simple, bounded by 1 per channel; saturated
        # highlights desaturate towards white (a luminance-based version would keep
        # hue but can push channels past 1).
        colour = colour / (1.0 + colour)
    colour = linear_to_srgb(np.clip(colour, 0.0, 1.0))
    if c == 4:
        alpha = np.clip(np.nan_to_num(a[:, :, 3:], nan=0.0), 0.0, 1.0)
        colour = np.concatenate([colour, alpha], axis=2)
    return np.floor(colour * 255.0 + 0.5).astype(np.uint8)


def _png_bitmap(u8: np.ndarray):
    import mitsuba as mi

    fmt = {1: mi.Bitmap.PixelFormat.Y, 3: mi.Bitmap.PixelFormat.RGB,
           4: mi.Bitmap.PixelFormat.RGBA}[u8.shape[2]]
    data = np.ascontiguousarray(u8[:, :, 0] if u8.shape[2] == 1 else u8)
    # uint8 Bitmaps are flagged sRGB-encoded by Mitsuba, which is what the data is.
    return mi.Bitmap(data, pixel_format=fmt)


# --------------------------------------------------------------------------- public API

def write_image(path, img, tonemap: str = "clamp", exposure: float = 0.0,
                allow_nonfinite: bool = False) -> str:
    """Write a linear image to ``path``; the format follows the extension.

    ``.exr``: OpenEXR float32, values stored unchanged (``tonemap``/``exposure`` ignored),
    channels Y / RGB / RGBA for 1 / 3 / 4 channels, ``C0..Cn`` otherwise.
    ``.png``: 8-bit sRGB: ``x * 2**exposure``, then ``tonemap`` ('clamp': clip to [0, 1];
    'reinhard': ``x / (1 + x)`` per channel), then the exact sRGB OETF.
    Parent directories are created. Non-finite pixels raise ValueError (they usually
    mean a bug) unless ``allow_nonfinite=True``; a file that cannot be written raises
    OSError. Returns the path written.
    """
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in WRITE_EXTENSIONS:
        raise ValueError(f"cannot write {path!r}: unsupported extension {ext or '(none)'!r}; "
                         f"supported: {', '.join(WRITE_EXTENSIONS)}")
    if tonemap not in TONEMAPS:
        raise ValueError(f"unknown tonemap {tonemap!r}; expected one of {', '.join(TONEMAPS)}")
    a = _as_hwc(img)
    _check_finite(a, allow_nonfinite, path)
    parent = os.path.dirname(path)
    if parent:
        try:
            os.makedirs(parent, exist_ok=True)
        except FileExistsError:     # a file where a folder of the path should be
            raise NotADirectoryError(f"cannot write {path}: {parent} is not a folder") from None
    try:
        if ext == ".exr":
            import OpenEXR

            names = _EXR_NAMES.get(a.shape[2]) or tuple(f"C{i}" for i in range(a.shape[2]))
            channels = {n: np.ascontiguousarray(a[:, :, i]) for i, n in enumerate(names)}
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, channels) as f:
                f.write(path)
        else:
            _png_bitmap(_encode_8bit(a, tonemap, exposure)).write(path)
    except RuntimeError as e:   # the writers (OpenEXR, Mitsuba's Bitmap) report I/O failures so
        raise OSError(f"cannot write {path}: {str(e).strip()}") from None
    return path


def to_png_bytes(img, tonemap: str = "clamp", exposure: float = 0.0,
                 allow_nonfinite: bool = False) -> bytes:
    """Encode a linear image as PNG file bytes (same pipeline as ``write_image(.png)``).

    Used for inline display in Jupyter.
    """
    a = _as_hwc(img)
    _check_finite(a, allow_nonfinite, "to_png_bytes")
    import mitsuba as mi

    stream = mi.MemoryStream()
    _png_bitmap(_encode_8bit(a, tonemap, exposure)).write(stream, mi.Bitmap.FileFormat.PNG)
    stream.seek(0)
    return bytes(stream.read(stream.size()))


def _read_exr(path: str) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(path, separate_channels=True) as f:
        chans = {name: np.asarray(c.pixels) for name, c in f.channels().items()}
    if not chans:
        raise ValueError(f"{path!r}: EXR file has no channels")
    order = [n for n in ("R", "G", "B", "A") if n in chans]
    if order == ["R", "G", "B"] or order == ["R", "G", "B", "A"]:
        names = order
    elif set(chans) == {"Y"}:
        names = ["Y"]
    elif set(chans) == {"Y", "A"}:
        names = ["Y", "A"]
    else:
        names = sorted(chans)
    return np.stack([chans[n].astype(np.float32) for n in names], axis=2)


def _read_bitmap(path: str) -> np.ndarray:
    import mitsuba as mi

    bmp = mi.Bitmap(path)
    raw = np.array(bmp, copy=True)
    if raw.ndim == 2:
        raw = raw[:, :, None]
    if raw.dtype.kind in "ui":
        a = raw.astype(np.float64) / np.iinfo(raw.dtype).max
    else:
        a = raw.astype(np.float64)
    if bmp.srgb_gamma():
        fmt = bmp.pixel_format()
        has_alpha = fmt in (mi.Bitmap.PixelFormat.RGBA, mi.Bitmap.PixelFormat.YA)
        n = a.shape[2] - 1 if has_alpha else a.shape[2]
        a[:, :, :n] = srgb_to_linear(a[:, :, :n])
    return a.astype(np.float32)


def read_image(path) -> np.ndarray:
    """Read an image as a linear float32 array of shape (H, W, C).

    ``.exr`` (OpenEXR): the stored values as float32 (half channels widened), channels in
    R, G, B, A order (Y for luminance-only files, otherwise sorted by name).
    Other formats (PNG, JPEG, HDR, PFM, ... via ``mitsuba.Bitmap``): integer data is
    normalised to [0, 1]; if Mitsuba flags the file as sRGB-encoded (``srgb_gamma()``:
    8-bit PNG/JPEG, and 16-bit PNGs without a linear gamma chunk) the colour channels
    are linearised with
    :func:`srgb_to_linear` (alpha is left as is). So an 8-bit sRGB PNG pixel value ``v``
    comes back as ``srgb_to_linear(v / 255)``. C is 1 (grey), 2 (grey + alpha), 3 or 4.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(f"image file not found: {path!r}")
    if path.lower().endswith(".exr"):
        return _read_exr(path)
    return _read_bitmap(path)


# --------------------------------------------------------------------------- IPython

def _tensor_types() -> list:
    """Dr.Jit float tensor types that should display as images (those importable)."""
    import importlib

    types = []
    for mod in ("drjit.llvm.ad", "drjit.llvm", "drjit.cuda.ad", "drjit.cuda"):
        try:
            types.append(getattr(importlib.import_module(mod), "TensorXf"))
        except Exception:  # CUDA modules may be missing or unusable on this machine
            pass
    return types


def _get_ipython():
    """The running IPython shell, or None."""
    import builtins
    import sys

    if "IPython" in sys.modules:
        try:
            shell = sys.modules["IPython"].get_ipython()
            if shell is not None:
                return shell
        except Exception:
            pass
    getter = getattr(builtins, "get_ipython", None)
    return getter() if callable(getter) else None


def _ipython_png(tensor):
    """IPython PNG formatter: PNG bytes for an (H, W, 3) tensor, None (text repr) else."""
    shape = tuple(getattr(tensor, "shape", ()))
    if len(shape) != 3 or shape[2] != 3 or shape[0] == 0 or shape[1] == 0:
        return None
    # Non-finite pixels are shown (NaN black, Inf white) rather than raising in display.
    return to_png_bytes(tensor, allow_nonfinite=True)


def register_ipython_display() -> bool:
    """Make (H, W, 3) Dr.Jit ``TensorXf`` values display inline as images in IPython.

    Registers a PNG formatter (clamp tone mapping) for the LLVM and CUDA tensor types,
    AD and non-AD; other shapes fall back to the text repr. Returns True if registered,
    False (doing nothing) outside IPython.
    """
    shell = _get_ipython()
    if shell is None:
        return False
    formatter = shell.display_formatter.formatters["image/png"]
    for t in _tensor_types():
        formatter.for_type(t, _ipython_png)
    return True
