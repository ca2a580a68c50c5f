/* 3x3 stride-1 convolutions by Winograd's minimal filtering F(m x m, 3x3), m = 2 or 4: each
 * m x m block of outputs ("tile") takes (m+2)^2 multiplies per input channel instead of 9 m^2
 * (16 instead of 36, or 36 instead of 144).
 *
 *   V = B^T d B   ((m+2)^2 input patch d of a tile, per input channel)
 *   U = G g G^T   (3x3 kernel g, per output/input channel pair; made once, at prepare time)
 *   M[xi] = U[xi] V[xi]   ((m+2)^2 products [cout x cin] x [cin x tiles], on the shared kernel)
 *   Y = A^T M A   (the m x m outputs)
 *
 * A task is one block of at most 132 output channels and one panel of 64 tiles. For each block
 * of input channels it transforms the patches (16 tiles at a time, vectorised across tiles,
 * from row buffers that already hold the padding) into (m+2)^2 panels, runs the products into
 * per-task accumulators, and finally transforms back and applies the epilogue. F(2x2)'s
 * transforms use only additions and halvings (a few float roundings from the direct sum);
 * F(4x4)'s scale by up to 8 (about 20x that error). Each output is computed in a fixed order,
 * independent of the thread count. */
#include "nn/nn_int.h"

#include <omp.h>
#include <stdlib.h>
#include <string.h>

#pragma GCC diagnostic ignored "-Wpsabi" /* vector helpers are always inlined */

typedef float vf __attribute__((vector_size(64)));
typedef float vfu __attribute__((vector_size(64), aligned(4), may_alias));
typedef int vi __attribute__((vector_size(64)));

#define TP 64    /* tiles per task (one panel) */
#define LDV 80   /* row stride of a transformed panel: 16 spare columns for the last group */
#define KCW 96   /* input channels per block */
#define MBW 132   /* output channels per task, at most */
/* row buffer length for tiles of m outputs: a panel's tiles plus the last group's overread */
#define LINE(m) ((m) * TP + 16)
#define WINO4_MIN_CH 64

static int rup6(int x) { return (x + 5) / 6 * 6; }

int nn_wino_eligible(const g3d_nn_conv *c)
{
    return !c->transposed && c->kh == 3 && c->kw == 3 && (c->stride <= 1) && (c->dilation <= 1) && (c->groups <= 1) &&
           c->cin >= 16 && c->cout >= 16;
}

/* F(4x4) where every transformed product keeps enough work to amortise its larger input
 * transform (36 panels instead of 16): enough channels on both sides, unless the caller has
 * asked for F(2x2)'s smaller kernels. */
int nn_wino_tile(const g3d_nn_conv *c)
{
    return !c->wino_small && c->cin >= WINO4_MIN_CH && c->cout >= WINO4_MIN_CH ? 4 : 2;
}

/* G for F(2x2, 3x3) (points 0, 1, -1, inf) and F(4x4, 3x3) (0, 1, -1, 2, -2, inf) */
static const double G2[4][3] = {{1, 0, 0}, {.5, .5, .5}, {.5, -.5, .5}, {0, 0, 1}};
static const double G4[6][3] = {{1. / 4, 0, 0},          {-1. / 6, -1. / 6, -1. / 6}, {-1. / 6, 1. / 6, -1. / 6},
                                {1. / 24, 1. / 12, 1. / 6}, {1. / 24, -1. / 12, 1. / 6}, {0, 0, 1}};

float *nn_wino_weights(const g3d_nn_conv *c)
{
    const int cin = c->cin, cout = c->cout, coutp = rup6(cout), m = nn_wino_tile(c), al = m + 2;
    const double(*G)[3] = m == 4 ? G4 : G2;
    float *U = calloc((size_t)al * al * coutp * cin, sizeof(float));
    if (!U) return NULL;
    for (int co = 0; co < cout; co++)
        for (int ci = 0; ci < cin; ci++) {
            float g[9];
            size_t at = ((size_t)co * cin + ci) * 9;
            if (c->wtype == G3D_DT_F32)
                memcpy(g, (const float *)c->w + at, sizeof g);
            else
                nn_widen(c->wtype, (const uint16_t *)c->w + at, g, 9);
            /* U = G g G^T in double, rounded once */
            double t[6][3];
            for (int i = 0; i < al; i++)
                for (int j = 0; j < 3; j++) t[i][j] = G[i][0] * g[j] + G[i][1] * g[3 + j] + G[i][2] * g[6 + j];
            for (int i = 0; i < al; i++)
                for (int j = 0; j < al; j++)
                    U[((size_t)(i * al + j) * coutp + co) * cin + ci] =
                        (float)(t[i][0] * G[j][0] + t[i][1] * G[j][1] + t[i][2] * G[j][2]);
        }
    return U;
}

