"""Image IO: PNG (8/16-bit), OpenEXR and ``.npy``, as float64 ``(H, W, C)`` arrays.

Every reader returns ``(H, W, C)`` float64 with ``C`` in 1..4 (row 0 = top of the image). PNG
values are mapped to [0, 1] (``v / 255`` or ``v / 65535``); they are taken as linear data unless
``srgb=True`` (colour images authored in sRGB). EXR and ``.npy`` are returned as stored.

Pillow reads 16-bit *colour* PNGs as 8-bit, so those are read and written by the small codec here
(zlib + the five PNG row filters, RFC 2083); everything else goes through Pillow.

Corrupt files raise :class:`~prefilter.errors.PrefilterError` naming the file: every PNG chunk's
CRC is checked before decoding, and EXRs written here carry the SHA-256 of their channels in the
header attribute ``prefilter_sha256``, verified at reading (EXR has no checksum of its own).
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
import sys
import tempfile
import zlib
from pathlib import Path

import numpy as np

from prefilter.fileio import array_digest, atomic_path
from prefilter.jit import njit_serial
from prefilter.errors import PrefilterError

__all__ = ["read_image", "write_image", "srgb_to_linear", "linear_to_srgb", "IMAGE_SUFFIXES"]

IMAGE_SUFFIXES = (".png", ".exr", ".npy")
_PNG_SIG = b"\x89PNG\r\n\x1a\n"


def srgb_to_linear(c) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding of values in [0, 1]."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear values in [0, 1]."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def _suffix(path: Path) -> str:
    s = path.suffix.lower()
    if s not in IMAGE_SUFFIXES:
        raise PrefilterError(
            f"{path}: unsupported image type {s or '(none)'!r}; expected one of "
            f"{', '.join(IMAGE_SUFFIXES)}"
        )
    return s


def _as_hwc(a: np.ndarray, where: str) -> np.ndarray:
    shape = a.shape
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or not 1 <= a.shape[2] <= 4:
        raise PrefilterError(f"{where}: expected an image of shape (H, W) or (H, W, 1..4), "
                             f"got shape {shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise PrefilterError(f"{where}: expected a non-empty image, got shape {shape}")
    return a


# -- PNG -----------------------------------------------------------------------------------------


@njit_serial
def _unfilter(raw, h, stride, bpp):  # pragma: no cover - compiled
    """Undo the PNG per-row filters (RFC 2083 section 6) in place; returns (h, stride) bytes."""
    out = np.zeros((h, stride), dtype=np.uint8)
    pos = 0
    for y in range(h):
        ft = raw[pos]
        pos += 1
        for x in range(stride):
            a = np.int32(out[y, x - bpp]) if x >= bpp else np.int32(0)
            b = np.int32(out[y - 1, x]) if y > 0 else np.int32(0)
            c = np.int32(out[y - 1, x - bpp]) if (y > 0 and x >= bpp) else np.int32(0)
            v = np.int32(raw[pos + x])
            if ft == 1:
                v += a
            elif ft == 2:
                v += b
            elif ft == 3:
                v += (a + b) // 2
            elif ft == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                v += a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
            out[y, x] = v & 255
        pos += stride
    return out


def _png_chunks(data: bytes, where: str):
    """``(kind, body)`` of every chunk, CRC-checked (RFC 2083 section 3.2), ending with IEND."""
    if not data.startswith(_PNG_SIG):
        raise PrefilterError(f"{where}: not a PNG file (bad signature)")
    pos = len(_PNG_SIG)
    while True:
        if pos + 12 > len(data):
            raise PrefilterError(f"{where}: truncated PNG (no IEND chunk)")
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        if pos + 12 + n > len(data):
            raise PrefilterError(f"{where}: truncated PNG chunk {kind!r}")
        body = data[pos + 8 : pos + 8 + n]
        (crc,) = struct.unpack(">I", data[pos + 8 + n : pos + 12 + n])
        if zlib.crc32(kind + body) & 0xFFFFFFFF != crc:
            raise PrefilterError(f"{where}: corrupt PNG chunk {kind!r} at byte {pos} (CRC "
                                 f"mismatch)")
        yield kind, body
        pos += 12 + n
        if kind == b"IEND":
            break  # bytes after IEND are ignored, like other PNG readers do


def _read_png16_colour(data: bytes, where: str):
    """Decode a non-interlaced 16-bit gray+alpha / RGB / RGBA PNG, or None if not that kind."""
    chunks = list(_png_chunks(data, where))
    if not chunks or chunks[0][0] != b"IHDR":
        raise PrefilterError(f"{where}: corrupt PNG (no IHDR chunk)")
    w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    channels = {4: 2, 2: 3, 6: 4}.get(ctype)
    if depth != 16 or channels is None:
        return None
    if interlace:
        raise PrefilterError(f"{where}: interlaced 16-bit colour PNGs are not supported")
    try:
        raw = zlib.decompress(b"".join(b for k, b in chunks if k == b"IDAT"))
    except zlib.error as exc:
        raise PrefilterError(f"{where}: corrupt PNG data ({exc})") from None
    stride = w * channels * 2
    if len(raw) < h * (stride + 1):
        raise PrefilterError(f"{where}: truncated PNG image data")
    rows = _unfilter(np.frombuffer(raw, dtype=np.uint8), h, stride, channels * 2)
    return rows.view(">u2").reshape(h, w, channels).astype(np.float64) / 65535.0


def _write_png16(path: Path, q: np.ndarray) -> None:
    h, w, c = q.shape
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[c]
    rows = q.astype(">u2").reshape(h, w * c).view(np.uint8)
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rows], axis=1).tobytes()  # filter 0

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(
            ">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, 16, ctype, 0, 0, 0)
    data = _PNG_SIG + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(
        b"IEND", b"")
    path.write_bytes(data)


def _read_png(path: Path) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    where = str(path)
    data = path.read_bytes()
    a = _read_png16_colour(data, where)  # also checks every chunk's CRC
    if a is not None:
        return a
    try:
        with Image.open(path) as im:
            im.load()
            mode = im.mode
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
                mode = im.mode
            if mode in ("1", "L", "LA", "RGB", "RGBA"):
                return np.asarray(im.convert(mode if mode != "1" else "L"), np.float64) / 255.0
            if mode.startswith("I;16") or mode == "I":
                return np.asarray(im, np.float64) / 65535.0
            raise PrefilterError(f"{where}: unsupported PNG mode {mode!r}")
    except PrefilterError:
        raise
    except (UnidentifiedImageError, OSError, SyntaxError) as exc:
        raise PrefilterError(f"{where}: unreadable or corrupt PNG ({exc})") from None
    except Exception as exc:  # noqa: BLE001 - any other decoding failure of a corrupt file
        raise PrefilterError(f"{where}: unreadable or corrupt PNG ({type(exc).__name__}: "
                             f"{exc})") from None


def _write_png(path: Path, a: np.ndarray, bits: int) -> None:
    from PIL import Image

    top = 255 if bits == 8 else 65535
    q = np.rint(np.clip(a, 0.0, 1.0) * top)
    if bits == 16 and a.shape[2] > 1:
        _write_png16(path, q.astype(np.uint16))
        return
    if bits == 16:
        im = Image.fromarray(q[..., 0].astype(np.uint16))
    else:
        mode = {1: "L", 2: "LA", 3: "RGB", 4: "RGBA"}[a.shape[2]]
        q8 = q.astype(np.uint8)
        im = Image.fromarray(q8[..., 0] if mode == "L" else q8, mode=mode if mode != "L" else None)
    im.save(path, format="PNG")


# -- EXR -----------------------------------------------------------------------------------------

_EXR_LAYOUTS = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


#: Custom EXR header attribute holding :func:`prefilter.fileio.array_digest` of the channels.
EXR_CHECKSUM = "prefilter_sha256"


def _flush_c_stdio() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library to reach: nothing buffered
        pass


@contextlib.contextmanager
def _native_output(captured: list[str]):
    """Collect into ``captured`` what OpenEXR and its binding print (messages about a corrupt
    file, some on stdout; through C stdio or Python's ``sys.stdout`` / ``sys.stderr``) instead
    of letting it reach the terminal: the error raised from it says it once, and a successful
    read prints nothing. The redirection is process-wide for the read's few milliseconds."""
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no usable descriptors: only Python's streams are redirected
        saved = None
    py = io.StringIO()
    with tempfile.TemporaryFile() as sink:
        if saved is not None:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
        try:
            with contextlib.redirect_stdout(py), contextlib.redirect_stderr(py):
                yield
        finally:
            _flush_c_stdio()  # iostreams are buffered when not a terminal
            if saved is not None:
                for fd, old in zip((1, 2), saved):
                    os.dup2(old, fd)
                    os.close(old)
            sink.seek(0)
            captured += py.getvalue().splitlines()
            captured += sink.read().decode("utf-8", "replace").splitlines()


def read_exr_channels(path: Path, *, require_checksum: bool = False) -> dict[str, np.ndarray]:
    """The channels of an EXR file as stored (float16/32 ``(H, W)``), checksum verified.

    Files written by this package carry :data:`EXR_CHECKSUM` (EXR itself has no checksum: a
    flipped bit in pixel data decodes silently to other values); it must match when present,
    and must be present with ``require_checksum`` (the project's own formats) or when the header
    holds an attribute whose name is one flipped bit away from it.
    """
    import OpenEXR

    native: list[str] = []
    try:
        with _native_output(native), OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
            header = f.header()
            want = header.get(EXR_CHECKSUM)
            damaged = [k for k in header if isinstance(k, str) and k != EXR_CHECKSUM
                       and len(k) == len(EXR_CHECKSUM)
                       and sum(a != b for a, b in zip(k, EXR_CHECKSUM)) == 1]
    except Exception as exc:  # noqa: BLE001 - RuntimeError, ValueError, UnicodeDecodeError, ...
        detail = "; ".join([f"{type(exc).__name__}: {exc}"] + native[:1])
        raise PrefilterError(f"{path}: unreadable or corrupt EXR ({detail})") from None
    if not ch or any(a.ndim != 2 or a.dtype.kind not in "fu" for a in ch.values()):
        raise PrefilterError(f"{path}: expected EXR channels of 2-D pixel arrays, got "
                             f"{ {k: (str(a.dtype), a.shape) for k, a in ch.items()} }")
    if want is None and (require_checksum or damaged):
        raise PrefilterError(f"{path}: {EXR_CHECKSUM}: missing checksum"
                             + (f" (an attribute {damaged[0]!r} stands in its place)" if damaged
                                else "") + ": the file is corrupt or was not written by prefilter")
    if want is not None:
        if isinstance(want, bytes):
            want = want.decode("latin-1")
        if not isinstance(want, str):  # a flipped bit in the attribute's type name
            raise PrefilterError(f"{path}: {EXR_CHECKSUM}: expected a string attribute, got "
                                 f"one of type {type(want).__name__}: the file is corrupt or "
                                 f"was modified")
        found = array_digest(ch)
        if want != found:
            raise PrefilterError(f"{path}: {EXR_CHECKSUM}: checksum mismatch (expected {want!r}, "
                                 f"found {found!r}): the file is corrupt or was modified")
    return ch


def _read_exr(path: Path) -> np.ndarray:
    ch = {k: v.astype(np.float64) for k, v in read_exr_channels(path).items()}
    for names in (("R", "G", "B", "A"), ("R", "G", "B"), ("Y", "A"), ("Y",)):
        if all(n in ch for n in names):
            return np.stack([ch[n] for n in names], axis=-1)
    if len(ch) == 1:
        return next(iter(ch.values()))[..., None]
    raise PrefilterError(
        f"{path}: expected EXR channels R,G,B[,A] or Y[,A], got {', '.join(sorted(ch))}")


def write_exr_channels(path: Path, chans: dict[str, np.ndarray]) -> None:
    """Write ``(H, W)`` float16/32 channels as a ZIP-compressed scanline EXR with the checksum
    attribute :data:`EXR_CHECKSUM` (not atomic: pass a temporary path)."""
    import OpenEXR

    chans = {k: np.ascontiguousarray(v) for k, v in chans.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              EXR_CHECKSUM: array_digest(chans)}
    with OpenEXR.File(header, chans) as f:
        f.write(str(path))


def _write_exr(path: Path, a: np.ndarray, half: bool) -> None:
    dtype = np.float16 if half else np.float32
    write_exr_channels(path, {n: np.ascontiguousarray(a[..., i], dtype=dtype)
                              for i, n in enumerate(_EXR_LAYOUTS[a.shape[2]])})


# -- public API ----------------------------------------------------------------------------------


def read_image(path: str | os.PathLike, *, srgb: bool = False) -> np.ndarray:
    """Read a PNG (8/16-bit), EXR or ``.npy`` image as float64 ``(H, W, C)``, ``C`` in 1..4.

    ``srgb=True`` decodes the colour channels of a PNG from sRGB to linear (alpha untouched);
    EXR and ``.npy`` are always linear. Raises :class:`PrefilterError` for a missing, unreadable or
    corrupt file, or one with an unsupported shape.
    """
    path = Path(path)
    kind = _suffix(path)
    if not path.is_file():
        raise PrefilterError(f"{path}: image file not found")
    if kind == ".png":
        a = _read_png(path)
        a = _as_hwc(a, str(path))
        if srgb:
            nc = a.shape[2] - (1 if a.shape[2] in (2, 4) else 0)
            a = np.concatenate([srgb_to_linear(a[..., :nc]), a[..., nc:]], axis=-1)
        return a
    if kind == ".exr":
        a = _read_exr(path)
    else:
        try:
            a = np.load(path, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - any decoding failure of a corrupt file
            raise PrefilterError(f"{path}: unreadable or corrupt .npy ({type(exc).__name__}: "
                                 f"{exc})") from None
        if not isinstance(a, np.ndarray):
            raise PrefilterError(f"{path}: expected a .npy array, got an .npz archive")
        if a.dtype.kind not in "biuf":
            raise PrefilterError(f"{path}: expected a numeric array, got dtype {a.dtype}")
        a = a.astype(np.float64)
    a = _as_hwc(a, str(path))
    if not np.all(np.isfinite(a)):
        raise PrefilterError(f"{path}: expected finite pixel values, got NaN or inf")
    return a


def write_image(path: str | os.PathLike, image, *, bits: int = 8, srgb: bool = False,
                half: bool = False) -> Path:
    """Write ``image`` ``(H, W)`` or ``(H, W, C)``, ``C`` in 1..4, atomically; returns the path.

    PNG: values are clipped to [0, 1] (after sRGB encoding of colour channels when ``srgb``) and
    quantised to ``bits`` = 8 or 16. EXR: float32 (``half=True``: float16), ZIP-compressed,
    channels Y / YA / RGB / RGBA, checksum attribute ``prefilter_sha256``. ``.npy``: float64.
    """
    path = Path(path)
    kind = _suffix(path)
    a = np.asarray(image)
    if a.dtype.kind not in "biuf":
        raise PrefilterError(f"image: expected a numeric array, got dtype {a.dtype}")
    a = _as_hwc(a.astype(np.float64), "image")
    if kind == ".png" and srgb:
        nc = a.shape[2] - (1 if a.shape[2] in (2, 4) else 0)
        a = np.concatenate([linear_to_srgb(a[..., :nc]), a[..., nc:]], axis=-1)
    if kind == ".png" and bits not in (8, 16):
        raise PrefilterError(f"bits: expected 8 or 16 for PNG, got {bits!r}")
    if kind != ".npy" and not np.all(np.isfinite(a)):
        raise PrefilterError("image: expected finite values, got NaN or inf")
    with atomic_path(path, suffix=kind) as tmp:
        if kind == ".png":
            _write_png(tmp, a, bits)
        elif kind == ".exr":
            _write_exr(tmp, a, half)
        else:
            with open(tmp, "wb") as fh:
                np.save(fh, a)
    return path


def png_bytes(rgb8) -> bytes:
    """Deterministic PNG encoding of an sRGB ``uint8 (H, W, 3)`` image."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb8, dtype=np.uint8), mode="RGB").save(buf, format="PNG")
    return buf.getvalue()


def save_png(path: str | os.PathLike, rgb8) -> Path:
    """Write an sRGB ``uint8 (H, W, 3)`` image as PNG, atomically."""
    a = np.asarray(rgb8)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[-1] != 3:
        raise PrefilterError(f"rgb8: expected a uint8 image (H, W, 3), got {a.dtype} {a.shape}")
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        tmp.write_bytes(png_bytes(a))
    return path
