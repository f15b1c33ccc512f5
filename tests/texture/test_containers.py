"""DDS and KTX2 writers, read back by parsers written here from the specifications.

DDS: Microsoft "DDS file layout" (DDS_HEADER, DDS_PIXELFORMAT, DDS_HEADER_DXT10) and the DXGI_FORMAT
enumeration. KTX2: Khronos KTX 2.0 specification (file structure, section 3) and the Khronos Data
Format 1.3 basic descriptor block. Pillow (13.0) opens DDS files but not float DXGI formats
("Unimplemented DXGI format"), and the one Python KTX2 parser on PyPI (pyktx2 0.3.1) rejects the
RGBSDA colour model, so both are parsed here field by field.
"""

from __future__ import annotations

import io
import struct

import numpy as np
import pytest

from prefilter.errors import PrefilterError
from prefilter.texture.containers import dds_bytes, ktx2_bytes, write_dds, write_ktx2

DXGI = {"R32G32B32A32_FLOAT": 2, "R16G16B16A16_FLOAT": 10, "R32G32_FLOAT": 16,
        "R16G16_FLOAT": 34, "R32_FLOAT": 41, "R16_FLOAT": 54}
VK = {"R16G16B16A16_SFLOAT": 97, "R32G32B32A32_SFLOAT": 109, "R16G16_SFLOAT": 83}


def read_dds(blob: bytes):
    """(header fields, dx10 fields, texels (L, H, W, C)) of an uncompressed float DX10 DDS."""
    assert blob[:4] == b"DDS "
    size, flags, height, width, pitch, _depth, mips = struct.unpack_from("<7I", blob, 4)
    pf_size, pf_flags, fourcc = struct.unpack_from("<II4s", blob, 76)
    caps = struct.unpack_from("<4I", blob, 108)
    dxgi, dim, misc, array_size, misc2 = struct.unpack_from("<5I", blob, 128)
    assert size == 124 and pf_size == 32 and pf_flags & 0x4 and fourcc == b"DX10"
    assert flags & 0x1007 == 0x1007  # CAPS | HEIGHT | WIDTH | PIXELFORMAT are required
    assert caps[0] & 0x1000  # DDSCAPS_TEXTURE
    assert dim == 3 and misc == 0  # TEXTURE2D, not a cube map
    fmt = {v: k for k, v in DXGI.items()}[dxgi]
    channels = fmt.count("32") + fmt.count("16")
    dtype = "<f4" if "32" in fmt else "<f2"
    assert pitch == width * channels * np.dtype(dtype).itemsize
    data = np.frombuffer(blob, dtype, offset=148).reshape(array_size, height, width, channels)
    return {"height": height, "width": width, "mips": mips, "format": fmt}, data


