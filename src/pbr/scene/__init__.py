"""Scene loading (Mitsuba dicts and XML), assembly and parameter traversal."""

from ..plugins.props import SceneError  # noqa: F401
from .loader import load_dict, load_file, load_string  # noqa: F401
from .params import traverse, SceneParameters  # noqa: F401
