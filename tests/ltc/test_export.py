"""Engine-layout exports of the isotropic GGX table, checked as each engine reads them.

Every preset's files are read back (DDS and KTX2 by field parsers written from the specifications,
JavaScript by node, C/C++ by g++, where installed), and the decoded texels are fed to the engines'
lookup, written here in NumPy as the shaders do it (three.js ``LTC_Uv`` + ``RE_Direct_RectArea``,
the reference code's ``ltc_quad.fs``, Babylon.js ``LTCUv`` / ``computeAreaLighting``, EEVEE
``lut_coords_ltc`` / ``ltc_matrix``):

    uv = (sqrt(alpha), sqrt(1 - cos theta)) * 63/64 + 0.5/64, bilinear, clamp to edge
    M^-1 = mat3(vec3(t1.x, 0, t1.y), vec3(0, 1, 0), vec3(t1.z, 0, t1.w))   (column-major)
    L = (F0 t2.x + (1 - F0) t2.y) * integral over M^-1 P

and compared with :class:`GGXTable` (``schlick_scale(n, f5, F0) * polygon_integral(M, P)``) on
random quads. At the engine's texel centres the two must agree to the storage precision; between
them the engine interpolates inverse-matrix texels while the table interpolates forward matrices
on its own grid, and the difference is the interpolation error (measured: median 3e-4, max 4 %).
A half-texel, axis or channel mistake breaks the texel-centre agreement by orders of magnitude
(:func:`test_lookup_detects_convention_errors`).
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from prefilter.ltc.export import PRESETS, export_preset, ltc_code_textures
from prefilter.sphere.polygon import polygon_integral, polygon_integral_minv
from prefilter.ltc.table import GGXTable
from prefilter.ltc.validate import random_quads

SIZE = 64


def _load_readers():
    """The spec-field DDS / KTX2 parsers of ``tests/texture/test_containers.py``."""
    path = Path(__file__).resolve().parents[1] / "texture" / "test_containers.py"
    spec = importlib.util.spec_from_file_location("_container_readers", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.read_dds, module.read_ktx2


read_dds, read_ktx2 = _load_readers()


@pytest.fixture(scope="module")
def table():
    return GGXTable.load()


@pytest.fixture(scope="module")
def exported(tmp_path_factory, table):
    out = tmp_path_factory.mktemp("ltc_export")
    has_zstd = importlib.util.find_spec("zstandard") is not None
    # bevy's KTX2 needs zstandard (its test skips without it)
    return {p: export_preset(p, out / p, table) for p in PRESETS if p != "bevy" or has_zstd}


@pytest.fixture(scope="module")
def reference_texels(table):
    return ltc_code_textures(table)


# --- the engines' lookup --------------------------------------------------------------------------


def sample_linear(tex, u, v):
    """GL_LINEAR with CLAMP_TO_EDGE of ``tex (H, W, C)`` at ``(u, v)`` in [0, 1]."""
    H, W = tex.shape[:2]
    x = np.clip(u * W - 0.5, 0, W - 1)
    y = np.clip(v * H - 0.5, 0, H - 1)
    i = np.minimum(np.floor(x).astype(int), W - 2)
    j = np.minimum(np.floor(y).astype(int), H - 2)
    a = (x - i)[..., None]
    b = (y - j)[..., None]
    return ((1 - a) * (1 - b) * tex[j, i] + a * (1 - b) * tex[j, i + 1]
            + (1 - a) * b * tex[j + 1, i] + a * b * tex[j + 1, i + 1])


def engine_lookup(ltc_1, ltc_2, roughness, cos_theta):
    """``(M^-1 (..., 3, 3), t2 (..., 4))`` as the shaders read them (view along +x)."""
    u = roughness * (SIZE - 1) / SIZE + 0.5 / SIZE
    v = np.sqrt(1.0 - cos_theta) * (SIZE - 1) / SIZE + 0.5 / SIZE
    t1 = sample_linear(np.asarray(ltc_1, float), u, v)
    t2 = sample_linear(np.asarray(ltc_2, float), u, v)
    Minv = np.zeros(t1.shape[:-1] + (3, 3))
    # GLSL mat3(c0, c1, c2) takes columns: c0 = (t1.x, 0, t1.y), c2 = (t1.z, 0, t1.w)
    Minv[..., 0, 0], Minv[..., 2, 0] = t1[..., 0], t1[..., 1]
    Minv[..., 0, 2], Minv[..., 2, 2] = t1[..., 2], t1[..., 3]
    Minv[..., 1, 1] = 1.0
    return Minv, t2


# Godot's frame (area_lights_inc.glsl, ltc_evaluate): z = -normalize(V - N (V.N)), x = N x z,
# y = N, so p_godot = P p with P below; its cosine is about y, brought back to z by S.
GODOT_P = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
GODOT_S = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def godot_lookup(lut1, lut2, roughness, cos_theta):
    """As ``ltc_evaluate_specular``: ``uv = (max(r, 0.02), theta / (pi/2)) * 63/64 + 0.5/64``,
    ``M_inv`` from the forward entries ``(a, b, c, d)``, ``e``; returned in the standard frame
    with ``(n, f5)`` (Godot's ``fresnel = (mag, fres)``, ``F = f0 x + (f90 - f0) y``). Exact
    ``acos`` here where the shader uses ``acos_approx``."""
    theta = np.arccos(np.clip(cos_theta, -1.0, 1.0))
    u = np.maximum(roughness, 0.02) * (SIZE - 1) / SIZE + 0.5 / SIZE
    v = theta / (0.5 * np.pi) * (SIZE - 1) / SIZE + 0.5 / SIZE
    abcd = sample_linear(np.asarray(lut1, float), u, v)
    emf = sample_linear(np.asarray(lut2, float), u, v)
    a, b, c, d = (abcd[..., k] for k in range(4))
    e = emf[..., 0]
    s = 1.0 / (a * e - b * d)
    Minv = np.zeros(a.shape + (3, 3))
    # GLSL mat3(col0, col1, col2): col0 = (0, 0, 1/c), col1 = (-d s, a s, 0), col2 = (-e s, b s, 0)
    Minv[..., 2, 0] = 1.0 / c
    Minv[..., 0, 1], Minv[..., 1, 1] = -d * s, a * s
    Minv[..., 0, 2], Minv[..., 1, 2] = -e * s, b * s
    return GODOT_S @ Minv @ GODOT_P, emf[..., 1:3]


def relative_errors(table, ltc_1, ltc_2, roughness, cos_theta, quads, f0, lookup=None):
    """Relative error of the engine's shading against the table's where the table's LTC
    integral is >= 1e-3 (quads that catch some of the lobe)."""
    Minv, t2 = (lookup or engine_lookup)(ltc_1, ltc_2, roughness, cos_theta)
    engine = (f0 * t2[..., 0] + (1 - f0) * t2[..., 1]) * polygon_integral_minv(Minv, quads)
    M, n, f5 = table.lookup_canonical(cos_theta, roughness ** 2)
    E = polygon_integral(M, quads)
    ref = (f0 * (n - f5) + f5) * E
    keep = E >= 1e-3
    assert keep.sum() > 0.7 * len(ref)
    return np.abs(engine - ref)[keep] / ref[keep]


def node_configurations(k=400, seed=5, view="sqrt"):
    """Roughness and view at engine texel centres inside the table's range, with quads."""
    rng = np.random.default_rng(seed)
    i = rng.integers(7, SIZE, k)  # sqrt(alpha) >= 0.111 > sqrt(alpha_min) = 0.1
    # sqrt(1 - cos theta) <= 61/63 < that of 88 deg; theta <= 61/63 * 90 = 87.1 deg
    v = rng.integers(0, SIZE - 2, k) / (SIZE - 1)
    cos_theta = 1.0 - v ** 2 if view == "sqrt" else np.cos(0.5 * np.pi * v)
    return i / (SIZE - 1), cos_theta, random_quads(k, rng)


def random_configurations(k=400, seed=6):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.1, 1.0, k)
    v = rng.uniform(0.0, 0.96, k)
    return r, 1.0 - v * v, random_quads(k, rng)


