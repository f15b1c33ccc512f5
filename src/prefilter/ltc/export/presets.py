"""Engine-layout files of the isotropic GGX LTC table (one writer per engine preset).

The reference code, three.js, Babylon.js, Blender, Unreal and the Bevy preset store the texels of
:func:`prefilter.ltc.export.layout.ltc_code_textures` (``u = sqrt(alpha)``,
``v = sqrt(1 - cos theta)``, 64 x 64 nodes at texel centres, inverse matrix divided by its middle
entry, ``ltc_2 = (n, f5, 0, sphere)``) in the container and element order each loader expects;
Godot (forward matrix, rows uniform in theta) and Unity HDRP (inverse matrix divided by its last
entry, another channel order) resample the table to their own conventions; ``compact`` encodes
the table's own grid (:mod:`prefilter.ltc.export.compact`). ``docs/ltc-export.md`` gives the
conventions and their sources per engine.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.fileio import atomic_path
from prefilter.ltc.export.layout import ENGINE_SIZE, ltc_code_textures, resample
from prefilter.texture.containers import write_dds, write_ktx2

__all__ = ["PRESETS", "Preset", "export_preset", "half_bits"]


def half_bits(x) -> np.ndarray:
    """IEEE 754 binary16 bit patterns (``uint16``) of ``x``, rounded to nearest even."""
    return np.asarray(x, dtype=np.float64).astype(np.float16).view(np.uint16)


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _write_bytes(path: Path, blob: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(blob)


def _literal(x: float, suffix: str) -> str:
    """A float32 literal with 9 significant digits (round-trips); C needs a '.' or exponent
    before the ``f`` suffix."""
    s = f"{x:.9g}"
    if suffix and not any(ch in s for ch in ".en"):
        s += ".0"
    return s + suffix


def _floats(values, per_line: int = 8, suffix: str = "") -> str:
    """Comma-separated float32 literals, ``per_line`` to a line."""
    v = np.asarray(values, dtype=np.float32).ravel()
    items = [_literal(float(x), suffix) for x in v]
    return ",\n".join(", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line))


def _ints(values, per_line: int = 16) -> str:
    items = [str(int(x)) for x in np.ravel(values)]
    return ",\n".join(", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line))


def _header(preset: str, table) -> str:
    return (f"Isotropic GGX LTC table written by `prefilter export-ltc --preset {preset}` "
            f"(table: {len(table.axis_t)} x {len(table.axis_r)}, alpha >= {table.alpha_min:.4g}, "
            f"theta <= {np.degrees(table.theta_max):.3g} deg)")


# ------------------------------------------------------------------------------------------------
# writers: (table, out_dir) -> list of written paths
# ------------------------------------------------------------------------------------------------


def _ltc_code(table, out: Path) -> list[Path]:
    """``ltc_1.dds``, ``ltc_2.dds`` (RGBA32F), ``ltc.js`` (``g_ltc_1``, ``g_ltc_2``) and
    ``ltc.inc`` (``tabM``, ``tabMinv``, ``tabMagnitude``), as the reference code's ``export.h``."""
    ltc_1, ltc_2 = ltc_code_textures(table)
    paths = [out / "ltc_1.dds", out / "ltc_2.dds", out / "ltc.js", out / "ltc.inc"]
    write_dds(paths[0], ltc_1.astype(np.float32))
    write_dds(paths[1], ltc_2.astype(np.float32))
    _write_text(paths[2], f"// {_header('ltc_code', table)}\n"
                f"var g_ltc_1 = [\n{_floats(ltc_1, 4)}\n];\n"
                f"var g_ltc_2 = [\n{_floats(ltc_2, 4)}\n];\n")
    M, n, _ = resample(table)
    Minv = np.linalg.inv(M)
    # glm is column-major: element [col][row], written col by col as export.h's writeTabC does
    col_major = np.swapaxes(M, -1, -2).reshape(-1, 9)
    col_major_inv = np.swapaxes(Minv, -1, -2).reshape(-1, 9)
    rows = ",\n".join("{" + _floats(e, 9, "f") + "}" for e in col_major)
    rows_inv = ",\n".join("{" + _floats(e, 9, "f") + "}" for e in col_major_inv)
    _write_text(paths[3], f"// {_header('ltc_code', table)}\n"
                f"// index [a + t * size]: a = roughness node (sqrt(alpha)), t = node of\n"
                f"// sqrt(1 - cos theta); mat33 column-major; M forward, third column of unit"
                f" length\n"
                f"static const int size = {ENGINE_SIZE};\n\n"
                f"static const mat33 tabM[size*size] = {{\n{rows}\n}};\n\n"
                f"static const mat33 tabMinv[size*size] = {{\n{rows_inv}\n}};\n\n"
                f"static const float tabMagnitude[size*size] = {{\n"
                f"{_floats(n, 8, suffix='f')}\n}};\n")
    return paths


