"""Built-in scenes."""

from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from . import backend
from .bsdfs import bsdf_names


def cornell_box(resolution: int = 256, spp: int = 64) -> dict:
    """The Cornell box of ``mi.cornell_box()`` (same geometry, materials, light and
    camera), as a Mitsuba-style scene dict."""
    backend.ensure_any()  # the dict holds Mitsuba transforms, which need a variant
    T = mi.ScalarTransform4f

    def rect(tf, bsdf):
        return {"type": "rectangle", "to_world": tf, "bsdf": {"type": "ref", "id": bsdf}}

    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": {
            "type": "perspective", "fov_axis": "smaller", "near_clip": 0.001, "far_clip": 100.0,
            "focus_distance": 1000, "fov": 39.3077,
            "to_world": T().look_at(origin=[0, 0, 3.9], target=[0, 0, 0], up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": resolution, "height": resolution,
                     "rfilter": {"type": "gaussian"}, "pixel_format": "rgb", "component_format": "float32"},
        },
        "white": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.885809, 0.698859, 0.666422]}},
        "green": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.105421, 0.37798, 0.076425]}},
        "red": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.570068, 0.0430135, 0.0443706]}},
        "light": {"type": "rectangle",
                  "to_world": T().translate([0.0, 0.99, 0.01]).rotate([1, 0, 0], 90).scale([0.23, 0.19, 0.19]),
                  "bsdf": {"type": "ref", "id": "white"},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [18.387, 13.9873, 6.75357]}}},
        "floor": rect(T().translate([0.0, -1.0, 0.0]).rotate([1, 0, 0], -90), "white"),
        "ceiling": rect(T().translate([0.0, 1.0, 0.0]).rotate([1, 0, 0], 90), "white"),
        "back": rect(T().translate([0.0, 0.0, -1.0]), "white"),
        "green-wall": rect(T().translate([1.0, 0.0, 0.0]).rotate([0, 1, 0], -90), "green"),
        "red-wall": rect(T().translate([-1.0, 0.0, 0.0]).rotate([0, 1, 0], 90), "red"),
        "small-box": {"type": "cube",
                      "to_world": T().translate([0.335, -0.7, 0.38]).rotate([0, 1, 0], -17).scale(0.3),
                      "bsdf": {"type": "ref", "id": "white"}},
        "large-box": {"type": "cube",
                      "to_world": T().translate([-0.33, -0.4, -0.28]).rotate([0, 1, 0], 18.25).scale([0.3, 0.61, 0.3]),
                      "bsdf": {"type": "ref", "id": "white"}},
    }


def glass_caustic(resolution: int = 64, spp: int = 64, light_size: float = 0.4, radiance: float = 30.0) -> dict:
    """A glass sphere (IOR 1.5) on a diffuse floor under a square area light (side
    ``light_size``, ``radiance``) 1.8 above it, out of the camera's view: light reaches the
    floor under the sphere only through the glass (a caustic; it needs max_depth >= 4:
    camera - floor - glass - glass - light), and the camera also sees the caustic through
    the sphere. A Mitsuba-style scene dict with a box filter."""
    backend.ensure_any()
    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40.0,
                   "to_world": T().look_at(origin=[0, 0.6, 3.0], target=[0, -0.8, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": resolution, "height": resolution,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "floor": {"type": "rectangle", "to_world": T().translate([0, -1, 0]).rotate([1, 0, 0], -90).scale(2.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.8]}}},
        "glass": {"type": "sphere", "center": [0.0, -0.6, 0.0], "radius": 0.4,
                  "bsdf": {"type": "dielectric", "int_ior": 1.5}},
        "light": {"type": "rectangle",
                  "to_world": T().translate([0.0, 1.2, 0.0]).rotate([1, 0, 0], 90).scale(light_size / 2),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}},
    }


def door_crack(resolution: int = 64, spp: int = 64, crack: float = 0.05, light_up: bool = False) -> dict:
    """Veach's door scene, simplified: a closed room (2 x 2 x 2, diffuse white) split by a
    wall with a slit ``crack`` wide (from z = -0.35), an area light in the smaller part
    facing its floor (or, ``light_up``, its ceiling), the camera in the larger part.
    Light reaches the camera's side only through the slit, mostly after bounces in the
    lit part: paths from the camera must find the slit and then the light. A
    Mitsuba-style scene dict with a box filter."""
    backend.ensure_any()
    T = mi.ScalarTransform4f
    white = {"type": "ref", "id": "white"}

    def wall(tf):
        return {"type": "rectangle", "to_world": tf, "bsdf": white}

    z0, z1 = -0.35, -0.35 + crack     # the slit
    return {
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 60.0,
                   "to_world": T().look_at(origin=[-0.8, 0.2, 0.95], target=[0.3, -0.3, -0.5], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": resolution, "height": resolution,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "white": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.75, 0.75, 0.75]}},
        "floor": wall(T().translate([0, -1, 0]).rotate([1, 0, 0], -90)),
        "ceiling": wall(T().translate([0, 1, 0]).rotate([1, 0, 0], 90)),
        "back": wall(T().translate([0, 0, -1])),
        "front": wall(T().translate([0, 0, 1]).rotate([0, 1, 0], 180)),
        "left": wall(T().translate([-1, 0, 0]).rotate([0, 1, 0], 90)),
        "right": wall(T().translate([1, 0, 0]).rotate([0, 1, 0], -90)),
        # The dividing wall at x = 0.3 (2 cm thick), open for z in [z0, z1].
        "wall-back": {"type": "cube", "to_world": T().translate([0.3, 0, (z0 - 1) / 2]).scale([0.02, 1, (z0 + 1) / 2]),
                      "bsdf": white},
        "wall-front": {"type": "cube", "to_world": T().translate([0.3, 0, (z1 + 1) / 2]).scale([0.02, 1, (1 - z1) / 2]),
                       "bsdf": white},
        "light": {"type": "rectangle",
                  "to_world": T().translate([0.65, 0.7 if light_up else 0.98, 0.5]).rotate([1, 0, 0], -90 if light_up else 90)
                  .scale(0.25),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [300.0, 300.0, 300.0]}}},
    }


