"""Uncompressed float textures in GPU containers: DDS (DX10 header) and KTX 2.0.

Both writers take ``(H, W, C)`` or ``(L, H, W, C)`` arrays (``L`` array layers) of ``float16`` or
``float32`` with ``C`` in {1, 2, 4}, row 0 first (the first row uploaded, ``v = 0`` in GL / D3D /
Vulkan texture coordinates). One array is one mip level; a list of arrays is a mip chain, level 0
first, level ``k`` of shape ``(max(H >> k, 1), max(W >> k, 1))`` (the full chain or a prefix of it).

* DDS: Microsoft, "DDS file layout" (``DDS_HEADER`` + ``DDS_HEADER_DXT10``), ``DXGI_FORMAT_R16*``
  / ``R32*_FLOAT``; Pillow reads these back (``PIL.DdsImagePlugin``).
* KTX 2.0: Khronos KTX 2.0 specification, sections 3 (file structure) and 3.10 (data format
  descriptor), with the basic descriptor block of the Khronos Data Format specification 1.3,
  section 5; optional Zstandard supercompression (scheme 2, ``zstandard`` package). The descriptor
  of a supercompressed file describes the inflated data (``bytesPlane0`` = texel size), following
  KTX-Specification issue 216.
"""

from __future__ import annotations

import os
import struct

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.fileio import atomic_path

__all__ = ["dds_bytes", "ktx2_bytes", "write_dds", "write_ktx2"]

# DXGI_FORMAT values (dxgiformat.h) by (bytes per channel, channels)
_DXGI = {(2, 1): 54, (2, 2): 34, (2, 4): 10, (4, 1): 41, (4, 2): 16, (4, 4): 2}
# VkFormat values (vulkan_core.h): R16_SFLOAT ... R32G32B32A32_SFLOAT
_VK = {(2, 1): 76, (2, 2): 83, (2, 4): 97, (4, 1): 100, (4, 2): 103, (4, 4): 109}

_DDSD_CAPS, _DDSD_HEIGHT, _DDSD_WIDTH, _DDSD_PITCH, _DDSD_PIXELFORMAT = 0x1, 0x2, 0x4, 0x8, 0x1000
_DDSD_MIPMAPCOUNT = 0x20000
_DDPF_FOURCC = 0x4
_DDSCAPS_COMPLEX, _DDSCAPS_TEXTURE, _DDSCAPS_MIPMAP = 0x8, 0x1000, 0x400000
_D3D10_RESOURCE_DIMENSION_TEXTURE2D = 3

KTX2_IDENTIFIER = bytes([0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A])
KTX2_SUPERCOMPRESSION = {None: 0, "zstd": 2}
# Khronos Data Format 1.3: RGBSDA colour model, BT.709 primaries, linear transfer; channel ids
_KHR_DF_MODEL_RGBSDA, _KHR_DF_PRIMARIES_BT709, _KHR_DF_TRANSFER_LINEAR = 1, 1, 1
_RGBA_CHANNEL_IDS = (0, 1, 2, 15)
_KHR_DF_SAMPLE_FLOAT, _KHR_DF_SAMPLE_SIGNED = 0x80, 0x40


def _as_layers(data, name: str) -> np.ndarray:
    """``data`` as ``(L, H, W, C)`` float16 / float32 (checked); a 3-D array is one layer."""
    a = np.asarray(data)
    if a.ndim == 3:
        a = a[None]
    if a.ndim != 4 or a.shape[-1] not in (1, 2, 4) or min(a.shape) < 1:
        raise PrefilterError(f"{name}: expected an (H, W, C) or (L, H, W, C) array with C in "
                             f"(1, 2, 4), got shape {np.shape(data)}")
    if a.dtype not in (np.float16, np.float32):
        raise PrefilterError(f"{name}: expected float16 or float32 texels, got {a.dtype}")
    if not np.all(np.isfinite(a)):
        raise PrefilterError(f"{name}: expected finite texels")
    return np.ascontiguousarray(a.astype(a.dtype.newbyteorder("<")))


