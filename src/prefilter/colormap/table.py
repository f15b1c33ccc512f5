"""Pre-convolved colour-map tables ``T(m, sigma) = [C * N(0, sigma^2)](m)`` (Heitz et al. 2013,
eq. 10).

A colour map is ``N`` colours sampled at the texel centres ``v_i = v0 + (i + 0.5) (v1 - v0) / N`` of
its value range ``[v0, v1]`` and linearly interpolated between them, exactly as a GPU samples a 1D
texture with linear filtering. Outside the centres the map is extended by ``edge``:

``"clamp"``
    the end colours continue for ever (``GL_CLAMP_TO_EDGE``);
``"mirror"``
    the map is reflected about ``v0`` and ``v1`` (``GL_MIRRORED_REPEAT``);
``"periodic"``
    the map repeats with period ``v1 - v0`` (``GL_REPEAT``).

The convolution of a piecewise-linear function with a Gaussian has a closed form (a sum of
Gaussian-smoothed ramps), so the table is exact up to rounding; no numerical quadrature and no
resolution parameter are involved. The table has ``n_sigma`` rows (``sigma_j = sigma_max j /
(n_sigma - 1)``, row 0 is the colour map itself) and ``n_mean`` columns at the texel centres of the
value range. :meth:`ColormapTable.lookup` interpolates it bilinearly; means outside the range wrap
or mirror exactly for periodic / mirror maps and are clamped to the edge column for clamp maps (an
approximation when ``sigma > 0``), ``sigma`` is clamped to ``[0, sigma_max]``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.special import ndtr

from prefilter.validation import (as_float_array, as_positive_int, broadcast_batch, check_memory,
                                  check_scalar)
from prefilter.jit import njit_parallel, njit_serial, prange, serial
from prefilter.errors import PrefilterError, TableFileError

__all__ = ["EDGES", "ColormapTable", "as_colormap", "gaussian_operator", "lookup",
           "prefilter_rows", "prefilter_table"]

EDGES = ("clamp", "mirror", "periodic")
#: Format name and version of the JSON sidecar of a baked table (:meth:`ColormapTable.save`).
FORMAT = "prefilter-colormap-table"
VERSION = 1
_INV_SQRT_2PI = 0.3989422804014327
# Samples within this many standard deviations of a table entry contribute to it (exp(-32) ~ 1e-14).
_REACH = 8.0


def _edge(edge: str) -> str:
    if edge not in EDGES:
        raise PrefilterError(f"edge: expected one of {', '.join(EDGES)}, got {edge!r}")
    return edge


def _value_range(value_range) -> tuple[float, float]:
    r = as_float_array(value_range, "value_range")
    if r.shape != (2,) or not r[1] > r[0]:
        raise PrefilterError(f"value_range: expected (lo, hi) with lo < hi, got {r.tolist()!r}")
    return float(r[0]), float(r[1])


def as_colormap(colormap, value_range=(0.0, 1.0), n: int = 256) -> np.ndarray:
    """Colour-map samples ``(N, C)`` at the texel centres of ``value_range``.

    ``colormap`` is an array ``(N,)`` / ``(N, C)`` of colours (returned as ``(N, C)`` float64) or a
    callable ``C(v) -> (..., C)`` (or ``(...)``) evaluated at ``n`` texel centres.
    """
    if callable(colormap):
        lo, hi = _value_range(value_range)
        n = as_positive_int(n, "n", lo=2)
        v = lo + (np.arange(n) + 0.5) * (hi - lo) / n
        c = as_float_array(colormap(v), "colormap(v)")
        if c.shape[:1] != (n,):
            raise PrefilterError(f"colormap(v): expected shape ({n},) or ({n}, C), got {c.shape}")
    else:
        c = as_float_array(colormap, "colormap", ndim_min=1)
    if c.ndim == 1:
        c = c[:, None]
    if c.ndim != 2 or c.shape[0] < 2 or c.shape[1] < 1:
        raise PrefilterError(f"colormap: expected shape (N, C) with N >= 2, got {c.shape}")
    return c


def _extend(n: int, pad: int, edge: str) -> np.ndarray:
    """Indices of the ``n`` samples extended by ``pad`` samples on each side (``edge`` rule)."""
    i = np.arange(-pad, n + pad)
    if edge == "periodic":
        return np.mod(i, n)
    if edge == "mirror":
        # reflection about the range ends maps centre -1 to centre 0, -2 to 1, ... (period 2n)
        j = np.mod(i, 2 * n)
        return np.where(j < n, j, 2 * n - 1 - j)
    return np.clip(i, 0, n - 1)


def _smoothed_ramp(x, sigma):
    """``E[max(0, x + sigma Z)]``, ``Z ~ N(0, 1)``: a ramp convolved with a Gaussian."""
    if sigma == 0.0:
        return np.maximum(x, 0.0)
    with np.errstate(over="ignore"):  # denormal sigma: z = +-inf gives the ramp itself
        z = x / sigma
        return x * ndtr(z) + sigma * _INV_SQRT_2PI * np.exp(-0.5 * z * z)


def _hat_kernel(sigma_samples: float, reach: int) -> np.ndarray:
    """Weights ``k(d)``, ``d = -reach..reach``, of the samples at offset ``d`` (in samples) in the
    Gaussian-smoothed linear interpolant: the hat ``max(0, 1 - |x|)`` convolved with
    ``N(0, sigma_samples^2)``. With ``hat(x) = r(x + 1) - 2 r(x) + r(x - 1)``, ``r = max(0, .)``,
    each ramp smooths in closed form; the kernel is even, so it is evaluated at ``-|d| <= 0``
    where the smoothed ramps are small (no cancellation)."""
    d = -np.arange(reach + 1, dtype=np.float64)
    k = (_smoothed_ramp(d + 1.0, sigma_samples) - 2.0 * _smoothed_ramp(d, sigma_samples)
         + _smoothed_ramp(d - 1.0, sigma_samples))
    return np.concatenate([k[:0:-1], k])


def gaussian_operator(n: int, sigma: float, edge: str = "clamp", n_out: int | None = None):
    """The linear map from ``n`` colour-map samples to their Gaussian convolution at ``n_out``
    texel centres (Heitz et al. 2013, eq. 10), in units where the range ``[0, 1]`` holds ``n``
    samples (``sigma`` is a fraction of the value range).

    The colour map is ``sum_j y_j hat(n v - j - 0.5)`` over the samples extended by ``edge``
    (``hat`` the linear-interpolation kernel), so its convolution is the same sum over the
    smoothed hats of :func:`_hat_kernel`; samples beyond ``8 sigma`` contribute less than 1e-14.

    Returns
    -------
    numpy.ndarray, shape (n_out, n)
        Rows sum to 1 (the operator preserves constants).
    """
    n = as_positive_int(n, "n", lo=2)
    n_out = n if n_out is None else as_positive_int(n_out, "n_out", lo=1)
    edge = _edge(edge)
    sigma = check_scalar(sigma, "sigma", lo=0.0)
    # the operator and the kernel (its reach grows with sigma), float64
    check_memory(8 * (n_out * (n + 2 * _REACH * sigma * n + 4) + 2 * _REACH * sigma * n),
                 f"sigma: a Gaussian operator of {n} samples at sigma {sigma:g}")
    if n_out != n:
        return _resampling_operator(n, sigma, edge, n_out)
    reach = int(np.ceil(_REACH * sigma * n)) + 1
    k = _hat_kernel(sigma * n, reach)
    i = np.arange(n)
    if edge == "clamp":
        # samples beyond the ends repeat the end samples: fold the kernel's tails onto them
        d = np.arange(n)[None, :] - i[:, None]
        op = np.where(np.abs(d) <= reach, k[np.clip(d + reach, 0, 2 * reach)], 0.0)
        cum = np.concatenate([[0.0], np.cumsum(k)])  # cum[t] = sum of k[:t]
        # sample 0 also gets offsets d <= -i, i.e. kernel indices <= reach - i
        op[:, 0] = cum[np.clip(reach - i + 1, 0, 2 * reach + 1)]
        op[:, -1] = cum[-1] - cum[np.clip(reach + (n - 1 - i), 0, 2 * reach + 1)]
        return op
    # periodic and mirror extensions both repeat with period 2n: fold the kernel onto it first
    period = 2 * n
    k2 = np.bincount(np.mod(np.arange(-reach, reach + 1), period), weights=k, minlength=period)
    e = np.mod(i[:, None] + np.arange(period)[None, :], period)  # (n, 2n) extended indices
    j = _extend_index(e, n, edge)
    rows = np.broadcast_to(i[:, None], j.shape)
    return np.bincount((rows * n + j).ravel(), weights=np.broadcast_to(k2, j.shape).ravel(),
                       minlength=n * n).reshape(n, n)


def _resampling_operator(n: int, sigma: float, edge: str, n_out: int) -> np.ndarray:
    """:func:`gaussian_operator` for ``n_out != n`` (a general, slower summation)."""
    pad = int(np.ceil(_REACH * sigma * n)) + 2
    idx = _extend(n, pad, edge)
    x = (np.arange(n_out) + 0.5) / n_out * n - 0.5  # output positions in sample units
    d = x[:, None] - np.arange(-pad, n + pad)[None, :]
    w = (_smoothed_ramp(-np.abs(d) + 1.0, sigma * n) - 2.0 * _smoothed_ramp(-np.abs(d), sigma * n)
         + _smoothed_ramp(-np.abs(d) - 1.0, sigma * n))
    op = np.zeros((n, n_out))
    np.add.at(op, idx, w.T)
    return op.T


#: Edge rules as the kernels number them.
EDGE_CODE = {"clamp": 0, "mirror": 1, "periodic": 2}


@njit_serial
def _edge_index(i, n, edge):  # pragma: no cover - compiled
    if edge == 0:
        return min(max(i, 0), n - 1)
    if edge == 2:
        return i % n
    j = i % (2 * n)
    return j if j < n else 2 * n - 1 - j


@njit_serial
def lookup_one(table, lo, hi, smax, edge, mean, sigma, out):  # pragma: no cover - compiled
    """``out (C,)``: bilinear lookup of a table ``(n_sigma, n_mean, C)`` (eq. 10; ``sigma <= 0``:
    row 0 only, the naive colour); the arguments after ``table`` as :func:`kernel_args` gives
    them. Called by :meth:`ColormapTable.lookup` and the shading kernels."""
    ns, n, c = table.shape
    x = (mean - lo) / (hi - lo) * n - 0.5
    # bring x into a range whose floor fits an int64 (|mean| > 1e17 would wrap to the wrong
    # edge): clamping saturates, mirror and periodic edges repeat with period 2n and n
    if edge == 0:
        x = min(max(x, -1.0), float(n))
    else:
        x = x % (2.0 * n if edge == 1 else float(n))
    x0 = math.floor(x)
    fx = x - x0
    i0 = _edge_index(int(x0), n, edge)
    i1 = _edge_index(int(x0) + 1, n, edge)
    if sigma <= 0.0 or ns == 1 or smax == 0.0:
        for k in range(c):
            out[k] = table[0, i0, k] * (1 - fx) + table[0, i1, k] * fx
        return
    y = min(sigma / smax, 1.0) * (ns - 1)
    j0 = min(int(math.floor(y)), ns - 2)
    fy = y - j0
    for k in range(c):
        a = table[j0, i0, k] * (1 - fx) + table[j0, i1, k] * fx
        b = table[j0 + 1, i0, k] * (1 - fx) + table[j0 + 1, i1, k] * fx
        out[k] = a * (1 - fy) + b * fy


@njit_parallel
def _lookup_kernel(table, lo, hi, smax, edge, mean, sigma, out):  # pragma: no cover - compiled
    for p in prange(mean.shape[0]):
        lookup_one(table, lo, hi, smax, edge, mean[p], sigma[p], out[p])
    return out


def _lookup(table, mean, sigma) -> np.ndarray:
    """``(N, C)`` lookups of a :class:`~prefilter.colormap.table.ColormapTable` at ``mean (N,)``,
    ``sigma (N,)`` (checked by the caller, :meth:`ColormapTable.lookup`)."""
    mean = np.ascontiguousarray(mean, dtype=np.float64)
    out = np.empty((mean.shape[0], table.table.shape[2]))
    return serial(_lookup_kernel, mean.shape[0])(
        *kernel_args(table), mean, np.ascontiguousarray(sigma, dtype=np.float64), out)


def kernel_args(table):
    """``(table, lo, hi, sigma_max, edge code)`` of a :class:`ColormapTable` for the kernels."""
    lo, hi = table.value_range
    return (np.ascontiguousarray(table.table), float(lo), float(hi), float(table.sigma_max),
            EDGE_CODE[table.edge])


@dataclass(frozen=True)
class ColormapTable:
    """A pre-convolved colour map ``T[j, i] = [C * N(0, sigma_j^2)](m_i)`` (eq. 10).

    Attributes
    ----------
    table : numpy.ndarray, shape (n_sigma, n_mean, C)
        Row ``j`` is the colour map blurred by a Gaussian of std ``sigma_max j / (n_sigma - 1)``.
    value_range : (float, float)
        The range whose texel centres the columns sample.
    sigma_max : float
        Std (in value units) of the last row.
    edge : {"clamp", "mirror", "periodic"}
    """

    table: np.ndarray
    value_range: tuple[float, float]
    sigma_max: float
    edge: str = "clamp"

    @property
    def n_mean(self) -> int:
        return self.table.shape[1]

    @property
    def n_sigma(self) -> int:
        return self.table.shape[0]

    @property
    def sigmas(self) -> np.ndarray:
        """Std of each row, ``(n_sigma,)``."""
        return np.linspace(0.0, self.sigma_max, self.n_sigma)

    @property
    def means(self) -> np.ndarray:
        """Mean at each column (texel centres of the value range), ``(n_mean,)``."""
        lo, hi = self.value_range
        return lo + (np.arange(self.n_mean) + 0.5) * (hi - lo) / self.n_mean

    def lookup(self, mean, sigma) -> np.ndarray:
        """Filtered colour ``<C, N(mean, sigma^2)>`` by bilinear interpolation (eq. 10).

        Parameters
        ----------
        mean, sigma : array_like, broadcastable shapes (...)
            Mean and standard deviation of the driving function over the footprint.

        Returns
        -------
        numpy.ndarray, shape (..., C)
        """
        m = as_float_array(mean, "mean")
        s = as_float_array(sigma, "sigma")
        if np.any(s < 0.0):
            raise PrefilterError(f"sigma: expected standard deviations >= 0, got min {s.min()!r}")
        shape = broadcast_batch(mean=m.shape, sigma=s.shape)
        m, s = np.broadcast_arrays(m, s)
        out = _lookup(self, m.reshape(-1), s.reshape(-1))
        return out.reshape(shape + (out.shape[1],))

    def naive(self, mean) -> np.ndarray:
        """The naive filter ``C(mean)`` (row 0), shape ``(..., C)``."""
        return self.lookup(mean, 0.0)

    def metadata(self) -> dict:
        """JSON-ready description of the table layout (for baked files and shaders)."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "value_range": list(self.value_range),
            "sigma_max": self.sigma_max,
            "edge": self.edge,
            "n_mean": self.n_mean,
            "n_sigma": self.n_sigma,
            "channels": int(self.table.shape[2]),
            "layout": "rows = sigma (row j: sigma_max * j / (n_sigma - 1), row 0 first); columns ="
                      " mean at texel centres lo + (i + 0.5) (hi - lo) / n_mean",
        }


    # -- files --------------------------------------------------------------------------------
    def save(self, path, *, meta: dict | None = None) -> tuple[Path, Path]:
        """Write the table image ``path`` (``.png``: 16-bit, ``.exr``: float32, ``.npy``:
        float64; rows = sigma) and its sidecar ``path.with_suffix(".json")`` (:meth:`metadata`
        plus ``meta``, ``table_file``, ``sha256``, the digest of the stored pixels as
        :func:`prefilter.texture.read_image` returns them, and ``meta_sha256``, the digest of all
        other fields).

        The two are one unit (:func:`prefilter.fileio.atomic_file_set`): they are written into a
        new version folder beside ``path`` and switched together by one atomic rename, so a
        process killed at any moment leaves the previous table and sidecar or the new ones;
        ``path`` and the sidecar are symbolic links into the current version. Concurrent saves
        to one ``path`` take turns (:func:`prefilter.fileio.bake_lock`, waiting)."""
        from prefilter.fileio import (array_digest, atomic_file_set, bake_lock, json_digest,
                                      save_json_atomic)
        from prefilter.texture.io import read_image, write_image

        path = Path(path)
        side = path.with_suffix(".json")
        if side == path:
            raise PrefilterError(f"path: expected the table image file, got the sidecar name "
                                 f"{path}")
        with bake_lock(path, wait=True), atomic_file_set([path, side]) as (img_tmp, side_tmp):
            write_image(img_tmp, self.table, bits=16)
            info = dict(meta or {})
            info.update(self.metadata(), table_file=path.name,
                        sha256=array_digest({"table": read_image(img_tmp)}))
            info["meta_sha256"] = json_digest(info)
            save_json_atomic(side_tmp, info)
        return path, side

    @classmethod
    def load(cls, path) -> "ColormapTable":
        """Read a table written by :meth:`save` (or ``prefilter bake colormap``) and its JSON
        sidecar; every field, the image shape and the checksum (when present) are verified and
        a failure raises :class:`~prefilter.errors.TableFileError` naming the file and field.
        ``path`` is resolved once and the sidecar read next to the file it names, so a save
        running at the same time is seen whole or not at all."""
        from prefilter.fileio import array_digest, json_digest
        from prefilter.texture.io import read_image

        path = Path(path)
        side = path.with_suffix(".json")
        if side == path:
            raise TableFileError(f"{path}: expected the table image, not its JSON sidecar")
        real = path.resolve()  # the current version of a saved table (see save)
        side_file = real.with_suffix(".json")
        if not side_file.is_file():
            raise TableFileError(f"{side}: colour-table metadata not found (written next to "
                                 f"{path.name} by `prefilter bake colormap`)")
        try:
            info = json.loads(side_file.read_text())
        except (ValueError, OSError) as exc:
            raise TableFileError(f"{side}: unreadable JSON ({type(exc).__name__}: {exc})"
                                 ) from None
        if not isinstance(info, dict):
            raise TableFileError(f"{side}: expected a JSON object, got {type(info).__name__}")
        if "meta_sha256" in info:
            want = info.pop("meta_sha256")
            if json_digest(info) != want:
                raise TableFileError(f"{side}: meta_sha256: checksum mismatch (expected {want!r})"
                                     f": the metadata is corrupt or was edited")

        def need(key, ok, what):
            if key not in info:
                raise TableFileError(f"{side}: {key}: required field is missing")
            if not ok(info[key]):
                raise TableFileError(f"{side}: {key}: expected {what}, got {info[key]!r}")
            return info[key]

        def num(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)

        def count(lo):
            return lambda v: isinstance(v, int) and not isinstance(v, bool) and lo <= v <= 1 << 20

        need("format", lambda v: v == FORMAT, repr(FORMAT))
        need("version", lambda v: v == VERSION and not isinstance(v, bool), str(VERSION))
        vr = need("value_range", lambda v: isinstance(v, list) and len(v) == 2
                  and all(map(num, v)) and v[0] < v[1], "[lo, hi] with lo < hi")
        smax = need("sigma_max", lambda v: num(v) and v > 0, "a number > 0")
        edge = need("edge", lambda v: v in EDGES, f"one of {', '.join(EDGES)}")
        shape = (need("n_sigma", count(2), "an integer >= 2"),
                 need("n_mean", count(2), "an integer >= 2"),
                 need("channels", count(1), "an integer >= 1"))
        if "table_file" in info and info["table_file"] != real.name:
            raise TableFileError(f"{side}: table_file: expected {real.name!r}, got "
                                 f"{info['table_file']!r}")
        try:
            img = read_image(real)
        except TableFileError:
            raise
        except PrefilterError as exc:
            raise TableFileError(str(exc)) from None
        if img.shape != shape:
            raise TableFileError(f"{path}: expected a table of shape {shape} (n_sigma, n_mean, "
                                 f"channels from {side.name}), got {img.shape}")
        if "sha256" in info and array_digest({"table": img}) != info["sha256"]:
            raise TableFileError(f"{path}: sha256: checksum mismatch with {side.name} (expected "
                                 f"{info['sha256']}): the file is corrupt or from another bake")
        return cls(img, (float(vr[0]), float(vr[1])), float(smax), edge)


