"""Image IO round trips (PNG 8/16 bit, EXR, npy), normal-map conventions, clear errors."""

import numpy as np
import pytest
from PIL import Image

from prefilter.errors import PrefilterError
from prefilter.texture import decode_normals, encode_normals, normal_map, read_image, write_image


@pytest.fixture
def img():
    return np.random.default_rng(0).uniform(0, 1, (13, 17, 3))


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("bits", [8, 16])
def test_png_round_trip_within_quantisation(tmp_path, channels, bits):
    a = np.random.default_rng(channels).uniform(0, 1, (9, 11, channels))
    p = write_image(tmp_path / "a.png", a, bits=bits)
    b = read_image(p)
    assert b.shape == a.shape and b.dtype == np.float64
    step = 1 / (2**bits - 1)
    assert np.abs(a - b).max() <= 0.5 * step + 1e-12


def test_png16_is_really_16_bit(tmp_path, img):
    # a ramp needing more than 8 bits survives; Pillow sees a 16-bit (or 16-bit gray) file
    a = np.linspace(0, 1, 1000).reshape(10, 100, 1) * np.ones(3)
    p = write_image(tmp_path / "r.png", a, bits=16)
    assert len(np.unique(read_image(p))) > 900
    with open(p, "rb") as fh:
        assert fh.read(26)[24] == 16  # IHDR bit depth


def test_png16_reader_all_filters(tmp_path):
    # Pillow writes 16-bit gray with adaptive filters; our colour reader handles the same filters:
    # build an RGB 16-bit file by writing it with Pillow's I;16 for each channel is impossible, so
    # encode rows with every filter type by hand and compare against the original values.
    import struct
    import zlib

    rng = np.random.default_rng(1)
    h, w, c = 6, 5, 3
    q = rng.integers(0, 65536, (h, w, c)).astype(">u2")
    rows = q.reshape(h, w * c).view(np.uint8).astype(np.int32)
    bpp = 2 * c
    raw = []
    for y in range(h):
        ft = y % 5
        cur = rows[y]
        prev = rows[y - 1] if y else np.zeros_like(cur)
        a = np.concatenate([np.zeros(bpp, int), cur[:-bpp]])
        cc = np.concatenate([np.zeros(bpp, int), prev[:-bpp]])
        if ft == 0:
            f = cur
        elif ft == 1:
            f = cur - a
        elif ft == 2:
            f = cur - prev
        elif ft == 3:
            f = cur - (a + prev) // 2
        else:
            p = a + prev - cc
            pa, pb, pc = np.abs(p - a), np.abs(p - prev), np.abs(p - cc)
            f = cur - np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, prev, cc))
        raw.append(bytes([ft]) + (f & 255).astype(np.uint8).tobytes())

    def chunk(k, b):
        return struct.pack(">I", len(b)) + k + b + struct.pack(">I", zlib.crc32(k + b))

    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"".join(raw))) + chunk(b"IEND", b""))
    (tmp_path / "f.png").write_bytes(data)
    assert np.array_equal(read_image(tmp_path / "f.png") * 65535, q.astype(float))


def test_png_srgb(tmp_path):
    a = np.array([[[0.0, 0.5, 1.0]]])
    write_image(tmp_path / "s.png", a, srgb=True, bits=16)
    raw = read_image(tmp_path / "s.png")
    assert raw[0, 0, 1] == pytest.approx(0.7353569, abs=1e-4)  # sRGB encoding of 0.5
    assert np.allclose(read_image(tmp_path / "s.png", srgb=True), a, atol=1e-4)


def test_png_read_by_pillow_8bit(tmp_path):
    a = (np.arange(60).reshape(4, 5, 3) * 4).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "p.png")
    assert np.array_equal(read_image(tmp_path / "p.png") * 255, a.astype(float))


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_exr_round_trip(tmp_path, channels):
    a = np.random.default_rng(2).normal(0, 10, (7, 9, channels))
    b = read_image(write_image(tmp_path / "a.exr", a))
    assert b.shape == a.shape
    assert np.allclose(a, b, rtol=2**-23, atol=0)  # float32 storage
    h = read_image(write_image(tmp_path / "h.exr", a, half=True))
    assert np.allclose(a, h, rtol=2**-10, atol=1e-4)


def test_npy_round_trip_exact(tmp_path, img):
    assert np.array_equal(read_image(write_image(tmp_path / "a.npy", img)), img)


def test_write_is_atomic_and_leaves_no_temp(tmp_path, img):
    write_image(tmp_path / "x.png", img)
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"]


