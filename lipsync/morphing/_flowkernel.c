/* The flow renderer's per-frame kernel: two bilinear image lookups and a blend per pixel.
 *
 * Called from lipsync.render (the Python wrapper owns all geometry and validation of
 * meaning; this file checks only what would make memory access unsafe). For each output
 * pixel Y of the region [ry0, ry1) x [rx0, rx1):
 *
 *     frame(Y) = wa * A(Y + da(Y)) + (1 - wa) * B(Y + db(Y))
 *
 * where da, db are the coarse inverse displacements (coarse point (i, j) at the centre of
 * the step x step block of the box) read bilinearly, and A, B are
 * sampled bilinearly with edge pixels repeated. The displacements at alpha are a weighted
 * sum of the stored int16 tables (at t = k / steps; the weights come from Python), made
 * here one coarse row at a time as the rows are reached, so a frame has no serial setup
 * pass and a band of rows touches only its own coarse rows. Images arrive packed as RGBX uint32 with
 * one extra column and row (so the +1 taps never need a bounds test: a position clamped
 * to the last pixel has a zero weight on them).
 *
 * Transparency (nch = 4): the fourth byte is alpha and the colours arrive premultiplied by
 * it, so the bilinear taps and the blend are sums of premultiplied values (a transparent
 * pixel's hidden colour weighs nothing: no dark fringe at edges). The output is RGBA with
 * straight alpha, colour = sum / alpha, the form PNG and video encoders take. nch = 3 is
 * the opaque path, unchanged: the same instructions in the same order as before RGBA.
 *
 * Why C: numba/LLVM never vectorises the two indirect lookups (it cannot prove the arrays
 * do not alias), which left a frame at ~13 ns per pixel. Here gathers fetch the four taps
 * of 16 (AVX-512) or 8 (AVX2) pixels at once, the blend weight is folded into the bilinear weights
 * (one fused multiply-add per tap and channel), and the displacement rows are upsampled
 * eight coarse points at a time. The widest path the CPU has is chosen at run time; CPUs
 * without AVX2 (and other architectures) get the same arithmetic one pixel at a time, and
 * the Python side then prefers its numba kernel.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define LS_X86 1
#include <immintrin.h>
#define LS_AVX2_TARGET __attribute__((target("avx2,fma")))
#else
#define LS_X86 0
#define LS_AVX2_TARGET
#endif

typedef struct {
    const uint32_t *pa, *pb;      /* padded RGBX images, row stride wp (elements) */
    const int16_t *ta, *tb;       /* stored tables (steps, hc, keep, 2) of each side */
    int keep, half;               /* columns stored; half: column j mirrors to wc-1-j, x negated */
    int idx[2][4];                /* tables summed for each side (-1: the zero table) */
    float wts[2][4];              /* their weights, divided by the tables' scale */
    uint8_t *out;                 /* RGB (nch 3) or RGBA (nch 4) frame, row stride out_stride (bytes) */
    Py_ssize_t out_stride;
    int w, h, wp, hc, wc, by0, bx0, bh, bw, step, ry0, ry1, rx0, rx1;
    float wa;                     /* weight of A (1 - alpha); B gets 1 - wa */
    int simd;                     /* the AVX2 path (checked against the CPU) */
    int nch;                      /* 3: RGBX in, RGB out; 4: premultiplied RGBA in, straight RGBA out */
} job_t;

/* ---------------------------------------------------------------- displacement rows */

/* Coarse row i of one side at this frame's alpha: the weighted sum of the stored tables,
 * mirrored to the full coarse width, as planar x and y rows. */
static inline __attribute__((always_inline))
void coarse_row_body(const job_t *j, int side, int i, float *cx, float *cy)
{
    const int16_t *tab = side ? j->tb : j->ta;
    size_t plane = (size_t)j->hc * j->keep * 2;
    for (int c = 0; c < j->keep; c++) { cx[c] = 0.f; cy[c] = 0.f; }
    for (int n = 0; n < 4; n++) {
        int k = j->idx[side][n];
        if (k < 0) continue;
        const int16_t *t = tab + (size_t)k * plane + (size_t)i * j->keep * 2;
        float w = j->wts[side][n];
        for (int c = 0; c < j->keep; c++) {
            cx[c] += w * (float)t[2 * c];
            cy[c] += w * (float)t[2 * c + 1];
        }
    }
    if (j->half)  /* the middle column of an odd width is its own mirror: keep it as stored */
        for (int c = 0; c < j->keep && j->wc - 1 - c >= j->keep; c++) {
            cx[j->wc - 1 - c] = -cx[c];
            cy[j->wc - 1 - c] = cy[c];
        }
}

/* The same loops built twice: vectorised for AVX2, and plain for any CPU. */
#if LS_X86
LS_AVX2_TARGET static void coarse_row_avx2(const job_t *j, int side, int i, float *cx, float *cy)
{
    coarse_row_body(j, side, i, cx, cy);
}
#endif
static void coarse_row_plain(const job_t *j, int side, int i, float *cx, float *cy)
{
    coarse_row_body(j, side, i, cx, cy);
}

static void coarse_row(const job_t *j, int side, int i, float *cx, float *cy)
{
#if LS_X86
    if (j->simd) { coarse_row_avx2(j, side, i, cx, cy); return; }
#endif
    coarse_row_plain(j, side, i, cx, cy);
}

/* Horizontal upsampling of one coarse row to the box's bw pixels, any step. */
static void upsample_generic(const float *c, int wc, int bw, int step, float *dst)
{
    for (int xl = 0; xl < bw; xl++) {
        float cx = ((float)xl + 0.5f) / (float)step - 0.5f;
        if (cx < 0.f) cx = 0.f;
        if (cx > (float)(wc - 1)) cx = (float)(wc - 1);
        int j0 = (int)cx;
        float fx = cx - (float)j0;
        int j1 = j0 + 1 < wc ? j0 + 1 : wc - 1;
        dst[xl] = c[j0] + fx * (c[j1] - c[j0]);
    }
}

/* Step 2 (the store's grid): pixel 2k+1 sits a quarter of the way from coarse point k to
 * k+1 and pixel 2k+2 three quarters; pixel 0 and a last odd pixel repeat the edge. */
static void upsample2_scalar(const float *c, int wc, int bw, float *dst)
{
    dst[0] = c[0];
    for (int k = 0; k + 1 < wc; k++) {
        dst[2 * k + 1] = 0.75f * c[k] + 0.25f * c[k + 1];
        if (2 * k + 2 < bw) dst[2 * k + 2] = 0.25f * c[k] + 0.75f * c[k + 1];
    }
    if (2 * wc - 1 < bw) dst[2 * wc - 1] = c[wc - 1];
}

