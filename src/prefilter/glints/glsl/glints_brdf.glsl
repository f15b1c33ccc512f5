// The glint BRDF (glints paper, eq. 1 and sec. 5.1; prefilter.glints.brdf.glint_brdf_cos):
// F(wi.h) G(wo, wi, h) D_P(h_xy) / (4 wo_z) in the geometric tangent frame, D_P the footprint's
// P-NDF: compressed point query at or above glSigmaMin, direct P-NDF below it.

// glint_ndf: footprint centre c and std sp in texels, s the projected half vector
float glintNdf(vec2 c, float sp, vec2 s) {
    if (glDirect == 1 && sp < glSigmaMin) return glDirectNdf(c, sp, s);
    return glPointQuery(c, sp, s);
}

// V-cavity masking min(1, 2 m_z w_z / (w.m)) (Cook and Torrance 1982), 0 when w.m <= 0
float glVcavityG1(vec3 w, vec3 m) {
    float wm = dot(w, m);
    if (!(wm > 0.0 && w.z > 0.0)) return 0.0;
    return clamp(2.0 * m.z * w.z / wm, 0.0, 1.0);
}

// Schlick 1994, eq. 24 (prefilter.microfacet.fresnel.schlick)
vec3 glSchlick(vec3 f0, float c) {
    c = clamp(c, 0.0, 1.0);
    float t = 1.0 - c;
    return f0 + (1.0 - f0) * (t * t * t * t * t);
}

// brdf_cos_from_ndf: F G D / (4 wo_z), zero below either horizon
vec3 glBrdfFromNdf(vec3 wo, vec3 wi, vec3 h, float D, vec3 f0) {
    if (!(wo.z > 0.0 && wi.z > 0.0 && h.z > 0.0)) return vec3(0.0);
    float G = min(glVcavityG1(wo, h), glVcavityG1(wi, h));
    return D * G / (4.0 * wo.z) * glSchlick(f0, dot(wi, h));
}

vec3 glHalf(vec3 wo, vec3 wi) {
    vec3 h = wo + wi;
    return h / max(length(h), 1e-30);
}

// glint_brdf_cos: the cosine-weighted glint BRDF of footprint (c, sp)
vec3 glintBrdfCos(vec2 c, float sp, vec3 wo, vec3 wi, vec3 f0) {
    vec3 h = glHalf(wo, wi);
    return glBrdfFromNdf(wo, wi, h, glintNdf(c, sp, h.xy), f0);
}

// the smooth lobe with the NDF's moments: a Gaussian in s of mean mu, covariance (xx, yy, xy)
// (prefilter.glints.gpu.slope_moments), the same masking and Fresnel
vec3 glSmoothBrdfCos(vec2 mu, vec3 cov, vec3 wo, vec3 wi, vec3 f0) {
    vec3 h = glHalf(wo, wi);
    vec2 e = h.xy - mu;
    float det = cov.x * cov.y - cov.z * cov.z;
    float quad = (cov.y * e.x * e.x - 2.0 * cov.z * e.x * e.y + cov.x * e.y * e.y) / det;
    float D = exp(-0.5 * quad) / (2.0 * GLT_PI * sqrt(det));
    return glBrdfFromNdf(wo, wi, h, D, f0);
}
