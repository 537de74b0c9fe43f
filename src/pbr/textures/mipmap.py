"""pbrt-v4's ``imagemap``: an image with a MIP pyramid, filtered over the pixel footprint."""

from __future__ import annotations

from .kinds import MIPMAP, key_path


class MipMap:
    kind = MIPMAP

    def __init__(self, path):
        self.path = key_path(path)
        self.params = {}


def build_table(items):
    raise NotImplementedError


def static_info(items):
    raise NotImplementedError


def evaluate(textures, i, uv, si, lam, active, illuminant=True):
    raise NotImplementedError