_THREE_MODULE = """\
// {header}
// three.js layout (examples/jsm/lights/RectAreaLightTexturesLib.js): 64 x 64 RGBA, rows
// v = sqrt(1 - cos theta), columns sqrt(alpha); LTC_*_1 = inverse matrix (m00, m20, m02, m22)
// divided by m11, LTC_*_2 = (magnitude, fresnel, 0, sphere form factor).
// WebGLRenderer: after RectAreaLightUniformsLib.init(), set UniformsLib.LTC_FLOAT_1/2 and
// LTC_HALF_1/2 to those of PrefilterLTCTexturesLib.init();
// WebGPURenderer: RectAreaLightNode.setLTC( PrefilterLTCTexturesLib.init() ).
import {{ ClampToEdgeWrapping, DataTexture, FloatType, HalfFloatType, LinearFilter, NearestFilter,
	RGBAFormat, UVMapping }} from 'three';

export const LTC_FLOAT_DATA_1 = new Float32Array( [
{f1}
] );

export const LTC_FLOAT_DATA_2 = new Float32Array( [
{f2}
] );

export const LTC_HALF_DATA_1 = new Uint16Array( [
{h1}
] );

export const LTC_HALF_DATA_2 = new Uint16Array( [
{h2}
] );

function dataTexture( data, type ) {{

	const texture = new DataTexture( data, {size}, {size}, RGBAFormat, type, UVMapping,
		ClampToEdgeWrapping, ClampToEdgeWrapping, LinearFilter, NearestFilter, 1 );
	texture.needsUpdate = true;
	return texture;

}}

export const PrefilterLTCTexturesLib = {{

	LTC_FLOAT_1: null, LTC_FLOAT_2: null, LTC_HALF_1: null, LTC_HALF_2: null,

	init() {{

		if ( this.LTC_FLOAT_1 === null ) {{

			this.LTC_FLOAT_1 = dataTexture( LTC_FLOAT_DATA_1, FloatType );
			this.LTC_FLOAT_2 = dataTexture( LTC_FLOAT_DATA_2, FloatType );
			this.LTC_HALF_1 = dataTexture( LTC_HALF_DATA_1, HalfFloatType );
			this.LTC_HALF_2 = dataTexture( LTC_HALF_DATA_2, HalfFloatType );

		}}

		return this;

	}}

}};
"""


def _threejs(table, out: Path) -> list[Path]:
    """``PrefilterLTCTexturesLib.js``: the four three.js DataTextures (float and half)."""
    ltc_1, ltc_2 = ltc_code_textures(table)
    path = out / "PrefilterLTCTexturesLib.js"
    _write_text(path, _THREE_MODULE.format(
        header=_header("threejs", table), size=ENGINE_SIZE, f1=_floats(ltc_1, 8),
        f2=_floats(ltc_2, 8), h1=_ints(half_bits(ltc_1)), h2=_ints(half_bits(ltc_2))))
    return [path]


def _babylon(table, out: Path) -> list[Path]:
    """``areaLightsLTC.bin``: per texel 8 little-endian binary16, ``ltc_1`` RGBA then ``ltc_2``
    RGBA (Babylon.js ``DecodeLTCTextureDataAsync`` de-interleaves it into two RGBA16F)."""
    ltc_1, ltc_2 = ltc_code_textures(table)
    interleaved = np.concatenate([half_bits(ltc_1), half_bits(ltc_2)], -1)  # (64, 64, 8)
    path = out / "areaLightsLTC.bin"
    _write_bytes(path, interleaved.astype("<u2").tobytes())
    return [path]