@pytest.mark.parametrize("name, content, words", [
    ("bad.png", b"not a png at all", ["bad.png", "PNG"]),
    ("bad.exr", b"\x76\x2f\x31\x01garbage", ["bad.exr", "EXR"]),
    ("bad.npy", b"\x93NUMPY garbage", ["bad.npy", ".npy"]),
    ("bad.tif", b"", ["bad.tif", "unsupported"]),
])
def test_corrupt_files_raise_clear_errors(tmp_path, name, content, words):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(PrefilterError) as e:
        read_image(tmp_path / name)
    for w in words:
        assert w in str(e.value)


def test_truncated_png16(tmp_path, img):
    p = write_image(tmp_path / "t.png", img, bits=16)
    (tmp_path / "u.png").write_bytes(p.read_bytes()[:60])
    with pytest.raises(PrefilterError, match="u.png"):
        read_image(tmp_path / "u.png")


def test_missing_and_bad_shapes(tmp_path):
    with pytest.raises(PrefilterError, match="not found"):
        read_image(tmp_path / "none.png")
    np.save(tmp_path / "s.npy", np.zeros((4, 4, 7)))
    with pytest.raises(PrefilterError, match=r"\(4, 4, 7\)"):
        read_image(tmp_path / "s.npy")
    with pytest.raises(PrefilterError, match="bits"):
        write_image(tmp_path / "a.png", np.zeros((2, 2)), bits=12)
    with pytest.raises(PrefilterError, match="shape"):
        write_image(tmp_path / "a.exr", np.zeros((2, 2, 5)))


def test_normal_map_conventions_round_trip(tmp_path):
    n = normal_map("gaussian", 32, 0, rms_slope=0.5, corr_length=3.0)
    for conv in ("opengl", "directx"):
        c = encode_normals(n, conv)
        back = decode_normals(read_image(write_image(tmp_path / f"{conv}.png", c, bits=16)), conv)
        assert np.abs(back - n).max() < 1e-4
    # the two conventions differ exactly by the green channel
    assert np.allclose(encode_normals(n, "opengl")[..., 1],
                       1 - encode_normals(n, "directx")[..., 1])


def test_opengl_green_points_up_the_image():
    # a facet tilted toward the top of the image (towards row 0, i.e. -v) has n_y < 0 in the
    # tangent frame (y = +v = down the rows) and a green value above 0.5 in an OpenGL map
    n = np.array([0.0, -0.6, 0.8])
    assert encode_normals(n, "opengl")[1] > 0.5
    assert encode_normals(n, "directx")[1] < 0.5
    with pytest.raises(PrefilterError, match="z >= 0"):
        decode_normals([0.5, 0.5, 0.2])
    with pytest.raises(PrefilterError, match="convention"):
        decode_normals([0.5, 0.5, 1.0], "vulkan")


def test_exr_checksum_attribute_of_another_type(tmp_path, capfd):
    """A flipped bit in the checksum attribute's type name ("string") makes OpenEXR return an
    opaque value: a PrefilterError naming the file, and nothing printed."""
    from prefilter.texture.io import EXR_CHECKSUM

    p = tmp_path / "a.exr"
    write_image(p, np.ones((2, 2, 3)))
    data = bytearray(p.read_bytes())
    data[data.index(EXR_CHECKSUM.encode()) + len(EXR_CHECKSUM) + 1] ^= 0x80
    p.write_bytes(bytes(data))
    capfd.readouterr()
    with pytest.raises(PrefilterError, match=rf"a\.exr: {EXR_CHECKSUM}: expected a string"):
        read_image(p)
    assert capfd.readouterr() == ("", "")


@pytest.mark.parametrize("at", [0, 9, len("prefilter_sha256") - 1])
def test_exr_checksum_attribute_name_with_a_flipped_bit(tmp_path, at):
    """A flipped bit in the checksum attribute's name must not turn the check off."""
    from prefilter.texture.io import EXR_CHECKSUM

    p = tmp_path / "a.exr"
    write_image(p, np.ones((2, 2, 3)))
    data = bytearray(p.read_bytes())
    data[data.index(EXR_CHECKSUM.encode()) + at] ^= 0x01
    p.write_bytes(bytes(data))
    with pytest.raises(PrefilterError, match=rf"a\.exr: {EXR_CHECKSUM}: missing checksum"):
        read_image(p)


def test_exr_without_checksum_is_refused_where_required(tmp_path):
    import OpenEXR

    from prefilter.texture.io import read_exr_channels

    p = tmp_path / "plain.exr"
    pixels = np.ones((2, 2), np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"Y": pixels}) as f:
        f.write(str(p))
    assert read_exr_channels(p)["Y"].shape == (2, 2)  # images from elsewhere carry none
    with pytest.raises(PrefilterError, match="missing checksum"):
        read_exr_channels(p, require_checksum=True)
