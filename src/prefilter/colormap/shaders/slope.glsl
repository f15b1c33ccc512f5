// Slope-correlated colour (Heitz et al. 2013, section 5.2, eq. 20; prefilter.colormap.slope):
// the view-dependent slope distribution D_s = ramp x Gaussian replaced by the Gaussian of its
// exact moments (slope_distribution, docs/slope-filtering.md), then <C_s, N(mean, cov)> from
// the isotropically pre-blurred stack (SlopeColormapTable.lookup): the stack at the minor std,
// CM_SLOPE_TAPS Gauss-Hermite taps along the major axis. The stack is uCmSlopeStack, RGBA32F,
// level k in rows k n .. k n + n - 1 (row = s_y, column = s_x), read with texelFetch.
uniform highp sampler2D uCmSlopeStack;

// trilinear read at slope s and isotropic std sigma (SlopeColormapTable._trilinear; clamped)
vec3 colormapSlopeTrilinear(vec2 s, float sigma) {
    int n = CM_SLOPE_N, nl = CM_SLOPE_LEVELS;
    float e = CM_SLOPE_EXTENT;
    vec2 xy = clamp((s + e) / (2.0 * e) * float(n) - 0.5, -1.0, float(n));
    vec2 f0 = floor(xy), f = xy - f0;
    int j0 = clamp(int(f0.x), 0, n - 1), j1 = clamp(int(f0.x) + 1, 0, n - 1);
    int i0 = clamp(int(f0.y), 0, n - 1), i1 = clamp(int(f0.y) + 1, 0, n - 1);
    float z = clamp(sigma / CM_SLOPE_SIGMA_MAX, 0.0, 1.0) * float(nl - 1);
    int k0 = min(int(floor(z)), nl - 2);
    float fz = z - float(k0);
    vec3 out3 = vec3(0.0);
    for (int q = 0; q < 2; ++q) {
        int r = (k0 + q) * n;
        vec3 top = texelFetch(uCmSlopeStack, ivec2(j0, r + i0), 0).rgb * (1.0 - f.x)
            + texelFetch(uCmSlopeStack, ivec2(j1, r + i0), 0).rgb * f.x;
        vec3 bot = texelFetch(uCmSlopeStack, ivec2(j0, r + i1), 0).rgb * (1.0 - f.x)
            + texelFetch(uCmSlopeStack, ivec2(j1, r + i1), 0).rgb * f.x;
        out3 += (q == 0 ? 1.0 - fz : fz) * (top * (1.0 - f.y) + bot * f.y);
    }
    return out3;
}

// <C_s, N(mean, cov)>, cov = (xx, yy, xy) (SlopeColormapTable.lookup)
vec3 colormapSlopeLookup(vec2 mean, vec3 cov) {
    float p = cov.x, q = cov.z, r = cov.y;
    float mid = 0.5 * (p + r), disc = sqrt(max(0.25 * (p - r) * (p - r) + q * q, 0.0));
    float l1 = mid + disc, l2 = max(mid - disc, 0.0);
    vec2 v1 = vec2(q, l1 - p), v2 = vec2(l1 - r, q);
    vec2 e1 = dot(v1, v1) >= dot(v2, v2) ? v1 : v2;
    float ne = length(e1);
    e1 = ne > 0.0 ? e1 / ne : vec2(1.0, 0.0);
    vec2 ax = sqrt(max(l1 - l2, 0.0)) * e1;
    float si = sqrt(l2);
    vec3 c = vec3(0.0);
    for (int k = 0; k < CM_SLOPE_TAPS; ++k)
        c += CM_SLOPE_W[k] * colormapSlopeTrilinear(mean + CM_SLOPE_X[k] * ax, si);
    return c;
}

// mean and covariance (xx, yy, xy) of D_s towards wo (tangent frame, wo.z > 0) for slopes
// N(mu, cov) over the footprint (slope.slope_distribution)
void colormapSlopeDistribution(vec3 wo, vec2 mu, vec3 cov, out vec2 meanD, out vec3 covD) {
    vec2 a = -wo.xy;
    float mt = wo.z + dot(a, mu);
    vec2 sa = vec2(cov.x * a.x + cov.z * a.y, cov.z * a.x + cov.y * a.y);
    float vt = dot(a, sa);
    if (!(vt > 1e-30)) { meanD = mu; covD = cov; return; }  // t does not vary
    float sd = sqrt(vt);
    float alpha = max(mt / sd, -37.0);
    float lam = colormapMills(alpha);  // phi(alpha) / Phi(alpha)
    float m1 = alpha + lam;
    float varU;
    if (alpha >= 0.0) {
        varU = 1.0 + lam / m1 - 1.0 / (m1 * m1);
    } else {
        float m2 = alpha * alpha + 1.0 + alpha * lam;
        float m3 = alpha * alpha * alpha + 3.0 * alpha + (alpha * alpha + 2.0) * lam;
        varU = m3 / m1 - (m2 / m1) * (m2 / m1);
    }
    varU = clamp(varU, 0.0, 1.0);
    meanD = mu + sa / (sd * m1);
    float shrink = (1.0 - varU) / vt;
    covD = cov - vec3(sa.x * sa.x, sa.y * sa.y, sa.x * sa.y) * shrink;
}

// filtered slope-correlated colour C_s_bar(wo) = <C_s, D_s> (slope.filter_slope)
vec3 colormapSlope(vec3 wo, vec2 mu, vec3 cov) {
    vec2 m;
    vec3 c;
    colormapSlopeDistribution(wo, mu, cov, m, c);
    return colormapSlopeLookup(m, c);
}

// the naive counterpart: C(mean slope) (SlopeColormapTable.naive)
vec3 colormapSlopeNaive(vec2 mu) {
    return colormapSlopeTrilinear(mu, 0.0);
}