#if LS_X86
__attribute__((target("avx2,fma")))
static void upsample2_avx2(const float *c, int wc, int bw, float *dst)
{
    const __m256 q1 = _mm256_set1_ps(0.25f), q3 = _mm256_set1_ps(0.75f);
    dst[0] = c[0];
    int k = 0;
    /* 8 coarse intervals -> 16 pixels; the last pixel of a block is written by the
     * scalar tail when it would pass bw. */
    for (; k + 9 <= wc && 2 * k + 17 <= bw; k += 8) {
        __m256 c0 = _mm256_loadu_ps(c + k), c1 = _mm256_loadu_ps(c + k + 1);
        __m256 a = _mm256_fmadd_ps(c0, q3, _mm256_mul_ps(c1, q1));
        __m256 b = _mm256_fmadd_ps(c0, q1, _mm256_mul_ps(c1, q3));
        __m256 lo = _mm256_unpacklo_ps(a, b), hi = _mm256_unpackhi_ps(a, b);
        _mm256_storeu_ps(dst + 2 * k + 1, _mm256_permute2f128_ps(lo, hi, 0x20));
        _mm256_storeu_ps(dst + 2 * k + 9, _mm256_permute2f128_ps(lo, hi, 0x31));
    }
    for (; k + 1 < wc; k++) {
        dst[2 * k + 1] = 0.75f * c[k] + 0.25f * c[k + 1];
        if (2 * k + 2 < bw) dst[2 * k + 2] = 0.25f * c[k] + 0.75f * c[k + 1];
    }
    if (2 * wc - 1 < bw) dst[2 * wc - 1] = c[wc - 1];
}
#endif

/* Per-band cache of the two coarse rows an output row lies between, each already
 * upsampled to the ROI's width (zero outside the box): a coarse row is combined and
 * upsampled once for the `step` output rows that use it, and the vertical lerp is done
 * by the pixel loop itself as it reads them. */
typedef struct {
    int row[2];          /* coarse row held in slot s, -1 if none */
    float *data[2];      /* slot s: planes ax, ay, bx, by of `stride` floats each */
    float *zero;         /* all-zero planes, for rows outside the box */
    float *coarse;       /* 4 * wc: the combined coarse row before upsampling */
    int stride;
} cache_t;

static void upsample(const job_t *j, const float *c, float *dst)
{
    if (j->step == 2) {
#if LS_X86
        if (j->simd) { upsample2_avx2(c, j->wc, j->bw, dst); return; }
#endif
        upsample2_scalar(c, j->wc, j->bw, dst);
    } else {
        upsample_generic(c, j->wc, j->bw, j->step, dst);
    }
}

static const float *coarse_get(const job_t *j, cache_t *cc, int i)
{
    for (int s = 0; s < 2; s++)
        if (cc->row[s] == i) return cc->data[s];
    /* replace the slot not holding the other row this output row needs (rows only grow) */
    int s = (cc->row[0] < cc->row[1]) ? 0 : 1;
    float *c = cc->coarse, *d = cc->data[s];
    coarse_row(j, 0, i, c, c + j->wc);
    coarse_row(j, 1, i, c + 2 * j->wc, c + 3 * j->wc);
    int off = j->bx0 - j->rx0;   /* the box lies inside the ROI */
    for (int p = 0; p < 4; p++) upsample(j, c + (size_t)p * j->wc, d + (size_t)p * cc->stride + off);
    cc->row[s] = i;
    return d;
}

/* The two upsampled rows output row y lies between, and its weight on the second. */
static void rows_for(const job_t *j, cache_t *cc, int y, const float **r0, const float **r1, float *fy)
{
    int yl = y - j->by0;
    if (j->hc <= 0 || yl < 0 || yl >= j->bh) {
        *r0 = *r1 = cc->zero;
        *fy = 0.f;
        return;
    }
    float cy = ((float)yl + 0.5f) / (float)j->step - 0.5f;
    if (cy < 0.f) cy = 0.f;
    if (cy > (float)(j->hc - 1)) cy = (float)(j->hc - 1);
    int i0 = (int)cy;
    int i1 = i0 + 1 < j->hc ? i0 + 1 : j->hc - 1;
    *fy = cy - (float)i0;
    *r0 = coarse_get(j, cc, i0);
    *r1 = coarse_get(j, cc, i1);
}

/* ---------------------------------------------------------------- pixels */

/* Premultiplied sums -> straight colour, c * 255 / alpha, as the vector paths compute it.
 * Where nothing opaque arrived the colour is zero. */
static inline void unpremultiply(float *acc)
{
    float s = acc[3] > 0.f ? 255.f / acc[3] : 0.f;
    for (int c = 0; c < 3; c++) acc[c] *= s;
}

/* Row y's displacements: r0, r1 hold planes ax, ay, bx, by (`stride` apart), lerped by fy. */
typedef struct {
    const float *r0, *r1;
    float fy;
    int stride;
} rows_t;

static inline void pixel_scalar(const job_t *j, int x, int y, const rows_t *rw, int o, uint8_t *dst)
{
    float acc[4] = {0.f, 0.f, 0.f, 0.f};
    const int nch = j->nch;
    const float xmax = (float)(j->w - 1), ymax = (float)(j->h - 1);
    for (int side = 0; side < 2; side++) {
        const uint32_t *img = side ? j->pb : j->pa;
        float k = side ? 1.f - j->wa : j->wa;
        const float *a0 = rw->r0 + (size_t)(2 * side) * rw->stride + o, *a1 = rw->r1 + (size_t)(2 * side) * rw->stride + o;
        const float *b0 = a0 + rw->stride, *b1 = a1 + rw->stride;
        float px = (float)x + (*a0 + rw->fy * (*a1 - *a0)), py = (float)y + (*b0 + rw->fy * (*b1 - *b0));
        px = px < 0.f ? 0.f : (px > xmax ? xmax : px);
        py = py < 0.f ? 0.f : (py > ymax ? ymax : py);
        float x0 = floorf(px), y0 = floorf(py);
        float fx = px - x0, fy = py - y0;
        size_t i = (size_t)y0 * (size_t)j->wp + (size_t)x0;
        uint32_t t[4] = {img[i], img[i + 1], img[i + j->wp], img[i + j->wp + 1]};
        float w[4] = {(1.f - fx) * (1.f - fy) * k, fx * (1.f - fy) * k, (1.f - fx) * fy * k, fx * fy * k};
        for (int c = 0; c < nch; c++)
            for (int n = 0; n < 4; n++) acc[c] += w[n] * (float)((t[n] >> (8 * c)) & 0xFF);
    }
    if (nch == 4) {
        unpremultiply(acc);
    }
    for (int c = 0; c < nch; c++) {
        int v = (int)(acc[c] + 0.5f);
        dst[c] = (uint8_t)(v < 0 ? 0 : (v > 255 ? 255 : v));
    }
}

