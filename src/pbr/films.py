"""``hdrfilm``: the image the camera develops, in linear sRGB.

Each camera sample contributes  w * XYZ(L)  and  w  to its pixel (w: the filter weight of
filter importance sampling); the developed pixel is the ratio, converted to sRGB. Samples
whose filter offset lands outside the image get w = 0, so border pixels average over the
image only, as Mitsuba's film does."""

from __future__ import annotations

from .filters import FILTERS, GaussianFilter
from .plugins.props import Props
from .plugins.registry import Registry

FILMS = Registry("film")


@FILMS.register("hdrfilm")
class HDRFilm:
    """``hdrfilm``: the image the camera develops (linear sRGB, float). Nested: a
    reconstruction filter (default ``gaussian``).

    ================  ======  =========  ===================================================
    name              type    default    meaning
    ================  ======  =========  ===================================================
    width             int     768        image width (pixels)
    height            int     576        image height (pixels)
    pixel_format      string  'rgb'      only 'rgb'
    component_format  string  'float32'  accepted: 'float16', 'float32' (images are float32)
    file_format       string  'openexr'  accepted: 'openexr', 'exr'
    crop_*            int     -          cropping is not supported (only the full image)
    sample_border     bool    false      only false
    ================  ======  =========  ===================================================
    """

    def __init__(self, props: Props):
        self.width = props.int("width", 768, min=1)
        self.height = props.int("height", 576, min=1)
        self.pixel_format = props.string("pixel_format", "rgb", choices=("rgb",))
        props.string("component_format", "float32", choices=("float16", "float32"))
        props.string("file_format", "openexr", choices=("openexr", "exr"))
        for k in ("crop_offset_x", "crop_offset_y"):
            if props.int(k, 0) != 0:
                raise props.error(k, "film cropping is not supported yet")
        for k, d in (("crop_width", self.width), ("crop_height", self.height)):
            if props.int(k, d) != d:
                raise props.error(k, "film cropping is not supported yet")
        if props.bool("sample_border", False):
            raise props.error("sample_border", "sample_border=true is not supported")
        self.rfilter = GaussianFilter(Props({"type": "gaussian"}, props.key("rfilter")))
        for key, child in props.children():
            if child["type"] in FILTERS:
                self.rfilter = FILTERS[child["type"]](props.child(key))
            else:
                raise props.error(key, f"unsupported reconstruction filter {child['type']!r} "
                                       f"(supported: {', '.join(FILTERS)})")
        props.finish()

    @property
    def size(self):
        return self.width, self.height