/* A run of tiles on one tile row: tiles (ty, tx0 .. tx0+len-1) at panel columns t .. t+len-1. */
typedef struct run {
    int ty, tx0, len, t;
} run;

static int make_runs(int tw, int t0, int nt, run *r)
{
    int n = 0;
    for (int t = 0; t < nt;) {
        int j = t0 + t, ty = j / tw, tx = j % tw, len = tw - tx < nt - t ? tw - tx : nt - t;
        r[n++] = (run){ty, tx, len, t};
        t += len;
    }
    return n;
}

static int map_index(g3d_nn_padmode m, int i, int n)
{
    if (m == G3D_PAD_REFLECT) i = i < 0 ? -i : i >= n ? 2 * (n - 1) - i : i;
    return i < 0 ? 0 : i >= n ? n - 1 : i; /* replicate, and reflect's far side of unused tiles */
}

/* line[u] = padded input (row iy, column x0 + u) for u < n. */
static void fill_line(const float *plane, int h, int w, g3d_nn_padmode mode, int iy, int x0, float *line, int n)
{
    if (iy < 0 || iy >= h) {
        if (mode == G3D_PAD_ZEROS) {
            memset(line, 0, sizeof(float) * n);
            return;
        }
        iy = map_index(mode, iy, h);
    }
    const float *row = plane + (size_t)iy * w;
    int lo = x0 < 0 ? -x0 : 0, hi = w - x0 < n ? w - x0 : n;
    if (hi < lo) hi = lo;
    for (int u = 0; u < lo && u < n; u++) line[u] = mode == G3D_PAD_ZEROS ? 0.0f : row[map_index(mode, x0 + u, w)];
    if (hi > lo) memcpy(line + lo, row + x0 + lo, sizeof(float) * (hi - lo));
    for (int u = hi > lo ? hi : lo; u < n; u++) line[u] = mode == G3D_PAD_ZEROS ? 0.0f : row[map_index(mode, x0 + u, w)];
}

#define CLONES __attribute__((target_clones("avx512f", "avx2", "default")))

/* V for 16 tiles from four row buffers (tile g starts at column 2g): vp[xi*kc*LDV] gets tile
 * values of transform entry xi. */
CLONES static void input_tiles(const float *const line[4], float *vp, long xs)
{
    static const vi even = {0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30};
    static const vi odd = {1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31};
    vf d[4][4];
    for (int a = 0; a < 4; a++) {
        vf l0 = *(const vfu *)line[a], l1 = *(const vfu *)(line[a] + 16);
        vf l2 = *(const vfu *)(line[a] + 2), l3 = *(const vfu *)(line[a] + 18);
        d[a][0] = __builtin_shuffle(l0, l1, even);
        d[a][1] = __builtin_shuffle(l0, l1, odd);
        d[a][2] = __builtin_shuffle(l2, l3, even);
        d[a][3] = __builtin_shuffle(l2, l3, odd);
    }
    /* t = B^T d with B^T = [1 0 -1 0; 0 1 1 0; 0 -1 1 0; 0 1 0 -1], then V = t B */
    for (int j = 0; j < 4; j++) {
        vf t0 = d[0][j] - d[2][j], t1 = d[1][j] + d[2][j], t2 = d[2][j] - d[1][j], t3 = d[1][j] - d[3][j];
        d[0][j] = t0, d[1][j] = t1, d[2][j] = t2, d[3][j] = t3;
    }
    for (int i = 0; i < 4; i++) {
        vf u0 = d[i][0] - d[i][2], u1 = d[i][1] + d[i][2], u2 = d[i][2] - d[i][1], u3 = d[i][1] - d[i][3];
        *(vfu *)(vp + (i * 4 + 0) * xs) = u0;
        *(vfu *)(vp + (i * 4 + 1) * xs) = u1;
        *(vfu *)(vp + (i * 4 + 2) * xs) = u2;
        *(vfu *)(vp + (i * 4 + 3) * xs) = u3;
    }
}

/* Y = A^T M A for 16 tiles: m[xi*xs] are the 16 accumulators; out0/out1 receive the two output
 * rows, interleaved (32 values each). */
