"""Image I/O: EXR/PNG round trips, sRGB curve, tone mapping, error handling, IPython hook."""
import builtins
import struct
import zlib

import pbr  # (first: configures libLLVM before Dr.Jit)
import numpy as np
import pytest

from pbr import image
from pbr.image import (linear_to_srgb, read_image, register_ipython_display, srgb_to_linear,
                       to_png_bytes, write_image)


def _png_pixels(data: bytes) -> np.ndarray:
    """Independent minimal PNG decoder (8-bit, filter types 0-4) used to check the writer."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, depth, ctype = ihdr[:4]
    assert depth == 8
    c = {0: 1, 2: 3, 6: 4, 4: 2}[ctype]
    raw = zlib.decompress(idat)
    stride = w * c
    out = np.zeros((h, stride), np.int32)
    prev = np.zeros(stride, np.int32)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = np.frombuffer(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)], np.uint8).astype(np.int32)
        cur = np.zeros(stride, np.int32)
        for i in range(stride):
            a = cur[i - c] if i >= c else 0
            b = prev[i]
            cc = prev[i - c] if i >= c else 0
            if f == 0:
                p = 0
            elif f == 1:
                p = a
            elif f == 2:
                p = b
            elif f == 3:
                p = (a + b) // 2
            else:
                pa, pb, pc = abs(b - cc), abs(a - cc), abs(a + b - 2 * cc)
                p = a if pa <= pb and pa <= pc else (b if pb <= pc else cc)
            cur[i] = (line[i] + p) & 255
        out[y] = cur
        prev = cur
    return out.reshape(h, w, c).astype(np.uint8)


def test_srgb_curve_known_values():
    # Exact piecewise curve, not gamma 2.2: linear part below the breakpoint.
    assert linear_to_srgb(0.0) == 0.0
    assert linear_to_srgb(1.0) == pytest.approx(1.0, abs=1e-12)
    assert linear_to_srgb(0.002) == pytest.approx(12.92 * 0.002)
    assert linear_to_srgb(0.18) == pytest.approx(1.055 * 0.18 ** (1 / 2.4) - 0.055)
    assert linear_to_srgb(0.18) != pytest.approx(0.18 ** (1 / 2.2), abs=1e-3)
    assert srgb_to_linear(0.5) == pytest.approx(0.21404114048223255, abs=1e-12)
    assert srgb_to_linear(0.02) == pytest.approx(0.02 / 12.92)
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    # Continuous at the breakpoint.
    assert linear_to_srgb(0.0031308) == pytest.approx(0.04045, abs=1e-6)


def test_exr_round_trip_exact(tmp_path):
    rng = np.random.default_rng(1)
    img = (rng.standard_normal((7, 5, 3)) * 100).astype(np.float32)
    img[0, 0] = [0.0, 1e-30, 65504.5]
    path = tmp_path / "sub" / "dir" / "a.exr"  # parent directories are created
    assert write_image(path, img) == str(path)
    back = read_image(path)
    assert back.dtype == np.float32 and back.shape == (7, 5, 3)
    np.testing.assert_array_equal(back, img)


def test_exr_grey_and_rgba(tmp_path):
    grey = np.arange(12, dtype=np.float32).reshape(3, 4)
    write_image(tmp_path / "g.exr", grey)
    np.testing.assert_array_equal(read_image(tmp_path / "g.exr"), grey[:, :, None])
    rgba = np.random.default_rng(2).random((3, 4, 4)).astype(np.float32)
    write_image(tmp_path / "a.exr", rgba)
    np.testing.assert_array_equal(read_image(tmp_path / "a.exr"), rgba)


def _tensor_types():
    """Dr.Jit's (AD, plain) tensor types of the backend the tests run on."""
    import drjit as dr
    mod = getattr(dr, pbr.get_backend())
    return mod.ad.TensorXf, mod.TensorXf


def test_exr_from_drjit_tensor(tmp_path):
    arr = np.random.default_rng(3).random((4, 6, 3)).astype(np.float32)
    write_image(tmp_path / "t.exr", _tensor_types()[0](arr))
    np.testing.assert_array_equal(read_image(tmp_path / "t.exr"), arr)


def test_png_round_trip_within_one_level(tmp_path):
    rng = np.random.default_rng(4)
    img = rng.random((9, 11, 3)).astype(np.float32)
    write_image(tmp_path / "a.png", img)
    back = read_image(tmp_path / "a.png")
    assert back.dtype == np.float32 and back.shape == img.shape
    # Compare in the encoded domain: one 8-bit step at most (half a step from rounding).
    err = np.abs(linear_to_srgb(back) - linear_to_srgb(img))
    assert err.max() <= 0.5 / 255 + 1e-6
    # read_image linearises: an 8-bit value v comes back as srgb_to_linear(v / 255).
    raw = _png_pixels((tmp_path / "a.png").read_bytes())
    np.testing.assert_allclose(back, srgb_to_linear(raw / 255.0), atol=1e-6)


def test_png_encoding_known_values(tmp_path):
    img = np.array([[[0.0, 0.5, 1.0], [2.0, -1.0, 0.0031308]]], np.float32)
    raw = _png_pixels(to_png_bytes(img))
    assert raw.shape == (1, 2, 3)
    expected = np.floor(linear_to_srgb(np.clip(img, 0, 1)) * 255 + 0.5)
    np.testing.assert_array_equal(raw, expected)
    assert raw[0, 0, 1] == 188  # sRGB(0.5) = 0.7354 -> 188 (gamma 2.2 would give 186)
    # The file written by write_image decodes to the same bytes.
    write_image(tmp_path / "k.png", img)
    np.testing.assert_array_equal(_png_pixels((tmp_path / "k.png").read_bytes()), raw)