def read_ktx2(blob: bytes):
    """Fields, DFD, key/values and level-0 bytes (inflated) of a one-level KTX2 file."""
    assert blob[:12] == bytes([0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A,
                               0x1A, 0x0A])
    names = ("vkFormat", "typeSize", "pixelWidth", "pixelHeight", "pixelDepth", "layerCount",
             "faceCount", "levelCount", "supercompressionScheme")
    h = dict(zip(names, struct.unpack_from("<9I", blob, 12)))
    dfd_off, dfd_len, kvd_off, kvd_len, sgd_off, sgd_len = struct.unpack_from("<4I2Q", blob, 48)
    assert h["levelCount"] == 1 and h["faceCount"] == 1 and sgd_len == 0
    offset, length, uncompressed = struct.unpack_from("<3Q", blob, 80)
    assert dfd_off == 104  # the DFD follows the one-entry level index
    total, = struct.unpack_from("<I", blob, dfd_off)
    assert total == dfd_len
    w = struct.unpack_from("<6I", blob, dfd_off + 4)
    block_size = w[1] >> 16
    dfd = {"vendor_type": w[0], "version": w[1] & 0xFFFF, "block_size": block_size,
           "model": w[2] & 0xFF, "primaries": (w[2] >> 8) & 0xFF,
           "transfer": (w[2] >> 16) & 0xFF, "flags": w[2] >> 24, "texel_block": w[3],
           "bytes_plane0": w[4] & 0xFF, "samples": []}
    assert 4 + block_size == dfd_len and (block_size - 24) % 16 == 0
    for k in range((block_size - 24) // 16):
        bit_offset, bit_length, channel, pos, lower, upper = struct.unpack_from(
            "<HBBIII", blob, dfd_off + 28 + 16 * k)
        dfd["samples"].append((bit_offset, bit_length + 1, channel & 0xF, channel >> 4, lower,
                               upper))
    kv, p = {}, kvd_off
    while p < kvd_off + kvd_len:
        n, = struct.unpack_from("<I", blob, p)
        key, value = blob[p + 4:p + 4 + n].split(b"\0", 1)
        kv[key.decode()] = value
        p += 4 + n + (-n % 4)
    assert offset >= kvd_off + kvd_len and offset + length == len(blob)
    level = blob[offset:offset + length]
    if h["supercompressionScheme"] == 2:
        zstandard = pytest.importorskip("zstandard")
        level = zstandard.ZstdDecompressor().decompress(level, max_output_size=uncompressed)
    else:
        assert h["supercompressionScheme"] == 0 and length == uncompressed
        assert offset % np.lcm(4, dfd["bytes_plane0"]) == 0
    assert len(level) == uncompressed
    return h, dfd, kv, level


@pytest.fixture
def texels():
    rng = np.random.default_rng(3)
    return rng.normal(size=(2, 5, 7, 4))


@pytest.mark.parametrize("dtype,fmt", [(np.float32, "R32G32B32A32_FLOAT"),
                                       (np.float16, "R16G16B16A16_FLOAT")])
def test_dds_round_trip(tmp_path, texels, dtype, fmt):
    a = texels[0].astype(dtype)
    write_dds(tmp_path / "t.dds", a)
    head, data = read_dds((tmp_path / "t.dds").read_bytes())
    assert head == {"height": 5, "width": 7, "mips": 1, "format": fmt}
    assert np.array_equal(data[0], a)


def test_dds_two_channels_and_arrays(texels):
    head, data = read_dds(dds_bytes(texels[..., :2].astype(np.float32)))
    assert head["format"] == "R32G32_FLOAT" and data.shape == (2, 5, 7, 2)
    assert np.array_equal(data, texels[..., :2].astype(np.float32))


def test_pillow_reads_float_dds_where_it_can(texels):
    # Pillow parses the header and (13.0) stops at float DXGI formats; should a later version
    # decode them, the texels must match.
    Image = pytest.importorskip("PIL.Image")
    a = texels[0].astype(np.float32)
    try:
        im = Image.open(io.BytesIO(dds_bytes(a)))
    except NotImplementedError as exc:
        assert "DXGI format 2" in str(exc)  # the header was read up to the format
        pytest.skip(f"Pillow does not decode float DDS: {exc}")
    assert im.size == (7, 5)
    assert np.allclose(np.asarray(im, dtype=np.float32), a)


@pytest.mark.parametrize("supercompression", [None, "zstd"])
def test_ktx2_layout(tmp_path, texels, supercompression):
    if supercompression:
        pytest.importorskip("zstandard")
    a = texels.astype(np.float16)
    write_ktx2(tmp_path / "t.ktx2", a, supercompression=supercompression)
    h, dfd, kv, level = read_ktx2((tmp_path / "t.ktx2").read_bytes())
    assert h == {"vkFormat": VK["R16G16B16A16_SFLOAT"], "typeSize": 2, "pixelWidth": 7,
                 "pixelHeight": 5, "pixelDepth": 0, "layerCount": 2, "faceCount": 1,
                 "levelCount": 1, "supercompressionScheme": 2 if supercompression else 0}
    # KDF 1.3 basic block: RGBSDA, BT.709, linear, 1x1 texels, 8 bytes, 4 signed float samples
    assert (dfd["vendor_type"], dfd["version"], dfd["block_size"]) == (0, 2, 24 + 4 * 16)
    assert (dfd["model"], dfd["primaries"], dfd["transfer"], dfd["flags"]) == (1, 1, 1, 0)
    assert dfd["texel_block"] == 0 and dfd["bytes_plane0"] == 8
    one, minus_one = (struct.unpack("<I", struct.pack("<f", x))[0] for x in (1.0, -1.0))
    assert dfd["samples"] == [(0, 16, 0, 0xC, minus_one, one), (16, 16, 1, 0xC, minus_one, one),
                              (32, 16, 2, 0xC, minus_one, one), (48, 16, 15, 0xC, minus_one, one)]
    assert kv["KTXwriter"].rstrip(b"\0") == b"prefilter"
    assert np.array_equal(np.frombuffer(level, "<f2").reshape(a.shape), a)


def test_ktx2_plain_2d_texture_has_no_layers(texels):
    h, dfd, _, level = read_ktx2(ktx2_bytes(texels[0].astype(np.float32), supercompression=None))
    assert h["layerCount"] == 0 and h["vkFormat"] == VK["R32G32B32A32_SFLOAT"]
    assert dfd["bytes_plane0"] == 16 and [s[1] for s in dfd["samples"]] == [32] * 4


@pytest.mark.parametrize("bad,match", [
    (np.zeros((4, 4, 3), np.float32), "C in"),
    (np.zeros((4, 4, 4), np.float64), "float16 or float32"),
    (np.full((2, 2, 1), np.inf, np.float32), "finite"),
])
def test_bad_input(bad, match):
    with pytest.raises(PrefilterError, match=match):
        dds_bytes(bad)
    with pytest.raises(PrefilterError, match=match):
        ktx2_bytes(bad, supercompression=None)


def test_unknown_supercompression():
    with pytest.raises(PrefilterError, match="supercompression"):
        ktx2_bytes(np.zeros((2, 2, 4), np.float16), supercompression="lz4")


def _chain(dtype, channels=1, layers=None, h=8, w=4):
    """A full mip chain of random texels, level k of shape ([layers,] H >> k, W >> k, C)."""
    rng = np.random.default_rng(5)
    lead = (layers,) if layers else ()
    return [rng.normal(size=lead + (max(h >> k, 1), max(w >> k, 1), channels)).astype(dtype)
            for k in range(max(h, w).bit_length())]


def read_dds_mips(blob: bytes):
    """(mipMapCount, flags, caps, levels of layer 0) of a DX10 DDS, parsed per the file layout."""
    _size, flags, height, width, _pitch, _depth, mips = struct.unpack_from("<7I", blob, 4)
    caps = struct.unpack_from("<I", blob, 108)[0]
    dxgi, _dim, _misc, array_size, _ = struct.unpack_from("<5I", blob, 128)
    fmt = {v: k for k, v in DXGI.items()}[dxgi]
    channels = fmt.count("32") + fmt.count("16")
    dtype = np.dtype("<f4" if "32" in fmt else "<f2")
    offset, layers = 148, []
    for _ in range(array_size):
        levels = []
        for k in range(mips):
            h, w = max(height >> k, 1), max(width >> k, 1)
            n = h * w * channels
            levels.append(np.frombuffer(blob, dtype, n, offset).reshape(h, w, channels))
            offset += n * dtype.itemsize
        layers.append(levels)
    assert offset == len(blob)
    return mips, flags, caps, layers


@pytest.mark.parametrize("dtype", [np.float16, np.float32])
def test_dds_mip_chain_layout(dtype):
    chain = _chain(dtype)
    mips, flags, caps, layers = read_dds_mips(dds_bytes(chain))
    assert mips == 4 and flags & 0x20000  # DDSD_MIPMAPCOUNT
    assert caps & 0x400008 == 0x400008  # DDSCAPS_MIPMAP | DDSCAPS_COMPLEX
    assert [lv.shape for lv in layers[0]] == [(8, 4, 1), (4, 2, 1), (2, 1, 1), (1, 1, 1)]
    assert all(np.array_equal(a, b) for a, b in zip(layers[0], chain))


def test_dds_mip_chain_of_arrays_is_layer_major():
    chain = _chain(np.float32, channels=2, layers=3)
    mips, _, _, layers = read_dds_mips(dds_bytes(chain))
    assert mips == 4 and len(layers) == 3
    for i in range(3):
        assert all(np.array_equal(layers[i][k], chain[k][i]) for k in range(4))


def test_dds_one_level_has_no_mip_flags():
    mips, flags, caps, _ = read_dds_mips(dds_bytes(_chain(np.float16)[:1]))
    assert mips == 1 and not flags & 0x20000 and not caps & 0x400008


def read_ktx2_mips(blob: bytes):
    """(header, level index, inflated levels) of a KTX2 file with any number of levels."""
    names = ("vkFormat", "typeSize", "pixelWidth", "pixelHeight", "pixelDepth", "layerCount",
             "faceCount", "levelCount", "supercompressionScheme")
    h = dict(zip(names, struct.unpack_from("<9I", blob, 12)))
    dfd_off = struct.unpack_from("<I", blob, 48)[0]
    index = [struct.unpack_from("<3Q", blob, 80 + 24 * k) for k in range(h["levelCount"])]
    assert dfd_off == 80 + 24 * h["levelCount"]  # the DFD follows the level index
    levels = []
    for offset, length, uncompressed in index:
        level = blob[offset:offset + length]
        if h["supercompressionScheme"] == 2:
            zstandard = pytest.importorskip("zstandard")
            level = zstandard.ZstdDecompressor().decompress(level, max_output_size=uncompressed)
        else:
            assert offset % 4 == 0 and length == uncompressed
        assert len(level) == uncompressed
        levels.append(level)
    return h, index, levels


@pytest.mark.parametrize("supercompression", [None, "zstd"])
def test_ktx2_mip_chain_layout(supercompression):
    if supercompression:
        pytest.importorskip("zstandard")
    chain = _chain(np.float16)
    blob = ktx2_bytes(chain, supercompression=supercompression)
    h, index, levels = read_ktx2_mips(blob)
    assert (h["levelCount"], h["pixelWidth"], h["pixelHeight"], h["layerCount"]) == (4, 4, 8, 0)
    # level data from the smallest level to the largest, the largest ending the file
    offsets = [o for o, _, _ in index]
    assert offsets == sorted(offsets, reverse=True)
    assert index[0][0] + index[0][1] == len(blob)
    for k, level in enumerate(levels):
        assert np.array_equal(np.frombuffer(level, "<f2").reshape(chain[k].shape), chain[k])


def test_ktx2_mip_chain_alignment_uncompressed():
    # R16 texels (2 bytes): uncompressed levels start at multiples of lcm(2, 4) = 4
    blob = ktx2_bytes(_chain(np.float16, h=4, w=2), supercompression=None)
    _, index, _ = read_ktx2_mips(blob)
    assert all(o % 4 == 0 for o, _, _ in index)


@pytest.mark.parametrize("bad,match", [
    ([], "at least one mip level"),
    ([np.zeros((4, 4, 1), np.float16), np.zeros((3, 2, 1), np.float16)], r"data\[1\]"),
    ([np.zeros((4, 4, 1), np.float16), np.zeros((2, 2, 1), np.float32)], "dtype"),
    ([np.zeros((2, 2, 1), np.float16)] + [np.zeros((1, 1, 1), np.float16)] * 2, "at most 2"),
])
def test_bad_mip_chains(bad, match):
    with pytest.raises(PrefilterError, match=match):
        dds_bytes(bad)
    with pytest.raises(PrefilterError, match=match):
        ktx2_bytes(bad, supercompression=None)