CLONES static void output_tiles(const float *m, long xs, float *out0, float *out1)
{
    static const vi lo = {0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23};
    static const vi hi = {8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31};
    vf p[2][4];
    for (int j = 0; j < 4; j++) {
        vf m0 = *(const vfu *)(m + j * xs), m1 = *(const vfu *)(m + (4 + j) * xs), m2 = *(const vfu *)(m + (8 + j) * xs),
           m3 = *(const vfu *)(m + (12 + j) * xs);
        p[0][j] = m0 + m1 + m2;
        p[1][j] = m1 - m2 - m3;
    }
    for (int i = 0; i < 2; i++) {
        vf y0 = p[i][0] + p[i][1] + p[i][2], y1 = p[i][1] - p[i][2] - p[i][3];
        float *o = i ? out1 : out0;
        *(vfu *)o = __builtin_shuffle(y0, y1, lo);
        *(vfu *)(o + 16) = __builtin_shuffle(y0, y1, hi);
    }
}

/* F(4x4) input transform for 16 tiles from six row buffers (tile g starts at column 4g):
 * stride-4 gathers by two rounds of even/odd shuffles. */
CLONES static void input_tiles4(const float *const line[6], float *vp, long xs)
{
    static const vi even = {0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30};
    static const vi odd = {1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31};
    vf d[6][6];
    for (int a = 0; a < 6; a++)
        for (int s = 0; s < 2; s++) {
            const float *p = line[a] + 4 * s;
            vf l0 = *(const vfu *)p, l1 = *(const vfu *)(p + 16), l2 = *(const vfu *)(p + 32), l3 = *(const vfu *)(p + 48);
            vf e0 = __builtin_shuffle(l0, l1, even), o0 = __builtin_shuffle(l0, l1, odd);
            vf e1 = __builtin_shuffle(l2, l3, even), o1 = __builtin_shuffle(l2, l3, odd);
            d[a][4 * s] = __builtin_shuffle(e0, e1, even);
            d[a][4 * s + 1] = __builtin_shuffle(o0, o1, even);
            if (!s) d[a][2] = __builtin_shuffle(e0, e1, odd), d[a][3] = __builtin_shuffle(o0, o1, odd);
        }
    /* B^T = [4 0 -5 0 1 0; 0 -4 -4 1 1 0; 0 4 -4 -1 1 0; 0 -2 -1 2 1 0; 0 2 -1 -2 1 0; 0 4 0 -5 0 1],
     * applied to the columns, then V = t B */
#define BT6(x0, x1, x2, x3, x4, x5, r)                                                                                   \
    do {                                                                                                               \
        vf s13 = x3 - 4 * x1, s24 = x4 - 4 * x2, q13 = 2 * (x3 - x1), q24 = x4 - x2;                                   \
        r[0] = 4 * x0 - 5 * x2 + x4;                                                                                   \
        r[1] = s24 + s13;                                                                                              \
        r[2] = s24 - s13;                                                                                              \
        r[3] = q24 + q13;                                                                                              \
        r[4] = q24 - q13;                                                                                              \
        r[5] = 4 * x1 - 5 * x3 + x5;                                                                                   \
    } while (0)
    vf t[6][6];
    for (int j = 0; j < 6; j++) {
        vf r[6];
        BT6(d[0][j], d[1][j], d[2][j], d[3][j], d[4][j], d[5][j], r);
        for (int i = 0; i < 6; i++) t[i][j] = r[i];
    }
    for (int i = 0; i < 6; i++) {
        vf r[6];
        BT6(t[i][0], t[i][1], t[i][2], t[i][3], t[i][4], t[i][5], r);
        for (int j = 0; j < 6; j++) *(vfu *)(vp + (i * 6 + j) * xs) = r[j];
    }
#undef BT6
}

/* Y = A^T M A for 16 F(4x4) tiles, A^T = [1 1 1 1 1 0; 0 1 -1 2 -2 0; 0 1 1 4 4 0;
 * 0 1 -1 8 -8 1]: out + 64 k receives output row k of the 16 tiles, interleaved. */
