"""Direct wave-optics NDF of footprints: the model itself, without pyramid or compression.

A footprint ``(c, sigma_p)`` is the incoherent sum of the coherence areas (level-0 windows, std
``sigma0``, on the lattice ``k stride0 + 0.5``) around it (Yan et al. 2018's footprint of many
coherence areas; :mod:`prefilter.glints.wave.ndf`):

    D(c, sigma_p; s) = sum_k w_k I_k(s) / sum_k w_k,
    w_k = exp(-|c_k - c|^2 / (2 v)),   v = sigma_p^2 - sigma0^2,

``I_k`` the coherent RGB image of area ``k`` (computed once per heightfield, uncompressed). Where
``v < (stride0 / 2)^2`` (footprints about the size of a coherence area or smaller) the weights
are the bilinear ones of the four nearest areas, as the pyramid's level 0 blends them. Weights
are cut at ``TRUNCATION`` stds; the images are looked up bilinearly between pixel centres with
the compressed lookup's taps (:func:`prefilter.glints._qkernels.pixel_taps`: pixels outside the
image weigh 0, so values fade to 0 from the outer pixel centres to half a pixel beyond the
support), as the ``glints-wave`` method's.
"""

from __future__ import annotations

import math

import numpy as np

from prefilter.jit import kernel_array, njit_parallel, prange
from prefilter.glints._qkernels import pixel_taps
from prefilter.glints.pyramid import plan
from prefilter.glints.wave.heightfield import Heightfield
from prefilter.glints.wave.ndf import rgb_images

TRUNCATION = 4.0


class DirectWave:
    """Level-0 RGB images ``(ny, nx, 3, R, R)`` float32 of a heightfield's coherence areas."""

    def __init__(self, hf: Heightfield, ndf_res: int = 64, support: float = 0.25,
                 stride0: int = 4, sigma0: float | None = None, images=None):
        self.pyr = plan(*hf.shape, stride0, sigma0)
        self.R, self.S = int(ndf_res), float(support)
        c = self.pyr.centers(0)
        self.images = (images if images is not None else
                       rgb_images(hf, c, self.pyr.sigma(0), self.R, self.S).astype(np.float32))

    def point(self, center, sigma_p, s) -> np.ndarray:
        """RGB NDF ``(N, 3)`` of footprints ``center (N, 2)``, ``sigma_p (N,)`` at ``s (N, 2)``."""
        c = np.ascontiguousarray(center, np.float64).reshape(-1, 2)
        sp = kernel_array(sigma_p, c.shape[:1], np.float64)
        s = np.ascontiguousarray(s, np.float64).reshape(-1, 2)
        out = np.zeros((len(c), 3))
        _direct_points(self.images, float(self.pyr.stride0), float(self.pyr.sigma(0)),
                       c, sp, s, -self.S, 2.0 * self.S / self.R, TRUNCATION, out)
        return out


