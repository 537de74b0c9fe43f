"""Plugins loaded on their own, as ``mitsuba.load_dict`` loads any plugin dict: an
integrator (``pbr.load_dict({'type': 'path', 'max_depth': 4})``, for ``pbr.render(scene,
integrator=...)``) or a sensor (for ``pbr.render(scene, sensor=...)``: rendering one
scene from many views). A sensor loaded alone sits in vacuum (a medium around the
camera needs the scene: put the sensor in the scene dict)."""

from __future__ import annotations

from ..cameras import SENSORS
from ..integrators import INTEGRATORS, SamplingIntegrator
from ..plugins.props import Props, SceneError


def load_object(d: dict):
    """The pbr object of a plugin dict ``d`` of an integrator or sensor type."""
    t = d.get("type") if isinstance(d, dict) else None
    if t in INTEGRATORS:
        return INTEGRATORS[t](Props(d, "integrator"))
    if t in SENSORS:
        sensor = SENSORS[t](Props(d, "sensor"))
        sensor.id = str(d.get("id", "sensor"))
        sensor.medium = 0
        return sensor
    raise SceneError(f"load_dict: expected a dict of type 'scene', an integrator ({INTEGRATORS.supported()}) "
                     f"or a sensor ({SENSORS.supported()}), got type {t!r}")


def as_integrator(x):
    """``render``'s ``integrator`` argument as a pbr integrator: one (``pbr.load_dict`` of
    an integrator dict) or the dict itself."""
    if isinstance(x, SamplingIntegrator):
        return x
    if isinstance(x, dict):
        obj = load_object(x)
        if not isinstance(obj, SamplingIntegrator):
            raise SceneError(f"render: integrator: expected an integrator dict, got type {x.get('type')!r}")
        return obj
    if type(x).__module__.startswith("mitsuba"):
        raise TypeError("render: integrator is a Mitsuba object; pbr renders with its own integrators: pass "
                        "the integrator's dict, or pbr.load_dict(that dict)")
    raise TypeError(f"render: integrator: expected a pbr integrator or an integrator dict, got {type(x).__name__}")