def _as_chain(data, name: str) -> list[np.ndarray]:
    """``data`` (one array, or a list of mip levels) as a list of ``(L, H_k, W_k, C)`` arrays of
    one dtype, channel count and layer count, level ``k`` halving level 0 (checked)."""
    if isinstance(data, (list, tuple)):
        if not data:
            raise PrefilterError(f"{name}: expected at least one mip level, got an empty list")
        levels = [_as_layers(d, f"{name}[{k}]") for k, d in enumerate(data)]
        if len({np.ndim(d) for d in data}) != 1:
            raise PrefilterError(f"{name}: expected every mip level with the same number of "
                                 f"dimensions, got {[np.ndim(d) for d in data]}")
    else:
        levels = [_as_layers(data, name)]
    n_layers, h, w, c = levels[0].shape
    if len(levels) > max(h, w).bit_length():
        raise PrefilterError(f"{name}: expected at most {max(h, w).bit_length()} mip levels for "
                             f"{h} x {w}, got {len(levels)}")
    for k, a in enumerate(levels):
        want = (n_layers, max(h >> k, 1), max(w >> k, 1), c)
        if a.shape != want or a.dtype != levels[0].dtype:
            raise PrefilterError(f"{name}[{k}]: expected mip level of shape {want[1:]} "
                                 f"({n_layers} layer(s)) and dtype {levels[0].dtype}, got "
                                 f"{a.shape[1:]} ({a.shape[0]} layer(s)) {a.dtype}")
    return levels


def dds_bytes(data) -> bytes:
    """A DDS file (``'DDS '`` + ``DDS_HEADER`` + ``DDS_HEADER_DXT10`` + texels) for ``data``.

    ``data`` (H, W, C) or (L, H, W, C): a 2D texture or a 2D texture array of ``L`` layers; or a
    list of such arrays, a mip chain (level 0 first). Texels are stored layer by layer, each
    layer's levels from the largest to the smallest (DDS file layout).
    """
    levels = _as_chain(data, "data")
    n_layers, h, w, c = levels[0].shape
    size = levels[0].dtype.itemsize
    pitch = w * c * size
    n_mips = len(levels)
    flags = _DDSD_CAPS | _DDSD_HEIGHT | _DDSD_WIDTH | _DDSD_PITCH | _DDSD_PIXELFORMAT
    caps = _DDSCAPS_TEXTURE
    if n_mips > 1:
        flags |= _DDSD_MIPMAPCOUNT
        caps |= _DDSCAPS_COMPLEX | _DDSCAPS_MIPMAP
    pixel_format = struct.pack("<II4sIIIII", 32, _DDPF_FOURCC, b"DX10", 0, 0, 0, 0, 0)
    header = struct.pack(
        "<IIIIIII11I", 124, flags, h, w, pitch, 0, n_mips, *([0] * 11)) + pixel_format + \
        struct.pack("<IIIII", caps, 0, 0, 0, 0)
    dx10 = struct.pack("<IIIII", _DXGI[size, c], _D3D10_RESOURCE_DIMENSION_TEXTURE2D, 0,
                       n_layers, 0)
    texels = b"".join(a[layer].tobytes() for layer in range(n_layers) for a in levels)
    return b"DDS " + header + dx10 + texels


def _dfd(size: int, channels: int) -> bytes:
    """The data format descriptor (``dfdTotalSize`` + one basic block) of a float format."""
    block_size = 24 + 16 * channels
    words = [0,  # vendorId 0 (Khronos), descriptorType 0 (basic)
             2 | (block_size << 16),  # versionNumber 2 (KDF 1.3)
             _KHR_DF_MODEL_RGBSDA | (_KHR_DF_PRIMARIES_BT709 << 8)
             | (_KHR_DF_TRANSFER_LINEAR << 16),  # flags 0: straight alpha
             0,  # texelBlockDimension 0..3 = 0 (1 x 1 x 1 x 1)
             size * channels, 0]  # bytesPlane0 = bytes per texel, other planes 0
    body = struct.pack("<6I", *words)
    one, minus_one = struct.unpack("<I", struct.pack("<f", 1.0))[0], \
        struct.unpack("<I", struct.pack("<f", -1.0))[0]
    for k in range(channels):
        channel_id = _RGBA_CHANNEL_IDS[k] if channels == 4 else k
        qualifiers = _KHR_DF_SAMPLE_FLOAT | _KHR_DF_SAMPLE_SIGNED
        body += struct.pack("<HBBIII", 8 * size * k, 8 * size - 1, channel_id | qualifiers,
                            0, minus_one, one)
    return struct.pack("<I", 4 + len(body)) + body