@njit_parallel
def _direct_points(img, stride, sigma0, c, sp, s, lo, h, trunc, out):  # pragma: no cover
    ny, nx, _, R, _ = img.shape
    vmin = 0.25 * stride * stride
    for q in prange(c.shape[0]):
        v = sp[q] * sp[q] - sigma0 * sigma0
        tent = v < vmin
        r = stride if tent else trunc * math.sqrt(v)
        # bilinear between pixel centres, taps outside the image weigh 0 (the compressed
        # lookup's pixel_taps)
        iy, u0, u1 = pixel_taps((s[q, 1] - lo) / h, R, True)
        ix, v0, v1 = pixel_taps((s[q, 0] - lo) / h, R, True)
        if u0 + u1 == 0.0 or v0 + v1 == 0.0:
            continue
        iy0, iy1 = max(iy, 0), min(iy + 1, R - 1)
        ix0, ix1 = max(ix, 0), min(ix + 1, R - 1)
        # lattice centres k stride + 0.5 within r of the footprint centre (periodic)
        kx0 = int(math.ceil((c[q, 0] - 0.5 - r) / stride))
        kx1 = int(math.floor((c[q, 0] - 0.5 + r) / stride))
        ky0 = int(math.ceil((c[q, 1] - 0.5 - r) / stride))
        ky1 = int(math.floor((c[q, 1] - 0.5 + r) / stride))
        wsum = 0.0
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for ky in range(ky0, ky1 + 1):
            dy = ky * stride + 0.5 - c[q, 1]
            yy = ky % ny
            for kx in range(kx0, kx1 + 1):
                dx = kx * stride + 0.5 - c[q, 0]
                if tent:
                    w = max(0.0, 1.0 - abs(dx) / stride) * max(0.0, 1.0 - abs(dy) / stride)
                else:
                    w = math.exp(-(dx * dx + dy * dy) / (2.0 * v))
                xx = kx % nx
                wsum += w
                for ch in range(3):
                    p = img[yy, xx, ch]
                    val = (u0 * (v0 * p[iy0, ix0] + v1 * p[iy0, ix1])
                           + u1 * (v0 * p[iy1, ix0] + v1 * p[iy1, ix1]))
                    if ch == 0:
                        a0 += w * val
                    elif ch == 1:
                        a1 += w * val
                    else:
                        a2 += w * val
        if wsum > 0:
            out[q, 0] = a0 / wsum
            out[q, 1] = a1 / wsum
            out[q, 2] = a2 / wsum


class PyramidWave:
    """The footprint pyramid of a :class:`DirectWave`'s images, uncompressed: per channel the
    coherence-area images filtered into the levels of ``pyr`` by
    :func:`prefilter.glints.pyramid.next_level` (float32 ``(n_images, R, R)``, flat in the
    pyramid's image order), queried as ``glints-wave`` queries its compressed maps (Gaussian
    resampling weights, :func:`prefilter.glints.pyramid.resample_weights`, and the bilinear
    lookup of :func:`prefilter.glints._qkernels.pixel_taps`). What the pyramid costs without the
    compression (``benchmarks/bench_glints_wave.py --split``)."""

    def __init__(self, dw: DirectWave, pyr=None):
        from prefilter.glints.pyramid import next_level

        self.pyr = dw.pyr if pyr is None else pyr
        self.R, self.S = dw.R, dw.S
        self.images = []
        for ch in range(3):
            lv = [np.ascontiguousarray(dw.images[:, :, ch])]
            for level in range(1, self.pyr.n_levels):
                lv.append(next_level(lv[-1], self.pyr.sigma(level - 1)
                                     / self.pyr.stride(level - 1)))
            self.images.append(np.concatenate([x.reshape(-1, *x.shape[2:]) for x in lv]))

    def point(self, center, sigma_p, s) -> np.ndarray:
        """RGB NDF ``(N, 3)`` of footprints ``center (N, 2)``, ``sigma_p (N,)`` at ``s (N, 2)``."""
        from prefilter.glints.pyramid import resample_weights

        c = np.asarray(center, np.float64).reshape(-1, 2)
        sp = np.broadcast_to(np.asarray(sigma_p, np.float64), c.shape[:1])
        s = np.asarray(s, np.float64).reshape(-1, 2)
        idx, w, _ = resample_weights(self.pyr, c, sp)
        # bilinear taps between pixel centres, zero outside the image (as pixel_taps)
        g = (s + self.S) / (2.0 * self.S / self.R) - 0.5
        i0 = np.floor(g).astype(np.int64)
        t = g - i0
        out = np.zeros((len(c), 3))
        for dy in (0, 1):
            for dx in (0, 1):
                iy, ix = i0[:, 1] + dy, i0[:, 0] + dx
                ok = (iy >= 0) & (iy < self.R) & (ix >= 0) & (ix < self.R)
                wt = np.where(ok, (t[:, 1] if dy else 1 - t[:, 1])
                              * (t[:, 0] if dx else 1 - t[:, 0]), 0.0)
                iy, ix = np.clip(iy, 0, self.R - 1), np.clip(ix, 0, self.R - 1)
                for ch in range(3):
                    v = self.images[ch][idx, iy[:, None], ix[:, None]]  # (N, K)
                    out[:, ch] += wt * np.sum(w * v, axis=1)
        return out
