"""pbr: a spectral, differentiable, physically based renderer on Dr.Jit.

Public API (see README.md)::

    import pbr
    pbr.set_backend("llvm")          # "llvm", "cuda" or "auto"
    scene = pbr.load_dict(pbr.cornell_box())
    img = pbr.render(scene, spp=64)  # mi.TensorXf (H, W, 3), linear sRGB
    pbr.write_image("out.exr", img)
    params = pbr.traverse(scene)
"""
from .backend import set_backend, get_backend, BackendError, VariantWarning  # noqa: F401  (configures libLLVM first)
from .scene import load_dict, load_file, load_string, traverse, SceneError, SceneParameters  # noqa: F401
from .scenes import cornell_box, materials_gallery  # noqa: F401
from .render import render  # noqa: F401
from .convergence import convergence  # noqa: F401
from .freeze import freeze  # noqa: F401
from .image import write_image, read_image, register_ipython_display  # noqa: F401

__version__ = "0.1.0"

register_ipython_display()