def _blender(table, out: Path) -> list[Path]:
    """``eevee_lut_ltc_ggx.cc``: ``ltc_mat_ggx[64][64][4]`` (= ``ltc_1``) and
    ``ltc_mag_ggx[64][64][2]`` (= ``(n, f5)``), ``[v][roughness]``, as EEVEE's ``eevee_lut.cc``."""
    ltc_1, ltc_2 = ltc_code_textures(table)
    path = out / "eevee_lut_ltc_ggx.cc"
    _write_text(path, f"/* {_header('blender', table)}.\n"
                f" * Replaces the two tables of source/blender/draw/engines/eevee/eevee_lut.cc:\n"
                f" * [y][x] = [sqrt(1 - cos theta)][roughness]; inverse matrix / m11; (n, f5)."
                f" */\n\n"
                f"namespace blender::eevee::lut {{\n\n"
                f"const float ltc_mat_ggx[64][64][4] = {{\n{_floats(ltc_1, 8, suffix='f')}\n}};\n\n"
                f"const float ltc_mag_ggx[64][64][2] = {{\n"
                f"{_floats(ltc_2[..., :2], 8, suffix='f')}\n}};\n\n"
                f"}}  // namespace blender::eevee::lut\n")
    return [path]


def _godot(table, out: Path) -> list[Path]:
    """``ltc_lut1.dds = (a, b, c, d)``, ``ltc_lut2.dds = (e, n, f5, 0)`` (RGBA32F): the *forward*
    matrix ``[[a, 0, d], [0, c, 0], [b, 0, e]]`` (row, column) on rows ``theta / (pi / 2)``, as
    Godot's ``area_lights_inc.glsl`` (``ltc_evaluate_specular``) reads it."""
    M, n, f5 = resample(table, view="theta")
    lut1 = np.stack([M[..., 0, 0], M[..., 2, 0], M[..., 1, 1], M[..., 0, 2]], -1)
    lut2 = np.stack([M[..., 2, 2], n, f5, np.zeros_like(n)], -1)
    paths = [out / "ltc_lut1.dds", out / "ltc_lut2.dds"]
    write_dds(paths[0], lut1.astype(np.float32))
    write_dds(paths[1], lut2.astype(np.float32))
    return paths


_HDRP_SOURCE = """\
// {header}
// Replaces Packages/com.unity.render-pipelines.high-definition/Runtime/Material/LTCAreaLight/
// Generated/LtcData.BRDF_GGX.cs. Index [roughnessIndex + 64 * thetaIndex]: alpha =
// (roughnessIndex / 63)^2, cos theta = 1 - (thetaIndex / 63)^2. Each texel: binary16 bits of
// (m00, m20, m11, m02) of M^-1 / m22, read by SampleLtcMatrix as the transposed matrix's
// _m00_m02_m11_m20 with _m22 = 1. No magnitude: HDRP takes it from its own FGD table.
using UnityEngine;
using System;

namespace UnityEngine.Rendering.HighDefinition
{{
    internal partial class LTCAreaLight
    {{
        internal static ushort[] s_LtcMatrixData_BRDF_GGX = new ushort[64 * 64 * 4]
        {{
{body}
        }};
    }}
}}
"""


def _unity_hdrp(table, out: Path) -> list[Path]:
    """``LtcData.BRDF_GGX.cs``: HDRP's ``s_LtcMatrixData_BRDF_GGX`` (binary16 bits of
    ``(m00, m20, m11, m02)`` of ``M^-1 / (M^-1)_22``), the reference code's grid."""
    M, _, _ = resample(table)
    Minv = np.linalg.inv(M)
    Minv = Minv / Minv[..., 2:3, 2:3]
    texels = np.stack([Minv[..., 0, 0], Minv[..., 2, 0], Minv[..., 1, 1], Minv[..., 0, 2]], -1)
    bits = half_bits(texels).reshape(-1, 4)
    body = ",\n".join("            " + ", ".join(str(int(x)) for x in row) for row in bits)
    path = out / "LtcData.BRDF_GGX.cs"
    _write_text(path, _HDRP_SOURCE.format(header=_header("unity-hdrp", table), body=body))
    return [path]


_UNREAL_HEADER = """\
// {header}
// Replaces Engine/Source/Runtime/Renderer/Private/LTC.h. FSystemTextures uploads LTC_Mat to the
// 64 x 64 PF_FloatRGBA texture LTCMat and channels 0-1 of LTC_Amp to the PF_G16R16F texture
// LTCAmp, texel (x, y) <- [4 * (x + y * LTC_Size) + k] (x = Roughness = sqrt(alpha),
// y = sqrt(1 - NoV), nodes at i / 63, sampled at uv * 63/64 + 0.5/64). LTC_Mat = (m00, m20, m02,
// m22) of M^-1 / (M^-1)_11, the matrix RectGGXApproxLTC applies to the rect (HLSL rows (x, 0, z),
// (0, 1, 0), (y, 0, w)); the shader inverts it to the forward matrix M (its InvLTC).
// LTC_Amp = (magnitude, fresnel, 0, sphere): SpecularColor = y + (x - y) * F0; z, w unread.
#pragma once

const int LTC_Size = 64;

static const float LTC_Mat[LTC_Size * LTC_Size * 4] = {{
{mat}
}};

static const float LTC_Amp[LTC_Size * LTC_Size * 4] = {{
{amp}
}};
"""


