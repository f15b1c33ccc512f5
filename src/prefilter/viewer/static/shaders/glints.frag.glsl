// The viewer's `glints` mode (prefilter.glints.render.shade_glints with mode "compressed"), after
// viewer.frag.glsl: geometric two-sided frame, Gaussian pixel footprint of std
// 0.5 sqrt|det J| texels (render.footprints), the glints GLSL's BRDF per point / directional
// light, Lambert by the polygon formula and range queries over 2 x 2 (then 4 x 4) patches of
// each quad light's half-vector region (render.quad_range). `glints-smooth`: the same shading
// with a Gaussian NDF of the map's slope moments (split view).
uniform vec2 glMomentMean;   // prefilter.glints.gpu.slope_moments
uniform vec3 glMomentCov;    // (xx, yy, xy)

const float GLT_QUAD_RANGE_MAX = 0.08;   // render.RANGE_MAX
const float GLT_QUAD_FILL_MIN = 0.3;     // render.FILL_MIN
const float GLT_HORIZON = 1e-3;

vec3 glintsBrdf(bool smoothLobe, vec2 c, float sp, vec3 wo, vec3 wi, vec3 f0) {
    return smoothLobe ? glSmoothBrdfCos(glMomentMean, glMomentCov, wo, wi, f0)
                      : glintBrdfCos(c, sp, wo, wi, f0);
}

vec3 glQuadPoint(vec3 C[4], float a, float b) {
    return (1.0 - a) * (1.0 - b) * C[0] + a * (1.0 - b) * C[1] + a * b * C[2] + (1.0 - a) * b * C[3];
}

// render.quad_range: false where the range path does not apply (value 0 then)
bool glQuadRange(vec3 C[4], vec3 wo, vec2 c, float sp, vec3 f0, int n, bool smoothLobe,
                 out vec3 val) {
    val = vec3(0.0);
    if (sp < glSigmaMin || !(wo.z > 0.0)) return false;
    if (!(dot(cross(C[1] - C[0], C[2] - C[0]), C[0]) < 0.0)) return false;
    float fn = float(n);
    vec4 rect[GLT_MAX_RECTS];
    vec3 fac[GLT_MAX_RECTS];
    float mean[GLT_MAX_RECTS];
    // validity over all patches first (every grid direction and every patch)
    for (int i = 0; i <= n; ++i) for (int j = 0; j <= n; ++j) {
        vec3 d = normalize(glQuadPoint(C, float(i) / fn, float(j) / fn));
        if (!(d.z > GLT_HORIZON) || !(glHalf(wo, d).z > 0.0)) return false;
    }
    for (int pass = 0; pass < 2; ++pass) {
        for (int i = 0; i < n; ++i) for (int j = 0; j < n; ++j) {
            // patch corners counter-clockwise in (a, b)
            vec2 q[4];
            ivec2 ij[4] = ivec2[4](ivec2(i, j), ivec2(i + 1, j), ivec2(i + 1, j + 1), ivec2(i, j + 1));
            for (int k = 0; k < 4; ++k)
                q[k] = glHalf(wo, normalize(glQuadPoint(C, float(ij[k].x) / fn, float(ij[k].y) / fn))).xy;
            float cr = 0.0, cx = 0.0, cy = 0.0;
            vec2 lo = q[0], hi = q[0];
            for (int k = 0; k < 4; ++k) {
                vec2 p = q[k], s = q[(k + 1) % 4];
                float x = p.x * s.y - s.x * p.y;
                cr += x; cx += (p.x + s.x) * x; cy += (p.y + s.y) * x;
                lo = min(lo, p); hi = max(hi, p);
            }
            float area = 0.5 * abs(cr);
            vec2 ext = hi - lo;
            if (pass == 0) {
                if (!(ext.x < GLT_QUAD_RANGE_MAX && ext.y < GLT_QUAD_RANGE_MAX)) return false;
                if (!(area >= GLT_QUAD_FILL_MIN * ext.x * ext.y)) return false;
                continue;
            }
            // equal-area rectangle at the centroid (render._equal_area_rects)
            float a2 = abs(cr) > 1e-30 ? cr : 1e-30;
            vec2 ctr = vec2(cx, cy) / (3.0 * a2);
            float f = sqrt(area / max(ext.x * ext.y, 1e-30));
            int p = i * n + j;
            rect[p] = vec4(ctr - 0.5 * f * ext, ctr + 0.5 * f * ext);
            vec3 wi = normalize(glQuadPoint(C, (float(i) + 0.5) / fn, (float(j) + 0.5) / fn));
            vec3 hc = glHalf(wo, wi);
            float jac = 4.0 * dot(wi, hc) / max(hc.z, 1e-30);
            fac[p] = glBrdfFromNdf(wo, wi, hc, 1.0, f0) * (jac * area);
            if (smoothLobe) {
                // the smooth lobe's NDF at the patch centre stands in for its range mean
                vec2 e = hc.xy - glMomentMean;
                vec3 cv = glMomentCov;
                float det = cv.x * cv.y - cv.z * cv.z;
                mean[p] = exp(-0.5 * (cv.y * e.x * e.x - 2.0 * cv.z * e.x * e.y
                                      + cv.x * e.y * e.y) / det) / (2.0 * GLT_PI * sqrt(det));
            }
        }
    }
    // every patch's rectangle in one range query (range_multi: the taps walked once per block)
    if (!smoothLobe) glRangeMulti(c, sp, rect, n * n, mean);
    for (int p = 0; p < n * n; ++p) val += fac[p] * mean[p];
    return true;
}

