"""Rendering: scenes as data, the pinhole camera and G-buffer, lights, shading methods, metrics.

``load_scene`` reads a JSON scene (``docs/scenes.md``); ``gbuffer`` traces primary rays and returns
per-pixel (or per-sub-sample) positions, frames, UVs and UV footprints; methods shade them;
``render(scene, method)`` is the scene -> image entry point (:mod:`prefilter.render.driver`).
"""

from prefilter.render.camera import (
    Camera,
    GBuffer,
    Rays,
    gbuffer,
    gbuffer_at,
    generate_rays,
    intersect,
    pixel_positions,
    rays_at,
)
from prefilter.render.driver import render
from prefilter.render.scene import Material, Plane, Scene, Sphere, TextureRef, load_scene

__all__ = [
    "Camera",
    "GBuffer",
    "Material",
    "Plane",
    "Rays",
    "Scene",
    "Sphere",
    "TextureRef",
    "gbuffer",
    "gbuffer_at",
    "generate_rays",
    "intersect",
    "load_scene",
    "pixel_positions",
    "rays_at",
    "render",
]