def _unreal(table, out: Path) -> list[Path]:
    """``LTC.h``: Unreal's ``LTC_Mat`` (the reference code's ``ltc_1`` texels, inverse matrix)
    and ``LTC_Amp`` (``ltc_2``), ``[4 * (x + y * 64) + k]``, as ``FSystemTextures`` uploads them."""
    ltc_1, ltc_2 = ltc_code_textures(table)
    path = out / "LTC.h"
    _write_text(path, _UNREAL_HEADER.format(header=_header("unreal", table),
                                            mat=_floats(ltc_1, 8, suffix="f"),
                                            amp=_floats(ltc_2, 8, suffix="f")))
    return [path]


def _bevy(table, out: Path) -> list[Path]:
    """``ltc_ggx.ktx2``: one 2-layer RGBA16F texture array (``ltc_1``, ``ltc_2``), Zstandard
    supercompressed."""
    ltc_1, ltc_2 = ltc_code_textures(table)
    path = out / "ltc_ggx.ktx2"
    write_ktx2(path, np.stack([ltc_1, ltc_2]).astype(np.float16), supercompression="zstd")
    return [path]


def _compact(table, out: Path) -> list[Path]:
    """``ggx_iso_half.npz`` and ``ggx_iso_fit.npz``: the encodings of
    :mod:`prefilter.ltc.export.compact` (checksummed ``.npz``)."""
    from prefilter.fileio import save_npz_atomic
    from prefilter.ltc.export.compact import ENCODINGS, encode

    paths = []
    for name in ENCODINGS:
        path = out / f"ggx_iso_{name}.npz"
        save_npz_atomic(path, format_name=f"ltc-iso-{name}", format_version=1,
                        **encode(table, name))
        paths.append(path)
    return paths


@dataclass(frozen=True)
class Preset:
    """One engine layout: ``write(table, out_dir) -> [paths]`` and a one-line summary."""

    write: Callable
    summary: str


PRESETS: dict[str, Preset] = {
    "ltc_code": Preset(_ltc_code, "reference code: ltc_1/ltc_2.dds (RGBA32F), ltc.js, ltc.inc"),
    "threejs": Preset(_threejs, "three.js: LTC_FLOAT_1/2 (Float32) and LTC_HALF_1/2 (half) "
                                "DataTextures in an ES module"),
    "babylon": Preset(_babylon, "Babylon.js: areaLightsLTC.bin (interleaved half floats)"),
    "godot": Preset(_godot, "Godot 4: ltc_lut1.dds, ltc_lut2.dds (RGBA32F, forward matrix, rows "
                            "theta)"),
    "blender": Preset(_blender, "Blender EEVEE: ltc_mat_ggx[64][64][4], ltc_mag_ggx[64][64][2]"),
    "unity-hdrp": Preset(_unity_hdrp, "Unity HDRP: LtcData.BRDF_GGX.cs (binary16 M^-1 / m22, "
                                      "no magnitude)"),
    "unreal": Preset(_unreal, "Unreal Engine: LTC.h (LTC_Mat inverse-matrix texels, LTC_Amp "
                              "magnitude / fresnel; uploaded as half floats)"),
    "bevy": Preset(_bevy, "KTX2 (zstd) 2-layer RGBA16F array in the reference layout (no "
                          "upstream Bevy reader)"),
    "compact": Preset(_compact, "the table's own grid as binary16 texels and as Chebyshev "
                                "coefficients (.npz)"),
}


def export_preset(preset: str, out_dir: str | os.PathLike, table=None) -> list[Path]:
    """Write the table (default: the shipped one) in ``preset``'s layout into ``out_dir``.

    Returns the written paths. Raises :class:`~prefilter.errors.PrefilterError` for an unknown
    preset.
    """
    from prefilter.ltc.table import as_table

    if preset not in PRESETS:
        raise PrefilterError(f"preset: expected one of {', '.join(sorted(PRESETS))}, "
                             f"got {preset!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return PRESETS[preset].write(as_table(table), out)
