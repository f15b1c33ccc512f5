// Compressed NDF queries (glints paper, eqs. 6-7): prefilter.glints.query.point_flat with
// interp="resample", bilinear=True (the `glints` method's surface) and range_multi over the
// resampling weights, as prefilter.glints._qkernels computes them (float32 here): per block, the
// taps' code rows are summed per CP group first (glGather), then each group's sum meets the
// group's factors once (glFlushPoint, glFlushRects): a tap costs its code row, an NDF pixel or
// a rectangle the ranks of the groups present, however many taps share them.

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


// -- one footprint's image blend -----------------------------------------------------------

// the taps of footprint (c, s): resampled level m >= 0 (centre ranges K, kernel std r, stride
// st, level ny x nx images, normalisation norm) or the trilinear blend (m < 0, 8 taps); taps
// of a window wider than its level (the top levels' few images) are merged per image
struct GlBlend { vec2 c; float s; int m; ivec4 K; float r, st, norm; int ny, nx, ty, tx; };

GlBlend glBlend(vec2 c, float s) {
    GlBlend b = GlBlend(c, s, glResampleLevel(s), ivec4(0), 1.0, 1.0, 1.0, 1, 1, 1, 8);
    if (b.m < 0) return b;
    b.K = glResampleTaps(b.m, c, s, b.r);
    b.st = glStride[b.m];
    b.ny = glShape[b.m].x; b.nx = glShape[b.m].y;
    float sxw = 0.0, syw = 0.0;
    for (int k = b.K.x; k <= b.K.y; ++k) sxw += glTapWeight(k, b.st, c.x, b.r);
    for (int k = b.K.z; k <= b.K.w; ++k) syw += glTapWeight(k, b.st, c.y, b.r);
    b.norm = sxw * syw;
    b.ty = min(b.K.w - b.K.z + 1, b.ny);
    b.tx = min(b.K.y - b.K.x + 1, b.nx);
    return b;
}

// summed weight of the centres k0, k0 + n, ... <= k1 (one image of a level n images wide)
float glWrapWeight(int k0, int k1, int n, float st, float c, float r) {
    float w = 0.0;
    for (int k = k0; k <= k1; k += n) w += glTapWeight(k, st, c, r);
    return w;
}

int glBlendTaps(GlBlend b) { return b.ty * b.tx; }

// tap t of the blend: its image and (resampled: unnormalised) weight
int glBlendTap(GlBlend b, int t, out float w) {
    if (b.m < 0) return glTrilinearTap(b.c, b.s, t, w);
    int iy = t / b.tx, ix = t - iy * b.tx;
    int ky = b.K.z + iy, kx = b.K.x + ix;
    w = glWrapWeight(ky, b.K.w, b.ny, b.st, b.c.y, b.r)
        * glWrapWeight(kx, b.K.y, b.nx, b.st, b.c.x, b.r);
    return glOffs[b.m] + glMod(ky, b.ny) * b.nx + glMod(kx, b.nx);
}

// -- per-group sums of the taps' code rows -------------------------------------------------

// slots of the groups being summed: group id, its record (rank, first component, code-row
// base and stride in texels of glC, 4 components a texel), the offset of its sum in glCw (4
// components an entry, each group's sum in whole entries); GLT_SUM_SIZE components in all
int glNs, glCwUsed;
int glGid[GLT_SLOTS];
ivec4 glGm[GLT_SLOTS];
int glGo[GLT_SLOTS];
vec4 glCw[GLT_SUM_SIZE / 4];

// add w times the code row of image img at block (bi, bj) to its group's slot; false: the
// slots are full (flush, then call again), true: added (or a blank block)
bool glAddRow(int img, float w, int bi, int bj) {
    int nb2 = glNb * glNb, blk = bi * glNb + bj;
    int k = glFetchIndex(img * nb2 + blk);
    if (k < 0) return true;
    int g = glFetchCell(img) * nb2 + blk;
    int u = -1;
    for (int v = 0; v < glNs; ++v) if (glGid[v] == g) { u = v; break; }
    if (u < 0) {
        ivec4 meta = glFetchMeta(g);
        int n4 = (meta.x + 3) / 4;
        if (glNs == GLT_SLOTS || glCwUsed + n4 > GLT_SUM_SIZE / 4) return false;
        u = glNs++;
        glGid[u] = g; glGm[u] = meta; glGo[u] = glCwUsed;
        glCwUsed += n4;
        for (int e = 0; e < n4; ++e) glCw[glGo[u] + e] = vec4(0.0);
    }
    ivec4 meta = glGm[u];
    GlCursor cc = glCursor(meta.z + k * meta.w, GLT_TEX_C);
    int o = glGo[u], n4 = (meta.x + 3) / 4;
    for (int e = 0; e < n4; ++e) {
        glCw[o + e] += w * texelFetch(glC, cc.p, 0);  // zero past the rank
        glStep(cc);
    }
    return true;
}