def check_convention(table, ltc_1, ltc_2, *, node_tol, lookup=None, view="sqrt"):
    """Texel centres: agreement to ``node_tol`` (storage precision); elsewhere: the
    interpolation difference (median <= 2e-3, p90 <= 1e-2, max <= 6e-2)."""
    for f0 in (1.0, 0.04):
        rel = relative_errors(table, ltc_1, ltc_2, *node_configurations(view=view), f0, lookup)
        assert rel.max() <= node_tol, (f0, rel.max())
        rel = relative_errors(table, ltc_1, ltc_2, *random_configurations(), f0, lookup)
        assert np.median(rel) <= 2e-3 and np.percentile(rel, 90) <= 1e-2 and rel.max() <= 6e-2


# float32 texels: the integral's relative rounding error stays below 1e-5 (measured 3e-7);
# binary16 keeps 11 significant bits (relative 4.9e-4 per entry): below 1e-2 (measured 5e-3)
F32_TOL, F16_TOL = 1e-5, 1e-2


# --- readers ------------------------------------------------------------------------------------


def node_json(script: str, cwd) -> object:
    if shutil.which("node") is None:
        pytest.skip("node is not installed")
    (Path(cwd) / "check.mjs").write_text(script)
    res = subprocess.run(["node", "check.mjs"], cwd=cwd, capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def cxx_output(source: str, tmp_path) -> np.ndarray:
    if shutil.which("g++") is None:
        pytest.skip("g++ is not installed")
    (tmp_path / "main.cc").write_text(source)
    exe = tmp_path / "main"
    res = subprocess.run(["g++", "-std=c++17", "-O0", "-o", str(exe), "main.cc"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    out = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60, check=True)
    return np.array(out.stdout.split(), dtype=np.float64)


# --- presets ------------------------------------------------------------------------------------


def test_cli_choices_are_the_presets():
    from prefilter.ltc.commands import export_ltc

    opt = next(p for p in export_ltc.params if p.name == "preset")
    assert sorted(opt.type.choices) == sorted(PRESETS)


def test_ltc_code_dds(exported, table, reference_texels):
    paths = {p.name: p for p in exported["ltc_code"]}
    textures = []
    for name in ("ltc_1.dds", "ltc_2.dds"):
        head, data = read_dds(paths[name].read_bytes())
        assert head == {"height": SIZE, "width": SIZE, "mips": 1, "format": "R32G32B32A32_FLOAT"}
        textures.append(data[0])
    ltc_1, ltc_2 = textures
    assert np.array_equal(ltc_1, reference_texels[0].astype(np.float32))
    # ltc_2.w: the clipped-sphere table; the reference code's last row is (1 + z) / 2 = i / 63
    assert np.allclose(ltc_2[-1, :, 3], np.arange(SIZE) / (SIZE - 1), atol=1e-5)
    assert np.allclose(ltc_2[:, -1, 3], 1.0, atol=1e-5) and np.all(ltc_2[:, 0, 3] == 0)
    check_convention(table, ltc_1, ltc_2, node_tol=F32_TOL)


def test_ltc_code_js_and_inc(exported, reference_texels, tmp_path):
    paths = {p.name: p for p in exported["ltc_code"]}
    # a classic script: its top-level `var`s become properties of the context
    arrays = node_json(f"""import fs from 'fs'; import vm from 'vm';
const ctx = {{}};
vm.runInNewContext(fs.readFileSync({json.dumps(str(paths["ltc.js"]))}, 'utf8'), ctx);
console.log(JSON.stringify([ctx.g_ltc_1, ctx.g_ltc_2]));""", tmp_path)
    for got, want in zip(arrays, reference_texels):
        assert np.array_equal(np.float32(got).reshape(SIZE, SIZE, 4), want.astype(np.float32))
    inc = paths["ltc.inc"]
    values = cxx_output(f"""#include <cstdio>
typedef float mat33[9];
#include "{inc}"
int main() {{
  for (int k = 0; k < size * size; ++k) for (int e = 0; e < 9; ++e) printf("%.9g ", tabM[k][e]);
  for (int k = 0; k < size * size; ++k) for (int e = 0; e < 9; ++e) printf("%.9g ", tabMinv[k][e]);
  for (int k = 0; k < size * size; ++k) printf("%.9g ", tabMagnitude[k]);
}}
""", tmp_path)
    n2 = SIZE * SIZE
    # column-major [col][row] -> (row, col)
    M = values[:9 * n2].reshape(SIZE, SIZE, 3, 3).swapaxes(-1, -2)
    Minv = values[9 * n2:18 * n2].reshape(SIZE, SIZE, 3, 3).swapaxes(-1, -2)
    assert np.allclose(M @ Minv, np.eye(3), atol=1e-5)
    Minv = Minv / Minv[..., 1:2, 1:2]
    ltc_1 = np.stack([Minv[..., 0, 0], Minv[..., 2, 0], Minv[..., 0, 2], Minv[..., 2, 2]], -1)
    assert np.allclose(ltc_1, reference_texels[0], rtol=1e-5, atol=1e-6)
    assert np.allclose(values[18 * n2:].reshape(SIZE, SIZE), reference_texels[1][..., 0],
                       rtol=1e-6)


THREE_STUB = """\
export const ClampToEdgeWrapping = 1001, FloatType = 1015, HalfFloatType = 1016,
  LinearFilter = 1006, NearestFilter = 1003, RGBAFormat = 1023, UVMapping = 300;
export class DataTexture {
  constructor(data, width, height, format, type, mapping, wrapS, wrapT, magFilter, minFilter,
              anisotropy) {
    Object.assign(this, {data, width, height, format, type, mapping, wrapS, wrapT, magFilter,
                         minFilter, anisotropy});
  }
}
"""


def test_threejs_module(exported, table, reference_texels, tmp_path):
    # three.js is not installed here: a stub `three` records the DataTexture arguments, node runs
    # the generated ES module as a browser would.
    (tmp_path / "node_modules" / "three").mkdir(parents=True)
    (tmp_path / "node_modules" / "three" / "package.json").write_text(
        '{"name": "three", "type": "module", "main": "index.js"}')
    (tmp_path / "node_modules" / "three" / "index.js").write_text(THREE_STUB)
    shutil.copy(exported["threejs"][0], tmp_path / "ltc.mjs")
    got = node_json("""
import { PrefilterLTCTexturesLib as L } from './ltc.mjs';
L.init();
const out = {};
for (const k of ['LTC_FLOAT_1', 'LTC_FLOAT_2', 'LTC_HALF_1', 'LTC_HALF_2']) {
  const t = L[k];
  out[k] = {kind: t.data.constructor.name, data: Array.from(t.data), width: t.width,
            height: t.height, format: t.format, type: t.type, wrap: [t.wrapS, t.wrapT],
            filters: [t.magFilter, t.minFilter], mapping: t.mapping};
}
console.log(JSON.stringify(out));
""", tmp_path)
    for k, kind, type_ in [("LTC_FLOAT_1", "Float32Array", 1015), ("LTC_FLOAT_2", "Float32Array",
                                                                     1015),
                           ("LTC_HALF_1", "Uint16Array", 1016), ("LTC_HALF_2", "Uint16Array",
                                                                 1016)]:
        t = got[k]
        assert (t["kind"], t["width"], t["height"], t["format"], t["type"]) == (
            kind, SIZE, SIZE, 1023, type_)
        assert t["wrap"] == [1001, 1001] and t["filters"] == [1006, 1003] and t["mapping"] == 300
    f1, f2 = (np.float32(got[k]["data"]).reshape(SIZE, SIZE, 4) for k in ("LTC_FLOAT_1",
                                                                           "LTC_FLOAT_2"))
    h1, h2 = (np.array(got[k]["data"], np.uint16).view(np.float16).reshape(SIZE, SIZE, 4)
              for k in ("LTC_HALF_1", "LTC_HALF_2"))
    assert np.array_equal(f1, reference_texels[0].astype(np.float32))
    assert np.array_equal(h1, reference_texels[0].astype(np.float16))
    check_convention(table, f1, f2, node_tol=F32_TOL)
    check_convention(table, h1, h2, node_tol=F16_TOL)


def test_babylon_bin(exported, table, reference_texels):
    raw = np.frombuffer(exported["babylon"][0].read_bytes(), "<u2")
    assert raw.size == SIZE * SIZE * 8
    # Babylon.js DecodeLTCTextureDataAsync: per pixel 8 values, 4 for LTC1 then 4 for LTC2
    px = raw.reshape(-1, 8)
    ltc_1 = px[:, :4].view(np.float16).reshape(SIZE, SIZE, 4)
    ltc_2 = px[:, 4:].view(np.float16).reshape(SIZE, SIZE, 4)
    assert np.array_equal(ltc_2, reference_texels[1].astype(np.float16))
    check_convention(table, ltc_1, ltc_2, node_tol=F16_TOL)


def test_blender_arrays(exported, table, tmp_path):
    src = exported["blender"][0]
    values = cxx_output(f"""#include <cstdio>
#include "{src}"
int main() {{
  using namespace blender::eevee::lut;
  for (int y = 0; y < 64; ++y) for (int x = 0; x < 64; ++x) for (int c = 0; c < 4; ++c)
    printf("%.9g ", ltc_mat_ggx[y][x][c]);
  for (int y = 0; y < 64; ++y) for (int x = 0; x < 64; ++x) for (int c = 0; c < 2; ++c)
    printf("%.9g ", ltc_mag_ggx[y][x][c]);
}}
""", tmp_path)
    ltc_1 = values[:SIZE * SIZE * 4].reshape(SIZE, SIZE, 4)
    mag = values[SIZE * SIZE * 4:].reshape(SIZE, SIZE, 2)
    # EEVEE reads (n, f5): F0 * n + (1 - F0) * f5 as the other engines
    ltc_2 = np.concatenate([mag, np.zeros((SIZE, SIZE, 2))], -1)
    check_convention(table, ltc_1, ltc_2, node_tol=F32_TOL)


def test_godot_dds(exported, table):
    paths = {p.name: p for p in exported["godot"]}
    luts = []
    for name in ("ltc_lut1.dds", "ltc_lut2.dds"):
        blob = paths[name].read_bytes()
        head, data = read_dds(blob)
        assert head == {"height": SIZE, "width": SIZE, "mips": 1, "format": "R32G32B32A32_FLOAT"}
        # Godot's make_ltc_lut.py skips a 148-byte header and embeds the rest as 64 x 64 RGBA32F
        godot = np.frombuffer(blob[148:], "<f4").reshape(SIZE, SIZE, 4)
        assert np.array_equal(godot, data[0])
        luts.append(godot)
    check_convention(table, *luts, node_tol=F32_TOL, lookup=godot_lookup, view="theta")


def test_unity_hdrp_source(exported, table):
    import re

    src = exported["unity-hdrp"][0].read_text()
    assert "internal static ushort[] s_LtcMatrixData_BRDF_GGX = new ushort[64 * 64 * 4]" in src
    # the array initialiser as C# reads it: index [roughnessIndex + 64 * thetaIndex], 4 per texel
    body = src[src.index("{", src.index("new ushort")) + 1:src.rindex("};")]
    texels = np.array(re.findall(r"\d+", body), dtype=np.uint16).view(np.float16)
    texels = texels.reshape(SIZE, SIZE, 4)

    def hdrp_lookup(tex, _unused, roughness, cos_theta):
        # SampleLtcMatrix: Remap01ToHalfTexelCoord((perceptualRoughness, sqrt(1 - NdotV)), 64);
        # invM._m22 = 1, invM._m00_m02_m11_m20 = texel; invM is M^-1 transposed
        u = roughness * (SIZE - 1) / SIZE + 0.5 / SIZE
        v = np.sqrt(1.0 - cos_theta) * (SIZE - 1) / SIZE + 0.5 / SIZE
        t = sample_linear(np.asarray(tex, float), u, v)
        invMT = np.zeros(t.shape[:-1] + (3, 3))
        m00, m02, m11, m20 = np.moveaxis(t, -1, 0)
        invMT[..., 0, 0], invMT[..., 0, 2], invMT[..., 1, 1], invMT[..., 2, 0] = m00, m02, m11, m20
        invMT[..., 2, 2] = 1.0
        # HDRP's magnitude comes from its own FGD table: the table's (n, f5) here
        _, n, f5 = table.lookup_canonical(cos_theta, roughness ** 2)
        return np.swapaxes(invMT, -1, -2), np.stack([n, f5], -1)

    check_convention(table, texels, None, node_tol=F16_TOL, lookup=hdrp_lookup)


def unreal_lookup(mat, amp, roughness, cos_theta):
    """As ``RectGGXApproxLTC`` (RectLightIntegrate.ush): ``uv = (Roughness, sqrt(1 - NoV)) *
    63/64 + 0.5/64``; ``LTC = float3x3(float3(x, 0, z), float3(0, 1, 0), float3(y, 0, w))``
    (HLSL rows) applied to the rect; ``SpecularColor = y + (x - y) F0`` from ``LTCAmp.xy``."""
    u = roughness * (SIZE - 1) / SIZE + 0.5 / SIZE
    v = np.sqrt(1.0 - cos_theta) * (SIZE - 1) / SIZE + 0.5 / SIZE
    t = sample_linear(np.asarray(mat, float), u, v)
    a = sample_linear(np.asarray(amp, float), u, v)
    Minv = np.zeros(t.shape[:-1] + (3, 3))
    Minv[..., 0, 0], Minv[..., 0, 2] = t[..., 0], t[..., 2]
    Minv[..., 2, 0], Minv[..., 2, 2] = t[..., 1], t[..., 3]
    Minv[..., 1, 1] = 1.0
    # the shader's InvLTC (forward matrix, for the light texture's direction) from the same texel
    det = t[..., 0] * t[..., 3] - t[..., 1] * t[..., 2]
    inv = t / det[..., None]
    fwd = np.zeros_like(Minv)
    fwd[..., 0, 0], fwd[..., 0, 2], fwd[..., 1, 1] = inv[..., 3], -inv[..., 2], 1.0
    fwd[..., 2, 0], fwd[..., 2, 2] = -inv[..., 1], inv[..., 0]
    assert np.allclose(fwd @ Minv, np.eye(3), atol=1e-9)
    return Minv, a[..., :2]


def test_unreal_header(exported, table, reference_texels, tmp_path):
    src = exported["unreal"][0]
    values = cxx_output(f"""#include <cstdio>
#include "{src}"
int main() {{
  static_assert(LTC_Size == 64, "size");
  // FSystemTextures: texel (x, y) channel k <- [4 * (x + y * LTC_Size) + k]
  for (int y = 0; y < LTC_Size; ++y) for (int x = 0; x < LTC_Size; ++x)
    for (int k = 0; k < 4; ++k) printf("%.9g ", LTC_Mat[4 * (x + y * LTC_Size) + k]);
  for (int y = 0; y < LTC_Size; ++y) for (int x = 0; x < LTC_Size; ++x)
    for (int k = 0; k < 2; ++k) printf("%.9g ", LTC_Amp[4 * (x + y * LTC_Size) + k]);
  printf("%d %d", (int)(sizeof(LTC_Mat) / sizeof(float)), (int)(sizeof(LTC_Amp) / sizeof(float)));
}}
""", tmp_path)
    n = SIZE * SIZE
    assert list(values[-2:]) == [4 * n, 4 * n]
    mat = values[:4 * n].reshape(SIZE, SIZE, 4)
    amp = values[4 * n:6 * n].reshape(SIZE, SIZE, 2)
    assert np.array_equal(np.float32(mat), reference_texels[0].astype(np.float32))
    # the engine stores both as half floats (PF_FloatRGBA, PF_G16R16F)
    mat16, amp16 = mat.astype(np.float16), amp.astype(np.float16)
    check_convention(table, mat16, amp16, node_tol=F16_TOL, lookup=unreal_lookup)


def test_bevy_ktx2(exported, table, reference_texels):
    pytest.importorskip("zstandard")
    h, dfd, _, level = read_ktx2(exported["bevy"][0].read_bytes())
    assert (h["vkFormat"], h["pixelWidth"], h["pixelHeight"], h["layerCount"],
            h["supercompressionScheme"]) == (97, SIZE, SIZE, 2, 2)
    ltc_1, ltc_2 = np.frombuffer(level, "<f2").reshape(2, SIZE, SIZE, 4)
    assert np.array_equal(ltc_1, reference_texels[0].astype(np.float16))
    check_convention(table, ltc_1, ltc_2, node_tol=F16_TOL)


# --- the test's power ---------------------------------------------------------------------------


def _mutations(ltc_1, ltc_2):
    yield "rows and columns swapped", ltc_1.swapaxes(0, 1), ltc_2.swapaxes(0, 1)
    yield "m20 and m02 swapped", ltc_1[..., [0, 2, 1, 3]], ltc_2
    yield "magnitude and fresnel swapped", ltc_1, ltc_2[..., [1, 0, 2, 3]]
    # texels holding the table at r, v = (i + 0.5) / 64, as an export that ignored the
    # half-texel remap (uv = (r, v) * 63/64 + 0.5/64) would store
    x = (np.arange(SIZE) + 0.5) / SIZE * (SIZE - 1) / SIZE + 0.5 / SIZE
    u, v = np.meshgrid(x, x)
    yield "half texel", sample_linear(ltc_1, u, v), sample_linear(ltc_2, u, v)


def test_lookup_detects_convention_errors(table, reference_texels):
    for name, ltc_1, ltc_2 in _mutations(*reference_texels):
        worst = max(relative_errors(table, ltc_1, ltc_2, *node_configurations(), f0).max()
                    for f0 in (1.0, 0.04))
        print(f"{name}: worst relative error at texel centres {worst:.3g}")
        assert worst > 10 * F16_TOL, name


def test_unknown_preset(tmp_path):
    from prefilter.errors import PrefilterError

    with pytest.raises(PrefilterError, match="preset"):
        export_preset("unity", tmp_path)


def test_half_bits_round_to_nearest_even():
    from prefilter.ltc.export import half_bits

    assert half_bits([1.0, -2.0, 65504.0, 1.0 + 2 ** -11]).tolist() == [0x3C00, 0xC000, 0x7BFF,
                                                                          0x3C00]
    assert struct.unpack("<e", struct.pack("<H", int(half_bits(0.1))))[0] == np.float16(0.1)


# --- compact encodings --------------------------------------------------------------------------


@pytest.mark.parametrize("encoding,nbytes,median,p90", [("half", 64 * 64 * 6 * 2, 5e-4, 2e-3),
                                                        ("fit", 6 * 11 * 11 * 4, 2e-3, 1e-2)])
def test_compact_encodings(table, encoding, nbytes, median, p90):
    # Against the full table on random quads (table integral >= 1e-3): binary16 keeps 11
    # significant bits (measured median 1e-4, p90 4e-4, max 1e-3); the degree-(10, 10)
    # Chebyshev fit measured median 6e-4, p90 5e-3 on 3000 configurations, with a few errors up
    # to 20 % near theta 61 deg, alpha 0.14, where m22 bends sharply along roughness.
    from prefilter.ltc.export.compact import decode, encode, encoded_bytes

    enc = encode(table, encoding)
    assert encoded_bytes(enc) == nbytes
    decoded = decode(enc)
    rng = np.random.default_rng(8)
    k = 600
    cos_theta = 1.0 - rng.uniform(0.0, table.axis_t[-1], k) ** 2
    alpha = rng.uniform(table.alpha_min, 1.0, k)
    quads = random_quads(k, rng)
    M0, n0, _ = table.lookup_canonical(cos_theta, alpha)
    M1, n1, _ = decoded.lookup_canonical(cos_theta, alpha)
    ref = n0 * polygon_integral(M0, quads)
    keep = ref >= 1e-3
    rel = np.abs(n1 * polygon_integral(M1, quads) - ref)[keep] / ref[keep]
    assert np.median(rel) <= median and np.percentile(rel, 90) <= p90


def test_compact_preset_files_round_trip(exported, table):
    from prefilter.fileio import load_npz_checked
    from prefilter.ltc.export.compact import decode, encode

    for path in exported["compact"]:
        name = path.stem.rsplit("_", 1)[-1]
        data = load_npz_checked(path, "compact LTC table", format_name=f"ltc-iso-{name}",
                                format_version=1)
        for key, value in encode(table, name).items():
            assert np.array_equal(data[key], value), (name, key)
        assert np.allclose(decode(data).M, decode(encode(table, name)).M)


def test_export_command(tmp_path):
    from click.testing import CliRunner

    from prefilter.cli import cli

    res = CliRunner().invoke(cli, ["export-ltc", "--preset", "babylon", "-o", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "areaLightsLTC.bin").stat().st_size == SIZE * SIZE * 16
    res = CliRunner().invoke(cli, ["export-ltc", "--preset", "babylon", "-o", str(tmp_path),
                                   "--measure"])
    assert res.exit_code != 0 and "--measure applies to --preset compact" in res.output


def test_sphere_form_factor():
    # Against closed forms (fully visible cap: z; hemisphere cap: (1 + z) / 2) and a Monte Carlo
    # estimate of the clipped projected solid angle of caps straddling the horizon.
    from prefilter.ltc.export import sphere_form_factor

    table = sphere_form_factor()
    x = np.arange(SIZE) / (SIZE - 1)
    z, length = 2 * x - 1, x
    assert np.allclose(table[-1], (1 + z) / 2, atol=1e-6)
    sigma = np.arcsin(np.sqrt(length))[:, None]
    visible = np.arccos(np.clip(z, -1, 1))[None, :] + sigma <= np.pi / 2
    assert np.allclose(table[np.broadcast_to(visible, table.shape)],
                       np.broadcast_to(z, table.shape)[visible], atol=1e-6)
    rng = np.random.default_rng(9)
    for j, i in [(20, 30), (40, 25), (50, 40), (10, 31)]:
        s, om = np.arcsin(np.sqrt(length[j])), np.arccos(z[i])
        n = 400_000
        ct = 1 - rng.random(n) * (1 - np.cos(s))  # uniform on the cap
        st = np.sqrt(1 - ct * ct)
        ph = rng.uniform(0, 2 * np.pi, n)
        wz = ct * np.cos(om) - st * np.cos(ph) * np.sin(om)
        estimate = 2 * np.pi * (1 - np.cos(s)) * np.maximum(wz, 0)
        value = estimate.mean() / (np.pi * length[j])
        se = estimate.std() / np.sqrt(n) / (np.pi * length[j])
        assert abs(table[j, i] - value) <= 4 * se + 1e-6, (j, i, table[j, i], value, se)


def test_compare_encodings_shares_references(table):
    # Few configurations and samples: the structure, the byte counts, and that the full table's
    # statistics are those of the acceptance run with the same seed.
    from prefilter.ltc.export.compact import compare_encodings
    from prefilter.ltc.validate import run_acceptance

    res = compare_encodings(table, n_configs=6, n_samples=2000, seed=3)
    assert {k: v["bytes"] for k, v in res.items()} == {"full": 98304, "half": 49152, "fit": 2904}
    ref = run_acceptance(table, 6, 2000, 3)["stats"]
    full = res["full"]["stats"][1e-3]
    assert full["count"] == ref["count"] and full["median"] == pytest.approx(ref["median"])
    assert set(res["half"]["stats"]) == {1e-3, 0.05}
