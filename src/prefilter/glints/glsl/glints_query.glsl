// Compressed NDF queries (glints paper, eqs. 6-7): prefilter.glints.query.point_flat with
// interp="resample", bilinear=True (the `glints` method's surface) and range_multi over the
// resampling weights, as prefilter.glints._qkernels computes them (float32 here).

// pixel_taps(f, R, True): pixels p0, p0 + 1 with weights 1 - t, t (0 outside [0, R))
void glPixelTaps(float f, out int p0, out float w0, out float w1) {
    float g = f - 0.5;
    float fp = floor(g);
    float t = g - fp;
    p0 = int(fp);
    w0 = (p0 >= 0 && p0 < glR) ? 1.0 - t : 0.0;
    w1 = (p0 + 1 >= 0 && p0 + 1 < glR) ? t : 0.0;
}

// _block_tap: tap d of the pair p0, p0 + 1 split at block boundaries; false: nothing to add
bool glBlockTap(int p0, float w0, float w1, int d, out int blk, out int off, out float w,
                out float wn) {
    w = d == 0 ? w0 : w1;
    blk = 0; off = 0; wn = 0.0;
    if (w == 0.0) return false;
    int p = p0 + d;
    blk = p / glB;
    if (d == 1 && w0 != 0.0 && p0 / glB == blk) return false;
    wn = (d == 0 && w1 != 0.0 && (p0 + 1) / glB == blk) ? w1 : 0.0;
    off = p - blk * glB;
    return true;
}

// _factor_dot: sum_r w[m + r] c[kc + r] fa_r fb_r, fa_r = wa0 Fa[ia, r] + wa1 Fa[ia + 1, r]
float glFactorDot(int m, int nr, int ia, float wa0, float wa1, int ja, float wb0, float wb1,
                  int kc) {
    int ra = m * glB + ia * nr, rb = m * glB + ja * nr;
    float s = 0.0;
    for (int r = 0; r < nr; ++r) {
        float fa = wa0 * glFetchFa(ra + r);
        if (wa1 != 0.0) fa += wa1 * glFetchFa(ra + nr + r);
        float fb = wb0 * glFetchFb(rb + r);
        if (wb1 != 0.0) fb += wb1 * glFetchFb(rb + nr + r);
        s += glFetchW(m + r) * (glFetchC(kc + r) * fa * fb);
    }
    return s;
}

// one image's contribution at block (bi, bj): its code row and group record; false if blank
bool glBlockRow(int img, int bi, int bj, out ivec4 meta, out int kc) {
    int nb2 = glNb * glNb;
    int k = glFetchIndex(img * nb2 + bi * glNb + bj);
    kc = 0;
    meta = ivec4(0);
    if (k < 0) return false;
    meta = glFetchMeta(glFetchCell(img) * nb2 + bi * glNb + bj);
    kc = meta.z + k * meta.w;
    return true;
}

// pyramid.resample_weights' level: the coarsest finer level with q >= q_min, -1: none
int glResampleLevel(float s) {
    if (!(s < glSig[glLevels - 1])) return -1;
    for (int lv = GLT_MAX_LEVELS - 1; lv >= 0; --lv) {
        if (lv >= glLevels || !(glSig[lv] < s)) continue;
        float a = glSig[lv] / s;
        if (sqrt(max(1.0 - a * a, 0.0)) * glSig[lv] / glStride[lv] >= GLT_RESAMPLE_Q_MIN)
            return lv;
    }
    return -1;
}

// the resampling taps of level m: centre index ranges (x0, x1, y0, y1) and the kernel std r
ivec4 glResampleTaps(int m, vec2 c, float s, out float r) {
    r = sqrt(s * s - glSig[m] * glSig[m]);
    float st = glStride[m];
    float hw = GLT_RESAMPLE_TRUNCATION * r / st;
    vec2 g = (c - 0.5) / st;
    return ivec4(int(ceil(g.x - hw)), int(floor(g.x + hw)), int(ceil(g.y - hw)),
                 int(floor(g.y + hw)));
}

float glTapWeight(int k, float st, float c, float r) {
    float d = (float(k) * st + 0.5 - c) / r;
    return exp(-0.5 * d * d);
}