static void row_scalar(const job_t *j, int y, const rows_t *rw, int o0, int o1)
{
    uint8_t *row = j->out + (size_t)y * j->out_stride;
    for (int o = o0; o < o1; o++) {
        int x = j->rx0 + o;
        pixel_scalar(j, x, y, rw, o, row + (size_t)j->nch * (size_t)x);
    }
}

#if LS_X86
/* ---- AVX2: eight pixels at a time */

/* Eight pixels' bilinear sample of one image, weighted by k, added into acc[nch]
 * (nch a constant at each call: the opaque and the RGBA paths are compiled apart). */
__attribute__((target("avx2,fma"), always_inline))
static inline void sample8(const uint32_t *img, int wp, __m256 px, __m256 py, __m256 k, __m256 *acc, const int nch)
{
    __m256 x0 = _mm256_floor_ps(px), y0 = _mm256_floor_ps(py);
    __m256 fx = _mm256_sub_ps(px, x0), fy = _mm256_sub_ps(py, y0);
    /* y0 * wp + x0 is exact in float32 for images under 2^24 pixels */
    __m256i idx = _mm256_cvttps_epi32(_mm256_fmadd_ps(y0, _mm256_set1_ps((float)wp), x0));
    __m256i t00 = _mm256_i32gather_epi32((const int *)img, idx, 4);
    __m256i t01 = _mm256_i32gather_epi32((const int *)(img + 1), idx, 4);
    __m256i t10 = _mm256_i32gather_epi32((const int *)(img + wp), idx, 4);
    __m256i t11 = _mm256_i32gather_epi32((const int *)(img + wp + 1), idx, 4);
    __m256 gy = _mm256_mul_ps(fy, k), hy = _mm256_sub_ps(k, gy);        /* k*fy, k*(1-fy) */
    __m256 w01 = _mm256_mul_ps(fx, hy), w00 = _mm256_sub_ps(hy, w01);
    __m256 w11 = _mm256_mul_ps(fx, gy), w10 = _mm256_sub_ps(gy, w11);
    const __m256i m = _mm256_set1_epi32(0xFF);
#define LS_CH(t, s) _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(t, s), m))
    acc[0] = _mm256_fmadd_ps(w00, _mm256_cvtepi32_ps(_mm256_and_si256(t00, m)), acc[0]);
    acc[0] = _mm256_fmadd_ps(w01, _mm256_cvtepi32_ps(_mm256_and_si256(t01, m)), acc[0]);
    acc[0] = _mm256_fmadd_ps(w10, _mm256_cvtepi32_ps(_mm256_and_si256(t10, m)), acc[0]);
    acc[0] = _mm256_fmadd_ps(w11, _mm256_cvtepi32_ps(_mm256_and_si256(t11, m)), acc[0]);
    if (nch == 3) {
        acc[1] = _mm256_fmadd_ps(w00, LS_CH(t00, 8), acc[1]);
        acc[1] = _mm256_fmadd_ps(w01, LS_CH(t01, 8), acc[1]);
        acc[1] = _mm256_fmadd_ps(w10, LS_CH(t10, 8), acc[1]);
        acc[1] = _mm256_fmadd_ps(w11, LS_CH(t11, 8), acc[1]);
        /* the X byte is zero, so the top channel needs no mask */
        acc[2] = _mm256_fmadd_ps(w00, _mm256_cvtepi32_ps(_mm256_srli_epi32(t00, 16)), acc[2]);
        acc[2] = _mm256_fmadd_ps(w01, _mm256_cvtepi32_ps(_mm256_srli_epi32(t01, 16)), acc[2]);
        acc[2] = _mm256_fmadd_ps(w10, _mm256_cvtepi32_ps(_mm256_srli_epi32(t10, 16)), acc[2]);
        acc[2] = _mm256_fmadd_ps(w11, _mm256_cvtepi32_ps(_mm256_srli_epi32(t11, 16)), acc[2]);
    } else {
        /* G and B by one byte shuffle each (instead of a shift and a mask) */
        const __m256i g = _mm256_setr_epi8(1, -1, -1, -1, 5, -1, -1, -1, 9, -1, -1, -1, 13, -1, -1, -1,
                                           1, -1, -1, -1, 5, -1, -1, -1, 9, -1, -1, -1, 13, -1, -1, -1);
        const __m256i b = _mm256_setr_epi8(2, -1, -1, -1, 6, -1, -1, -1, 10, -1, -1, -1, 14, -1, -1, -1,
                                           2, -1, -1, -1, 6, -1, -1, -1, 10, -1, -1, -1, 14, -1, -1, -1);
#define LS_SH(t, sel) _mm256_cvtepi32_ps(_mm256_shuffle_epi8(t, sel))
        acc[1] = _mm256_fmadd_ps(w00, LS_SH(t00, g), acc[1]);
        acc[1] = _mm256_fmadd_ps(w01, LS_SH(t01, g), acc[1]);
        acc[1] = _mm256_fmadd_ps(w10, LS_SH(t10, g), acc[1]);
        acc[1] = _mm256_fmadd_ps(w11, LS_SH(t11, g), acc[1]);
        acc[2] = _mm256_fmadd_ps(w00, LS_SH(t00, b), acc[2]);
        acc[2] = _mm256_fmadd_ps(w01, LS_SH(t01, b), acc[2]);
        acc[2] = _mm256_fmadd_ps(w10, LS_SH(t10, b), acc[2]);
        acc[2] = _mm256_fmadd_ps(w11, LS_SH(t11, b), acc[2]);
#undef LS_SH
        /* alpha is the top byte: no mask */
        acc[3] = _mm256_fmadd_ps(w00, _mm256_cvtepi32_ps(_mm256_srli_epi32(t00, 24)), acc[3]);
        acc[3] = _mm256_fmadd_ps(w01, _mm256_cvtepi32_ps(_mm256_srli_epi32(t01, 24)), acc[3]);
        acc[3] = _mm256_fmadd_ps(w10, _mm256_cvtepi32_ps(_mm256_srli_epi32(t10, 24)), acc[3]);
        acc[3] = _mm256_fmadd_ps(w11, _mm256_cvtepi32_ps(_mm256_srli_epi32(t11, 24)), acc[3]);
    }
#undef LS_CH
}