def _kvd(pairs: dict[str, str]) -> bytes:
    out = b""
    for key in sorted(pairs):
        kv = key.encode() + b"\0" + pairs[key].encode() + b"\0"
        out += struct.pack("<I", len(kv)) + kv + b"\0" * (-len(kv) % 4)
    return out


def ktx2_bytes(data, *, supercompression: str | None = "zstd", zstd_level: int = 19,
               writer: str = "prefilter") -> bytes:
    """A KTX 2.0 file holding ``data`` (H, W, C) or (L, H, W, C) (a 2D array of ``L`` layers), or
    a list of such arrays, a mip chain (level 0 first).

    ``supercompression``: ``"zstd"`` (scheme 2, needs the ``zstandard`` package; each level
    compressed on its own) or ``None``. ``layerCount`` is 0 for a plain 2D texture (3-D arrays),
    ``L`` for arrays. The level index lists level 0 first; the level data are stored from the
    smallest level to the largest (KTX 2.0, section 3.9).
    """
    if supercompression not in KTX2_SUPERCOMPRESSION:
        raise PrefilterError(f"supercompression: expected one of "
                             f"{sorted(map(str, KTX2_SUPERCOMPRESSION))}, got {supercompression!r}")
    first = data[0] if isinstance(data, (list, tuple)) and data else data
    is_array = np.ndim(first) == 4
    levels = _as_chain(data, "data")
    n_layers, h, w, c = levels[0].shape
    size = levels[0].dtype.itemsize
    raws = [a.tobytes() for a in levels]
    stored = raws
    if supercompression == "zstd":
        try:
            import zstandard
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise PrefilterError("supercompression 'zstd': the zstandard package is not "
                                 "installed (pip install zstandard)") from exc
        compressor = zstandard.ZstdCompressor(level=zstd_level)
        stored = [compressor.compress(raw) for raw in raws]
    dfd = _dfd(size, c)
    kvd = _kvd({"KTXwriter": writer})
    header_size = 12 + 9 * 4 + 4 * 4 + 2 * 8  # identifier, header, index
    level_index_size = 3 * 8 * len(levels)
    dfd_offset = header_size + level_index_size
    kvd_offset = dfd_offset + len(dfd)
    end = kvd_offset + len(kvd)
    # level data alignment: lcm(texel size, 4) uncompressed, 1 when supercompressed (spec 3.9.7)
    align = 1 if supercompression else int(np.lcm(size * c, 4))
    offsets = [0] * len(levels)
    body = bytearray()
    for k in reversed(range(len(levels))):  # the smallest level first
        pad = -(end + len(body)) % align
        body += b"\0" * pad
        offsets[k] = end + len(body)
        body += stored[k]
    out = bytearray(KTX2_IDENTIFIER)
    out += struct.pack("<9I", _VK[size, c], size, w, h, 0, n_layers if is_array else 0, 1,
                       len(levels), KTX2_SUPERCOMPRESSION[supercompression])
    out += struct.pack("<4I2Q", dfd_offset, len(dfd), kvd_offset, len(kvd), 0, 0)
    for k in range(len(levels)):
        out += struct.pack("<3Q", offsets[k], len(stored[k]), len(raws[k]))
    out += dfd + kvd + body
    return bytes(out)


def write_dds(path: str | os.PathLike, data) -> None:
    """Write :func:`dds_bytes` of ``data`` to ``path`` atomically."""
    blob = dds_bytes(data)
    with atomic_path(path) as tmp:
        tmp.write_bytes(blob)


def write_ktx2(path: str | os.PathLike, data, **kwargs) -> None:
    """Write :func:`ktx2_bytes` of ``data`` to ``path`` atomically (keywords as there)."""
    blob = ktx2_bytes(data, **kwargs)
    with atomic_path(path) as tmp:
        tmp.write_bytes(blob)
