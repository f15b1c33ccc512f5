// Glints map textures (prefilter.glints.gpu.export_gpu): flat arrays in 2D array textures, element
// k at texel (k % w, (k / w) % h) of layer k / (w h); single-channel but glC (4 codes a texel),
// glMeta, glElements.
#define GLT_TEX_FA 0
#define GLT_TEX_FB 1
#define GLT_TEX_PA 2
#define GLT_TEX_PB 3
#define GLT_TEX_C 4
#define GLT_TEX_W 5
#define GLT_TEX_META 6
#define GLT_TEX_INDEX 7
#define GLT_TEX_CELL 8
#define GLT_TEX_ELEMENTS 9
uniform highp sampler2DArray glFa, glFb, glPa, glPb, glC, glW, glElements;
uniform highp isampler2DArray glMeta, glIndex, glCell;
uniform ivec2 glDims[10];          // (w, h) of each texture, in the order above
uniform int glR, glB, glNb;        // NDF resolution, block, blocks per axis
uniform float glLo, glPitch;       // NDF images' lower corner in s and pixel pitch
uniform int glLevels;              // pyramid levels
uniform int glOffs[GLT_MAX_LEVELS];     // first image of each level
uniform ivec2 glShape[GLT_MAX_LEVELS];  // centres (ny, nx) of each level
uniform float glSig[GLT_MAX_LEVELS], glStride[GLT_MAX_LEVELS];
uniform ivec2 glMapSize;           // normal map (H, W) texels
uniform float glSigmaMin;          // smallest resampled footprint std (texels)
uniform float glSr;                // intrinsic roughness of the direct P-NDF
uniform int glDirect;              // 1: the elements texture is there (direct P-NDF fallback)

ivec3 glAt(int k, int t) {
    ivec2 d = glDims[t];
    return ivec3(k % d.x, (k / d.x) % d.y, k / (d.x * d.y));
}
float glFetchFa(int k) { return texelFetch(glFa, glAt(k, GLT_TEX_FA), 0).r; }
float glFetchFb(int k) { return texelFetch(glFb, glAt(k, GLT_TEX_FB), 0).r; }
float glFetchPa(int k) { return texelFetch(glPa, glAt(k, GLT_TEX_PA), 0).r; }
float glFetchPb(int k) { return texelFetch(glPb, glAt(k, GLT_TEX_PB), 0).r; }
float glFetchC(int k) { return texelFetch(glC, glAt(k, GLT_TEX_C), 0).r; }
float glFetchW(int k) { return texelFetch(glW, glAt(k, GLT_TEX_W), 0).r; }
ivec4 glFetchMeta(int g) { return texelFetch(glMeta, glAt(g, GLT_TEX_META), 0); }
int glFetchIndex(int k) { return texelFetch(glIndex, glAt(k, GLT_TEX_INDEX), 0).r; }
int glFetchCell(int img) { return texelFetch(glCell, glAt(img, GLT_TEX_CELL), 0).r; }
vec4 glFetchElement(int k) { return texelFetch(glElements, glAt(k, GLT_TEX_ELEMENTS), 0); }
int glMod(int a, int m) { int r = a % m; return r < 0 ? r + m : r; }

// a cursor over consecutive flat elements of texture t: the texel of element k, then one step
// per element without the divisions of glAt (a group's rank components are adjacent)
struct GlCursor { ivec3 p; ivec2 d; };
GlCursor glCursor(int k, int t) { return GlCursor(glAt(k, t), glDims[t]); }
void glStep(inout GlCursor c) {
    if (++c.p.x == c.d.x) {
        c.p.x = 0;
        if (++c.p.y == c.d.y) { c.p.y = 0; ++c.p.z; }
    }
}
