"""``hdrfilm``: the image the camera develops, in linear sRGB.

Each camera sample contributes  w * XYZ(L)  and  w  to its pixel (w: the filter weight of
filter importance sampling); the developed pixel is the ratio, converted to sRGB. Samples
whose filter offset lands outside the image get w = 0, so border pixels average over the
image only, as Mitsuba's film does."""

from __future__ import annotations

from .filters import FILTERS, GaussianFilter
from .plugins.props import Props, did_you_mean
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
    crop_offset_x     int     0          left column of the crop window
    crop_offset_y     int     0          top row of the crop window
    crop_width        int     width      crop window width: the rendered image's width
    crop_height       int     height     crop window height: the rendered image's height
    pixel_format      string  'rgb'      only 'rgb'
    component_format  string  'float32'  accepted: 'float16', 'float32' (images are float32)
    file_format       string  'openexr'  accepted: 'openexr', 'exr'
    sample_border     bool    false      only false
    ================  ======  =========  ===================================================

    With a crop window, the camera keeps the full film's view (aspect ratio and field of
    view) and the image holds the window's pixels only, as in Mitsuba: ``size`` is the
    window's (crop_width, crop_height), ``full_size`` the film's (width, height).
    """

    def __init__(self, props: Props):
        self.width = props.int("width", 768, min=1)
        self.height = props.int("height", 576, min=1)
        self.pixel_format = props.string("pixel_format", "rgb", choices=("rgb",))
        props.string("component_format", "float32", choices=("float16", "float32"))
        props.string("file_format", "openexr", choices=("openexr", "exr"))
        self.crop_offset = (props.int("crop_offset_x", 0, min=0), props.int("crop_offset_y", 0, min=0))
        self.crop_size = (props.int("crop_width", self.width, min=1), props.int("crop_height", self.height, min=1))
        for k, o, c, n in (("crop_width", self.crop_offset[0], self.crop_size[0], self.width),
                           ("crop_height", self.crop_offset[1], self.crop_size[1], self.height)):
            if o + c > n:
                raise props.error(k, f"the crop window (offset {o} + size {c}) exceeds the film's {n} pixels")
        if props.bool("sample_border", False):
            raise props.error("sample_border", "sample_border=true is not supported")
        self.rfilter = GaussianFilter(Props({"type": "gaussian"}, props.key("rfilter")))
        for key, child in props.children():
            if child["type"] in FILTERS:
                self.rfilter = FILTERS[child["type"]](props.child(key))
            else:
                raise props.error(key, f"unsupported reconstruction filter {child['type']!r}"
                                       f"{did_you_mean(child['type'], FILTERS)} (supported: {', '.join(FILTERS)})")
        props.finish()

    @property
    def size(self):
        """(width, height) of the rendered image: the crop window's."""
        return self.crop_size

    @property
    def full_size(self):
        """(width, height) of the whole film (which sets the camera's view)."""
        return self.width, self.height