// from tap t0 on, the blend's code rows of block (bi, bj) into the (emptied) slots, consecutive
// taps of one image merged; returns the first tap not added when the slots are full (all added:
// the number of taps)
int glGather(GlBlend b, int t0, int bi, int bj) {
    glNs = 0; glCwUsed = 0;
    int n = glBlendTaps(b), img = -1, ts = t0;
    float w = 0.0;
    for (int t = t0; t < n; ++t) {
        float wt;
        int it = glBlendTap(b, t, wt);
        if (wt == 0.0) continue;
        if (it == img) { w += wt; continue; }
        if (img >= 0 && !glAddRow(img, w, bi, bj)) return ts;
        img = it; w = wt; ts = t;
    }
    if (img >= 0 && !glAddRow(img, w, bi, bj)) return ts;
    return n;
}

// -- point query ---------------------------------------------------------------------------

// the slots' groups at one NDF pixel pair: sum_slots sum_r w_r cw_r fa_r fb_r, fa_r = wa0
// Fa[ia, r] + wa1 Fa[ia + 1, r] (_flush_slots / _factor_dot)
float glFlushPoint(int ia, float wa0, float wa1, int ja, float wb0, float wb1) {
    float s = 0.0;
    for (int u = 0; u < glNs; ++u) {
        int nr = glGm[u].x, m = glGm[u].y, o = glGo[u];
        int ra = m * glB + ia * nr, rb = m * glB + ja * nr;
        GlCursor a0 = glCursor(ra, GLT_TEX_FA), a1 = glCursor(ra + nr, GLT_TEX_FA);
        GlCursor b0 = glCursor(rb, GLT_TEX_FB), b1 = glCursor(rb + nr, GLT_TEX_FB);
        GlCursor cw = glCursor(m, GLT_TEX_W);
        // the second row only with a nonzero weight (it may be past the group's block)
        bool two_a = wa1 != 0.0, two_b = wb1 != 0.0;
        for (int r = 0; r < nr; ++r) {
            float fa = wa0 * texelFetch(glFa, a0.p, 0).r;
            if (two_a) { fa += wa1 * texelFetch(glFa, a1.p, 0).r; glStep(a1); }
            float fb = wb0 * texelFetch(glFb, b0.p, 0).r;
            if (two_b) { fb += wb1 * texelFetch(glFb, b1.p, 0).r; glStep(b1); }
            s += texelFetch(glW, cw.p, 0).r * (glCw[o + r / 4][r % 4] * fa * fb);
            glStep(a0); glStep(b0); glStep(cw);
        }
    }
    return s;
}

// NDF value at q of footprint (c, s), bilinear between NDF pixel centres (bilinear_kernel /
// resample_point_kernel)
float glPointQuery(vec2 c, float s, vec2 q) {
    GlBlend b = glBlend(c, s);
    int i0, j0;
    float u0, u1, v0, v1;
    glPixelTaps((q.y - glLo) / glPitch, i0, u0, u1);
    glPixelTaps((q.x - glLo) / glPitch, j0, v0, v1);
    int n = glBlendTaps(b);
    float acc = 0.0;
    for (int di = 0; di < 2; ++di) {
        int bi, ia;
        float wi, wa1;
        if (!glBlockTap(i0, u0, u1, di, bi, ia, wi, wa1)) continue;
        for (int dj = 0; dj < 2; ++dj) {
            int bj, ja;
            float wj, wb1;
            if (!glBlockTap(j0, v0, v1, dj, bj, ja, wj, wb1)) continue;
            for (int t = 0; t < n;) {
                t = glGather(b, t, bi, bj);
                acc += glFlushPoint(ia, wi, wa1, ja, wj, wb1);
            }
        }
    }
    return acc / b.norm;
}

// -- range queries -------------------------------------------------------------------------

// sum of one axis's mass over prefix rows n, coefficients k (_axis_rows) of 4 cursors
float glAxisMass(float p0, float p1, float p2, float p3, vec4 k) {
    return k.y * (p1 - k.x * p0) + k.z * (p2 - p1) + k.w * (p3 - p2);
}

