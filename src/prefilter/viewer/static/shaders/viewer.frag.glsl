// The viewer's shader: the Python renderer's `ltc`, `ltc-multiscale`, `ltc-aniso` and
// `ltc-multiscale-aniso` and `leadr-point` methods per pixel (prefilter.render.driver, camera,
// shading; prefilter.multiscale.render / aniso; prefilter.ltc.aniso.render;
// prefilter.leadr.render), in float32. Included after ltc_iso.glsl, ltc_aniso.glsl,
// multiscale.glsl and leadr.glsl (the exported snippets).
#define MAX_OBJECTS 4
#define MAX_QUADS 4
#define METHOD_LTC 0
#define METHOD_MULTISCALE 1
#define METHOD_ANISO 2
#define METHOD_MULTISCALE_ANISO 3
#define METHOD_LEADR_POINT 4
#define METHOD_COLORMAP_FILTERED 5
#define METHOD_COLORMAP_NAIVE 6
#define METHOD_LEADR_ENV 7
#define METHOD_LEADR_IRRADIANCE 8
#ifndef METHOD_COLORMAP_LIT  // viewer.js defines it (its index in the page's METHODS)
#define METHOD_COLORMAP_LIT -1
#endif

uniform highp sampler2D uAtlas;     // mip chains, RGBA32F, uAtlasWidth texels per row
uniform highp sampler2D uAtlas16;   // the same atlas in RGBA16F (LEADR's f16 moment maps)
uniform int uMapsHalf;              // 1: leadr-point reads its moment maps from uAtlas16
uniform highp isampler2D uLevels;   // per mip level: (offset, height, width, stride)
uniform int uAtlasWidth;
uniform vec3 uCamO, uCamR, uCamU, uCamF;  // origin, right, true up, forward (unit)
uniform float uCamSy;                     // image-plane units per pixel: 2 tan(fov/2) / height
uniform vec2 uSize;                       // image width, height (pixels)
uniform int uNumObjects;
uniform int uObjType[MAX_OBJECTS];        // 0 plane, 1 sphere
uniform vec3 uObjC[MAX_OBJECTS], uObjN[MAX_OBJECTS], uObjT[MAX_OBJECTS], uObjB[MAX_OBJECTS];
uniform vec4 uObjP[MAX_OBJECTS];          // plane size (2), sphere radius, unused
uniform vec2 uObjUV[MAX_OBJECTS];         // uv_scale
uniform vec2 uMatAlpha[MAX_OBJECTS];      // alpha_x, alpha_y
uniform vec3 uMatBase[MAX_OBJECTS], uMatF0[MAX_OBJECTS];
uniform ivec4 uMatMap[MAX_OBJECTS];       // normal chain (first level, levels), slope chain
uniform ivec4 uMatColor[MAX_OBJECTS];     // colour chain (first level, levels, channels)
uniform ivec2 uMatHeight[MAX_OBJECTS];    // height map's slope-moment chain (leadr-point)
uniform ivec2 uColormapChain;             // colour-map driver's (E[f], E[f^2]) chain, or -1
uniform int uColormapDriver;              // 0 texture, 1 noise (its mean chain), 2 height, 3 slope
uniform vec4 uColormapLight;              // height, slope: world direction to the light, w = 1
#define COLORMAP_NOISE 1
#define COLORMAP_HEIGHT 2
#define COLORMAP_SLOPE 3
uniform int uNumQuads;
uniform vec3 uQuadV[4 * MAX_QUADS], uQuadN[MAX_QUADS], uQuadL[MAX_QUADS];
uniform int uNumPoints, uNumDirs;
uniform vec3 uPointP[MAX_QUADS], uPointI[MAX_QUADS];   // point lights: position, intensity
uniform vec3 uDirD[MAX_QUADS], uDirE[MAX_QUADS];       // directional: direction of travel, irradiance
uniform int uMethodLeft, uMethodRight;    // methods left / right of the split
uniform float uSplit;                     // split position in pixels from the left
uniform int uLinear;                      // 1: linear radiance out (float target), 0: display
uniform float uExposure;
out vec4 fragColor;

const float PI = 3.14159265358979;
const float VIEW_Z_MIN = 1e-3;           // prefilter.render.shading.VIEW_Z_MIN

// -- G-buffer (prefilter.render.kernels.camera_trace) ----------------------------------------------

struct Hit { int id; float dist; vec3 p, n, t, b; vec2 uv; vec4 dudv; };  // dudv = (du/dx, du/dy, dv/dx, dv/dy)

