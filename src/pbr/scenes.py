"""Built-in scenes."""

from __future__ import annotations

import mitsuba as mi
import numpy as np


def cornell_box(resolution: int = 256, spp: int = 64) -> dict:
    """The Cornell box of ``mi.cornell_box()`` (same geometry, materials, light and
    camera), as a Mitsuba-style scene dict."""
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
