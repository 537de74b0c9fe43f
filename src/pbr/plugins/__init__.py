"""Plugin plumbing, the bottom layer every plugin family builds on: typed access to a
plugin's parameters with key paths (:mod:`.props`), differentiable parameters owned by
scene objects (:mod:`.params`), the per-family registries of type names
(:mod:`.registry`) and the walk over every Dr.Jit table a scene holds (:mod:`.tables`).
Nothing here imports a plugin family. See docs/architecture.md."""

from .props import Props, SceneError  # noqa: F401
from .params import ParamOwner, param_table  # noqa: F401
from .registry import Registry  # noqa: F401