bool trace(vec3 o, vec3 d, vec3 ddx, vec3 ddy, out Hit h) {
    float best = 1e30;
    int kb = -1;
    for (int k = 0; k < MAX_OBJECTS; ++k) {
        if (k >= uNumObjects) break;
        vec3 c = uObjC[k];
        float t;
        if (uObjType[k] == 0) {
            float den = dot(d, uObjN[k]);
            if (!(abs(den) > 1e-12)) continue;
            t = dot(c - o, uObjN[k]) / den;
            vec3 q = o + t * d - c;
            if (!(t > 1e-6 && abs(dot(q, uObjT[k])) <= uObjP[k].x / 2.0
                  && abs(dot(q, uObjB[k])) <= uObjP[k].y / 2.0)) continue;
        } else {
            vec3 oc = o - c;
            float b = dot(oc, d), cc = dot(oc, oc) - uObjP[k].z * uObjP[k].z;
            float disc = b * b - cc;
            if (!(disc >= 0.0)) continue;
            float s = sqrt(disc);
            t = -b - s;
            if (!(t > 1e-6)) t = -b + s;
            if (!(t > 1e-6)) continue;
        }
        if (t < best) { best = t; kb = k; }
    }
    h.id = kb;
    h.dist = best;
    if (kb < 0) return false;
    float t = best;
    vec3 p = o + t * d, c = uObjC[kb];
    vec2 s0 = uObjUV[kb];
    vec3 n, tg, bt;
    float gu, gv;
    if (uObjType[kb] == 0) {
        n = uObjN[kb]; tg = uObjT[kb]; bt = uObjB[kb];
        vec3 q = p - c;
        float su = s0.x / uObjP[kb].x, sv = s0.y / uObjP[kb].y;
        h.uv = vec2(dot(q, tg) * su + 0.5 * s0.x, dot(q, bt) * sv + 0.5 * s0.y);
        gu = su; gv = sv;
    } else {
        float r = uObjP[kb].z;
        vec3 ex = uObjT[kb], ey = uObjN[kb], ez = uObjB[kb];
        vec3 q = (p - c) / r;
        float x = dot(q, ex), y = clamp(dot(q, ey), -1.0, 1.0), z = dot(q, ez);
        float theta = acos(y), phi = atan(z, x);
        if (phi < 0.0) phi += 2.0 * PI;
        float st = max(sqrt(x * x + z * z), 1e-12);
        float cp = x / st, sp = z / st;
        n = q / length(q);
        tg = -sp * ex + cp * ez;
        bt = y * cp * ex - st * ey + y * sp * ez;
        h.uv = vec2(phi / (2.0 * PI) * s0.x, theta / PI * s0.y);
        gu = s0.x / (2.0 * PI * r * st); gv = s0.y / (PI * r);
    }
    // Igehy 1999: the hit point moves on the tangent plane
    float dn = dot(d, n);
    vec3 dpdx = t * (ddx - dot(ddx, n) / dn * d), dpdy = t * (ddy - dot(ddy, n) / dn * d);
    h.p = p; h.n = n; h.t = tg; h.b = bt;
    h.dudv = vec4(gu * dot(tg, dpdx), gu * dot(tg, dpdy), gv * dot(bt, dpdx), gv * dot(bt, dpdy));
    return true;
}

// -- mip chains (prefilter.render.kernels._footprint_into) ---------------------------------------

int imod(int a, int m) { int r = a % m; return r < 0 ? r + m : r; }

bool gHalf = false;  // read the float16 atlas (set around LEADR's moment lookups)

vec4 atlasTexel(int k) {
    ivec2 p = ivec2(k % uAtlasWidth, k / uAtlasWidth);
    return gHalf ? texelFetch(uAtlas16, p, 0) : texelFetch(uAtlas, p, 0);
}

// wrapped bilinear lookup of level `level` (8 channels: A = 0..3, B = 4..7), weight added
void bilinearAdd(int level, vec2 uv, float wgt, inout vec4 A, inout vec4 B) {
    ivec4 L = texelFetch(uLevels, ivec2(level, 0), 0);
    // period 1: wrapping first keeps float32 texel coordinates exact for large uv
    vec2 f = uv - floor(uv);
    float x = f.x * float(L.z) - 0.5, y = f.y * float(L.y) - 0.5;
    float x0 = floor(x), y0 = floor(y), fx = x - x0, fy = y - y0;
    int i0 = imod(int(y0), L.y), j0 = imod(int(x0), L.z);
    int i1 = (i0 + 1) % L.y, j1 = (j0 + 1) % L.z;
    int k00 = L.x + (i0 * L.z + j0) * L.w, k01 = L.x + (i0 * L.z + j1) * L.w;
    int k10 = L.x + (i1 * L.z + j0) * L.w, k11 = L.x + (i1 * L.z + j1) * L.w;
    float w00 = (1.0 - fx) * (1.0 - fy), w01 = fx * (1.0 - fy);
    float w10 = (1.0 - fx) * fy, w11 = fx * fy;
    A += wgt * (w00 * atlasTexel(k00) + w01 * atlasTexel(k01) + w10 * atlasTexel(k10)
                + w11 * atlasTexel(k11));
    if (L.w > 1) {
        B += wgt * (w00 * atlasTexel(k00 + 1) + w01 * atlasTexel(k01 + 1)
                    + w10 * atlasTexel(k10 + 1) + w11 * atlasTexel(k11 + 1));
    }
}

// major axis of the footprint in texels of the chain's level 0 (texture.mip.footprint_axes)
float footprintMajor(ivec2 chain, vec4 dudv) {
    ivec4 L0 = texelFetch(uLevels, ivec2(chain.x, 0), 0);
    float w0 = float(L0.z), h0 = float(L0.y);
    float j00 = dudv.x * w0, j01 = dudv.y * w0, j10 = dudv.z * h0, j11 = dudv.w * h0;
    float p = j00 * j00 + j01 * j01, r = j10 * j10 + j11 * j11, q = j00 * j10 + j01 * j11;
    float disc = sqrt(max(0.25 * (p - r) * (p - r) + q * q, 0.0));
    return sqrt(0.5 * (p + r) + disc);
}

// the footprint ellipse in texels of the chain's level 0: major and minor axis, the major
// direction as a unit vector in texel space (kernels._footprint_axes, texture.mip.footprint_axes)
void footprintAxes(ivec2 chain, vec4 dudv, out float major, out float minor, out vec2 dir) {
    ivec4 L0 = texelFetch(uLevels, ivec2(chain.x, 0), 0);
    float w0 = float(L0.z), h0 = float(L0.y);
    float j00 = dudv.x * w0, j01 = dudv.y * w0, j10 = dudv.z * h0, j11 = dudv.w * h0;
    float p = j00 * j00 + j01 * j01, r = j10 * j10 + j11 * j11, q = j00 * j10 + j01 * j11;
    float disc = sqrt(max(0.25 * (p - r) * (p - r) + q * q, 0.0));
    float l1 = 0.5 * (p + r) + disc, l2 = max(0.5 * (p + r) - disc, 0.0);
    // eigenvector of l1: (q, l1 - p) or (l1 - r, q), whichever is longer (stable)
    vec2 v1 = vec2(q, l1 - p), v2 = vec2(l1 - r, q);
    dir = dot(v1, v1) >= dot(v2, v2) ? v1 : v2;
    float nd = length(dir);
    dir = nd > 0.0 ? dir / nd : vec2(1.0, 0.0);
    major = sqrt(l1);
    minor = sqrt(l2);
}

