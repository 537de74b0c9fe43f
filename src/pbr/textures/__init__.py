"""Spectral textures: every spectrum-valued parameter of a scene is a texture *slot*.

* :mod:`.kinds`: what a slot holds (constant spectra, ``checkerboard``, ``bitmap``,
  pbrt-v4's ``scale``/``mix`` combinators, ``sqrt``, Mitsuba's ``mesh_attribute``);
* :mod:`.loading`: parameter values -> slots, one loading function per plugin type
  (:data:`TEXTURE_TYPES`);
* :mod:`.tables`: the per-kind Dr.Jit tables, a named structure;
* :mod:`.textureset`: :class:`TextureSet`, the scene's slots, their tables and their
  evaluation in kernels;
* :mod:`.meshattr`: mesh attributes (reading them from PLY/OBJ files, evaluating them).

Parameters (``.value`` of constants, ``.data`` of bitmaps, ``.scale`` of mesh
attributes) are Dr.Jit arrays exposed to :func:`pbr.traverse`; tables are rebuilt from
them, differentiably, on ``update()``.
"""

from .kinds import (BASE_ONE, BASE_SIGMOID, BASE_TABLE, BITMAP, CHECKERBOARD, COMPOSITE, CONSTANT,  # noqa: F401
                    MESH_ATTRIBUTE, OP_CHECKER, OP_MIX, OP_SCALE, OP_SQRT, Bitmap, Checkerboard, Composite,
                    ConstantSpectrum, MeshAttribute)
from .loading import TEXTURE_TYPES, add_tabulated, load_spectrum, read_spectrum_file, table_from_pairs  # noqa: F401
from .tables import TextureTables  # noqa: F401
from .textureset import TextureSet  # noqa: F401