__attribute__((target("avx2,fma"), always_inline))
static inline void row_avx2_body(const job_t *j, int y, const rows_t *rows, const int nch)
{
    int rw = j->rx1 - j->rx0;
    const float *u0 = rows->r0, *u1 = rows->r1;
    const size_t st = (size_t)rows->stride;
    const __m256 vy = _mm256_set1_ps(rows->fy);
    uint8_t *row = j->out + (size_t)y * j->out_stride + (size_t)nch * (size_t)j->rx0;
    const __m256 zero = _mm256_setzero_ps();
    const __m256 xmax = _mm256_set1_ps((float)(j->w - 1)), ymax = _mm256_set1_ps((float)(j->h - 1));
    const __m256 ka = _mm256_set1_ps(j->wa), kb = _mm256_set1_ps(1.f - j->wa);
    const __m256 fy = _mm256_set1_ps((float)y), half = _mm256_set1_ps(0.5f);
    const __m256 lane = _mm256_setr_ps(0.f, 1.f, 2.f, 3.f, 4.f, 5.f, 6.f, 7.f);
    /* RGBX dwords -> 12 RGB bytes at the start of each 128-bit lane */
    const __m256i pack = _mm256_setr_epi8(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1,
                                          0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1);
    int o = 0;
    for (; o + 8 <= rw; o += 8) {
        __m256 fx = _mm256_add_ps(_mm256_set1_ps((float)(j->rx0 + o)), lane);
        __m256 acc[4] = {zero, zero, zero, zero};
#define LS_DISP(p) _mm256_fmadd_ps(vy, _mm256_sub_ps(_mm256_loadu_ps(u1 + (p) * st + o), _mm256_loadu_ps(u0 + (p) * st + o)), \
                                  _mm256_loadu_ps(u0 + (p) * st + o))
        __m256 ax = _mm256_add_ps(fx, LS_DISP(0));
        __m256 ay = _mm256_add_ps(fy, LS_DISP(1));
        ax = _mm256_min_ps(_mm256_max_ps(ax, zero), xmax);
        ay = _mm256_min_ps(_mm256_max_ps(ay, zero), ymax);
        sample8(j->pa, j->wp, ax, ay, ka, acc, nch);
        __m256 bx = _mm256_add_ps(fx, LS_DISP(2));
        __m256 by = _mm256_add_ps(fy, LS_DISP(3));
#undef LS_DISP
        bx = _mm256_min_ps(_mm256_max_ps(bx, zero), xmax);
        by = _mm256_min_ps(_mm256_max_ps(by, zero), ymax);
        sample8(j->pb, j->wp, bx, by, kb, acc, nch);
        if (nch == 4) {
            /* straight colour c * 255 / alpha (zero where alpha is); premultiplied sums never
             * exceed alpha, the clamp only catches rounding */
            __m256 s = _mm256_and_ps(_mm256_cmp_ps(acc[3], zero, _CMP_GT_OQ),
                                     _mm256_div_ps(_mm256_set1_ps(255.f), acc[3]));
            const __m256i top = _mm256_set1_epi32(255);
            __m256i r = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(acc[0], s), half)), top);
            __m256i g = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(acc[1], s), half)), top);
            __m256i b = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(acc[2], s), half)), top);
            __m256i a = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_add_ps(acc[3], half)), top);
            __m256i px = _mm256_or_si256(_mm256_or_si256(r, _mm256_slli_epi32(g, 8)),
                                         _mm256_or_si256(_mm256_slli_epi32(b, 16), _mm256_slli_epi32(a, 24)));
            _mm256_storeu_si256((__m256i *)(row + 4 * (size_t)o), px);
            continue;
        }
        /* weights sum to one, so each channel is within [0, 255] up to rounding */
        __m256i r = _mm256_cvttps_epi32(_mm256_add_ps(acc[0], half));
        __m256i g = _mm256_cvttps_epi32(_mm256_add_ps(acc[1], half));
        __m256i b = _mm256_cvttps_epi32(_mm256_add_ps(acc[2], half));
        __m256i px = _mm256_or_si256(r, _mm256_or_si256(_mm256_slli_epi32(g, 8), _mm256_slli_epi32(b, 16)));
        px = _mm256_shuffle_epi8(px, pack);
        __m128i lo = _mm256_castsi256_si128(px), hi = _mm256_extracti128_si256(px, 1);
        uint8_t *d = row + 3 * (size_t)o;
        /* exactly 24 bytes: nothing past the eighth pixel is touched */
        _mm_storel_epi64((__m128i *)d, lo);
        uint32_t v = (uint32_t)_mm_extract_epi32(lo, 2);
        memcpy(d + 8, &v, 4);
        _mm_storel_epi64((__m128i *)(d + 12), hi);
        v = (uint32_t)_mm_extract_epi32(hi, 2);
        memcpy(d + 20, &v, 4);
    }
    if (o < rw) row_scalar(j, y, rows, o, rw);
}

__attribute__((target("avx2,fma")))
static void row_avx2(const job_t *j, int y, const rows_t *rows)
{
    if (j->nch == 4) row_avx2_body(j, y, rows, 4);
    else row_avx2_body(j, y, rows, 3);
}


/* ---- AVX-512: the same arithmetic in the same order, sixteen pixels at a time (so the
 * two paths give identical frames); 16-lane gathers and one masked 48-byte store. */
