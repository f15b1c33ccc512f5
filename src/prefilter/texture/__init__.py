"""Textures: seeded procedural data, image IO, normal-map encodings and mip chains.

``procedural`` generates the built-in data (Gaussian-statistics normal and height maps, brushed
metal, scratches, flakes, scalar noise with known variance per mip level); ``io`` reads and writes
PNG / EXR / ``.npy``; ``normalmap`` encodes tangent-space normals (OpenGL or DirectX green);
``mip`` builds periodic box-filtered pyramids (unnormalised averaged normals, moments) and looks
them up by footprint.
"""

from prefilter.texture.io import read_image, write_image
from prefilter.texture.mip import (
    MipChain,
    footprint_axes,
    lod_from_footprint,
    moment_chain,
    moments_to_stats,
)
from prefilter.texture.normalmap import decode_normals, encode_normals
from prefilter.texture.procedural import (
    HEIGHT_KINDS,
    NORMAL_KINDS,
    HeightMap,
    height_map,
    noise,
    noise_level_variance,
    noise_texture,
    normal_map,
    slopes_to_normals,
)

__all__ = [
    "MipChain",
    "decode_normals",
    "encode_normals",
    "footprint_axes",
    "lod_from_footprint",
    "moment_chain",
    "moments_to_stats",
    "read_image",
    "write_image",
    "HEIGHT_KINDS",
    "NORMAL_KINDS",
    "HeightMap",
    "height_map",
    "noise",
    "noise_level_variance",
    "noise_texture",
    "normal_map",
    "slopes_to_normals",
]