vec3 shadeGlints(Hit h, vec3 view, bool smoothLobe) {
    int k = h.id;
    vec3 gn = h.n, gt = h.t, gb = h.b;
    if (dot(view, gn) < 0.0) { gn = -gn; gb = -gb; }  // two-sided: flip n, b
    vec3 wo = normalize(vec3(dot(view, gt), dot(view, gb), dot(view, gn)));
    // render.footprints: centre uv (W, H) texels (whole periods removed: the map tiles), std
    // PIXEL_SIGMA sqrt|det J| of J = diag(W, H) dudv
    vec2 size = vec2(float(glMapSize.y), float(glMapSize.x));
    vec2 c = (h.uv - floor(h.uv)) * size;
    vec4 J = h.dudv * vec4(size.x, size.x, size.y, size.y);
    float sp = 0.5 * sqrt(abs(J.x * J.w - J.y * J.z));
    vec3 base = uMatBase[k], f0 = uMatF0[k];
    vec3 L = vec3(0.0);
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumPoints) break;
        vec3 d = uPointP[q] - h.p;
        float d2 = max(dot(d, d), 1e-30);
        vec3 w = d / sqrt(d2);
        vec3 wi = normalize(vec3(dot(w, gt), dot(w, gb), dot(w, gn)));
        L += (glintsBrdf(smoothLobe, c, sp, wo, wi, f0) + base / PI * max(wi.z, 0.0))
             * uPointI[q] / d2;
    }
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumDirs) break;
        vec3 w = -uDirD[q];
        vec3 wi = normalize(vec3(dot(w, gt), dot(w, gb), dot(w, gn)));
        L += (glintsBrdf(smoothLobe, c, sp, wo, wi, f0) + base / PI * max(wi.z, 0.0)) * uDirE[q];
    }
    for (int q = 0; q < MAX_QUADS; ++q) {
        if (q >= uNumQuads) break;
        vec3 Q[4] = vec3[4](uQuadV[4 * q], uQuadV[4 * q + 1], uQuadV[4 * q + 2], uQuadV[4 * q + 3]);
        L += ltcQuad(Q, uQuadN[q], uQuadL[q], h.p, gt, gb, gn, mat3(1.0), base, vec3(0.0));
        vec3 C[4];
        for (int v = 0; v < 4; ++v) {
            vec3 d = Q[v] - h.p;
            C[v] = vec3(dot(d, gt), dot(d, gb), dot(d, gn));
        }
        vec3 val;
        if (glQuadRange(C, wo, c, sp, f0, 2, smoothLobe, val)
            || glQuadRange(C, wo, c, sp, f0, 4, smoothLobe, val))
            L += val * uQuadL[q];
    }
    return L;
}