// trilinear read of the chain at `lod` (clamped to its levels), weight added
// (kernels._trilinear_into)
void trilinearAdd(ivec2 chain, vec2 uv, float lod, float wgt, inout vec4 A, inout vec4 B) {
    lod = clamp(lod, 0.0, float(chain.y - 1));
    if (chain.y > 1) {
        int l0 = min(int(floor(lod)), chain.y - 2);
        float t = lod - float(l0);
        bilinearAdd(chain.x + l0, uv, wgt * (1.0 - t), A, B);
        bilinearAdd(chain.x + l0 + 1, uv, wgt * t, A, B);
    } else {
        bilinearAdd(chain.x, uv, wgt, A, B);
    }
}

// isotropic trilinear lookup at lod = log2(major axis of the footprint in texels)
void footprint(ivec2 chain, vec2 uv, vec4 dudv, out vec4 A, out vec4 B) {
    A = vec4(0.0); B = vec4(0.0);
    trilinearAdd(chain, uv, log2(max(footprintMajor(chain, dudv), 1.0)), 1.0, A, B);
}

// ltc-multiscale's normal-map read (multiscale.render.taps_lookup; the fused
// kernels.ltc_samples_kernel): the footprint biased by MS_LOD_BIAS / MS_LOD_START; below
// MS_TAPS_BELOW texels, a footprint more than MS_TAPS_RATIO times longer than wide is the mean of
// n = clamp(ceil(major / minor), 2, MS_TAPS) unnormalised trilinear taps at the cell centres of
// the major axis, at lod = log2(max(minor, major / n)): the averaged normal's length r then sees
// the spread of normals along the whole elongated footprint, not of a blurred isotropic one.
void footprintMs(ivec2 chain, vec2 uv, vec4 dudv, out vec4 A, out vec4 B) {
    A = vec4(0.0); B = vec4(0.0);
    float major, minor;
    vec2 dir;
    footprintAxes(chain, dudv, major, minor, dir);
    // a constant bias scales the footprint; a ramped one (start >= 0) is added to the LOD
    float ns = MS_LOD_START < 0.0 ? exp2(MS_LOD_BIAS) : 1.0;
    float lod = log2(max(ns * major, 1.0));
    float bias = MS_LOD_START < 0.0 ? 0.0 : clamp(lod - MS_LOD_START, 0.0, MS_LOD_BIAS);
    int n = 1;
    if (MS_TAPS >= 2 && major < MS_TAPS_BELOW && major > MS_TAPS_RATIO * minor)
        n = int(min(max(ceil(major / max(minor, 1e-30)), 2.0), float(MS_TAPS)));
    if (n == 1) {
        trilinearAdd(chain, uv, lod + bias, 1.0, A, B);
        return;
    }
    float lodT = log2(max(ns * max(minor, major / float(n)), 1.0)) + bias;
    float lodc = clamp(lodT, 0.0, float(chain.y - 1));
    ivec4 L0 = texelFetch(uLevels, ivec2(chain.x, 0), 0);
    vec2 axis = dir * major / vec2(float(L0.z), float(L0.y));
    float w = 1.0 / float(n);
    for (int i = 0; i < MS_TAPS; ++i) {
        if (i >= n) break;
        vec2 p = uv + ((float(i) + 0.5) / float(n) - 0.5) * axis;
        if (MS_TAPS_NORM && lodc < 1.0 && chain.y > 1) {
            // the level-0 bilinear normal renormalised, then blended with level 1
            vec4 a0 = vec4(0.0), b0 = vec4(0.0);
            bilinearAdd(chain.x, p, 1.0, a0, b0);
            float ln = length(a0.xyz);
            A += w * (ln > 0.0 ? (1.0 - lodc) / ln : 1.0 - lodc) * a0;
            bilinearAdd(chain.x + 1, p, w * lodc, A, B);
        } else {
            trilinearAdd(chain, p, lodT, w, A, B);
        }
    }
}

// LEADR's box filter of the moments over the pixel footprint (leadr.render.footprint_moments,
// leadr.kernels.box_moments_kernel): T x T trilinear taps at uv + dudv (ox, oy), ox, oy the
// cell centres of [-1/2, 1/2], T = clamp(ceil(major / 2), 1, LEADR_TAPS), each at
// lod = log2(max(major / T, 1)); moments are linear, so this averages the pixel's own texels.
void footprintBox(ivec2 chain, vec2 uv, vec4 dudv, out vec4 A, out vec4 B) {
    A = vec4(0.0); B = vec4(0.0);
    float major = footprintMajor(chain, dudv);
    int T = int(clamp(ceil(major / 2.0), 1.0, float(LEADR_TAPS)));
    float lod = clamp(log2(max(major / float(T), 1.0)), 0.0, float(chain.y - 1));
    int l0 = min(int(floor(lod)), max(chain.y - 2, 0));
    float f = chain.y > 1 ? lod - float(l0) : 0.0;
    float w = 1.0 / float(T * T);
    for (int i = 0; i < LEADR_TAPS; ++i) {
        if (i >= T) break;
        float oy = (float(i) + 0.5) / float(T) - 0.5;
        for (int j = 0; j < LEADR_TAPS; ++j) {
            if (j >= T) break;
            float ox = (float(j) + 0.5) / float(T) - 0.5;
            vec2 p = uv + vec2(dudv.x * ox + dudv.y * oy, dudv.z * ox + dudv.w * oy);
            bilinearAdd(chain.x + l0, p, w * (1.0 - f), A, B);
            if (chain.y > 1) bilinearAdd(chain.x + l0 + 1, p, w * f, A, B);
        }
    }
}

