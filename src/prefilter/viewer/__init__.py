"""The WebGL2 viewer: the project's methods in a real GPU pipeline, checked against Python.

:func:`export_scene` writes a static folder (page, exported GLSL snippets, tables in float32 and
float16, normal-map mip chains; formats in ``docs/viewer.md``); :func:`serve` serves it on
127.0.0.1; :func:`pixel_match` renders scenes in headless Chromium and compares the float
framebuffer with :func:`prefilter.render.render`; :func:`screenshots` writes a PNG per mode and
:func:`frame_time` measures the frame time. Commands: ``prefilter view`` and ``prefilter export``
(:mod:`prefilter.viewer.commands`).
"""

from prefilter.viewer.export import BUILTIN_MAPS, METHODS, default_scene, export_scene, viewer_scene
from prefilter.viewer.server import serve

_MATCH = ("SCENES", "frame_time", "pixel_match", "screenshots")


def __getattr__(name):
    # imported on use, so that ``python -m prefilter.viewer.match`` runs the module only once
    if name in _MATCH:
        from prefilter.viewer import match

        return getattr(match, name)
    raise AttributeError(f"module 'prefilter.viewer' has no attribute {name!r}")

__all__ = ["BUILTIN_MAPS", "METHODS", "SCENES", "default_scene", "export_scene", "frame_time",
           "pixel_match", "screenshots", "serve", "viewer_scene"]