def test_tonemap_and_exposure():
    img = np.array([[[1.0, 3.0, 0.25]]], np.float32)
    reinhard = _png_pixels(to_png_bytes(img, tonemap="reinhard"))
    # Per channel x / (1 + x): 0.5, 0.75, 0.2.
    expected = np.floor(linear_to_srgb(np.array([0.5, 0.75, 0.2])) * 255 + 0.5)
    np.testing.assert_array_equal(reinhard[0, 0], expected)
    clamp = _png_pixels(to_png_bytes(img, tonemap="clamp"))
    np.testing.assert_array_equal(clamp[0, 0], np.floor(linear_to_srgb([1.0, 1.0, 0.25]) * 255 + 0.5))
    # +1 stop doubles: 0.25 -> 0.5; -2 stops quarters: 3 -> 0.75.
    up = _png_pixels(to_png_bytes(img, exposure=1.0))
    assert up[0, 0, 2] == np.floor(linear_to_srgb(0.5) * 255 + 0.5)
    down = _png_pixels(to_png_bytes(img, exposure=-2.0))
    assert down[0, 0, 1] == np.floor(linear_to_srgb(0.75) * 255 + 0.5)
    with pytest.raises(ValueError, match="tonemap"):
        to_png_bytes(img, tonemap="filmic")


def test_png_grey_and_alpha(tmp_path):
    grey = np.full((2, 3), 0.5, np.float32)
    write_image(tmp_path / "g.png", grey)
    back = read_image(tmp_path / "g.png")
    assert back.shape == (2, 3, 1)
    assert back[0, 0, 0] == pytest.approx(srgb_to_linear(188 / 255), abs=1e-6)
    rgba = np.zeros((2, 2, 4), np.float32)
    rgba[..., :3] = 0.5
    rgba[..., 3] = 0.5
    write_image(tmp_path / "a.png", rgba)
    raw = _png_pixels((tmp_path / "a.png").read_bytes())
    assert list(raw[0, 0]) == [188, 188, 188, 128]  # alpha is not sRGB-encoded
    back = read_image(tmp_path / "a.png")
    assert back[0, 0, 3] == pytest.approx(128 / 255, abs=1e-6)


def test_nonfinite_rejected(tmp_path):
    img = np.zeros((4, 4, 3), np.float32)
    img[0, 0, 0] = np.nan
    img[1, 1, 1] = np.inf
    img[2, 2, 2] = np.nan
    for name in ("a.exr", "a.png"):
        with pytest.raises(ValueError, match=r"3 non-finite value\(s\) \(2 NaN, 1 Inf\)"):
            write_image(tmp_path / name, img)
        assert not (tmp_path / name).exists()
    with pytest.raises(ValueError, match="non-finite"):
        to_png_bytes(img)
    write_image(tmp_path / "ok.png", img, allow_nonfinite=True)
    raw = _png_pixels((tmp_path / "ok.png").read_bytes())
    assert raw[0, 0, 0] == 0 and raw[1, 1, 1] == 255
    write_image(tmp_path / "ok.exr", img, allow_nonfinite=True)
    back = read_image(tmp_path / "ok.exr")
    assert np.isnan(back[0, 0, 0]) and np.isinf(back[1, 1, 1])


def test_bad_extension(tmp_path):
    path = tmp_path / "a.tiff"
    with pytest.raises(ValueError) as e:
        write_image(path, np.zeros((2, 2, 3)))
    msg = str(e.value)
    assert str(path) in msg and ".exr" in msg and ".png" in msg and ".tiff" in msg
    with pytest.raises(ValueError, match="supported"):
        write_image(tmp_path / "noext", np.zeros((2, 2, 3)))


def test_bad_shape_and_missing_file(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        write_image(tmp_path / "a.exr", np.zeros(5))
    with pytest.raises(ValueError, match="channels"):
        write_image(tmp_path / "a.png", np.zeros((2, 2, 5)))
    with pytest.raises(FileNotFoundError):
        read_image(tmp_path / "missing.png")


class _FakeFormatter:
    def __init__(self):
        self.types = {}

    def for_type(self, typ, func):
        self.types[typ] = func


class _FakeShell:
    def __init__(self):
        self.png = _FakeFormatter()
        self.display_formatter = type("DF", (), {"formatters": {"image/png": self.png}})()


def test_register_ipython_display(monkeypatch):
    monkeypatch.setattr(image, "_get_ipython", lambda: None)
    assert register_ipython_display() is False

    shell = _FakeShell()
    monkeypatch.setattr(image, "_get_ipython", lambda: shell)
    assert register_ipython_display() is True
    ad_tensor, tensor = _tensor_types()
    assert ad_tensor in shell.png.types and tensor in shell.png.types
    fmt = shell.png.types[ad_tensor]
    arr = np.random.default_rng(5).random((3, 4, 3)).astype(np.float32)
    data = fmt(ad_tensor(arr))
    assert data == to_png_bytes(arr)
    assert _png_pixels(data).shape == (3, 4, 3)
    assert fmt(ad_tensor(np.zeros((3, 4), np.float32))) is None
    assert fmt(ad_tensor(np.zeros(7, np.float32))) is None


def test_get_ipython_from_builtins(monkeypatch):
    shell = _FakeShell()
    monkeypatch.setattr(builtins, "get_ipython", lambda: shell, raising=False)
    assert image._get_ipython() is shell
    assert register_ipython_display() is True
    monkeypatch.delattr(builtins, "get_ipython")
    assert image._get_ipython() is None