// -- shading (prefilter.render.shading) -----------------------------------------------------------

// shading_frame: the normal m (tangent space, need not be unit), tangent re-orthogonalised
void shadingFrame(vec3 t, vec3 b, vec3 n, vec3 m, out vec3 ts, out vec3 bs, out vec3 ns) {
    ns = m.x * t + m.y * b + m.z * n;
    float ln = length(ns);
    ns = ln > 1e-12 ? ns / ln : n;
    ts = t - dot(t, ns) * ns;
    float lt = length(ts);
    ts = lt > 1e-9 ? ts / lt : normalize(cross(b, ns));
    bs = (dot(cross(n, t), b) >= 0.0 ? 1.0 : -1.0) * cross(ns, ts);
}

vec3 localView(vec3 v, vec3 ts, vec3 bs, vec3 ns) {
    return normalize(vec3(dot(v, ts), dot(v, bs), max(dot(v, ns), VIEW_Z_MIN)));
}

vec3 shadeQuads(vec3 pos, vec3 ts, vec3 bs, vec3 ns, mat3 Minv, vec3 base, vec3 spec) {
    vec3 L = vec3(0.0);
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumQuads) break;
        vec3 Q[4] = vec3[4](uQuadV[4 * q], uQuadV[4 * q + 1], uQuadV[4 * q + 2], uQuadV[4 * q + 3]);
        L += ltcQuad(Q, uQuadN[q], uQuadL[q], pos, ts, bs, ns, Minv, base, spec);
    }
    return L;
}

// GGX(ax, ay) with height-correlated Smith masking and Schlick Fresnel, cosine-weighted, plus
// Lambert: prefilter.render.shading.brdf_cos (Walter et al. 2007 eq. 20; Heitz 2014 eq. 99)
float ggxLambda(vec3 w, float ax, float ay) {
    float a2 = ((ax * w.x) * (ax * w.x) + (ay * w.y) * (ay * w.y)) / max(w.z * w.z, 1e-30);
    return a2 / (1.0 + sqrt(1.0 + a2)) / 2.0;
}

vec3 brdfCos(vec3 wo, vec3 wi, float ax, float ay, vec3 base, vec3 f0) {
    if (!(wi.z > 0.0)) return vec3(0.0);
    vec3 h = normalize(wo + wi);
    float spec = 0.0;
    if (wo.z > 0.0 && h.z > 0.0) {
        float t = (h.x / ax) * (h.x / ax) + (h.y / ay) * (h.y / ay) + h.z * h.z;
        float D = 1.0 / (PI * ax * ay * t * t);
        spec = D / (1.0 + ggxLambda(wo, ax, ay) + ggxLambda(wi, ax, ay)) / (4.0 * wo.z);
    }
    float c = clamp(dot(wi, h), 0.0, 1.0);
    vec3 F = f0 + (1.0 - f0) * pow(1.0 - c, 5.0);
    return base / PI * wi.z + F * spec;
}

// point and directional lights: the BRDF evaluated directly (shading.shade_delta_lights)
vec3 shadeDelta(vec3 pos, vec3 ts, vec3 bs, vec3 ns, vec3 wo, float ax, float ay, vec3 base,
                vec3 f0) {
    vec3 L = vec3(0.0);
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumPoints) break;
        vec3 d = uPointP[q] - pos;
        float d2 = max(dot(d, d), 1e-30);
        vec3 w = d / sqrt(d2);
        L += brdfCos(wo, vec3(dot(w, ts), dot(w, bs), dot(w, ns)), ax, ay, base, f0)
             * uPointI[q] / d2;
    }
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumDirs) break;
        vec3 w = -uDirD[q];
        L += brdfCos(wo, vec3(dot(w, ts), dot(w, bs), dot(w, ns)), ax, ay, base, f0) * uDirE[q];
    }
    return L;
}

// the geometric frame (two-sided: seen from behind, n and b flip), the height map's slope
// moments box-filtered over the footprint and their LEADR statistics with the micro roughness,
// and the view in that frame: what leadr-point and the environment modes share
void leadrFootprint(Hit h, vec3 view, out vec3 gt, out vec3 gb, out vec3 gn, out vec3 wo,
                    out vec2 mu, out vec3 cov) {
    gn = h.n; gt = h.t; gb = h.b;
    if (dot(view, gn) < 0.0) { gn = -gn; gb = -gb; }
    vec4 A = vec4(0.0), B = vec4(0.0);
    ivec2 hc = uMatHeight[h.id];
    if (hc.x >= 0) {
        gHalf = uMapsHalf == 1;
        footprintBox(hc, h.uv, h.dudv, A, B);
        gHalf = false;
    }
    leadrStats(A, B.x, uMatAlpha[h.id], mu, cov);
    wo = normalize(vec3(dot(view, gt), dot(view, gb), dot(view, gn)));
}