#define LS_AVX512_TARGET __attribute__((target("avx512f,avx512bw,avx512dq,avx512vl,avx2,fma")))
LS_AVX512_TARGET __attribute__((always_inline))
static inline void sample16(const uint32_t *img, int wp, __m512 px, __m512 py, __m512 k, __m512 *acc, const int nch)
{
    __m512 x0 = _mm512_roundscale_ps(px, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
    __m512 y0 = _mm512_roundscale_ps(py, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC);
    __m512 fx = _mm512_sub_ps(px, x0), fy = _mm512_sub_ps(py, y0);
    __m512i idx = _mm512_cvttps_epi32(_mm512_fmadd_ps(y0, _mm512_set1_ps((float)wp), x0));
    __m512i t00 = _mm512_i32gather_epi32(idx, (const int *)img, 4);
    __m512i t01 = _mm512_i32gather_epi32(idx, (const int *)(img + 1), 4);
    __m512i t10 = _mm512_i32gather_epi32(idx, (const int *)(img + wp), 4);
    __m512i t11 = _mm512_i32gather_epi32(idx, (const int *)(img + wp + 1), 4);
    __m512 gy = _mm512_mul_ps(fy, k), hy = _mm512_sub_ps(k, gy);
    __m512 w01 = _mm512_mul_ps(fx, hy), w00 = _mm512_sub_ps(hy, w01);
    __m512 w11 = _mm512_mul_ps(fx, gy), w10 = _mm512_sub_ps(gy, w11);
    const __m512i m = _mm512_set1_epi32(0xFF);
#define LS_C0(t) _mm512_cvtepi32_ps(_mm512_and_si512(t, m))
#define LS_C1(t) _mm512_cvtepi32_ps(_mm512_and_si512(_mm512_srli_epi32(t, 8), m))
#define LS_C2(t) _mm512_cvtepi32_ps(_mm512_srli_epi32(t, 16))
    acc[0] = _mm512_fmadd_ps(w00, LS_C0(t00), acc[0]); acc[0] = _mm512_fmadd_ps(w01, LS_C0(t01), acc[0]);
    acc[0] = _mm512_fmadd_ps(w10, LS_C0(t10), acc[0]); acc[0] = _mm512_fmadd_ps(w11, LS_C0(t11), acc[0]);
    if (nch == 3) {
        acc[1] = _mm512_fmadd_ps(w00, LS_C1(t00), acc[1]); acc[1] = _mm512_fmadd_ps(w01, LS_C1(t01), acc[1]);
        acc[1] = _mm512_fmadd_ps(w10, LS_C1(t10), acc[1]); acc[1] = _mm512_fmadd_ps(w11, LS_C1(t11), acc[1]);
        acc[2] = _mm512_fmadd_ps(w00, LS_C2(t00), acc[2]); acc[2] = _mm512_fmadd_ps(w01, LS_C2(t01), acc[2]);
        acc[2] = _mm512_fmadd_ps(w10, LS_C2(t10), acc[2]); acc[2] = _mm512_fmadd_ps(w11, LS_C2(t11), acc[2]);
    } else {
        /* G and B by one byte shuffle each, as sample8 */
        const __m512i g = _mm512_broadcast_i32x4(_mm_setr_epi8(1, -1, -1, -1, 5, -1, -1, -1, 9, -1, -1, -1, 13, -1, -1, -1));
        const __m512i b = _mm512_broadcast_i32x4(_mm_setr_epi8(2, -1, -1, -1, 6, -1, -1, -1, 10, -1, -1, -1, 14, -1, -1, -1));
#define LS_SH(t, sel) _mm512_cvtepi32_ps(_mm512_shuffle_epi8(t, sel))
#define LS_C3(t) _mm512_cvtepi32_ps(_mm512_srli_epi32(t, 24))
        acc[1] = _mm512_fmadd_ps(w00, LS_SH(t00, g), acc[1]); acc[1] = _mm512_fmadd_ps(w01, LS_SH(t01, g), acc[1]);
        acc[1] = _mm512_fmadd_ps(w10, LS_SH(t10, g), acc[1]); acc[1] = _mm512_fmadd_ps(w11, LS_SH(t11, g), acc[1]);
        acc[2] = _mm512_fmadd_ps(w00, LS_SH(t00, b), acc[2]); acc[2] = _mm512_fmadd_ps(w01, LS_SH(t01, b), acc[2]);
        acc[2] = _mm512_fmadd_ps(w10, LS_SH(t10, b), acc[2]); acc[2] = _mm512_fmadd_ps(w11, LS_SH(t11, b), acc[2]);
        acc[3] = _mm512_fmadd_ps(w00, LS_C3(t00), acc[3]); acc[3] = _mm512_fmadd_ps(w01, LS_C3(t01), acc[3]);
        acc[3] = _mm512_fmadd_ps(w10, LS_C3(t10), acc[3]); acc[3] = _mm512_fmadd_ps(w11, LS_C3(t11), acc[3]);
#undef LS_SH
#undef LS_C3
    }
#undef LS_C0
#undef LS_C1
#undef LS_C2
}

LS_AVX512_TARGET __attribute__((always_inline))
static inline void row_avx512_body(const job_t *j, int y, const rows_t *rows, const int nch)
{
    int rw = j->rx1 - j->rx0;
    const float *u0 = rows->r0, *u1 = rows->r1;
    const size_t st = (size_t)rows->stride;
    const __m512 vy = _mm512_set1_ps(rows->fy);
    uint8_t *row = j->out + (size_t)y * j->out_stride + (size_t)nch * (size_t)j->rx0;
    const __m512 zero = _mm512_setzero_ps();
    const __m512 xmax = _mm512_set1_ps((float)(j->w - 1)), ymax = _mm512_set1_ps((float)(j->h - 1));
    const __m512 ka = _mm512_set1_ps(j->wa), kb = _mm512_set1_ps(1.f - j->wa);
    const __m512 fy = _mm512_set1_ps((float)y), half = _mm512_set1_ps(0.5f);
    const __m512 lane = _mm512_setr_ps(0.f, 1.f, 2.f, 3.f, 4.f, 5.f, 6.f, 7.f, 8.f, 9.f, 10.f, 11.f, 12.f, 13.f, 14.f, 15.f);
    const __m512i pack = _mm512_broadcast_i32x4(_mm_setr_epi8(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, -1, -1, -1, -1));
    const __m512i gather = _mm512_setr_epi32(0, 1, 2, 4, 5, 6, 8, 9, 10, 12, 13, 14, 15, 15, 15, 15);
    int o = 0;
    for (; o + 16 <= rw; o += 16) {
        __m512 fx = _mm512_add_ps(_mm512_set1_ps((float)(j->rx0 + o)), lane);
        __m512 acc[4] = {zero, zero, zero, zero};
#define LS_DISP(p) _mm512_fmadd_ps(vy, _mm512_sub_ps(_mm512_loadu_ps(u1 + (p) * st + o), _mm512_loadu_ps(u0 + (p) * st + o)), \
                                  _mm512_loadu_ps(u0 + (p) * st + o))
        __m512 ax = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(fx, LS_DISP(0)), zero), xmax);
        __m512 ay = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(fy, LS_DISP(1)), zero), ymax);
        sample16(j->pa, j->wp, ax, ay, ka, acc, nch);
        __m512 bx = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(fx, LS_DISP(2)), zero), xmax);
        __m512 by = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(fy, LS_DISP(3)), zero), ymax);
        sample16(j->pb, j->wp, bx, by, kb, acc, nch);
