"""GLSL of the multi-scale roughness as the ``ltc-multiscale`` method computes it, and the data it
reads.

Tao et al. 2021: ``alpha_meso(r)`` inverts eq. 4 (the mean resultant length of the footprint's
normals) and ``alpha_total`` combines micro and meso roughness (eq. 7 form). The Python default
(:mod:`prefilter.multiscale.meso`, ``variant="exact"``) interpolates the exact inverse linearly at
4097 nodes uniform in ``x = sqrt(3 (1 - r))``; the shader reads the same nodes from a float32
texture of ``ALPHA_MESO_WIDTH`` texels per row (:func:`alpha_meso_nodes`) and interpolates them
the same way. ``alpha_total`` is our refit (:data:`prefilter.multiscale.FIT_COEFFS`) in closed
form. The normal-map footprint bias of each method's default (``lod_bias``, ``lod_bias_start``)
and its anisotropic taps of near, elongated footprints (``taps``, ``taps_below``, ``taps_ratio``,
``taps_normalize``) are read from their signatures (:func:`footprint_bias`,
:func:`footprint_taps`), so the shader follows the Python defaults; the viewer's
``viewer.frag.glsl`` (``footprintMs``) reads the normal map with them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter.fileio import atomic_path, write_text_atomic

__all__ = ["ALPHA_MESO_WIDTH", "GLSL", "alpha_meso_nodes", "export_all",
           "footprint_bias", "footprint_taps", "glsl_source"]

#: Texels per row of the ``alpha_meso`` node texture (WebGL2 guarantees 2048).
ALPHA_MESO_WIDTH = 64

GLSL = """\
// Multi-scale LTC roughness (Tao et al. 2021, eqs. 4-7; prefilter `multiscale/glsl.py`).
// alphaMesoNodes: {n} floats alpha(x_k), x_k = k / {last}, x = sqrt(3 (1 - r)), {w} per row.
uniform highp sampler2D alphaMesoNodes;
const int MS_NODES = {n}, MS_ROW = {w};

float msNode(int k) {{ return texelFetch(alphaMesoNodes, ivec2(k % MS_ROW, k / MS_ROW), 0).r; }}

// eq. 4 inverted: meso roughness from the length r of the footprint's averaged normal
float alphaMeso(float r) {{
    float x = sqrt(clamp(3.0 * (1.0 - r), 0.0, 1.0)) * float(MS_NODES - 1);
    int k = min(int(floor(x)), MS_NODES - 2);
    return mix(msNode(k), msNode(k + 1), x - float(k));
}}

// The methods' default footprint bias: the normal map is read 2^s coarser, s = bias, or, with a
// ramp start (>= 0), s = clamp(log2(max(major, 1)) - start, 0, bias) for a footprint whose major
// axis is `major` texels (prefilter.multiscale.render._bias_scale).
const float MS_LOD_BIAS = {bias!r}, MS_LOD_START = {start!r};        // ltc-multiscale
const float MSA_LOD_BIAS = {abias!r}, MSA_LOD_START = {astart!r};    // ltc-multiscale-aniso
float msLodScale(float major, float bias, float start) {{
    if (start < 0.0) return exp2(bias);
    return exp2(clamp(log2(max(major, 1.0)) - start, 0.0, bias));
}}

// ltc-multiscale's anisotropic taps (prefilter.multiscale.render.taps_lookup): a footprint whose
// major axis is below MS_TAPS_BELOW texels and longer than MS_TAPS_RATIO times the minor one is
// read as the mean of clamp(ceil(major / minor), 2, MS_TAPS) unnormalised trilinear taps along
// the major axis at the LOD of max(minor, major / n); MS_TAPS < 2: off. MS_TAPS_NORM: each tap's
// level-0 read renormalised below LOD 1.
const int MS_TAPS = {taps};
const float MS_TAPS_BELOW = {below}, MS_TAPS_RATIO = {ratio};
const bool MS_TAPS_NORM = {norm};