// leadr-point (prefilter.leadr.render.shade_leadr_delta): the height map's slope moments
// box-filtered over the footprint, LEADR statistics with the micro roughness, geometric frame,
// diffuse with self-shadowing (G2 / G1, in leadrDelta); colour and
// normal maps are not read (as the Python method); quad lights are not shaded.
vec3 shadeLeadr(Hit h, vec3 view) {
    int k = h.id;
    vec3 gn, gt, gb, wo;
    vec2 mu;
    vec3 cov;
    leadrFootprint(h, view, gt, gb, gn, wo, mu, cov);
    vec3 L = vec3(0.0);
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumPoints) break;
        vec3 d = uPointP[q] - h.p;
        float d2 = max(dot(d, d), 1e-30);
        vec3 w = d / sqrt(d2);
        vec3 wi = normalize(vec3(dot(w, gt), dot(w, gb), dot(w, gn)));
        L += leadrDelta(wo, wi, mu, cov, uMatBase[k], uMatF0[k]) * uPointI[q] / d2;
    }
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumDirs) break;
        vec3 w = -uDirD[q];
        vec3 wi = normalize(vec3(dot(w, gt), dot(w, gb), dot(w, gn)));
        L += leadrDelta(wo, wi, mu, cov, uMatBase[k], uMatF0[k]) * uDirE[q];
    }
    return L;
}

// the two-sided tangent frame's view and light directions of the height / slope drivers
// (grazing and back-facing ones just above the horizon, as the Python methods)
void colormapViewLight(Hit h, vec3 view, vec3 l, bool hasLight, out vec3 wo, out vec3 wi) {
    float s = dot(view, h.n) < 0.0 ? -1.0 : 1.0;
    vec3 gt = h.t, gb = s * h.b, gn = s * h.n;
    wo = normalize(vec3(dot(view, gt), dot(view, gb), max(dot(view, gn), 1e-3)));
    wi = hasLight ? normalize(vec3(dot(l, gt), dot(l, gb), max(dot(l, gn), 1e-3)))
                  : vec3(0.0, 0.0, 1.0);
}

// the slope driver's footprint covariance (xx, yy, xy) (texture.footprint_stats: moments
// M = (E[sx], E[sy], E[sx^2], E[sy^2]), B.x = E[sx sy]; the taps' level-0 interpolation
// covariance ic removed with weight 1 - clamp(lod, 0, 1), then clamped positive semi-definite
// as texture._psd); the mean slope is M.xy
vec3 colormapSlopeCov(vec4 M, vec4 B, vec3 ic, float lod) {
    vec2 mu = M.xy;
    vec3 c = vec3(max(M.z - mu.x * mu.x, 0.0), max(M.w - mu.y * mu.y, 0.0), B.x - mu.x * mu.y);
    c -= (1.0 - clamp(lod, 0.0, 1.0)) * ic;
    float mid = 0.5 * (c.x + c.y);
    float disc = sqrt(0.25 * (c.x - c.y) * (c.x - c.y) + c.z * c.z);
    float l1 = max(mid + disc, 0.0), l2 = max(mid - disc, 0.0);
    float phi = c.z == 0.0 && c.x == c.y ? 0.0 : 0.5 * atan(2.0 * c.z, c.x - c.y);
    float cs = cos(phi), sn = sin(phi);
    return vec3(l1 * cs * cs + l2 * sn * sn, l1 * sn * sn + l2 * cs * cs, (l1 - l2) * cs * sn);
}

// the driver's footprint statistics: M, B the mean moments (slopes: B.x = E[sx sy]), iv / ic
// the taps' level-0 interpolation variance / slope covariance, lod and the area LOD
struct CmStats { vec4 M, B; float iv; vec3 ic; float lod, areaLod; };

CmStats colormapStats(Hit h, bool filtered) {
    ivec2 ch = uColormapChain;
    ivec4 L0 = texelFetch(uLevels, ivec2(ch.x, 0), 0);
    float w = float(L0.z), hh = float(L0.y);
    float major, minor;
    vec2 dir;
    footprintAxes(ch, h.dudv, major, minor, dir);
    int taps = minor > 0.0 ? int(min(max(ceil(major / minor), 1.0), 8.0)) : 8;
    float lod = log2(max(max(minor, major / 8.0), 1.0));
    float areaLod = 0.5 * log2(max(major * minor, 1.0));
    vec2 axis = dir * major / vec2(w, hh);
    int n = ch.y;
    bool want = filtered && lod < 1.0 && uColormapDriver != COLORMAP_NOISE;
    float t = n > 1 ? max(lod, 0.0) : 0.0, iv = 0.0;
    vec3 ic = vec3(0.0);
    float tl = clamp(lod, 0.0, float(n - 1));
    int l0 = n > 1 ? min(int(floor(tl)), n - 2) : 0;
    float tt = n > 1 ? tl - float(l0) : 0.0;
    vec4 M = vec4(0.0), B = vec4(0.0);
    for (int i = 0; i < 8; ++i) {
        if (i >= taps) break;
        vec2 uv = h.uv + ((float(i) + 0.5) / float(taps) - 0.5) * axis;
        float wt = 1.0 / float(taps);
        if (!want) {
            if (n == 1) bilinearAdd(ch.x, uv, wt, M, B);
            else {
                if (tt < 1.0) bilinearAdd(ch.x + l0, uv, wt * (1.0 - tt), M, B);
                if (tt > 0.0) bilinearAdd(ch.x + l0 + 1, uv, wt * tt, M, B);
            }
            continue;
        }
        vec4 m0 = vec4(0.0), b0 = vec4(0.0);
        bilinearAdd(ch.x, uv, 1.0, m0, b0);
        M += (1.0 - t) * wt * m0;
        B += (1.0 - t) * wt * b0;
        if (t > 0.0) bilinearAdd(ch.x + 1, uv, t * wt, M, B);
        iv += (m0.y - m0.x * m0.x) * wt;
        // slopes: the tap's level-0 covariance (xx, yy, xy), diagonal clamped at 0
        ic += wt * vec3(max(m0.z - m0.x * m0.x, 0.0), max(m0.w - m0.y * m0.y, 0.0),
                        b0.x - m0.x * m0.y);
    }
    return CmStats(M, B, iv, ic, lod, areaLod);
}