#undef LS_DISP
        if (nch == 4) {  /* as row_avx2_body */
            __mmask16 some = _mm512_cmp_ps_mask(acc[3], zero, _CMP_GT_OQ);
            __m512 s = _mm512_maskz_div_ps(some, _mm512_set1_ps(255.f), acc[3]);
            const __m512i top = _mm512_set1_epi32(255);
            __m512i r = _mm512_min_epi32(_mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(acc[0], s), half)), top);
            __m512i g = _mm512_min_epi32(_mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(acc[1], s), half)), top);
            __m512i b = _mm512_min_epi32(_mm512_cvttps_epi32(_mm512_add_ps(_mm512_mul_ps(acc[2], s), half)), top);
            __m512i a = _mm512_min_epi32(_mm512_cvttps_epi32(_mm512_add_ps(acc[3], half)), top);
            __m512i px = _mm512_or_si512(_mm512_or_si512(r, _mm512_slli_epi32(g, 8)),
                                         _mm512_or_si512(_mm512_slli_epi32(b, 16), _mm512_slli_epi32(a, 24)));
            _mm512_storeu_si512((void *)(row + 4 * (size_t)o), px);
            continue;
        }
        __m512i r = _mm512_cvttps_epi32(_mm512_add_ps(acc[0], half));
        __m512i g = _mm512_cvttps_epi32(_mm512_add_ps(acc[1], half));
        __m512i b = _mm512_cvttps_epi32(_mm512_add_ps(acc[2], half));
        __m512i px = _mm512_or_si512(r, _mm512_or_si512(_mm512_slli_epi32(g, 8), _mm512_slli_epi32(b, 16)));
        px = _mm512_permutexvar_epi32(gather, _mm512_shuffle_epi8(px, pack));
        /* exactly 48 bytes (12 dwords): nothing past the sixteenth pixel is touched */
        _mm512_mask_storeu_epi32(row + 3 * (size_t)o, (__mmask16)0x0FFF, px);
    }
    if (o < rw) row_scalar(j, y, rows, o, rw);
}

LS_AVX512_TARGET
static void row_avx512(const job_t *j, int y, const rows_t *rows)
{
    if (j->nch == 4) row_avx512_body(j, y, rows, 4);
    else row_avx512_body(j, y, rows, 3);
}

/* The widest path this CPU runs: 2 AVX-512 (F, BW, DQ, VL), 1 AVX2 + FMA, 0 neither. */
static int simd_level(void)
{
    static int cached = -1;
    if (cached < 0) {
        __builtin_cpu_init();
        cached = 0;
        if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) {
            cached = 1;
            if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw")
                && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl"))
                cached = 2;
        }
    }
    return cached;
}
#else
static int simd_level(void) { return 0; }
#endif

/* ---------------------------------------------------------------- Python binding */

static int check_buffer(Py_buffer *b, Py_ssize_t need, const char *name)
{
    if (b->len < need) {
        PyErr_Format(PyExc_ValueError, "%s: buffer of %zd bytes, %zd needed", name, b->len, need);
        return -1;
    }
    return 0;
}

static PyObject *warp_blend(PyObject *self, PyObject *args)
{
    Py_buffer pa, pb, ta, tb, out;
    job_t j;
    memset(&j, 0, sizeof j);
    int simd = 2, nch = 3;
    if (!PyArg_ParseTuple(args, "y*y*y*y*w*niiiiiiiiiiiiiiii(iiii)(ffff)(iiii)(ffff)f|ii",
                          &pa, &pb, &ta, &tb, &out, &j.out_stride,
                          &j.w, &j.h, &j.wp, &j.hc, &j.wc, &j.keep, &j.half, &j.by0, &j.bx0, &j.bh, &j.bw,
                          &j.step, &j.ry0, &j.ry1, &j.rx0, &j.rx1,
                          &j.idx[0][0], &j.idx[0][1], &j.idx[0][2], &j.idx[0][3],
                          &j.wts[0][0], &j.wts[0][1], &j.wts[0][2], &j.wts[0][3],
                          &j.idx[1][0], &j.idx[1][1], &j.idx[1][2], &j.idx[1][3],
                          &j.wts[1][0], &j.wts[1][1], &j.wts[1][2], &j.wts[1][3], &j.wa, &simd, &nch))
        return NULL;
    j.nch = nch;
    PyObject *result = NULL;
    float *scratch = NULL;
    int rw = j.rx1 - j.rx0;
    /* Geometry that would make a read or write leave its buffer is refused here. */
    if ((j.nch != 3 && j.nch != 4) || j.w < 1 || j.h < 1 || j.wp < j.w + 1 || j.step < 1 || j.hc < 0 || j.wc < 0
        || j.ry0 < 0 || j.ry1 > j.h || j.rx0 < 0 || j.rx1 > j.w || j.out_stride < j.nch * (Py_ssize_t)j.w
        || (j.hc > 0 && (j.wc < 1 || j.bw < 1 || j.bh < 1 || j.bx0 < j.rx0 || j.bx0 + j.bw > j.rx1
                         || (Py_ssize_t)j.wc * j.step < j.bw || (Py_ssize_t)j.hc * j.step < j.bh
                         || j.keep > j.wc || (j.half ? 2 * j.keep < j.wc : j.keep != j.wc)))) {
        PyErr_SetString(PyExc_ValueError, "warp_blend: inconsistent geometry");
        goto done;
    }
    Py_ssize_t plane = (Py_ssize_t)j.hc * j.keep * 2 * (Py_ssize_t)sizeof(int16_t);
    for (int side = 0; side < 2; side++)
        for (int n = 0; n < 4; n++)
            if (j.idx[side][n] >= 0 && check_buffer(side ? &tb : &ta, (j.idx[side][n] + 1) * plane, side ? "tb" : "ta"))
                goto done;
    if (check_buffer(&pa, (Py_ssize_t)(j.h + 1) * j.wp * 4, "pa") || check_buffer(&pb, (Py_ssize_t)(j.h + 1) * j.wp * 4, "pb")
        || (j.ry1 > j.ry0 && check_buffer(&out, (Py_ssize_t)(j.ry1 - 1) * j.out_stride + j.nch * (Py_ssize_t)j.w, "out")))
        goto done;
    j.pa = pa.buf; j.pb = pb.buf; j.ta = ta.buf; j.tb = tb.buf; j.out = out.buf;
    if (rw <= 0 || j.ry1 <= j.ry0) { result = Py_None; Py_INCREF(result); goto done; }
    j.simd = simd < simd_level() ? (simd < 0 ? 0 : simd) : simd_level();
    size_t stride = (size_t)rw + 8;
    /* zeroed once: the planes' columns outside the box are never written */
    scratch = calloc((size_t)4 * (j.wc + 8) + 12 * stride, sizeof(float));
    if (!scratch) { PyErr_NoMemory(); goto done; }
    Py_BEGIN_ALLOW_THREADS
    cache_t cc = {{-1, -1}, {scratch + 4 * stride, scratch + 8 * stride}, scratch,
                  scratch + 12 * stride, (int)stride};
    rows_t rows;
    rows.stride = (int)stride;
    for (int y = j.ry0; y < j.ry1; y++) {
        rows_for(&j, &cc, y, &rows.r0, &rows.r1, &rows.fy);
#if LS_X86
        if (j.simd == 2) row_avx512(&j, y, &rows);
        else if (j.simd) row_avx2(&j, y, &rows);
        else
#endif
            row_scalar(&j, y, &rows, 0, rw);
    }
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    free(scratch);
    PyBuffer_Release(&pa); PyBuffer_Release(&pb); PyBuffer_Release(&ta); PyBuffer_Release(&tb);
    PyBuffer_Release(&out);
    return result;
}