CLONES static void output_tiles4(const float *m, long xs, float *out)
{
    static const vi lo = {0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23};
    static const vi hi = {8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31};
#define AT6(x0, x1, x2, x3, x4, x5, r)                                                                                   \
    do {                                                                                                               \
        vf a12 = x1 + x2, s12 = x1 - x2, a34 = x3 + x4, s34 = x3 - x4;                                                 \
        r[0] = x0 + a12 + a34;                                                                                         \
        r[1] = s12 + 2 * s34;                                                                                          \
        r[2] = a12 + 4 * a34;                                                                                          \
        r[3] = s12 + 8 * s34 + x5;                                                                                     \
    } while (0)
    vf p[4][6];
    for (int j = 0; j < 6; j++) {
        vf r[4];
        AT6(*(const vfu *)(m + j * xs), *(const vfu *)(m + (6 + j) * xs), *(const vfu *)(m + (12 + j) * xs),
            *(const vfu *)(m + (18 + j) * xs), *(const vfu *)(m + (24 + j) * xs), *(const vfu *)(m + (30 + j) * xs), r);
        for (int k = 0; k < 4; k++) p[k][j] = r[k];
    }
    for (int k = 0; k < 4; k++) {
        vf y[4];
        AT6(p[k][0], p[k][1], p[k][2], p[k][3], p[k][4], p[k][5], y);
        vf alo = __builtin_shuffle(y[0], y[2], lo), ahi = __builtin_shuffle(y[0], y[2], hi);
        vf blo = __builtin_shuffle(y[1], y[3], lo), bhi = __builtin_shuffle(y[1], y[3], hi);
        float *o = out + 64 * k;
        *(vfu *)o = __builtin_shuffle(alo, blo, lo);
        *(vfu *)(o + 16) = __builtin_shuffle(alo, blo, hi);
        *(vfu *)(o + 32) = __builtin_shuffle(ahi, bhi, lo);
        *(vfu *)(o + 48) = __builtin_shuffle(ahi, bhi, hi);
    }
#undef AT6
}

typedef struct wtask {
    const g3d_nn_conv *c;
    const float *U, *x;
    int h, w, ho, wo, m, th, tw, coutp, kc, mbs;
    float *y;
    const g3d_nn_epi *epi;
} wtask;

static void run_task(const wtask *T, int m0, int t0, float *vp, float *macc, float *lines, run *runs)
{
    const g3d_nn_conv *c = T->c;
    const int cin = c->cin, ntiles = T->th * T->tw, nt = ntiles - t0 < TP ? ntiles - t0 : TP;
    const int mb = T->coutp - m0 < T->mbs ? T->coutp - m0 : T->mbs, nv = (nt + 15) / 16;
    const int nr = make_runs(T->tw, t0, nt, runs), m = T->m, al = m + 2, nx = al * al, ll = LINE(m);
    const long mstride = (long)MBW * TP;
    float *line[6];
    for (int a = 0; a < al; a++) line[a] = lines + a * ll;
    for (int c0 = 0; c0 < cin; c0 += T->kc) {
        const int kc = cin - c0 < T->kc ? cin - c0 : T->kc;
        for (int ci = 0; ci < kc; ci++) {
            const float *plane = T->x + (size_t)(c0 + ci) * T->h * T->w;
            for (int r = 0; r < nr; r++) {
                const int iy0 = m * runs[r].ty - c->pad_h, ix0 = m * runs[r].tx0 - c->pad_w;
                /* the run's tiles need m len + 2 values; the last group of 16 reads on to
                 * m (16 groups + 1), values that only reach unused tiles (kept finite) */
                const int used = m * runs[r].len + 2, read = m * (16 * ((runs[r].len + 15) / 16) + 1);
                const float *src[6];
                for (int a = 0; a < al; a++) {
                    const int iy = iy0 + a;
                    if (iy >= 0 && iy < T->h && ix0 >= 0 && ix0 + read <= T->w) {
                        /* no padding and all it reads inside the row: in place (copying every
                         * input row (m+2)/m times had cost 5-7 % of MoGe-2's pass) */
                        src[a] = plane + (size_t)iy * T->w + ix0;
                        continue;
                    }
                    fill_line(plane, T->h, T->w, c->pad_mode, iy, ix0, line[a], used);
                    if (read > used) memset(line[a] + used, 0, sizeof(float) * (read - used));
                    src[a] = line[a];
                }
                for (int g = 0; g < runs[r].len; g += 16) {
                    const float *lg[6];
                    for (int a = 0; a < al; a++) lg[a] = src[a] + m * g;
                    float *v = vp + (long)ci * LDV + runs[r].t + g;
                    if (m == 4)
                        input_tiles4(lg, v, (long)kc * LDV);
                    else
                        input_tiles(lg, v, (long)kc * LDV);
                }
            }
        }
        for (int xi = 0; xi < nx; xi++) {
            const float *A = T->U + ((size_t)xi * T->coutp + m0) * cin + c0;
            const float *B = vp + (long)xi * kc * LDV;
            for (int ir = 0; ir < mb; ir += NN_MR)
                nn_kernel(kc, A + (long)ir * cin, cin, 1, B, LDV, macc + xi * mstride + (long)ir * TP, TP, nv, c0 > 0);
        }
    }
    /* back to pixels, with the epilogue */
    const g3d_nn_epi *e = T->epi;
    const size_t plane = (size_t)T->ho * T->wo;
    const int ow = 16 * m; /* output row of a group of 16 tiles */
    float out[256];
    for (int i = 0; i < mb && m0 + i < c->cout; i++) {
        const int co = m0 + i;
        const float bias = c->b ? c->b[co] : 0.0f, sc = e && e->scale ? e->scale[co] : 1.0f;
        float *yc = T->y + co * plane;
        const float *rc = e && e->res ? e->res + co * plane : NULL;
        for (int r = 0; r < nr; r++)
            for (int g = 0; g < runs[r].len; g += 16) {
                if (m == 4)
                    output_tiles4(macc + (long)i * TP + runs[r].t + g, mstride, out);
                else
                    output_tiles(macc + (long)i * TP + runs[r].t + g, mstride, out, out + 32);
                for (int k = 0; k < m * ow; k++) out[k] += bias;
                if (e && e->act != G3D_ACT_NONE) nn_act(e->act, out, m * ow);
                const int ox0 = m * (runs[r].tx0 + g), n = runs[r].len - g < 16 ? m * (runs[r].len - g) : ow;
                const int cols = T->wo - ox0 < n ? T->wo - ox0 : n;
                for (int a = 0; a < m; a++) {
                    const int oy = m * runs[r].ty + a;
                    if (oy >= T->ho) break;
                    float *yr = yc + (size_t)oy * T->wo + ox0;
                    const float *rr = rc ? rc + (size_t)oy * T->wo + ox0 : NULL;
                    for (int k = 0; k < cols; k++) yr[k] = (rr ? rr[k] : 0.0f) + sc * out[ow * a + k];
                }
            }
    }
}

