"""Textures: seeded procedural data, image IO, normal-map encodings and mip chains.

``procedural`` generates the built-in data (Gaussian-statistics normal and height maps, brushed
metal, scratches, flakes, scalar noise with known variance per mip level); ``io`` reads and writes
PNG / EXR / ``.npy``; ``normalmap`` encodes tangent-space normals (OpenGL or DirectX green);
``mip`` builds periodic box-filtered pyramids (unnormalised averaged normals, moments) and looks
them up by footprint.
"""

from prefilter.texture.procedural import (
    HEIGHT_KINDS,
    NORMAL_KINDS,
    HeightMap,
    height_map,
    noise,
    noise_level_variance,
    normal_map,
    slopes_to_normals,
)

__all__ = [
    "HEIGHT_KINDS",
    "NORMAL_KINDS",
    "HeightMap",
    "height_map",
    "noise",
    "noise_level_variance",
    "normal_map",
    "slopes_to_normals",
]