// the slots' groups over one rectangle of a block, rows (nA, kA), columns (nB, kB):
// sum_slots sum_r w_r cw_r da_r db_r (_flush_rects)
float glFlushRect(ivec4 nA, vec4 kA, ivec4 nB, vec4 kB) {
    float s = 0.0;
    for (int u = 0; u < glNs; ++u) {
        int nr = glGm[u].x, m = glGm[u].y, o = glGo[u], base = m * (glB + 1);
        GlCursor a0 = glCursor(base + nA.x * nr, GLT_TEX_PA);
        GlCursor a1 = glCursor(base + nA.y * nr, GLT_TEX_PA);
        GlCursor a2 = glCursor(base + nA.z * nr, GLT_TEX_PA);
        GlCursor a3 = glCursor(base + nA.w * nr, GLT_TEX_PA);
        GlCursor b0 = glCursor(base + nB.x * nr, GLT_TEX_PB);
        GlCursor b1 = glCursor(base + nB.y * nr, GLT_TEX_PB);
        GlCursor b2 = glCursor(base + nB.z * nr, GLT_TEX_PB);
        GlCursor b3 = glCursor(base + nB.w * nr, GLT_TEX_PB);
        GlCursor cw = glCursor(m, GLT_TEX_W);
        for (int r = 0; r < nr; ++r) {
            float da = glAxisMass(texelFetch(glPa, a0.p, 0).r, texelFetch(glPa, a1.p, 0).r,
                                  texelFetch(glPa, a2.p, 0).r, texelFetch(glPa, a3.p, 0).r, kA);
            float db = glAxisMass(texelFetch(glPb, b0.p, 0).r, texelFetch(glPb, b1.p, 0).r,
                                  texelFetch(glPb, b2.p, 0).r, texelFetch(glPb, b3.p, 0).r, kB);
            s += glCw[o + r / 4][r % 4] * (texelFetch(glW, cw.p, 0).r * (da * db));
            glStep(a0); glStep(a1); glStep(a2); glStep(a3);
            glStep(b0); glStep(b1); glStep(b2); glStep(b3); glStep(cw);
        }
    }
    return s;
}

// range_multi with the resampling weights (query.weights(interp="resample")): the means of the
// footprint's NDF image over rectangles rect[k] = (lo_x, lo_y, hi_x, hi_y) in s, k < n (zero
// outside the support; sec. 4.4, eq. 7); the taps are walked once per block touched by any
void glRangeMulti(vec2 c, float s, vec4 rect[GLT_MAX_RECTS], int n,
                  out float mean[GLT_MAX_RECTS]) {
    vec4 cl[GLT_MAX_RECTS];    // clipped pixel bounds (cx0, cx1, cy0, cy1)
    ivec4 bk[GLT_MAX_RECTS];   // blocks (bi0, bi1, bj0, bj1), bi0 > bi1: empty
    float R = float(glR);
    ivec4 ub = ivec4(glNb, -1, glNb, -1);
    for (int k = 0; k < GLT_MAX_RECTS; ++k) mean[k] = 0.0;
    for (int k = 0; k < n; ++k) {
        vec2 p0 = (rect[k].xy - glLo) / glPitch, p1 = (rect[k].zw - glLo) / glPitch;
        cl[k] = vec4(max(p0.x, 0.0), min(p1.x, R), max(p0.y, 0.0), min(p1.y, R));
        bk[k] = ivec4(1, 0, 1, 0);
        if (!(cl[k].y > cl[k].x && cl[k].w > cl[k].z)) continue;
        bk[k] = ivec4(int(cl[k].z) / glB, min(int(ceil(cl[k].w)) / glB, glNb - 1),
                      int(cl[k].x) / glB, min(int(ceil(cl[k].y)) / glB, glNb - 1));
        ub = ivec4(min(ub.x, bk[k].x), max(ub.y, bk[k].y), min(ub.z, bk[k].z), max(ub.w, bk[k].w));
    }
    GlBlend b = glBlend(c, s);
    int nt = glBlendTaps(b);
    for (int bi = ub.x; bi <= ub.y; ++bi) {
        for (int bj = ub.z; bj <= ub.w; ++bj) {
            bool any = false;
            for (int k = 0; k < n; ++k)
                any = any || (bk[k].x <= bi && bi <= bk[k].y && bk[k].z <= bj && bj <= bk[k].w);
            if (!any) continue;
            for (int t = 0; t < nt;) {
                t = glGather(b, t, bi, bj);
                if (glNs == 0) continue;
                for (int k = 0; k < n; ++k) {
                    if (!(bk[k].x <= bi && bi <= bk[k].y && bk[k].z <= bj && bj <= bk[k].w))
                        continue;
                    ivec4 nA, nB;
                    vec4 kA, kB;
                    glAxisRows(cl[k].z - float(bi * glB), cl[k].w - float(bi * glB), nA, kA);
                    glAxisRows(cl[k].x - float(bj * glB), cl[k].y - float(bj * glB), nB, kB);
                    mean[k] += glFlushRect(nA, kA, nB, kB);
                }
            }
        }
    }
    for (int k = 0; k < n; ++k) {
        vec2 d = (rect[k].zw - rect[k].xy) / glPitch;
        if (bk[k].x <= bk[k].y) mean[k] /= b.norm * d.x * d.y;
    }
}

// the mean over one rectangle [lo, hi] (glRangeMulti)
float glRangeQuery(vec2 c, float s, vec2 lo, vec2 hi) {
    vec4 rect[GLT_MAX_RECTS];
    rect[0] = vec4(lo, hi);
    float mean[GLT_MAX_RECTS];
    glRangeMulti(c, s, rect, 1, mean);
    return mean[0];
}