// interp_weights: trilinear image `t` (0..7) of a footprint and its weight
int glTrilinearTap(vec2 c, float s, int t, out float w) {
    int top = glLevels - 1;
    float tt = clamp(log2(max(s, 1e-30) / glSig[0]), 0.0, float(top));
    int l0 = min(int(floor(tt)), max(top - 1, 0));
    float fl = top == 0 ? 0.0 : tt - float(l0);
    int dl = t / 4, dy = (t / 2) % 2, dx = t % 2;
    int lv = min(l0 + dl, top);
    float wl = dl == 1 ? fl : 1.0 - fl;
    float st = glStride[lv];
    vec2 g = (c - 0.5) / st;
    vec2 g0 = floor(g);
    vec2 f = g - g0;
    int ny = glShape[lv].x, nx = glShape[lv].y;
    int ix = glMod(int(g0.x) + dx, nx), iy = glMod(int(g0.y) + dy, ny);
    w = wl * (dx == 1 ? f.x : 1.0 - f.x) * (dy == 1 ? f.y : 1.0 - f.y);
    return glOffs[lv] + iy * nx + ix;
}

// NDF value at q of one image blend, bilinear between NDF pixel centres (bilinear_kernel /
// resample_point_kernel): footprint (c, s), `m` the resampled level or -1 (trilinear)
float glPointQuery(vec2 c, float s, vec2 q) {
    int m = glResampleLevel(s);
    int i0, j0;
    float u0, u1, v0, v1;
    glPixelTaps((q.y - glLo) / glPitch, i0, u0, u1);
    glPixelTaps((q.x - glLo) / glPitch, j0, v0, v1);
    float r = 1.0, norm = 1.0;
    ivec4 K = ivec4(0);
    float st = 1.0;
    int ny = 1, nx = 1;
    if (m >= 0) {
        K = glResampleTaps(m, c, s, r);
        st = glStride[m];
        ny = glShape[m].x; nx = glShape[m].y;
        float sxw = 0.0, syw = 0.0;
        for (int k = K.x; k <= K.y; ++k) sxw += glTapWeight(k, st, c.x, r);
        for (int k = K.z; k <= K.w; ++k) syw += glTapWeight(k, st, c.y, r);
        norm = sxw * syw;
    }
    float acc = 0.0;
    for (int di = 0; di < 2; ++di) {
        int bi, ia;
        float wi, wa1;
        if (!glBlockTap(i0, u0, u1, di, bi, ia, wi, wa1)) continue;
        for (int dj = 0; dj < 2; ++dj) {
            int bj, ja;
            float wj, wb1;
            if (!glBlockTap(j0, v0, v1, dj, bj, ja, wj, wb1)) continue;
            ivec4 meta;
            int kc;
            if (m >= 0) {
                for (int ty = K.z; ty <= K.w; ++ty) {
                    float wy = glTapWeight(ty, st, c.y, r);
                    int row = glOffs[m] + glMod(ty, ny) * nx;
                    for (int tx = K.x; tx <= K.y; ++tx) {
                        if (!glBlockRow(row + glMod(tx, nx), bi, bj, meta, kc)) continue;
                        acc += wy * glTapWeight(tx, st, c.x, r)
                               * glFactorDot(meta.y, meta.x, ia, wi, wa1, ja, wj, wb1, kc);
                    }
                }
            } else {
                for (int t = 0; t < 8; ++t) {
                    float w;
                    int img = glTrilinearTap(c, s, t, w);
                    if (w == 0.0 || !glBlockRow(img, bi, bj, meta, kc)) continue;
                    acc += w * glFactorDot(meta.y, meta.x, ia, wi, wa1, ja, wj, wb1, kc);
                }
            }
        }
    }
    return acc / norm;
}

// _prefix_pos: row n and weight t of the prefix sum at u pixels of a block
void glPrefixPos(float u, out int n, out float t) {
    n = 0; t = 0.0;
    if (u <= 0.0) return;
    if (u >= float(glB)) { n = glB; return; }
    n = int(u);
    t = u - float(n);
}

// _axis_rows: rows n (4) and coefficients (k0, c0, cm, c1) of an axis's mass over [u0, u1]
void glAxisRows(float u0, float u1, out ivec4 n, out vec4 k) {
    int na0, na1;
    float ta0, ta1;
    glPrefixPos(u0, na0, ta0);
    glPrefixPos(u1, na1, ta1);
    if (na1 > na0) {
        n = ivec4(na0, na0 + 1, na1, ta1 != 0.0 ? na1 + 1 : na1);
        k = vec4(1.0, 1.0 - ta0, 1.0, ta1);
    } else {
        int n1 = ta1 > ta0 ? na0 + 1 : na0;
        n = ivec4(na0, n1, n1, n1);
        k = vec4(1.0, ta1 - ta0, 0.0, 0.0);
    }
    if (n.x == 0) { n.x = n.y; k.x = 0.0; }
}