// eqs. 6-7, our refit: alpha^2 = a^2 + b^2 + ab (c0 + p (c1 + c2 p) + c3 ab), p = a + b
float alphaTotal(float a, float b) {{
    float p = a + b, q = a * b;
    float t2 = a * a + b * b + q * ({c0:.9g} + p * ({c1:.9g} + {c2:.9g} * p) + {c3:.9g} * q);
    return clamp(sqrt(max(t2, 0.0)), 0.0, 1.0);
}}
"""


def alpha_meso_nodes() -> np.ndarray:
    """The nodes ``alpha(x_k)`` of the default ``alpha_meso`` as float32, padded with the last
    value to rows of :data:`ALPHA_MESO_WIDTH`: shape ``(rows, ALPHA_MESO_WIDTH)``."""
    from prefilter.multiscale.meso import _A_NODES

    n = len(_A_NODES)
    rows = -(-n // ALPHA_MESO_WIDTH)
    out = np.full(rows * ALPHA_MESO_WIDTH, _A_NODES[-1], np.float32)
    out[:n] = _A_NODES
    return out.reshape(rows, ALPHA_MESO_WIDTH)


def footprint_bias(fn) -> tuple[float, float]:
    """``(lod_bias, lod_bias_start)`` defaults of a render method's signature (``start = -1``
    for a constant bias; ``(0, -1)`` for methods without the options)."""
    import inspect

    params = inspect.signature(fn).parameters

    def default(name, fallback):
        p = params.get(name)
        return fallback if p is None or p.default is inspect.Parameter.empty else p.default

    start = default("lod_bias_start", None)
    return float(default("lod_bias", 0.0)), -1.0 if start is None else float(start)


def footprint_taps(fn) -> tuple[int, float, float, bool]:
    """``(taps, taps_below, taps_ratio, taps_normalize)`` defaults of a render method's signature
    (``(0, 4.0, 1.5, False)``, i.e. no taps, for methods without the options)."""
    import inspect

    params = inspect.signature(fn).parameters

    def default(name, fallback):
        p = params.get(name)
        return fallback if p is None or p.default is inspect.Parameter.empty else p.default

    return (int(default("taps", 0)), float(default("taps_below", 4.0)),
            float(default("taps_ratio", 1.5)), bool(default("taps_normalize", False)))


def _glsl_float(x: float) -> str:
    # GLSL ES has no inf literal: "below inf texels" (every footprint) is below float32's max
    return "3.0e38" if x > 3.0e38 else repr(float(x))


def glsl_source() -> str:
    """:data:`GLSL` with the node count, :data:`~prefilter.multiscale.FIT_COEFFS`, the default
    footprint biases of ``render_multiscale`` / ``render_multiscale_aniso`` and the default
    anisotropic taps of ``render_multiscale`` filled in."""
    from prefilter.multiscale.aniso import render_multiscale_aniso
    from prefilter.multiscale.convolution import FIT_COEFFS
    from prefilter.multiscale.meso import _A_NODES
    from prefilter.multiscale.render import render_multiscale

    c0, c1, c2, c3 = FIT_COEFFS
    n = len(_A_NODES)
    bias, start = footprint_bias(render_multiscale)
    abias, astart = footprint_bias(render_multiscale_aniso)
    taps, below, ratio, norm = footprint_taps(render_multiscale)
    return GLSL.format(n=n, last=n - 1, w=ALPHA_MESO_WIDTH, c0=c0, c1=c1, c2=c2, c3=c3,
                       bias=bias, start=start, abias=abias, astart=astart, taps=taps,
                       below=_glsl_float(below), ratio=_glsl_float(ratio),
                       norm="true" if norm else "false")


def export_all(out_dir) -> list[Path]:
    """Write ``alpha_meso_f32.bin`` (raw little-endian float32 :func:`alpha_meso_nodes`) and
    ``multiscale.glsl``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    b, g = out / "alpha_meso_f32.bin", out / "multiscale.glsl"
    with atomic_path(b, suffix=".bin") as tmp:
        tmp.write_bytes(alpha_meso_nodes().astype("<f4").tobytes())
    write_text_atomic(g, glsl_source())
    return [b, g]