/* ---------------------------------------------------------------- RGB -> yuv420p */

/* BT.709 limited range in fixed point, the arithmetic of lipsync/yuv.py (which passes the
 * constants, so there is one source for them): luma per pixel, chroma from the sums of
 * each 2x2 block. Built twice like the rows above; GCC vectorises the AVX2 copy. */
typedef struct {
    const uint8_t *rgb;
    uint8_t *out;
    int w, h;
    int32_t c[9], yhalf, chalf, shift;
} yuv_t;

static inline __attribute__((always_inline)) void yuv_body(const yuv_t *a)
{
    const int32_t yr = a->c[0], yg = a->c[1], yb = a->c[2], ur = a->c[3], ug = a->c[4], ub = a->c[5];
    const int32_t vr = a->c[6], vg = a->c[7], vb = a->c[8];
    const int w = a->w, h = a->h, cw = w / 2, s1 = a->shift, s2 = a->shift + 2;
    uint8_t *u = a->out + (size_t)w * h, *v = u + (size_t)cw * (h / 2);
    for (int r = 0; r < h; r++) {
        const uint8_t *row = a->rgb + (size_t)r * w * 3;
        uint8_t *y = a->out + (size_t)r * w;
        for (int x = 0; x < w; x++)
            y[x] = (uint8_t)((yr * row[3 * x] + yg * row[3 * x + 1] + yb * row[3 * x + 2] + a->yhalf) >> s1);
    }
    for (int j = 0; j < h / 2; j++) {
        const uint8_t *p = a->rgb + (size_t)(2 * j) * w * 3, *q = p + (size_t)w * 3;
        for (int i = 0; i < cw; i++) {
            int k = 6 * i;
            int32_t rs = p[k] + p[k + 3] + q[k] + q[k + 3];
            int32_t gs = p[k + 1] + p[k + 4] + q[k + 1] + q[k + 4];
            int32_t bs = p[k + 2] + p[k + 5] + q[k + 2] + q[k + 5];
            u[(size_t)j * cw + i] = (uint8_t)((ur * rs + ug * gs + ub * bs + a->chalf) >> s2);
            v[(size_t)j * cw + i] = (uint8_t)((vr * rs + vg * gs + vb * bs + a->chalf) >> s2);
        }
    }
}

#if LS_X86
LS_AVX2_TARGET static void yuv_avx2(const yuv_t *a) { yuv_body(a); }
#endif
static void yuv_plain(const yuv_t *a) { yuv_body(a); }

static PyObject *rgb_to_yuv420p(PyObject *self, PyObject *args)
{
    Py_buffer rgb, out;
    yuv_t a;
    if (!PyArg_ParseTuple(args, "y*w*ii(iiiiiiiii)iii", &rgb, &out, &a.w, &a.h, &a.c[0], &a.c[1], &a.c[2],
                          &a.c[3], &a.c[4], &a.c[5], &a.c[6], &a.c[7], &a.c[8], &a.yhalf, &a.chalf, &a.shift))
        return NULL;
    PyObject *result = NULL;
    if (a.w < 2 || a.h < 2 || a.w % 2 || a.h % 2 || a.shift < 1 || a.shift > 24) {
        PyErr_SetString(PyExc_ValueError, "rgb_to_yuv420p: even width and height needed");
        goto done;
    }
    if (check_buffer(&rgb, (Py_ssize_t)a.w * a.h * 3, "rgb")
        || check_buffer(&out, (Py_ssize_t)a.w * a.h + 2 * (Py_ssize_t)(a.w / 2) * (a.h / 2), "out"))
        goto done;
    a.rgb = rgb.buf;
    a.out = out.buf;
    Py_BEGIN_ALLOW_THREADS
#if LS_X86
    if (simd_level() >= 1) yuv_avx2(&a);
    else
#endif
        yuv_plain(&a);
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&rgb);
    PyBuffer_Release(&out);
    return result;
}

/* ---------------------------------------------------------------- Beier-Neely field */

/* The displacement field of lipsync.warp (see its docstring for the algebra): per line,
 * every quantity is a column part (c * x) plus a row part (c * y + c0), each computed in
 * double and rounded to float before they are added. Columns go in blocks: a block's
 * column parts (4 x lines x block floats) stay in cache while every row reuses them, and
 * the pixel loop runs over contiguous floats, which GCC vectorises (the AVX2 copy 8 wide;
 * no contraction into FMA: -std=c99 keeps each float operation rounded as written, the
 * arithmetic of the numba copy). Runs without the GIL, so preprocessing computes pairs in
 * threads. coef holds per line: sx sy s0 vx vy v0 half lenp dxx dxy dx0 dyx dyy dy0. */
enum { BN_NCOEF = 14 };
typedef struct {
    const double *xs, *ys, *coef;
    float *out;                     /* (h, w, 2) */
    int w, h, lines, block;
    float a, b;
    float *col, *acc;               /* scratch: 4 * lines * block, 3 * block */
} bn_t;

/* One line's weighted displacement added to a block row's sums. The exponent is the same
 * for every pixel: one loop per common case, each a straight vectorisable loop (no pow()). */
static inline __attribute__((always_inline))
void bn_line(int n, const float *restrict cs, const float *restrict cv, const float *restrict cx,
             const float *restrict cy, float *restrict aw, float *restrict ax, float *restrict ay,
             float rs, float rv, float rdx, float rdy, float half, float lenp, float a, float b)
{
#define LS_BN_LOOP(WEIGHT)                                              \
    for (int c = 0; c < n; c++) {                                       \
        float s = fabsf(cs[c] + rs) - half;                             \
        s = s > 0.f ? s : 0.f;                                          \
        const float v = cv[c] + rv;                                     \
        const float d = sqrtf(s * s + v * v) + a;                       \
        const float q = lenp / d;                                       \
        const float wt = WEIGHT;                                        \
        aw[c] += wt;                                                    \
        ax[c] += (cx[c] + rdx) * wt;                                    \
        ay[c] += (cy[c] + rdy) * wt;                                    \
    }
    if (b == 2.f) { LS_BN_LOOP(q * q) }
    else if (b == 4.f) { LS_BN_LOOP((q * q) * (q * q)) }
    else if (b == 1.f) { LS_BN_LOOP(q) }
    else { LS_BN_LOOP(powf(q, b)) }
#undef LS_BN_LOOP
}

