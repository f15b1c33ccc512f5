// The direct P-NDF of Yan et al. 2016 below the finest level (prefilter.glints.brdf.direct_ndf,
// truncated at GLT_FALLBACK_TRUNCATION stds): per texel of the footprint window, the element's
// Gaussian in s (slope marginal conditioned on the footprint, intrinsic roughness glSr),
// weighted by the Gaussian footprint; elements beyond 6 of their stds dropped (most of them
// before their Jacobian is read, by a bound from the |J|_F stored next to their slope).
float glDirectNdf(vec2 c, float sp, vec2 q) {
    float sh2 = GLT_SIGMA_H * GLT_SIGMA_H, sp2 = sp * sp, tot2 = sp2 + sh2;
    float rad = GLT_FALLBACK_TRUNCATION * sqrt(tot2);
    int x0 = int(ceil(c.x - rad - 0.5)), x1 = int(floor(c.x + rad - 0.5));
    int y0 = int(ceil(c.y - rad - 0.5)), y1 = int(floor(c.y + rad - 0.5));
    float f = sh2 / tot2, var = sp2 * sh2 / tot2, inv = 1.0 / (2.0 * tot2), sr2 = glSr * glSr;
    int H = glMapSize.x, W = glMapSize.y;
    float sx = 0.0, sy = 0.0, acc = 0.0;
    for (int x = x0; x <= x1; ++x) {
        float dx = c.x - (float(x) + 0.5);
        sx += exp(-dx * dx * inv);
    }
    for (int y = y0; y <= y1; ++y) {
        float dy = c.y - (float(y) + 0.5);
        float wy = exp(-dy * dy * inv);
        sy += wy;
        int row = glMod(y, H) * W, xm = glMod(x0, W);
        GlCursor e = glCursor(2 * (row + xm), GLT_TEX_ELEMENTS);
        float racc = 0.0;
        for (int x = x0; x <= x1; ++x) {
            float dx = c.x - (float(x) + 0.5);
            vec4 se = texelFetch(glElements, e.p, 0);  // s_x, s_y, |J|_F
            GlCursor ej = e;
            glStep(ej);
            if (++xm == W) { xm = 0; e = glCursor(2 * row, GLT_TEX_ELEMENTS); }
            else { glStep(e); glStep(e); }
            // |e| >= |q - s| - f |J|_F |d| and the covariance's largest eigenvalue is at most
            // sr2 + var |J|_F^2: beyond 6 stds there too, the element is dropped unread
            float nJ = se.z, lb = max(length(q - se.xy) - f * nJ * length(vec2(dx, dy)), 0.0);
            if (lb * lb >= 36.01 * (sr2 + var * nJ * nJ)) continue;
            vec4 J = texelFetch(glElements, ej.p, 0);  // J00, J01, J10, J11
            float ex = q.x - se.x - (J.x * f * dx + J.y * f * dy);
            float ey = q.y - se.y - (J.z * f * dx + J.w * f * dy);
            // element_covariance: sr2 I + var J J^T; its determinant without cancellation
            float P = J.x * J.x + J.y * J.y, Q = J.z * J.z + J.w * J.w;
            float a = sr2 + var * P, b = var * (J.x * J.z + J.y * J.w), d = sr2 + var * Q;
            float dJ = J.x * J.w - J.y * J.z;
            float det = sr2 * sr2 + sr2 * var * (P + Q) + var * var * dJ * dJ;
            float quad = d * ex * ex - 2.0 * b * ex * ey + a * ey * ey;
            if (quad < 36.0 * det) racc += exp(-dx * dx * inv) * exp(-0.5 * quad / det) / sqrt(det);
        }
        acc += wy * racc;
    }
    return acc / (2.0 * GLT_PI * sx * sy);
}
