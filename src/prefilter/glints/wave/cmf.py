"""Spectral samples and their conversion to linear sRGB through CIE 1931 XYZ.

Colour matching functions: the multi-lobe piecewise-Gaussian fit of Wyman, Sloan and Shirley 2013,
"Simple analytic approximations to the CIE XYZ colour matching functions", JCGT 2(2), eq. 2
(the CIE 1931 2-degree observer to within the variability of the tabulated data). XYZ -> linear
sRGB: the IEC 61966-2-1 matrix (D65 white).
"""

from __future__ import annotations

import numpy as np

#: Number of spectral samples (glint paper sec. 4.1, as Kuznetsov et al. 2019).
N_WAVELENGTHS = 8
#: Visible range in metres, split in 8 equal bins; the samples are the bins' centres.
VISIBLE = (400e-9, 700e-9)
WAVELENGTHS = VISIBLE[0] + (np.arange(N_WAVELENGTHS) + 0.5) * (
    (VISIBLE[1] - VISIBLE[0]) / N_WAVELENGTHS)

#: XYZ -> linear sRGB (IEC 61966-2-1).
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986],
                        [-0.9689, 1.8758, 0.0415],
                        [0.0557, -0.2040, 1.0570]])
#: Rec. 709 luminance weights of linear sRGB (the Y row of the inverse matrix).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

# (weight, mean nm, std below the mean, std above) per lobe: Wyman et al. 2013 eq. 2
_LOBES = {
    "x": ((1.056, 599.8, 37.9, 31.0), (0.362, 442.0, 16.0, 26.7), (-0.065, 501.1, 20.4, 26.2)),
    "y": ((0.821, 568.8, 46.9, 40.5), (0.286, 530.9, 16.3, 31.1)),
    "z": ((1.217, 437.0, 11.8, 36.0), (0.681, 459.0, 26.0, 13.8)),
}


def cie_xyz(wavelength) -> np.ndarray:
    """CIE 1931 colour matching functions ``(..., 3)`` at ``wavelength`` (metres), Wyman et al.
    2013 eq. 2: sums of piecewise Gaussians ``a exp(-(l - mu)^2 / (2 s^2))``, ``s`` the lobe's
    left or right std."""
    lam = np.asarray(wavelength, float) * 1e9
    out = []
    for key in "xyz":
        v = np.zeros_like(lam)
        for a, mu, s1, s2 in _LOBES[key]:
            t = (lam - mu) / np.where(lam < mu, s1, s2)
            v = v + a * np.exp(-0.5 * t * t)
        out.append(v)
    return np.stack(out, axis=-1)


def rgb_weights(wavelengths=WAVELENGTHS) -> np.ndarray:
    """Weights ``(3, L)``: channel ``c`` of an NDF is ``sum_l w[c, l] D_l``.

    ``XYZ_TO_SRGB`` times the colour matching functions at the samples (equal bins), each row
    scaled to sum 1: a wavelength-independent NDF (an equal-energy white light on a surface that
    does not disperse) maps to the same image in R, G and B, and each channel keeps the energy
    of the spectral images.
    """
    w = XYZ_TO_SRGB @ cie_xyz(wavelengths).T
    return w / w.sum(axis=1, keepdims=True)


def spectral_to_rgb(spectral, wavelengths=WAVELENGTHS) -> np.ndarray:
    """RGB NDF images ``(..., 3, R, R)`` from spectral ones ``(..., L, R, R)``, gamut-mapped.

    Monochromatic light lies outside the sRGB gamut, so a pixel lit by few wavelengths can get a
    negative channel; such a pixel is desaturated towards its luminance ``Y`` (``Y + t (rgb - Y)``
    with the largest ``t`` that makes every channel >= 0), which keeps ``Y`` (the sampling
    density) and makes the images non-negative (what the non-negative CP needs).
    """
    s = np.asarray(spectral, float)
    rgb = np.einsum("cl,...lij->...cij", rgb_weights(wavelengths), s)
    Y = np.einsum("c,...cij->...ij", LUMINANCE, rgb)[..., None, :, :]
    lo = rgb.min(axis=-3, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(lo < 0, Y / np.maximum(Y - lo, 1e-300), 1.0)
    t = np.clip(t, 0.0, 1.0)
    return np.maximum(Y + t * (rgb - Y), 0.0)