// the height driver's footprint variance (level-0 interpolation variance removed)
float colormapHeightVar(CmStats s) {
    float var = s.M.y - s.M.x * s.M.x;
    if (s.lod < 1.0) var -= (1.0 - max(s.lod, 0.0)) * s.iv;
    return var;
}

// texture / noise: the colour of the footprint (no view or light dependence)
vec3 colormapFlat(CmStats s, bool filtered) {
    if (uColormapDriver == COLORMAP_NOISE)
        return colormapFiltered(s.M.x, filtered ? colormapNoiseSigma(s.areaLod) : 0.0);
    return colormapFiltered(s.M.x, filtered ? sqrt(max(colormapHeightVar(s), 0.0)) : 0.0);
}

// colormap-filtered / -naive (prefilter.colormap.render; kernels._fetch and the _texture /
// _noise / _height kernels, texture.footprint_stats for slopes): the driver's chain over the
// anisotropic footprint (up to 8 trilinear taps along the major axis), for moments the level-0
// interpolation variance removed under magnification, then the exported snippet: the table
// lookup (texture), the noise std at the area LOD (noise), the height filtering towards the
// view and the light (height), the slope filtering towards the view times V_bar (slope).
// Unlit: the colour term itself.
vec3 shadeColormap(Hit h, vec3 view, bool filtered) {
    if (uColormapChain.x < 0) return vec3(0.0);
    CmStats s = colormapStats(h, filtered);
    vec3 wo, wi;
    colormapViewLight(h, view, uColormapLight.xyz, uColormapLight.w > 0.0, wo, wi);
    if (uColormapDriver == COLORMAP_SLOPE) {
        // V_bar towards the view and the light (eq. 13) times Cs_bar (eqs. 19, 20) or, naive,
        // the map at the mean slope (prefilter.colormap.render._slope_shader)
        float lo = colormapLambda(wo), li = colormapLambda(wi);
        vec3 col = filtered ? colormapSlope(wo, s.M.xy, colormapSlopeCov(s.M, s.B, s.ic, s.lod))
                            : colormapSlopeNaive(s.M.xy);
        return (1.0 + lo) / (1.0 + lo + li) * col;
    }
    if (uColormapDriver == COLORMAP_HEIGHT) {
        float lo = colormapLambda(wo), li = colormapLambda(wi);
        return filtered ? colormapHeightFootprint(s.M.x, colormapHeightVar(s), lo, li)
                        : colormapHeightNaive(s.M.x, lo, li);
    }
    return colormapFlat(s, filtered);
}

#ifndef GLINTS  // colormap-lit reads the environment texture of leadr_env.glsl
// colormap-lit, one light: irradiance E at normal incidence from world direction w (unit)
vec3 colormapLitLight(CmStats s, vec3 w, vec3 E, vec3 gt, vec3 gb, vec3 gn, vec3 cs, float lo) {
    vec3 wl = vec3(dot(w, gt), dot(w, gb), dot(w, gn));
    float c = max(wl.z, 0.0);
    if (!(c > 0.0)) return vec3(0.0);
    if (uColormapDriver != COLORMAP_HEIGHT && uColormapDriver != COLORMAP_SLOPE)
        return E * (c / PI) * cs;
    float li = colormapLambda(normalize(vec3(wl.xy, max(wl.z, 1e-3))));
    if (uColormapDriver == COLORMAP_SLOPE) return E * (c / PI) * (1.0 + lo) / (1.0 + lo + li) * cs;
    return E * (c / PI) * colormapHeightFootprint(s.M.x, colormapHeightVar(s), lo, li);
}

