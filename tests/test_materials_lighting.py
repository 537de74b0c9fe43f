"""Materials under a point light and an environment map (direct and indirect light),
compared with Mitsuba (the area-light case is in each family's tests)."""

import pytest

from mitsuba_scenes import lit_box, compare_with_mitsuba

MATERIALS = {
    "roughconductor": ({"type": "roughconductor", "material": "Au", "distribution": "ggx", "alpha": 0.2},
                       {"type": "conductor", "material": "Ag"}),
    "roughdielectric": ({"type": "roughdielectric", "distribution": "ggx", "alpha": 0.25},
                        {"type": "dielectric", "int_ior": 1.33}),
    "plastic": ({"type": "roughplastic", "distribution": "ggx", "alpha": 0.2,
                 "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}},
                {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.3, 0.1]}}),
    "principled": ({"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.6, 0.2]},
                    "metallic": 0.6, "roughness": 0.3},
                   {"type": "principledthin", "base_color": {"type": "rgb", "value": [0.3, 0.8, 0.4]},
                    "spec_trans": 0.4, "roughness": 0.3}),
}


@pytest.mark.parametrize("lighting", ["point", "envmap"])
@pytest.mark.parametrize("name", list(MATERIALS))
def test_matches_mitsuba(name, lighting, scale):
    small, large = MATERIALS[name]
    res = compare_with_mitsuba(lit_box(small, large, lighting, scale), scale)
    print(name, lighting, res.summary())
    assert res.passed, res.summary()