float glAxisMass(bool rows, int base, int nr, int r, ivec4 n, vec4 k) {
    float p0, p1, p2, p3;
    if (rows) {
        p0 = glFetchPa(base + n.x * nr + r); p1 = glFetchPa(base + n.y * nr + r);
        p2 = glFetchPa(base + n.z * nr + r); p3 = glFetchPa(base + n.w * nr + r);
    } else {
        p0 = glFetchPb(base + n.x * nr + r); p1 = glFetchPb(base + n.y * nr + r);
        p2 = glFetchPb(base + n.z * nr + r); p3 = glFetchPb(base + n.w * nr + r);
    }
    return k.y * (p1 - k.x * p0) + k.z * (p2 - p1) + k.w * (p3 - p2);
}

// mass of one image's block over the rows / columns of (nA, kA), (nB, kB)
float glRectMass(ivec4 meta, int kc, ivec4 nA, vec4 kA, ivec4 nB, vec4 kB) {
    int nr = meta.x, m = meta.y, base = meta.y * (glB + 1);
    float s = 0.0;
    for (int r = 0; r < nr; ++r) {
        float da = glAxisMass(true, base, nr, r, nA, kA);
        float db = glAxisMass(false, base, nr, r, nB, kB);
        s += glFetchC(kc + r) * (glFetchW(m + r) * (da * db));
    }
    return s;
}

// range_multi with the resampling weights (query.weights(interp="resample")): mean of the
// footprint's NDF image over [lo, hi] in s (zero outside the support; sec. 4.4, eq. 7)
float glRangeQuery(vec2 c, float s, vec2 lo, vec2 hi) {
    vec2 p0 = (lo - glLo) / glPitch, p1 = (hi - glLo) / glPitch;
    float area = (p1.x - p0.x) * (p1.y - p0.y);
    float R = float(glR);
    float cx0 = max(p0.x, 0.0), cx1 = min(p1.x, R), cy0 = max(p0.y, 0.0), cy1 = min(p1.y, R);
    if (!(cx1 > cx0 && cy1 > cy0)) return 0.0;
    int bi0 = int(cy0) / glB, bi1 = min(int(ceil(cy1)) / glB, glNb - 1);
    int bj0 = int(cx0) / glB, bj1 = min(int(ceil(cx1)) / glB, glNb - 1);
    int m = glResampleLevel(s);
    float r = 1.0, norm = 1.0, st = 1.0;
    ivec4 K = ivec4(0);
    int ny = 1, nx = 1;
    if (m >= 0) {
        K = glResampleTaps(m, c, s, r);
        st = glStride[m];
        ny = glShape[m].x; nx = glShape[m].y;
        float sxw = 0.0, syw = 0.0;
        for (int k = K.x; k <= K.y; ++k) sxw += glTapWeight(k, st, c.x, r);
        for (int k = K.z; k <= K.w; ++k) syw += glTapWeight(k, st, c.y, r);
        norm = sxw * syw;
    }
    float acc = 0.0;
    for (int bi = bi0; bi <= bi1; ++bi) {
        ivec4 nA;
        vec4 kA;
        glAxisRows(cy0 - float(bi * glB), cy1 - float(bi * glB), nA, kA);
        for (int bj = bj0; bj <= bj1; ++bj) {
            ivec4 nB;
            vec4 kB;
            glAxisRows(cx0 - float(bj * glB), cx1 - float(bj * glB), nB, kB);
            ivec4 meta;
            int kc;
            if (m >= 0) {
                for (int ty = K.z; ty <= K.w; ++ty) {
                    float wy = glTapWeight(ty, st, c.y, r) / norm;
                    int row = glOffs[m] + glMod(ty, ny) * nx;
                    for (int tx = K.x; tx <= K.y; ++tx) {
                        if (!glBlockRow(row + glMod(tx, nx), bi, bj, meta, kc)) continue;
                        acc += wy * glTapWeight(tx, st, c.x, r)
                               * glRectMass(meta, kc, nA, kA, nB, kB);
                    }
                }
            } else {
                for (int t = 0; t < 8; ++t) {
                    float w;
                    int img = glTrilinearTap(c, s, t, w);
                    if (w == 0.0 || !glBlockRow(img, bi, bj, meta, kc)) continue;
                    acc += w * glRectMass(meta, kc, nA, kA, nB, kB);
                }
            }
        }
    }
    return acc / area;
}
