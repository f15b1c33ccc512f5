"""Writing roughness levels: per-level EXR / PNG, the DDS and KTX2 mip chains read back field by
field (Microsoft DDS file layout; KTX 2.0 section 3), ORM packing."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.roughness.outputs import pack_orm, to_space, write_levels
from prefilter.texture.io import read_image


def _levels(h=8, w=4, channels=None):
    """A full chain of random levels (H >> k, W >> k[, C])."""
    rng = np.random.default_rng(1)
    tail = (channels,) if channels else ()
    return [rng.random((max(h >> k, 1), max(w >> k, 1)) + tail)
            for k in range(max(h, w).bit_length())]


def dds_levels(blob):
    """Mip levels of a one-layer DX10 DDS: (format id, [(H_k, W_k, C) arrays])."""
    height, width, _pitch, _depth, mips = struct.unpack_from("<5I", blob, 12)
    dxgi, = struct.unpack_from("<I", blob, 128)
    channels, dtype = {54: (1, "<f2"), 41: (1, "<f4"), 10: (4, "<f2"), 2: (4, "<f4")}[dxgi]
    out, offset = [], 148
    for k in range(mips):
        h, w = max(height >> k, 1), max(width >> k, 1)
        a = np.frombuffer(blob, dtype, h * w * channels, offset).reshape(h, w, channels)
        out.append(a)
        offset += a.nbytes
    assert offset == len(blob)
    return dxgi, out


def ktx2_levels(blob):
    """Mip levels of an uncompressed one-layer float KTX2: (vkFormat, [(H_k, W_k, C) arrays])."""
    vk, type_size, width, height, _d, _layers, _faces, count, scheme = struct.unpack_from(
        "<9I", blob, 12)
    assert scheme == 0
    channels = {76: 1, 100: 1, 97: 4, 109: 4}[vk]
    out = []
    for k in range(count):
        offset, length, _ = struct.unpack_from("<3Q", blob, 80 + 24 * k)
        h, w = max(height >> k, 1), max(width >> k, 1)
        out.append(np.frombuffer(blob, f"<f{type_size}", h * w * channels, offset)
                   .reshape(h, w, channels))
    return vk, out


def test_write_levels_all_formats(tmp_path):
    levels = _levels()
    files = write_levels(levels, tmp_path)
    assert {f.name for f in files} == ({f"roughness_L{k}.{e}" for k in range(4)
                                        for e in ("exr", "png")} | {"roughness.dds",
                                                                    "roughness.ktx2"})
    for k, a in enumerate(levels):
        assert np.allclose(read_image(tmp_path / f"roughness_L{k}.exr")[..., 0], a, atol=1e-3)
        assert np.allclose(read_image(tmp_path / f"roughness_L{k}.png")[..., 0], a,
                           atol=0.5 / 255 + 1e-9)
    dxgi, dds = dds_levels((tmp_path / "roughness.dds").read_bytes())
    vk, ktx = ktx2_levels((tmp_path / "roughness.ktx2").read_bytes())
    assert (dxgi, vk) == (54, 76)  # R16_FLOAT, VK_FORMAT_R16_SFLOAT
    for k, a in enumerate(levels):
        assert np.array_equal(dds[k][..., 0], a.astype(np.float16))
        assert np.array_equal(ktx[k][..., 0], a.astype(np.float16))


def test_write_levels_float32_and_selected_formats(tmp_path):
    levels = _levels(4, 4)
    files = write_levels(levels, tmp_path, formats=("dds",), float_bits=32)
    assert [f.name for f in files] == ["roughness.dds"]
    dxgi, dds = dds_levels(files[0].read_bytes())
    assert dxgi == 41 and all(np.array_equal(d[..., 0], a.astype(np.float32))
                              for d, a in zip(dds, levels))
    with pytest.raises(PrefilterError, match="float_bits"):
        write_levels(levels, tmp_path, float_bits=8)
    with pytest.raises(PrefilterError, match="formats"):
        write_levels(levels, tmp_path, formats=("tga",))


def test_pack_orm_defaults_and_source(tmp_path):
    levels = _levels()
    packed = pack_orm(levels)
    assert [p.shape for p in packed] == [(8, 4, 3), (4, 2, 3), (2, 1, 3), (1, 1, 3)]
    for p, a in zip(packed, levels):
        assert np.all(p[..., 0] == 1.0) and np.array_equal(p[..., 1], a)
        assert np.all(p[..., 2] == 0.0)
    orm = np.random.default_rng(2).random((8, 4, 3))
    packed = pack_orm(levels, orm)
    assert np.allclose(packed[3][0, 0], [orm[..., 0].mean(), levels[3][0, 0],
                                         orm[..., 2].mean()])
    write_levels(packed, tmp_path, stem="orm", formats=("ktx2", "dds"))
    _, ktx = ktx2_levels((tmp_path / "orm.ktx2").read_bytes())
    dxgi, dds = dds_levels((tmp_path / "orm.dds").read_bytes())
    assert dxgi == 10  # R16G16B16A16_FLOAT
    for k, p in enumerate(packed):
        want = np.concatenate([p, np.ones(p.shape[:2] + (1,))], -1).astype(np.float16)
        assert np.array_equal(ktx[k], want) and np.array_equal(dds[k], want)
    with pytest.raises(PrefilterError, match="ORM texture"):
        pack_orm(levels, orm[:4])


def test_to_space():
    a = [np.array([[0.04, 0.25]])]
    assert np.allclose(to_space(a, "perceptual")[0], [[0.2, 0.5]])
    assert np.array_equal(to_space(a, "alpha")[0], a[0])
    with pytest.raises(PrefilterError, match="space"):
        to_space(a, "linear")
