"""pbr vs Mitsuba 3 over several scenes: time at equal spp and resolution (warm kernels,
same process, interleaved pairs) and the image-mean ratio as a sanity check of the
backend (a wrong backend shows up here first: the CUDA backend once rendered the Cornell
box 95x too bright).

Scenes (all Mitsuba-loadable dicts from ``pbr.scenes``, ``path`` integrator):

- ``cornell``: the built-in Cornell box (diffuse), max_depth 8;
- ``cornell-glossy``: the same with a rough copper and a rough plastic block;
- ``gallery``: the materials gallery without the 4 cells Mitsuba lacks (16 BSDF families
  on spheres and a hair tuft of B-spline curves), max_depth 12;
- ``caustic``: a glass sphere on a floor, light reaching it through the glass;
- ``door``: Veach's door scene, simplified (light through a slit).

Prints per scene pbr's and Mitsuba's median times, the time ratio (pbr / Mitsuba, target
<= 1; the median of per-pair ratios) and the image-mean ratio (expected 1 within noise),
then the geometric mean of the time ratios.

    python benchmarks/bench_scenes.py [--res 128] [--spp 16] [--reps 3] [--backend llvm] [--scenes cornell,gallery]
"""

from __future__ import annotations

import argparse

import numpy as np

import pbr
import drjit as dr
import mitsuba as mi

from bench_cornell import interleaved
from pbr.scene.xml import to_xml

# Gallery cells Mitsuba 3.9 cannot load (pbrt-v4 features); tests/test_gallery.py checks
# that each one fails there.
NOT_IN_MITSUBA = ("dispersive BK7", "coateddiffuse", "coatedconductor", "diffusetransmission")


def scene_dicts(res: int, spp: int) -> dict:
    from pbr.scenes import GALLERY_MATERIALS, glass_caustic, door_crack, materials_gallery
    path = lambda depth: {"type": "path", "max_depth": depth}  # noqa: E731
    out = {}
    d = pbr.cornell_box(res, spp)
    d["integrator"] = path(8)
    out["cornell"] = d
    d = pbr.cornell_box(res, spp)
    d["integrator"] = path(8)
    d["small-box"]["bsdf"] = {"type": "roughconductor", "material": "Cu", "distribution": "ggx", "alpha": 0.2}
    d["large-box"]["bsdf"] = {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                              "diffuse_reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}
    out["cornell-glossy"] = d
    mats = [m for m in GALLERY_MATERIALS if m[0] not in NOT_IN_MITSUBA]
    out["gallery"] = materials_gallery(res, spp, materials=mats)
    for name, d in (("caustic", glass_caustic(res, spp)), ("door", door_crack(res, spp))):
        d["integrator"] = path(8)
        out[name] = d
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128, help="image width (height follows the scene's aspect)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--backend", default="llvm")
    ap.add_argument("--scenes", default="cornell,cornell-glossy,gallery,caustic,door")
    a = ap.parse_args(argv)
    pbr.set_backend(a.backend)
    dicts = scene_dicts(a.res, a.spp)
    print(f"{a.res} wide, {a.spp} spp, backend {pbr.get_backend()}, median of {a.reps} interleaved pairs")
    print(f"{'scene':15s} {'pbr s':>8s} {'Mitsuba s':>10s} {'time ratio':>11s} {'mean ratio':>11s}")
    ratios = []
    for name in a.scenes.split(","):
        d = dicts[name]
        # Mitsuba reads the scene as pbr's XML writer gives it (its dict loader takes no
        # NumPy matrices, which the gallery's twosided checkerboard uses for to_uv).
        scene, mscene = pbr.load_dict(d), mi.load_string(to_xml(d))
        seed = [0]
        last = {}

        def run_pbr():
            seed[0] += 1
            last["pbr"] = np.asarray(pbr.render(scene, spp=a.spp, seed=seed[0], progress=False))

        def run_mi():
            seed[0] += 1
            img = mi.render(mscene, spp=a.spp, seed=seed[0])
            dr.eval(img)
            last["mi"] = np.asarray(img)[..., :3]

        t_pbr, t_mi, ratio = interleaved(run_pbr, run_mi, a.reps)
        mean_ratio = float(last["pbr"].mean() / max(last["mi"].mean(), 1e-12))
        ratios.append(ratio)
        print(f"{name:15s} {t_pbr:8.3f} {t_mi:10.3f} {ratio:11.3f} {mean_ratio:11.3f}", flush=True)
    print(f"geometric mean of the time ratios over {len(ratios)} scenes: "
          f"{float(np.exp(np.mean(np.log(ratios)))):.3f}")


if __name__ == "__main__":
    main()