g3d_status nn_wino_forward(const g3d_nn_conv *c, const float *U, const float *x, int h, int w, int ho, int wo, float *y,
                           const g3d_nn_epi *epi)
{
    wtask T = {.c = c, .U = U, .x = x, .h = h, .w = w, .ho = ho, .wo = wo, .m = nn_wino_tile(c),
               .coutp = rup6(c->cout), .kc = c->cin < KCW ? c->cin : KCW, .y = y, .epi = epi};
    T.th = (ho + T.m - 1) / T.m, T.tw = (wo + T.m - 1) / T.m;
    const int nx = (T.m + 2) * (T.m + 2);
    /* output-channel blocks of equal size (a multiple of 6, at most MBW) */
    const int nmb = (T.coutp + MBW - 1) / MBW;
    T.mbs = rup6((T.coutp + nmb - 1) / nmb);
    const int npan = (T.th * T.tw + TP - 1) / TP, ntask = nmb * npan;
    int nth = omp_in_parallel() ? 1 : omp_get_max_threads();
    if (nth > ntask) nth = ntask;
    int failed = 0;
#pragma omp parallel num_threads(nth)
    {
        float *vp = aligned_alloc(64, sizeof(float) * nx * KCW * LDV);
        /* + 16: the last group of a row reads up to 15 values past the panel */
        float *macc = aligned_alloc(64, sizeof(float) * (nx * MBW * TP + 16));
        float *lines = malloc(sizeof(float) * (T.m + 2) * LINE(T.m));
        run *runs = malloc(sizeof(run) * (TP + 1));
        if (!vp || !macc || !lines || !runs) {
#pragma omp atomic write
            failed = 1;
        } else {
            /* columns past the last tile of a panel are read: keep them finite */
            memset(vp, 0, sizeof(float) * nx * KCW * LDV);
            memset(macc, 0, sizeof(float) * (nx * MBW * TP + 16));
        }
#pragma omp for schedule(dynamic, 1)
        for (int t = 0; t < ntask; t++)
            if (vp && macc && lines && runs) run_task(&T, (t / npan) * T.mbs, (t % npan) * TP, vp, macc, lines, runs);
        free(vp), free(macc), free(lines), free(runs);
    }
    if (failed) return G3D_ERR(G3D_ERR_NOMEM, "conv (Winograd): cannot allocate the per-thread tiles");
    return G3D_OK;
}
