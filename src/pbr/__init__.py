"""pbr: a spectral, differentiable, physically based renderer on Dr.Jit.

Public API (see README.md): set_backend, cornell_box, load_dict, load_file, render,
write_image, traverse.
"""
from .backend import set_backend, backend, BackendError  # noqa: F401  (configures libLLVM first)
