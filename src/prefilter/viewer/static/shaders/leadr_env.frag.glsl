// leadr-env / leadr-irradiance (prefilter.leadr.render.shade_leadr_env / shade_leadr_irradiance,
// algorithm=full): the height map's moments box-filtered over the footprint as leadr-point, the
// environment terms of the exported leadr_env.glsl, and the point / directional lights as
// leadr-point (leadr-irradiance: their shadowed diffuse only). Geometric frame, two-sided.
// Included after viewer.frag.glsl (which declares it).
vec3 shadeLeadrEnv(Hit h, vec3 view, bool diffuseOnly) {
    int k = h.id;
    vec3 gn, gt, gb, wo;
    vec2 mu;
    vec3 cov;
    leadrFootprint(h, view, gt, gb, gn, wo, mu, cov);
    mat3 toMap = LEADR_ENV_FROM_WORLD * mat3(gt, gb, gn);
    vec3 base = uMatBase[k], f0 = uMatF0[k];
    vec3 L = vec3(0.0), E = vec3(0.0);  // E: the diffuse layer's light (albedo 1)
    if (leadrEnvLevels > 0) {
        if (!diffuseOnly && any(notEqual(f0, vec3(0.0))))
            L += leadrEnvSpecular(wo, mu, cov, f0, toMap);
        if (any(notEqual(base, vec3(0.0)))) E += leadrEnvDiffuse(wo, mu, cov, toMap);
    }
    for (int q = 0; q < 2 * MAX_QUADS; ++q) {
        if (q >= uNumPoints + uNumDirs) break;
        vec3 w, e;
        if (q < uNumPoints) {
            vec3 d = uPointP[q] - h.p;
            float d2 = max(dot(d, d), 1e-30);
            w = d / sqrt(d2);
            e = uPointI[q] / d2;
        } else {
            w = -uDirD[q - uNumPoints];
            e = uDirE[q - uNumPoints];
        }
        vec3 wi = normalize(vec3(dot(w, gt), dot(w, gb), dot(w, gn)));
        if (diffuseOnly) E += leadrDiffuse(wo, wi, mu, cov) * leadrShadowing(wo, wi, mu, cov) * e;
        else L += leadrDelta(wo, wi, mu, cov, base, f0) * e;
    }
    return L + base * E;
}