# The gallery's data files (written by scenes/data/make_gallery_data.py). The dict holds
# absolute paths; ``to_xml(d, base_dir=...)`` writes them relative to the scene file.
GALLERY_DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                            "scenes", "data")

# One entry per BSDF family: (label, bsdf dict). Extended as families are added.
# ``hair`` is shown on a tuft of curves (GALLERY_DATA/hair_tuft.txt), the others on spheres.
GALLERY_MATERIALS = [
    ("diffuse", {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.2, 0.2]}}),
    ("conductor Au", {"type": "conductor", "material": "Au"}),
    ("roughconductor Cu", {"type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": 0.2}),
    ("anisotropic Al", {"type": "roughconductor", "material": "Al", "distribution": "ggx",
                        "alpha_u": 0.05, "alpha_v": 0.4}),
    ("dielectric", {"type": "dielectric", "int_ior": 1.5}),
    ("dispersive BK7", {"type": "dielectric", "int_ior": "glass-BK7"}),
    ("thindielectric", {"type": "thindielectric"}),
    ("roughdielectric", {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.2}),
    ("plastic", {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.3, 0.7]}}),
    ("roughplastic", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                      "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.8, 0.1]}}),
    ("coateddiffuse", {"type": "coateddiffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.5, 0.6]},
                       "roughness": 0.05}),
    ("coatedconductor", {"type": "coatedconductor", "interface.roughness": 0.02, "conductor.roughness": 0.3}),
    ("principled", {"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.5, 0.1]},
                    "metallic": 0.5, "roughness": 0.3, "clearcoat": 0.5}),
    ("principledthin", {"type": "principledthin", "base_color": {"type": "rgb", "value": [0.2, 0.7, 0.3]},
                        "spec_trans": 0.5, "roughness": 0.4}),
    ("diffusetransmission", {"type": "diffusetransmission", "reflectance": 0.3, "transmittance": 0.5}),
    ("subsurface", {"type": "subsurface", "reflectance": {"type": "rgb", "value": [0.8, 0.45, 0.3]}, "mfp": 0.03}),
    ("mask", {"type": "mask", "opacity": 0.5, "b": {"type": "diffuse", "reflectance": 0.8}}),
    ("blendbsdf", {"type": "blendbsdf", "weight": 0.5, "a": {"type": "diffuse", "reflectance": 0.2},
                   "b": {"type": "roughconductor", "material": "Ag", "alpha": 0.1}}),
    ("twosided", {"type": "twosided", "b": {"type": "diffuse", "reflectance":
                                            {"type": "checkerboard", "to_uv": np.diag([8.0, 8.0, 1.0, 1.0])}}}),
    ("measured (GGX Au table)", {"type": "measured", "filename": os.path.join(GALLERY_DATA, "gold_ggx.bsdf")}),
    ("hair", {"type": "hair", "eumelanin": 0.15, "pheomelanin": 0.8}),
]


def materials_gallery(resolution: int = 480, spp: int = 64, materials=None) -> dict:
    """A grid of spheres, one per BSDF family (``GALLERY_MATERIALS``; ``hair`` on a tuft of
    fibres instead), on a diffuse floor under an area light: a Mitsuba-style scene dict.
    Rendered by ``path``, or ``volpath`` where a ``subsurface`` sphere needs it."""
    mats = [m for m in (materials or GALLERY_MATERIALS) if m[1]["type"] in bsdf_names()]
    backend.ensure_any()
    T = mi.ScalarTransform4f
    cols = 5
    rows = (len(mats) + cols - 1) // cols
    d = {
        "type": "scene",
        "integrator": {"type": "volpath" if any(m[1]["type"] == "subsurface" for m in mats) else "path",
                       "max_depth": 12},
        "sensor": {"type": "perspective", "fov": 40.0,
                   "to_world": T().look_at(origin=[0, 4.5, 9.5], target=[0, 0.2, 0], up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": {"type": "hdrfilm", "width": resolution, "height": int(resolution * 0.75)}},
        "floor": {"type": "rectangle", "to_world": T().translate([0, -0.5, 0]).rotate([1, 0, 0], -90).scale(12),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard",
                           "color0": 0.6, "color1": 0.3, "to_uv": T().scale([24, 24, 1])}}},
        "light": {"type": "rectangle", "to_world": T().translate([0, 7, 3]).rotate([1, 0, 0], 110).scale(4),
                  "emitter": {"type": "area", "radiance": 2.5}},
        "backlight": {"type": "rectangle", "to_world": T().translate([0, 3, -8]).scale([10, 4, 1]),
                      "emitter": {"type": "area", "radiance": {"type": "d65", "scale": 0.25}}},
    }
    for i, (name, bsdf) in enumerate(mats):
        r, c = divmod(i, cols)
        x = (c - (cols - 1) / 2) * 1.3
        z = (r - (rows - 1) / 2) * 1.4
        if bsdf["type"] == "hair":
            d[f"hair-{i:02d}"] = {"type": "bsplinecurve", "filename": os.path.join(GALLERY_DATA, "hair_tuft.txt"),
                                  "to_world": T().translate([x, -0.5, z]), "bsdf": bsdf}
        else:
            d[f"sphere-{i:02d}"] = {"type": "sphere", "radius": 0.5, "center": [x, 0.0, z], "bsdf": bsdf}
    return d
