// Height-correlated colour over a footprint (Heitz et al. 2013, section 5.1, eqs. 13-17, with
// our footprint extension: prefilter.colormap.height.height_footprint, kernels._height_kernel).
// Heights are normalised (sigma_h = 1); the footprint's heights are N(mean, var). The probit
// tilt (kappa_L, d_L) of P_h^L is read linearly in log L from CM_PROBIT_KAPPA / CM_PROBIT_D
// (height._probit_table); Phi and the Mills ratio phi / Phi come from colormapErfcx, stable in
// the deep-shadow tail. CM_SLOPE_COV = (xx, yy, xy) of the height map's slopes.

// Smith Lambda of the centred Gaussian surface (eq. 3) towards w (w.z > 0)
float colormapLambda(vec3 w) {
    float r = length(w.xy);
    if (!(r > 0.0)) return 0.0;
    vec2 c = w.xy / r;
    float s = sqrt(CM_SLOPE_COV.x * c.x * c.x + 2.0 * CM_SLOPE_COV.z * c.x * c.y
                   + CM_SLOPE_COV.y * c.y * c.y);
    float a = w.z / r / (s * 1.41421356);
    return max(0.5 * exp(-a * a) * (1.0 / (a * 1.77245385) - colormapErfcx(a)), 0.0);
}

// (kappa_L, d_L): no tilt below the grid
vec2 colormapProbit(float lam) {
    if (lam < CM_PROBIT_LMIN) return vec2(0.0, 40.0);
    float x = (log(lam) - CM_PROBIT_T0) / CM_PROBIT_DT;
    int i = clamp(int(x), 0, CM_PROBIT_N - 2);
    float f = clamp(x - float(i), 0.0, 1.0);
    return vec2(mix(CM_PROBIT_KAPPA[i], CM_PROBIT_KAPPA[i + 1], f),
                mix(CM_PROBIT_D[i], CM_PROBIT_D[i + 1], f));
}

// log Phi(z)
float colormapLogPhi(float z) {
    float e = colormapErfcx(abs(z) * 0.70710678);
    return z < 0.0 ? log(0.5 * e) - 0.5 * z * z : log(1.0 - 0.5 * e * exp(-0.5 * z * z));
}

// V_bar <C_h, D_h> (eq. 14) of a footprint with height mean `mean` and variance `var`
vec3 colormapHeightFootprint(float mean, float var, float lambdaO, float lambdaI) {
    float v = max(var, 0.0);
    vec2 p1 = colormapProbit(lambdaO + lambdaI), p0 = colormapProbit(lambdaO);
    float ir1 = 1.0 / sqrt(1.0 + p1.x * p1.x * v);
    float z1 = (p1.x * mean + p1.y) * ir1;
    float z0 = (p0.x * mean + p0.y) / sqrt(1.0 + p0.x * p0.x * v);
    float lz = colormapMills(z1);
    float vb = exp(colormapLogPhi(z1) - colormapLogPhi(z0));
    float a = p1.x * v * ir1;
    float m = mean + a * lz;
    float vv = max(v - a * a * lz * (z1 + lz), 0.0);
    return vb * colormapFiltered(m, sqrt(vv));
}

// the naive counterpart: V_bar C(mean), V_bar = (1 + Lambda_o) / (1 + Lambda_o + Lambda_i)
vec3 colormapHeightNaive(float mean, float lambdaO, float lambdaI) {
    return (1.0 + lambdaO) / (1.0 + lambdaO + lambdaI) * colormapFiltered(mean, 0.0);
}
