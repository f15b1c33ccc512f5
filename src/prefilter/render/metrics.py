"""Image error metrics, temporal flicker and display encoding for comparing renders.

Conventions: images are linear RGB arrays ``(..., H, W, 3)``; in every two-image metric the first
argument is the image under test and the second the reference (relative MSE divides by the
reference, FLIP is asymmetric). Reductions average over pixels and the three channels equally.

* :func:`rmse`: ``sqrt(mean((a - b)^2))``.
* :func:`relmse`: ``mean((a - b)^2 / (b^2 + eps))``, the relative MSE of rendering papers; ``eps``
  keeps black reference pixels from dominating.
* :func:`flip`: NVIDIA FLIP (Andersson et al. 2020, HDR-FLIP 2021) via ``flip_evaluator``.
* :func:`flicker`: mean over pixels of the per-pixel standard deviation of luminance over K
  sub-pixel-jittered frames: how much a still image shimmers when the camera moves a little.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from prefilter.validation import as_float_array, as_positive_int
from prefilter.errors import PrefilterError

#: Rec. 709 / sRGB luminance weights for linear RGB.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])

TONEMAPS = ("aces", "reinhard", "clamp")
FLIP_TONEMAPPERS = ("aces", "hable", "reinhard")


# --------------------------------------------------------------------------------------- checks


def _image(x, name: str) -> np.ndarray:
    """A finite float64 image ``(..., H, W, 3)``."""
    a = as_float_array(x, name, ndim_min=3, last_dim=3)
    if a.shape[-3] == 0 or a.shape[-2] == 0:
        raise PrefilterError(f"{name}: expected a non-empty image (..., H, W, 3), got {a.shape}")
    return a


def _image_pair(a, b, names=("a", "b")) -> tuple[np.ndarray, np.ndarray]:
    a, b = _image(a, names[0]), _image(b, names[1])
    if a.shape[-3:] != b.shape[-3:]:
        raise PrefilterError(
            f"{names[0]}, {names[1]}: expected images of the same size, got shapes "
            f"{a.shape} and {b.shape}"
        )
    try:
        np.broadcast_shapes(a.shape, b.shape)
    except ValueError:
        raise PrefilterError(
            f"{names[0]}, {names[1]}: batch dimensions do not broadcast: {a.shape} vs {b.shape}"
        ) from None
    return a, b


def _pixel_weights(mask, shape: tuple[int, ...]) -> np.ndarray | None:
    """``mask`` as non-negative weights broadcast to the pixel grid ``shape`` ``(..., H, W)``."""
    if mask is None:
        return None
    m = np.asarray(mask)
    w = as_float_array(m.astype(np.float64) if m.dtype == bool else m, "mask")
    try:
        w = np.broadcast_to(w, shape)
    except ValueError:
        raise PrefilterError(
            f"mask: expected a shape broadcastable to the pixel grid {shape}, got {w.shape}"
        ) from None
    if np.any(w < 0):
        raise PrefilterError("mask: expected booleans or non-negative weights, got negative values")
    if np.any(w.sum(axis=(-2, -1)) <= 0):
        raise PrefilterError("mask: selects no pixel (all weights are zero)")
    return w


def _pixel_mean(per_pixel: np.ndarray, weights: np.ndarray | None):
    """Weighted mean over the last two (pixel) axes; a float for a single image."""
    if weights is None:
        out = per_pixel.mean(axis=(-2, -1))
    else:
        out = (per_pixel * weights).sum(axis=(-2, -1)) / weights.sum(axis=(-2, -1))
    return float(out) if np.ndim(out) == 0 else out


# -------------------------------------------------------------------------------- pixel errors


def rmse(a, b, mask=None):
    """Root-mean-square error between a test image and a reference.

    ``sqrt(mean over pixels and channels of (a - b)^2)``.

    Parameters
    ----------
    a, b : array_like, shape (..., H, W, 3)
        Test and reference images (linear RGB); leading batch dimensions broadcast.
    mask : array_like of bool or float, shape broadcastable to (..., H, W), optional
        Pixels to include (or non-negative per-pixel weights).

    Returns
    -------
    float, or ndarray of shape (...) for batched input.
    """
    a, b = _image_pair(a, b)
    sq = np.mean((a - b) ** 2, axis=-1)
    mse = _pixel_mean(sq, _pixel_weights(mask, sq.shape))
    return float(np.sqrt(mse)) if isinstance(mse, float) else np.sqrt(mse)


def relmse(a, b, eps: float = 1e-2, mask=None):
    """Relative mean-squared error of a test image ``a`` against a reference ``b``.

    ``mean over pixels and channels of (a - b)^2 / (b^2 + eps)``: each channel is normalised by
    its own reference value and the three channels are averaged with equal weight.

    Parameters
    ----------
    a, b : array_like, shape (..., H, W, 3)
        Test and reference images (linear RGB).
    eps : float
        Positive regulariser so black reference pixels do not divide by zero.
    mask : array_like, shape broadcastable to (..., H, W), optional
        Pixels to include (or non-negative per-pixel weights).

    Returns
    -------
    float, or ndarray of shape (...) for batched input.
    """
    a, b = _image_pair(a, b)
    eps = float(as_float_array(eps, "eps"))
    if not eps > 0:
        raise PrefilterError(f"eps: expected a positive number, got {eps}")
    rel = np.mean((a - b) ** 2 / (b**2 + eps), axis=-1)
    return _pixel_mean(rel, _pixel_weights(mask, rel.shape))


def luminance(image) -> np.ndarray:
    """Rec. 709 luminance ``(..., )`` of linear RGB ``(..., 3)``."""
    x = as_float_array(image, "image", ndim_min=1, last_dim=3)
    return x @ LUMINANCE_WEIGHTS


# ------------------------------------------------------------------------------------------ FLIP


class FlipResult(NamedTuple):
    """Mean FLIP error, the per-pixel map ``(H, W)`` in [0, 1], and the settings FLIP used."""

    mean: float
    error_map: np.ndarray
    settings: dict


def flip(
    test,
    reference,
    *,
    hdr: bool = True,
    ppd: float | None = None,
    tonemapper: str = "aces",
    start_exposure: float | None = None,
    stop_exposure: float | None = None,
    num_exposures: int | None = None,
) -> FlipResult:
    """NVIDIA FLIP perceptual difference of ``test`` against ``reference``.

    Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating Images" (LDR-FLIP),
    and 2021, "Visualizing Errors in Rendered High Dynamic Range Images" (HDR-FLIP).

    HDR-FLIP (``hdr=True``) is for linear images (EXR renders, values >= 0, unbounded): it tone
    maps both images at exposures from ``start_exposure`` to ``stop_exposure`` (by default chosen
    by FLIP from the reference's luminance range) and keeps the per-pixel maximum LDR-FLIP.
    LDR-FLIP (``hdr=False``) is for display-encoded sRGB images with values in [0, 1].

    Parameters
    ----------
    test, reference : array_like, shape (H, W, 3)
    hdr : bool
        HDR-FLIP on linear input (default) or LDR-FLIP on sRGB input.
    ppd : float, optional
        Pixels per degree of visual angle; default FLIP's 67 (0.7 m from a 0.7 m wide 4K monitor).
    tonemapper : {"aces", "hable", "reinhard"}
        Tone mapper HDR-FLIP assumes.
    start_exposure, stop_exposure : float, optional
        Exposure range in stops (give both or neither); default computed by FLIP.
    num_exposures : int >= 2, optional
        Number of exposures in the range; default computed by FLIP.

    Returns
    -------
    FlipResult(mean, error_map (H, W), settings)
        ``settings`` holds the ppd, tone mapper and exposures actually used (for reports).
    """
    test, reference = _image_pair(test, reference, ("test", "reference"))
    if test.shape != reference.shape or test.ndim != 3:
        raise PrefilterError(
            f"test, reference: expected two single images (H, W, 3) of the same shape, got "
            f"{test.shape} and {reference.shape}"
        )
    if hdr:
        for name, x in (("test", test), ("reference", reference)):
            if np.any(x < 0):
                raise PrefilterError(f"{name}: HDR-FLIP expects non-negative linear values, "
                                     f"got minimum {x.min():.4g}")
    else:
        for name, x in (("test", test), ("reference", reference)):
            if np.any((x < 0) | (x > 1)):
                raise PrefilterError(f"{name}: LDR-FLIP expects sRGB values in [0, 1], got range "
                                     f"[{x.min():.4g}, {x.max():.4g}]")
    params: dict = {}
    if ppd is not None:
        ppd = float(as_float_array(ppd, "ppd"))
        if not ppd > 0:
            raise PrefilterError(f"ppd: expected a positive number of pixels per degree, got {ppd}")
        params["ppd"] = ppd
    if tonemapper not in FLIP_TONEMAPPERS:
        raise PrefilterError(f"tonemapper: expected one of {FLIP_TONEMAPPERS}, got {tonemapper!r}")
    params["tonemapper"] = tonemapper
    if (start_exposure is None) != (stop_exposure is None):
        raise PrefilterError("start_exposure, stop_exposure: give both or neither")
    if start_exposure is not None:
        lo = float(as_float_array(start_exposure, "start_exposure"))
        hi = float(as_float_array(stop_exposure, "stop_exposure"))
        if lo > hi:
            raise PrefilterError(f"start_exposure: expected <= stop_exposure ({hi}), got {lo}")
        params.update(startExposure=lo, stopExposure=hi)
    if num_exposures is not None:
        # flip_evaluator silently returns 0 error for a single exposure
        params["numExposures"] = as_positive_int(num_exposures, "num_exposures", lo=2)

    ref32 = np.ascontiguousarray(reference, dtype=np.float32)
    test32 = np.ascontiguousarray(test, dtype=np.float32)
    if hdr and "startExposure" not in params and not np.any(ref32 > 0):
        # FLIP derives exposures from the reference's luminance and aborts the process on a black
        # reference; take them from the test image instead (two black images have zero error).
        if not np.any(test32 > 0):
            settings = {"ppd": params.get("ppd"), "tonemapper": tonemapper, "hdr": hdr}
            return FlipResult(0.0, np.zeros(test.shape[:2]), settings)
        auto = _flip_evaluate(test32, test32, hdr, params)[1]
        params.update(startExposure=auto["startExposure"], stopExposure=auto["stopExposure"])
    error_map, used = _flip_evaluate(ref32, test32, hdr, params)
    settings = {"hdr": hdr, "ppd": float(used["ppd"]), "tonemapper": str(used["tonemapper"])}
    if hdr:
        settings.update(
            start_exposure=float(used["startExposure"]),
            stop_exposure=float(used["stopExposure"]),
            num_exposures=int(used["numExposures"]),
        )
    error_map = error_map[..., 0].astype(np.float64)
    return FlipResult(float(error_map.mean()), error_map, settings)


def _flip_evaluate(ref32, test32, hdr: bool, params: dict):
    import flip_evaluator

    error_map, _, used = flip_evaluator.evaluate(
        ref32, test32, "HDR" if hdr else "LDR", inputsRGB=not hdr, applyMagma=False,
        computeMeanError=False, parameters=dict(params),
    )
    return np.asarray(error_map), used


def flip_heatmap(error_map) -> np.ndarray:
    """The FLIP error map ``(H, W)`` in [0, 1] as an sRGB ``uint8 (H, W, 3)`` magma heat map."""
    e = as_float_array(error_map, "error_map", ndim_min=2)
    if e.ndim != 2:
        raise PrefilterError(f"error_map: expected shape (H, W), got {e.shape}")
    if np.any((e < 0) | (e > 1 + 1e-6)):
        raise PrefilterError(f"error_map: expected values in [0, 1], got [{e.min()}, {e.max()}]")
    from matplotlib import colormaps

    rgba = colormaps["magma"](np.minimum(e, 1.0), bytes=True)
    return np.ascontiguousarray(rgba[..., :3])


# -------------------------------------------------------------------------------------- flicker


def flicker_map(frames, *, channels: str = "luminance") -> np.ndarray:
    """Per-pixel standard deviation ``(H, W)`` over K frames ``(K, H, W, 3)``.

    The sample standard deviation (``ddof=1``) of each pixel over the K frames, computed on
    Rec. 709 luminance (``channels="luminance"``, what the eye sees as flicker) or per RGB channel
    and averaged over the channels (``channels="rgb"``).
    """
    f = as_float_array(frames, "frames")
    if f.ndim != 4 or f.shape[-1] != 3 or f.shape[0] < 2 or 0 in f.shape:
        raise PrefilterError(f"frames: expected shape (K, H, W, 3) with K >= 2, got {f.shape}")
    if channels == "luminance":
        return _sample_std(f @ LUMINANCE_WEIGHTS)
    if channels == "rgb":
        return _sample_std(f).mean(axis=-1)
    raise PrefilterError(f"channels: expected 'luminance' or 'rgb', got {channels!r}")


def _sample_std(x: np.ndarray) -> np.ndarray:
    # shifting by the first frame makes a constant pixel exactly 0 (np.std leaves ~1e-17)
    d = x - x[0]
    return np.sqrt(np.sum((d - d.mean(axis=0)) ** 2, axis=0) / (x.shape[0] - 1))


def flicker(frames, *, channels: str = "luminance") -> float:
    """Temporal flicker: mean over pixels of :func:`flicker_map` of frames ``(K, H, W, 3)``.

    Render one view under K sub-pixel camera jitters (:func:`jitter_offsets`); an aliased shader
    changes pixel values between jitters, a well prefiltered one does not. Compare the method's
    flicker with the reference's (a supersampled reference flickers little).
    """
    return float(flicker_map(frames, channels=channels).mean())


def jitter_offsets(k: int) -> np.ndarray:
    """``k`` sub-pixel offsets ``(k, 2)`` in [-0.5, 0.5)^2: the Halton (2, 3) sequence, centred.

    Deterministic and well spread for any ``k``, so flicker numbers are reproducible.
    """
    k = as_positive_int(k, "k")
    i = np.arange(1, k + 1)
    return np.stack([_radical_inverse(i, 2), _radical_inverse(i, 3)], axis=-1) - 0.5


def _radical_inverse(i: np.ndarray, base: int) -> np.ndarray:
    out = np.zeros(i.shape)
    scale = 1.0 / base
    i = i.copy()
    while np.any(i > 0):
        out += (i % base) * scale
        i //= base
        scale /= base
    return out


def flicker_of(render: Callable[[np.ndarray], np.ndarray], k: int = 8, *,
               channels: str = "luminance") -> float:
    """:func:`flicker` of ``render(offset)`` over the ``k`` offsets of :func:`jitter_offsets`.

    ``render`` maps a sub-pixel camera offset ``(2,)`` (in pixels) to a linear image (H, W, 3).
    """
    k = as_positive_int(k, "k", lo=2)
    frames = [np.asarray(render(o), dtype=np.float64) for o in jitter_offsets(k)]
    shapes = {f.shape for f in frames}
    if len(shapes) != 1:
        raise PrefilterError(f"render: expected frames of one shape, got {sorted(shapes)}")
    return flicker(np.stack(frames), channels=channels)


# ----------------------------------------------------------------------------- display encoding


def tonemap(image, *, method: str = "aces", exposure: float = 0.0) -> np.ndarray:
    """Map linear radiance ``(..., 3)`` scaled by ``2**exposure`` to display-linear [0, 1].

    ``"aces"``: Narkowicz's 2015 fit of the ACES filmic curve (the curve HDR-FLIP assumes by
    default) ``x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)``; ``"reinhard"``: ``x / (1 + x)``;
    ``"clamp"``: ``min(x, 1)``. Negative values are clamped to 0.
    """
    x = as_float_array(image, "image", ndim_min=1, last_dim=3)
    e = float(as_float_array(exposure, "exposure"))
    x = np.maximum(x * 2.0**e, 0.0)
    if method == "aces":
        y = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)
    elif method == "reinhard":
        y = x / (1.0 + x)
    elif method == "clamp":
        y = x
    else:
        raise PrefilterError(f"method: expected one of {TONEMAPS}, got {method!r}")
    return np.clip(y, 0.0, 1.0)


def linear_to_srgb(x) -> np.ndarray:
    """The sRGB transfer function (IEC 61966-2-1) on display-linear values in [0, 1]."""
    x = np.clip(as_float_array(x, "x"), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(x) -> np.ndarray:
    """Inverse of :func:`linear_to_srgb` on sRGB values in [0, 1]."""
    x = np.clip(as_float_array(x, "x"), 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def to_srgb8(image, *, exposure: float = 0.0, method: str = "aces") -> np.ndarray:
    """Linear RGB ``(..., 3)`` to displayable sRGB ``uint8 (..., 3)``: tone map, encode, round."""
    y = linear_to_srgb(tonemap(image, method=method, exposure=exposure))
    return np.round(y * 255.0).astype(np.uint8)


def from_srgb8(image) -> np.ndarray:
    """sRGB ``uint8 (..., 3)`` to linear float64 in [0, 1]."""
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise PrefilterError(f"image: expected uint8 sRGB values, got dtype {a.dtype}")
    return srgb_to_linear(a / 255.0)
