"""Writing a roughness mip chain: per-level EXR / PNG, one DDS and one KTX2 with the whole chain,
optionally packed into the green channel of an occlusion-roughness-metal (ORM) texture (glTF 2.0
``metallicRoughnessTexture`` channels G = roughness, B = metal; R = occlusion by convention)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.texture.containers import write_dds, write_ktx2
from prefilter.texture.io import write_image
from prefilter.texture.mip import MipChain

__all__ = ["FORMATS", "SPACES", "pack_orm", "to_space", "write_levels"]

FORMATS = ("exr", "png", "dds", "ktx2")
#: Output roughness: ``"perceptual"`` = sqrt(alpha) (glTF, Filament, Unreal), or GGX ``"alpha"``.
SPACES = ("perceptual", "alpha")


def to_space(levels, space: str) -> list[np.ndarray]:
    """GGX ``alpha`` levels as ``space``: perceptual ``sqrt(alpha)`` or ``alpha`` itself."""
    if space not in SPACES:
        raise PrefilterError(f"space: expected one of {', '.join(SPACES)}, got {space!r}")
    return [np.sqrt(a) if space == "perceptual" else np.asarray(a) for a in levels]


def pack_orm(levels, orm=None) -> list[np.ndarray]:
    """Levels ``(H_k, W_k)`` packed as ORM levels ``(H_k, W_k, 3)``: G = the level; R and B the
    box-filtered occlusion and metal of ``orm (H, W, >=3)`` (default occlusion 1, metal 0)."""
    h, w = np.shape(levels[0])
    if orm is None:
        rb = [np.stack([np.ones_like(a), np.zeros_like(a)], -1) for a in levels]
    else:
        orm = np.asarray(orm, dtype=np.float64)
        if orm.ndim != 3 or orm.shape[2] < 3 or orm.shape[:2] != (h, w):
            raise PrefilterError(f"ORM texture: expected an (H, W, 3 or 4) image of the normal "
                                 f"map's size {h} x {w}, got shape {orm.shape}")
        rb = MipChain(orm[..., [0, 2]]).levels[:len(levels)]
    return [np.stack([c[..., 0], a, c[..., 1]], -1) for a, c in zip(levels, rb)]


def write_levels(levels, out, *, stem: str = "roughness", formats=FORMATS, float_bits: int = 16,
                 png_bits: int = 8, supercompression: str | None = None) -> list[Path]:
    """Write levels ``(H_k, W_k)`` or ``(H_k, W_k, 3)`` (values in [0, 1]) into folder ``out``.

    ``<stem>_L<k>.exr`` / ``.png`` per level (linear values, not sRGB), ``<stem>.dds`` and
    ``<stem>.ktx2`` with the whole mip chain (``float_bits`` 16 or 32 per channel; three
    channels are stored as RGBA with A = 1, the formats having no three-channel float layout).
    Returns the paths written.
    """
    unknown = sorted(set(formats) - set(FORMATS))
    if unknown:
        raise PrefilterError(f"formats: expected some of {', '.join(FORMATS)}, got {unknown}")
    if float_bits not in (16, 32):
        raise PrefilterError(f"float_bits: expected 16 or 32, got {float_bits!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for k, a in enumerate(levels):
        for ext in ("exr", "png"):
            if ext in formats:
                written.append(write_image(out / f"{stem}_L{k}.{ext}", a, bits=png_bits,
                                           half=float_bits == 16))
    dtype = np.float16 if float_bits == 16 else np.float32
    texels = []
    for a in levels:
        a = np.asarray(a, dtype=np.float64)
        a = a[..., None] if a.ndim == 2 else np.concatenate([a, np.ones(a.shape[:2] + (1,))], -1)
        texels.append(a.astype(dtype))
    if "dds" in formats:
        write_dds(out / f"{stem}.dds", texels)
        written.append(out / f"{stem}.dds")
    if "ktx2" in formats:
        write_ktx2(out / f"{stem}.ktx2", texels, supercompression=supercompression)
        written.append(out / f"{stem}.ktx2")
    return written
