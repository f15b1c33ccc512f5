"""Uncompressed float textures in GPU containers: DDS (DX10 header) and KTX 2.0.

Both writers take ``(H, W, C)`` or ``(L, H, W, C)`` arrays (``L`` array layers) of ``float16`` or
``float32`` with ``C`` in {1, 2, 4} and store one mip level, row 0 first (the first row uploaded,
``v = 0`` in GL / D3D / Vulkan texture coordinates).

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
_DDPF_FOURCC = 0x4
_DDSCAPS_TEXTURE = 0x1000
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


def dds_bytes(data) -> bytes:
    """A DDS file (``'DDS '`` + ``DDS_HEADER`` + ``DDS_HEADER_DXT10`` + texels) for ``data``.

    ``data`` (H, W, C) or (L, H, W, C): a 2D texture or a 2D texture array of ``L`` layers.
    """
    a = _as_layers(data, "data")
    n_layers, h, w, c = a.shape
    size = a.dtype.itemsize
    pitch = w * c * size
    pixel_format = struct.pack("<II4sIIIII", 32, _DDPF_FOURCC, b"DX10", 0, 0, 0, 0, 0)
    header = struct.pack(
        "<IIIIIII11I", 124,
        _DDSD_CAPS | _DDSD_HEIGHT | _DDSD_WIDTH | _DDSD_PITCH | _DDSD_PIXELFORMAT,
        h, w, pitch, 0, 1, *([0] * 11)) + pixel_format + struct.pack(
        "<IIIII", _DDSCAPS_TEXTURE, 0, 0, 0, 0)
    dx10 = struct.pack("<IIIII", _DXGI[size, c], _D3D10_RESOURCE_DIMENSION_TEXTURE2D, 0,
                       n_layers, 0)
    return b"DDS " + header + dx10 + a.tobytes()


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
    """A KTX 2.0 file holding ``data`` (H, W, C) or (L, H, W, C) (a 2D array of ``L`` layers).

    ``supercompression``: ``"zstd"`` (scheme 2, needs the ``zstandard`` package) or ``None``.
    One mip level; ``layerCount`` is 0 for a plain 2D texture (3-D ``data``), ``L`` for arrays.
    """
    if supercompression not in KTX2_SUPERCOMPRESSION:
        raise PrefilterError(f"supercompression: expected one of "
                             f"{sorted(map(str, KTX2_SUPERCOMPRESSION))}, got {supercompression!r}")
    is_array = np.ndim(data) == 4
    a = _as_layers(data, "data")
    n_layers, h, w, c = a.shape
    size = a.dtype.itemsize
    raw = a.tobytes()
    level = raw
    if supercompression == "zstd":
        try:
            import zstandard
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise PrefilterError("supercompression 'zstd': the zstandard package is not "
                                 "installed (pip install zstandard)") from exc
        level = zstandard.ZstdCompressor(level=zstd_level).compress(raw)
    dfd = _dfd(size, c)
    kvd = _kvd({"KTXwriter": writer})
    header_size = 12 + 9 * 4 + 4 * 4 + 2 * 8  # identifier, header, index
    level_index_size = 3 * 8
    dfd_offset = header_size + level_index_size
    kvd_offset = dfd_offset + len(dfd)
    end = kvd_offset + len(kvd)
    # level data alignment: lcm(texel size, 4) uncompressed, 1 when supercompressed (spec 3.9.7)
    align = 1 if supercompression else int(np.lcm(size * c, 4))
    data_offset = end + (-end % align)
    out = bytearray(KTX2_IDENTIFIER)
    out += struct.pack("<9I", _VK[size, c], size, w, h, 0, n_layers if is_array else 0, 1, 1,
                       KTX2_SUPERCOMPRESSION[supercompression])
    out += struct.pack("<4I2Q", dfd_offset, len(dfd), kvd_offset, len(kvd), 0, 0)
    out += struct.pack("<3Q", data_offset, len(level), len(raw))
    out += dfd + kvd + b"\0" * (data_offset - end) + level
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