def _extend_index(i: np.ndarray, n: int, edge: str) -> np.ndarray:
    if edge == "periodic":
        return np.mod(i, n)
    j = np.mod(i, 2 * n)
    return np.where(j < n, j, 2 * n - 1 - j)


def prefilter_table(colormap, value_range=(0.0, 1.0), sigma_max: float = 0.25, size: int = 256,
                    edge: str = "clamp", n_sigma: int | None = None) -> ColormapTable:
    """Pre-convolve a colour map with Gaussians of std ``0..sigma_max`` (Heitz et al. 2013, eq. 10).

    Parameters
    ----------
    colormap : array_like (N,) / (N, C), or callable ``C(v)``
        Colours at the ``N`` texel centres of ``value_range`` (see module docstring), or a
        function sampled at ``size`` centres.
    value_range : (float, float)
        Values ``[v0, v1]`` the colour map spans.
    sigma_max : float
        Largest standard deviation (value units) of the driving function the table serves.
    size : int
        Columns (means); the colour map is resampled to it (exactly, through the closed form) when
        ``N != size``.
    edge : {"clamp", "mirror", "periodic"}
        How the colour map continues outside ``value_range``.
    n_sigma : int, optional
        Rows (default ``size``).

    Returns
    -------
    ColormapTable
    """
    lo, hi = _value_range(value_range)
    size = as_positive_int(size, "size", lo=2)
    n_sigma = size if n_sigma is None else as_positive_int(n_sigma, "n_sigma", lo=2)
    smax = check_scalar(sigma_max, "sigma_max", lo=0.0, lo_open=True)
    # the table (up to 4 channels) and the widest row's kernel and temporaries (prefilter_rows),
    # float64; the kernel spans 2 _REACH sigma_max / (v1 - v0) value ranges of `size` samples
    check_memory(8 * (4 * n_sigma * size + 8 * (2 * _REACH * smax / (hi - lo) * size + 3)),
                 f"sigma_max: a {n_sigma} x {size} table with sigma_max {smax:g} over the value "
                 f"range [{lo:g}, {hi:g}]")
    edge = _edge(edge)
    c = as_colormap(colormap, (lo, hi), size)
    n = c.shape[0]
    if n != size:
        # resample the piecewise-linear map at the table's centres (sigma = 0 is a pure resampling)
        c = gaussian_operator(n, 0.0, edge, n_out=size) @ c
        n = size
    sig = np.linspace(0.0, smax, n_sigma) / (hi - lo)
    table = prefilter_rows(c, sig, edge)
    table[0] = c  # the sigma = 0 row is the colour map itself, bit for bit
    return ColormapTable(table, (lo, hi), smax, edge)


