"""View-independent output: per-vertex values of a solution and mesh export.

A vertex's value is the area-weighted average of its adjacent patches' values (the
welded subdivided meshes of :class:`.patches.Patches`). Colours are the binned spectra
converted to XYZ with pbr's colour matching functions and then to linear sRGB; the
``srgb`` colour space additionally applies the sRGB transfer curve. Exported files
(any format trimesh writes by extension, e.g. ``.ply``, ``.glb``) store 8-bit RGBA
vertex colours: ``exposure`` (stops) scales linear values first, values are clipped
to [0, 1]. For unclipped floats use :func:`vertex_colors` directly.
"""

from __future__ import annotations

import numpy as np

from ...image import linear_to_srgb

COLOR_SPACES = ("srgb", "linear")


def vertex_values(patches, values: np.ndarray) -> np.ndarray:
    """(V, ...) area-weighted averages of per-patch ``values`` (N, ...) at the vertices."""
    values = np.asarray(values, np.float64)
    flat = values.reshape(len(values), -1)
    acc = np.zeros((patches.n_vertices, flat.shape[1]))
    wsum = np.zeros(patches.n_vertices)
    for k in range(3):
        np.add.at(acc, patches.faces[:, k], patches.area[:, None] * flat)
        np.add.at(wsum, patches.faces[:, k], patches.area)
    out = acc / np.maximum(wsum, 1e-300)[:, None]
    return out.reshape((patches.n_vertices,) + values.shape[1:])


def vertex_colors(solution, space: str = "linear") -> np.ndarray:
    """(V, 3) float colours of the vertices (radiance L -> linear sRGB, or sRGB-encoded)."""
    if space not in COLOR_SPACES:
        raise ValueError(f"vertex_colors: space must be one of {COLOR_SPACES}, got {space!r}")
    rgb = solution.bins.to_srgb(vertex_values(solution.patches, solution.L))
    return linear_to_srgb(rgb) if space == "srgb" else rgb


def export_mesh(solution, path: str, space: str = "srgb", exposure: float = 0.0):
    """Write the subdivided meshes with their vertex colours; returns the trimesh mesh."""
    import trimesh
    rgb = vertex_colors(solution, "linear") * 2.0 ** exposure
    if space == "srgb":
        rgb = linear_to_srgb(np.clip(rgb, 0.0, None))
    elif space != "linear":
        raise ValueError(f"export_mesh: space must be one of {COLOR_SPACES}, got {space!r}")
    rgba = np.concatenate([np.clip(rgb, 0.0, 1.0), np.ones((len(rgb), 1))], axis=1)
    P = solution.patches
    mesh = trimesh.Trimesh(vertices=P.vertices, faces=P.faces, process=False,
                           vertex_colors=np.round(rgba * 255).astype(np.uint8))
    mesh.export(path)
    return mesh