static inline __attribute__((always_inline)) void bn_body(const bn_t *t)
{
    const int L = t->lines, B = t->block;
    const float a = t->a, b = t->b;
    float *acc_w = t->acc, *acc_x = t->acc + B, *acc_y = t->acc + 2 * B;
    for (int c0 = 0; c0 < t->w; c0 += B) {
        const int n = t->w - c0 < B ? t->w - c0 : B;
        for (int i = 0; i < L; i++) {
            const double *k = t->coef + (size_t)i * BN_NCOEF;
            float *cs = t->col + ((size_t)0 * L + i) * B, *cv = t->col + ((size_t)1 * L + i) * B;
            float *cx = t->col + ((size_t)2 * L + i) * B, *cy = t->col + ((size_t)3 * L + i) * B;
            for (int c = 0; c < n; c++) {
                const double x = t->xs[c0 + c];
                cs[c] = (float)(k[0] * x);
                cv[c] = (float)(k[3] * x);
                cx[c] = (float)(k[8] * x);
                cy[c] = (float)(k[11] * x);
            }
        }
        for (int r = 0; r < t->h; r++) {
            const double y = t->ys[r];
            for (int c = 0; c < n; c++) { acc_w[c] = 0.f; acc_x[c] = 0.f; acc_y[c] = 0.f; }
            for (int i = 0; i < L; i++) {
                const double *k = t->coef + (size_t)i * BN_NCOEF;
                const float rs = (float)(k[1] * y + k[2]), rv = (float)(k[4] * y + k[5]);
                const float rdx = (float)(k[9] * y + k[10]), rdy = (float)(k[12] * y + k[13]);
                const float half = (float)k[6], lenp = (float)k[7];
                bn_line(n, t->col + ((size_t)0 * L + i) * B, t->col + ((size_t)1 * L + i) * B,
                        t->col + ((size_t)2 * L + i) * B, t->col + ((size_t)3 * L + i) * B,
                        acc_w, acc_x, acc_y, rs, rv, rdx, rdy, half, lenp, a, b);
            }
            float *o = t->out + ((size_t)r * t->w + c0) * 2;
            for (int c = 0; c < n; c++) {
                o[2 * c] = acc_x[c] / acc_w[c];
                o[2 * c + 1] = acc_y[c] / acc_w[c];
            }
        }
    }
}

#if LS_X86
LS_AVX2_TARGET static void bn_avx2(const bn_t *t) { bn_body(t); }
#endif
static void bn_plain(const bn_t *t) { bn_body(t); }

static PyObject *beier_neely_field(PyObject *self, PyObject *args)
{
    Py_buffer xs, ys, coef, out;
    bn_t t;
    memset(&t, 0, sizeof t);
    int simd = 2;
    if (!PyArg_ParseTuple(args, "y*y*y*w*iiiiff|i", &xs, &ys, &coef, &out, &t.w, &t.h, &t.lines, &t.block,
                          &t.a, &t.b, &simd))
        return NULL;
    PyObject *result = NULL;
    float *scratch = NULL;
    if (t.w < 0 || t.h < 0 || t.lines < 1 || t.block < 1 || !(t.a > 0.f) || !(t.b > 0.f)) {
        PyErr_SetString(PyExc_ValueError, "beier_neely_field: inconsistent arguments");
        goto done;
    }
    if (check_buffer(&xs, (Py_ssize_t)t.w * 8, "xs") || check_buffer(&ys, (Py_ssize_t)t.h * 8, "ys")
        || check_buffer(&coef, (Py_ssize_t)t.lines * BN_NCOEF * 8, "coef")
        || check_buffer(&out, (Py_ssize_t)t.w * t.h * 2 * 4, "out"))
        goto done;
    scratch = malloc(((size_t)4 * t.lines + 3) * t.block * sizeof(float));
    if (!scratch) { PyErr_NoMemory(); goto done; }
    t.xs = xs.buf; t.ys = ys.buf; t.coef = coef.buf; t.out = out.buf;
    t.col = scratch;
    t.acc = scratch + (size_t)4 * t.lines * t.block;
    Py_BEGIN_ALLOW_THREADS
#if LS_X86
    if (simd >= 1 && simd_level() >= 1) bn_avx2(&t);
    else
#endif
        bn_plain(&t);
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    free(scratch);
    PyBuffer_Release(&xs); PyBuffer_Release(&ys); PyBuffer_Release(&coef); PyBuffer_Release(&out);
    return result;
}

static PyObject *simd_available(PyObject *self, PyObject *noargs)
{
    return PyLong_FromLong(simd_level());
}

static PyMethodDef methods[] = {
    {"warp_blend", warp_blend, METH_VARARGS,
     "warp_blend(pa, pb, ta, tb, out, out_stride, w, h, wp, hc, wc, keep, half, by0, bx0, bh, bw, step,\n"
     "           ry0, ry1, rx0, rx1, idx_a, wts_a, idx_b, wts_b, wa, simd=2, nch=3)\n"
     "Render rows [ry0, ry1) x columns [rx0, rx1) of a flow frame into out (see lipsync.render);\n"
     "nch 4: premultiplied RGBA in, straight RGBA out."},
    {"rgb_to_yuv420p", rgb_to_yuv420p, METH_VARARGS,
     "rgb_to_yuv420p(rgb, out, w, h, coefficients, yhalf, chalf, shift): see lipsync.yuv."},
    {"beier_neely_field", beier_neely_field, METH_VARARGS,
     "beier_neely_field(xs, ys, coef, out, w, h, lines, block, a, b, simd=2)\n"
     "The Beier-Neely displacement at the pixels ys x xs into out (h, w, 2) float32 (see lipsync.warp)."},
    {"simd_available", simd_available, METH_NOARGS,
     "The widest path this CPU runs: 2 AVX-512, 1 AVX2, 0 neither (warp_blend's simd caps it)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_flowkernel",
                                    "The flow renderer's compiled frame kernel (see lipsync.render), yuv420p conversion (lipsync.yuv) and the Beier-Neely field (lipsync.warp).", -1, methods};

PyMODINIT_FUNC PyInit__flowkernel(void) { return PyModule_Create(&module); }