def prefilter_rows(c, sigmas, edge: str = "clamp") -> np.ndarray:
    """Rows of the table: colour-map samples ``c (n, C)`` convolved with Gaussians of std
    ``sigmas`` (fractions of the value range), at the ``n`` texel centres (Heitz et al. 2013,
    eq. 10).

    The same sums as ``gaussian_operator(n, s, edge) @ c`` (equal to ~1e-15), by FFT: the
    smoothed-hat kernel of each row (closed form, :func:`_hat_kernel`) is folded onto the period
    ``2n`` of mirror maps / ``n`` of periodic ones and applied as a circular convolution; a clamp
    map convolves its ``n`` samples linearly (zero padding to ``2n``) and adds the kernel's tail
    masses beyond each end times the end colours. Cost ``O(n log n + 8 sigma n)`` a row instead of
    the operator's ``O(n^2)``. Each row is computed on its own, so any subset of ``sigmas`` gives
    the same rows bit for bit (resumable bakes can compute them in chunks).

    Parameters
    ----------
    c : array_like, shape (n, C)
    sigmas : array_like, shape (k,)
        Standard deviations, fractions of the value range, ``>= 0``.
    edge : {"clamp", "mirror", "periodic"}

    Returns
    -------
    numpy.ndarray, shape (k, n, C)
    """
    c = as_float_array(c, "c", ndim_min=2)
    if c.ndim != 2 or c.shape[0] < 2:
        raise PrefilterError(f"c: expected colour-map samples of shape (n, C), n >= 2, got "
                             f"{c.shape}")
    sig = as_float_array(sigmas, "sigmas", ndim_min=1)
    if sig.ndim != 1 or np.any(sig < 0.0):
        raise PrefilterError(f"sigmas: expected a 1D array of stds >= 0, got shape {sig.shape}")
    edge = _edge(edge)
    n = c.shape[0]
    if edge == "clamp":
        period, ext = 2 * n, np.concatenate([c, np.zeros_like(c)])
    elif edge == "mirror":
        period, ext = 2 * n, np.concatenate([c, c[::-1]])
    else:
        period, ext = n, c
    spectrum = np.fft.rfft(ext, axis=0)
    out = np.empty((sig.size, n, c.shape[1]))
    for r, s in enumerate(sig * n):
        reach = int(np.ceil(_REACH * s)) + 1
        k = _hat_kernel(s, reach)
        d = np.arange(-reach, reach + 1)
        if edge == "clamp":
            # samples 0..n-1 only meet offsets |d| < n; the rest is the clamped ends' share
            inner = np.abs(d) < n
            kp = np.zeros(period)
            kp[np.mod(d[inner], period)] = k[inner]
        else:
            kp = np.bincount(np.mod(d, period), weights=k, minlength=period)
        row = np.fft.irfft(np.fft.rfft(kp)[:, None] * spectrum, n=period, axis=0)[:n]
        if edge == "clamp":
            # tail[m] = sum_{d >= m} k(d), summed from the small far end: the left end colour
            # weighs tail[i + 1] at column i, the right one tail[n - i]
            tail = np.concatenate([np.cumsum(k[:reach:-1])[::-1], [0.0]])  # d = 1 .. reach
            i = np.arange(n)
            wl = np.where(i + 1 <= reach, tail[np.minimum(i, reach)], 0.0)
            wr = np.where(n - i <= reach, tail[np.minimum(n - i - 1, reach)], 0.0)
            row += wl[:, None] * c[0] + wr[:, None] * c[-1]
        out[r] = row
    return out


def as_table(table, cls=None, name: str = "table"):
    """``table`` if it is a :class:`ColormapTable` (or ``cls``), else a PrefilterError."""
    cls = ColormapTable if cls is None else cls
    if not isinstance(table, cls):
        raise PrefilterError(f"{name}: expected a {cls.__name__} (prefilter_table / "
                             f"{cls.__name__}.load), got {type(table).__name__}")
    return table


def lookup(table: ColormapTable, mean, sigma) -> np.ndarray:
    """``table.lookup(mean, sigma)``: bilinear lookup of a :class:`ColormapTable` (eq. 10)."""
    return as_table(table).lookup(mean, sigma)