// colormap-lit (prefilter.colormap.lit.shade_lit, filter=filtered): the filtered colour of the
// visible and lit microfacets times the Lambert term, summed over the point and directional
// lights, the quad lights as 4 x 4 point-like patches (lit.QUAD_PATCHES, _quad_patches) and the
// environment as the texels of one mip level (lit.scene_sources)
vec3 shadeColormapLit(Hit h, vec3 view) {
    if (uColormapChain.x < 0) return vec3(0.0);
    CmStats s = colormapStats(h, true);
    float sg = dot(view, h.n) < 0.0 ? -1.0 : 1.0;
    vec3 gt = h.t, gb = sg * h.b, gn = sg * h.n;
    vec3 wo = normalize(vec3(dot(view, gt), dot(view, gb), max(dot(view, gn), 1e-3)));
    float lo = 0.0;
    vec3 cs = vec3(0.0);  // the light-independent colour: C0_bar (texture, noise), Cs_bar (slope)
    if (uColormapDriver == COLORMAP_SLOPE || uColormapDriver == COLORMAP_HEIGHT)
        lo = colormapLambda(wo);
    if (uColormapDriver == COLORMAP_SLOPE)
        cs = colormapSlope(wo, s.M.xy, colormapSlopeCov(s.M, s.B, s.ic, s.lod));
    else if (uColormapDriver != COLORMAP_HEIGHT) {
        cs = colormapFlat(s, true);
    }
    vec3 L = vec3(0.0);
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumPoints) break;
        vec3 d = uPointP[q] - h.p;
        float d2 = max(dot(d, d), 1e-30);
        L += colormapLitLight(s, d / sqrt(d2), uPointI[q] / d2, gt, gb, gn, cs, lo);
    }
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumDirs) break;
        L += colormapLitLight(s, normalize(-uDirD[q]), uDirE[q], gt, gb, gn, cs, lo);
    }
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumQuads) break;
        vec3 v0 = uQuadV[4 * q], v1 = uQuadV[4 * q + 1], v2 = uQuadV[4 * q + 2];
        vec3 v3 = uQuadV[4 * q + 3];
        for (int k = 0; k < 16; ++k) {
            float u = (float(k / 4) + 0.5) / 4.0, v = (float(k % 4) + 0.5) / 4.0;
            vec3 p = (1.0 - u) * (1.0 - v) * v0 + u * (1.0 - v) * v1 + u * v * v2
                     + (1.0 - u) * v * v3;
            vec3 du = (1.0 - v) * (v1 - v0) + v * (v2 - v3);
            vec3 dv = (1.0 - u) * (v3 - v0) + u * (v2 - v1);
            vec3 a = cross(du, dv) / 16.0;
            float area = length(a);
            vec3 d = p - h.p;
            float d2 = max(dot(d, d), 1e-30);
            vec3 w = d / sqrt(d2);
            float cl = max(-dot(w, a / area), 0.0);
            L += colormapLitLight(s, w, area * uQuadL[q] * (cl / d2), gt, gb, gn, cs, lo);
        }
    }
    // the environment: the texels of its first level with at most 8 rows (lit.ENV_ROWS), each
    // a directional light of irradiance L Omega (envmap.texel_directions; map -> world by the
    // transpose of ENV_FROM_WORLD)
    int el = -1;
    for (int l = 0; l < 16; ++l) {
        if (l >= leadrEnvLevels) break;
        if (textureSize(leadrEnv, l).y <= 8) { el = l; break; }
    }
    if (leadrEnvLevels > 0 && el < 0) el = 0;
    if (el >= 0) {
        ivec2 es = textureSize(leadrEnv, el);
        for (int i = 0; i < 64; ++i) {
            if (i >= es.y) break;
            float t0 = PI * float(i) / float(es.y), t1 = PI * float(i + 1) / float(es.y);
            float th = 0.5 * (t0 + t1);
            float om = (cos(t0) - cos(t1)) * 2.0 * PI / float(es.x);
            for (int j = 0; j < 128; ++j) {
                if (j >= es.x) break;
                float ph = (float(j) + 0.5) * 2.0 * PI / float(es.x);
                vec3 d = vec3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th));
                vec3 E = texelFetch(leadrEnv, ivec2(j, i), el).rgb * om;
                L += colormapLitLight(s, d * LEADR_ENV_FROM_WORLD, E, gt, gb, gn, cs, lo);
            }
        }
    }
    return L;
}
#endif

// leadr-env / leadr-irradiance: shaders/leadr_env.frag.glsl
vec3 shadeLeadrEnv(Hit h, vec3 view, bool diffuseOnly);
#ifdef GLINTS
// the glints modes (shaders/glints.frag.glsl, compiled only into the glints program)
vec3 shadeGlints(Hit h, vec3 view, bool smoothLobe);
#endif

