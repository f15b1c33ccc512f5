// The direct P-NDF of Yan et al. 2016 below the finest level (prefilter.glints.brdf.direct_ndf,
// truncated at GLT_FALLBACK_TRUNCATION stds): per texel of the footprint window, the element's
// Gaussian in s (slope marginal conditioned on the footprint, intrinsic roughness glSr),
// weighted by the Gaussian footprint; elements beyond 6 of their stds dropped.
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
        int row = glMod(y, H) * W;
        float racc = 0.0;
        for (int x = x0; x <= x1; ++x) {
            float dx = c.x - (float(x) + 0.5);
            int k = 2 * (row + glMod(x, W));
            vec2 s = glFetchElement(k).xy;
            vec4 J = glFetchElement(k + 1);  // J00, J01, J10, J11
            float ex = q.x - s.x - (J.x * f * dx + J.y * f * dy);
            float ey = q.y - s.y - (J.z * f * dx + J.w * f * dy);
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