vec3 shade(Hit h, vec3 view, int method) {
#ifdef GLINTS
    // the glints program shades nothing else (its samplers would exceed the 16 units WebGL2
    // guarantees next to the other methods')
    return shadeGlints(h, view, method == METHOD_GLINTS_SMOOTH);
#endif
    if (method == METHOD_LEADR_POINT) return shadeLeadr(h, view);
#ifndef GLINTS
    // the environment modes' program part (shaders/leadr_env.frag.glsl) is not in the glints one
    if (method == METHOD_LEADR_ENV || method == METHOD_LEADR_IRRADIANCE)
        return shadeLeadrEnv(h, view, method == METHOD_LEADR_IRRADIANCE);
#endif
#ifndef GLINTS
    // nor the colour-map modes (the slope stack would be one more sampler there)
    if (method == METHOD_COLORMAP_FILTERED || method == METHOD_COLORMAP_NAIVE)
        return shadeColormap(h, view, method == METHOD_COLORMAP_FILTERED);
    if (method == METHOD_COLORMAP_LIT) return shadeColormapLit(h, view);
#endif
    int k = h.id;
    ivec4 map = uMatMap[k];
    vec3 gn = h.n, gt = h.t, gb = h.b;
    if (dot(view, gn) < 0.0) { gn = -gn; gb = -gb; }  // two-sided: flip n, b
    vec3 base = uMatBase[k], f0 = uMatF0[k];
    float ax = uMatAlpha[k].x, ay = uMatAlpha[k].y;
    vec3 ts = gt, bs = gb, ns = gn;
    mat3 Minv;
    float mag, f5;
    if (method == METHOD_MULTISCALE_ANISO) {
        // prefilter.multiscale.aniso.aniso_attributes, combine = "lean"
        vec2 mean = vec2(0.0);
        vec3 cm = vec3(0.0);  // meso covariance (xx, yy, xy)
        if (map.z >= 0) {
            vec4 A, B;
            vec4 fp = h.dudv * msLodScale(footprintMajor(map.zw, h.dudv), MSA_LOD_BIAS,
                                          MSA_LOD_START);
            footprint(map.zw, h.uv, fp, A, B);
            mean = A.xy;
            cm = vec3(max(A.z - mean.x * mean.x, 0.0), max(A.w - mean.y * mean.y, 0.0),
                      B.x - mean.x * mean.y);
        }
        const float C2 = 0.78 * 0.78;  // GGX_PER_BECKMANN^2
        float a = C2 * cm.x + 0.5 * ax * ax, c = C2 * cm.y + 0.5 * ay * ay, b = C2 * cm.z;
        float mid = 0.5 * (a + c), disc = sqrt(0.25 * (a - c) * (a - c) + b * b);
        float l1 = mid + disc, l2 = max(mid - disc, 0.0);
        // numpy's arctan2(0, 0) = 0 (GLSL leaves it undefined)
        float phi = (b == 0.0 && a - c == 0.0) ? 0.0 : 0.5 * atan(2.0 * b, a - c);
        float co = cos(phi), si = sin(phi);
        vec3 tr = co * gt + si * gb, br = -si * gt + co * gb;
        vec3 m = vec3(-co * mean.x - si * mean.y, si * mean.x - co * mean.y, 1.0);
        shadingFrame(tr, br, gn, m, ts, bs, ns);
        ax = min(sqrt(2.0 * l1), 1.0);
        ay = min(sqrt(2.0 * l2), 1.0);
    } else if (map.x >= 0) {
        vec4 A, B;
        if (method == METHOD_MULTISCALE) footprintMs(map.xy, h.uv, h.dudv, A, B);
        else footprint(map.xy, h.uv, h.dudv, A, B);
        shadingFrame(gt, gb, gn, A.xyz, ts, bs, ns);
        if (method == METHOD_MULTISCALE) {
            float am = alphaMeso(min(length(A.xyz), 1.0));
            ax = ay = alphaTotal(min(sqrt(ax * ay), 1.0), am);
        }
    } else if (map.z >= 0) {
        // a height map: its mean slope gives the normal (texture.slopes_to_normals); r = 1
        vec4 A, B;
        footprint(map.zw, h.uv, h.dudv, A, B);
        shadingFrame(gt, gb, gn, vec3(-A.x, -A.y, 1.0), ts, bs, ns);
        if (method == METHOD_MULTISCALE) ax = ay = alphaTotal(min(sqrt(ax * ay), 1.0), 0.0);
    } else if (method == METHOD_MULTISCALE) {
        ax = ay = alphaTotal(min(sqrt(ax * ay), 1.0), alphaMeso(1.0));
    }
    ivec4 cmap = uMatColor[k];
    if (cmap.x >= 0) {  // a colour map multiplies base_color (footprint's mip level)
        vec4 A, B;
        footprint(cmap.xy, h.uv, h.dudv, A, B);
        base *= cmap.z >= 3 ? A.rgb : vec3(A.r);
    }
    vec3 wo = localView(view, ts, bs, ns);
    bool aniso = method == METHOD_ANISO || method == METHOD_MULTISCALE_ANISO;
    // the isotropic methods shade delta lights with the isotropic alpha they give the table
    float ai = sqrt(ax * ay);
    vec3 Ld = shadeDelta(h.p, ts, bs, ns, wo, aniso ? ax : ai, aniso ? ay : ai, base, f0);
    if (aniso) {
        vec3 w = normalize(vec3(wo.xy, max(wo.z, 1e-4)));
        ltcAnisoLookup(w, clamp(ax, 1e-4, 1.0), clamp(ay, 1e-4, 1.0), Minv, mag, f5);
    } else {
        ltcIsoLookup(wo, sqrt(ax * ay), Minv, mag, f5);
    }
    vec3 spec = f0 * (mag - f5) + f5;
    return Ld + shadeQuads(h.p, ts, bs, ns, Minv, base, spec);
}

// display only (the Python renderer does not draw emitters): the nearest quad light in front of
// the ray's hit, seen from its lit side
bool hitLight(vec3 o, vec3 d, float tmax, out vec3 L) {
    bool found = false;
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumQuads) break;
        vec3 n = uQuadN[q], v0 = uQuadV[4 * q];
        float den = dot(d, n);
        if (den >= 0.0) continue;
        float t = dot(v0 - o, n) / den;
        if (!(t > 0.0 && t < tmax)) continue;
        vec3 p = o + t * d;
        bool inside = true;
        for (int k = 0; k < 4; ++k) {
            vec3 a = uQuadV[4 * q + k], b = uQuadV[4 * q + (k + 1) % 4];
            if (dot(cross(b - a, p - a), n) < 0.0) inside = false;
        }
        if (inside) { tmax = t; L = uQuadL[q]; found = true; }
    }
    return found;
}

vec3 srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

void main() {
    // pixel (row i, column j) has its centre at (j + 0.5, i + 0.5), row 0 at the top
    vec2 xy = vec2(gl_FragCoord.x, uSize.y - gl_FragCoord.y);
    vec2 pp = vec2(xy.x - uSize.x / 2.0, uSize.y / 2.0 - xy.y) * uCamSy;
    vec3 d = uCamF + pp.x * uCamR + pp.y * uCamU;
    float inv = 1.0 / length(d);
    d *= inv;
    // derivatives of d / |d| (camera.rays_at)
    vec3 ex = uCamSy * uCamR, ey = -uCamSy * uCamU;
    vec3 ddx = (ex - dot(d, ex) * d) * inv, ddy = (ey - dot(d, ey) * d) * inv;
    Hit h;
    vec3 L = vec3(0.0);
    int method = gl_FragCoord.x < uSplit ? uMethodLeft : uMethodRight;
    if (trace(uCamO, d, ddx, ddy, h)) L = shade(h, -d, method);
    if (uLinear == 1) {
        fragColor = vec4(L, h.id >= 0 ? 1.0 : 0.0);
    } else {
        vec3 Le;
        if (hitLight(uCamO, d, h.id >= 0 ? h.dist : 1e30, Le)) L = Le;
        vec3 c = srgb(L * uExposure);
        if (abs(gl_FragCoord.x - uSplit) < 1.0 && uSplit > 0.0 && uSplit < uSize.x)
            c = vec3(1.0, 0.8, 0.2);
        fragColor = vec4(c, 1.0);
    }
}
