/* The product driver: C = A B cut into tiles of C whose size depends only on the shape, each
 * tile computed by one thread over the whole of K (in blocks that fit the caches), then passed
 * through the epilogue (bias, activation, LayerScale, residual) while still in cache.
 *
 * Inside a tile: a block of B (KC rows x NT columns) is packed into 64-column panels (or used
 * in place when it was packed at load time), then for each group of 6 rows of A the kernel
 * sweeps the panels. A is never packed: the kernel broadcasts its elements straight from the
 * caller's rows (16-bit weights are widened per tile first). */
#include "nn/nn_int.h"

#include <immintrin.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

static long rup(long x, long m) { return (x + m - 1) / m * m; }
static long cdiv(long x, long m) { return (x + m - 1) / m; }

/* ---- 16-bit widening ------------------------------------------------------------------- */
__attribute__((target("avx2,f16c"))) static long widen_f16c(const uint16_t *src, float *dst, long n)
{
    long i = 0;
    for (; i + 8 <= n; i += 8) _mm256_storeu_ps(dst + i, _mm256_cvtph_ps(_mm_loadu_si128((const __m128i *)(src + i))));
    return i;
}

void nn_widen(g3d_dtype t, const uint16_t *src, float *dst, long n)
{
    if (t == G3D_DT_BF16) {
        uint32_t *d = (uint32_t *)dst;
        for (long i = 0; i < n; i++) d[i] = (uint32_t)src[i] << 16;
        return;
    }
    long i = 0;
    if (nn_isa() >= NN_ISA_AVX2 && __builtin_cpu_supports("f16c")) i = widen_f16c(src, dst, n);
    g3d_dtype_to_f32(G3D_DT_F16, src + i, dst + i, n - i);
}

/* ---- packing B --------------------------------------------------------------------------- */
typedef float v16u __attribute__((vector_size(64), aligned(4), may_alias));

/* Copies n <= 64 floats. Packing copies such short runs by the million; GCC turns a memcpy of
 * unknown small size into `rep movs`, whose start-up costs more than the copy. */
static inline void copy_run(float *restrict d, const float *restrict s, int n)
{
    int i = 0;
    for (; i + 16 <= n; i += 16) *(v16u *)(d + i) = *(const v16u *)(s + i);
    for (; i < n; i++) d[i] = s[i];
}

/* Panel q of a packed block holds rows 0..kc-1 of columns 64q..64q+63 at bp + q*kc*64; the
 * columns past nt up to the next multiple of 16 are zero so the kernel can read them. */
static void zero_tail(float *bp, int kc, int nt)
{
    int used = nt & 63;
    if (!used) return;
    int pad = (int)rup(used, 16) - used;
    if (!pad) return;
    float *d = bp + (long)(nt >> 6) * kc * 64 + used;
    for (int k = 0; k < kc; k++) memset(d + (long)k * 64, 0, sizeof(float) * pad);
}

static void pack_rows(const float *b, long ldb, int k0, int kc, int n0, int nt, float *bp)
{
    for (int k = 0; k < kc; k++) {
        const float *src = b + (long)(k0 + k) * ldb + n0;
        for (int q = 0; q * 64 < nt; q++) {
            int cols = nt - 64 * q < 64 ? nt - 64 * q : 64;
            copy_run(bp + ((long)q * kc + k) * 64, src + 64 * q, cols);
        }
    }
    zero_tail(bp, kc, nt);
}

static void pack_cols(const float *b, long ldb, int k0, int kc, int n0, int nt, float *bp)
{
    for (int j = 0; j < nt; j++) {
        const float *src = b + (long)(n0 + j) * ldb + k0;
        float *d = bp + (long)(j >> 6) * kc * 64 + (j & 63);
        for (int k = 0; k < kc; k++) d[(long)k * 64] = src[k];
    }
    zero_tail(bp, kc, nt);
}

/* Asks for the block of B a tile reads in place (kc rows of nt columns, a multiple of 16, at
 * row stride ldb) to be brought into L2, in the order its first group of rows reads it: one
 * request per line, all issued before the kernel waits for the first of them. */
static void prefetch_rows(const float *b, long ldb, int kc, int nt)
{
    for (int q = 0; q * 64 < nt; q++)
        for (int k = 0; k < kc; k++)
            for (int j = 64 * q; j < nt && j < 64 * q + 64; j += 16) _mm_prefetch((const char *)(b + k * ldb + j), _MM_HINT_T1);
}

/* A run of output pixels on one row of the output grid inside one panel. */
typedef struct piece {
    int qy, qx, len, t;
} piece;

static int conv_pieces(const nn_convsrc *s, int n0, int nt, piece *p)
{
    int np = 0;
    for (int t = 0; t < nt;) {
        int j = n0 + t, qy = j / s->qw, qx = j % s->qw;
        int len = s->qw - qx;
        if (len > nt - t) len = nt - t;
        if (len > 64 - (t & 63)) len = 64 - (t & 63);
        p[np++] = (piece){qy, qx, len, t};
        t += len;
    }
    return np;
}

/* Cloned per instruction set: the stride-2 gathers of downsampling convolutions vectorise
 * with AVX-512's two-register permutes. */
__attribute__((target_clones("avx512f", "avx2", "default"))) static void
pack_conv(const nn_convsrc *s, int k0, int kc, const piece *p, int np, int nt, float *bp)
{
    const int h = s->h, w = s->w, st = s->stride;
    const int zeros = s->pad == G3D_PAD_ZEROS;
    int c = k0 / s->ntaps, tp = k0 % s->ntaps; /* channel and tap of row k0 + k */
    for (int k = 0; k < kc; k++, tp = tp + 1 == s->ntaps ? (c++, 0) : tp + 1) {
        const int dy = s->dy[tp], dx = s->dx[tp];
        const float *plane = s->x + (size_t)c * h * w;
        for (int e = 0; e < np; e++) {
            float *d = bp + (long)(p[e].t >> 6) * kc * 64 + (long)k * 64 + (p[e].t & 63);
            int len = p[e].len, iy = p[e].qy * st + dy;
            if (iy < 0 || iy >= h) {
                if (zeros) {
                    memset(d, 0, sizeof(float) * len);
                    continue;
                }
                iy = nn_pad_index(s->pad, iy, h);
            }
            const float *row = plane + (size_t)iy * w;
            int ix0 = p[e].qx * st + dx;
            /* u in [lo, hi) reads inside the row */
            int lo = ix0 >= 0 ? 0 : (-ix0 + st - 1) / st;
            int hi = ix0 > w - 1 ? 0 : (w - 1 - ix0) / st + 1;
            if (hi > len) hi = len;
            if (lo > len) lo = len;
            if (hi < lo) hi = lo;
            for (int u = 0; u < lo; u++) d[u] = zeros ? 0.0f : row[nn_pad_index(s->pad, ix0 + u * st, w)];
            if (st == 1)
                copy_run(d + lo, row + ix0 + lo, hi - lo);
            else if (st == 2) /* a constant stride vectorises */
                for (int u = lo; u < hi; u++) d[u] = row[ix0 + 2 * u];
            else
                for (int u = lo; u < hi; u++) d[u] = row[ix0 + u * st];
            for (int u = hi; u < len; u++) d[u] = zeros ? 0.0f : row[nn_pad_index(s->pad, ix0 + u * st, w)];
        }
    }
    zero_tail(bp, kc, nt);
}

/* ---- tiling ---------------------------------------------------------------------------- */
typedef struct tiling {
    int KC, MT, NT;
} tiling;

/* Rows handled together: NN_MR for the kernel, and a multiple of ilv so interleaved rows stay
 * in one tile and one epilogue call (lcm(NN_MR, ilv)). */
static int row_unit(const nn_gemm *g)
{
    int unit = NN_MR;
    if (g->ilv > 1)
        while (unit % g->ilv) unit += NN_MR;
    return unit;
}

/* A pure function of the shape (never of the thread count). K in blocks of <= 320 so a packed
 * block of B stays in L2. Every tile packs its own block of B (unless B was packed at load),
 * so the rows of a tile share one packing: a tile takes all rows up to 512 when B is a plain
 * matrix (a 1x1 convolution's input map: each value is copied once per call, not once per
 * 216 rows), up to ~216 for a convolution's gathered input and ~96 for pre-packed weights;
 * 256 columns; shrunk until there are at least 8 tiles to share out. Row tiles are multiples
 * of NN_MR and of the interleave ilv. Where all rows fit one tile (SD's 77 text tokens) the
 * columns are split down to the kernel's width of 16 before the rows: each thread then reads
 * only its columns of B (split by rows, both threads had read all of a 77 x 768 -> 320
 * projection's 1 MB of weights from L3), and the kernel is as fast 16 columns wide as 64. */
static tiling choose_tiling(const nn_gemm *g)
{
    tiling t;
    int nb = g->K <= 384 ? 1 : (int)cdiv(g->K, 320);
    t.KC = (int)cdiv(g->K, nb);
    const int cap = g->bkind == NN_B_PANELS ? 96 : g->bkind == NN_B_ROWS ? 512 : 216, unit = row_unit(g);
    t.MT = (int)rup(cdiv(g->M, cdiv(g->M, cap)), unit);
    t.NT = g->N > 128 ? 256 : g->N > 64 ? 128 : 64; /* halved below: a multiple or divisor of 64 */
    const int one_band = t.MT >= g->M;
    while (cdiv(g->M, t.MT) * cdiv(g->N, t.NT) < 8) {
        if (t.NT > 64 || (one_band && t.NT > 16 && g->N > t.NT / 2))
            t.NT /= 2;
        else if (t.MT > 4 * unit)
            t.MT = (int)rup(t.MT / 2, unit);
        else
            break;
    }
    return t;
}

/* ---- epilogue -------------------------------------------------------------------------- */
/* The epilogue's loops are cloned per instruction set like the packing (the library itself is
 * built for baseline x86-64). */
#define CLONES __attribute__((target_clones("avx512f", "avx2", "default")))

/* v = scale * act(alpha v + bias) over n values of rows row0.. row0+rows-1 of C (at v, row
 * stride ldv) whose first column is n0. One call per group of rows: a call per row through
 * the clone's dispatch had cost a 1x1 convolution over 64 channels 5 % of its time. */
CLONES static void row_ops(const nn_gemm *g, float *v0, long ldv, int rows, int n, int row0, int n0)
{
    const g3d_nn_epi *e = g->epi;
    const float *scale = e ? e->scale : NULL;
    const int act = e && e->act != G3D_ACT_NONE;
    for (int i = 0; i < rows; i++) {
        float *v = v0 + (long)i * ldv;
        const int row = row0 + i, ch = g->chan_div ? row / g->chan_div : row;
        if (g->alpha != 1.0f)
            for (int j = 0; j < n; j++) v[j] *= g->alpha;
        if (g->bias) {
            if (g->chan_rows) {
                float bb = g->bias[ch];
                for (int j = 0; j < n; j++) v[j] += bb;
            } else {
                const float *bb = g->bias + n0;
                for (int j = 0; j < n; j++) v[j] += bb[j];
            }
        }
        if (act) nn_act(e->act, v, n);
        if (scale) {
            if (g->chan_rows) {
                float sc = scale[ch];
                for (int j = 0; j < n; j++) v[j] *= sc;
            } else {
                const float *sc = scale + n0;
                for (int j = 0; j < n; j++) v[j] *= sc[j];
            }
        }
    }
}

/* y = r + v over n values (r may be y; r == NULL: y = v, nothing to do where v is y) */
CLONES static void row_store(float *y, const float *r, const float *v, int n)
{
    if (r)
        for (int j = 0; j < n; j++) y[j] = r[j] + v[j];
    else if (v != y)
        memcpy(y, v, sizeof(float) * n);
}

/* Rows m0.. m0+mt-1 of C, columns n0.. n0+nt-1, held at ct with row stride ldc. */
static void epilogue(const nn_gemm *g, float *ct, long ldc, int m0, int mt, int n0, int nt)
{
    const float *res = g->epi ? g->epi->res : NULL;
    row_ops(g, ct, ldc, mt, nt, m0, n0);
    for (int i = 0; i < mt; i++) {
        float *v = ct + (long)i * ldc;
        const int row = m0 + i;
        const long base = g->rowoff ? g->rowoff[row] : (long)row * g->ldy;
        float *y = g->y + base;
        const float *r = res ? res + base : NULL;
        if (!g->qw) {
            if (r || v != y + n0) row_store(y + n0, r ? r + n0 : NULL, v, nt);
        } else {
            /* runs along one output row: strided stores, no per-element index arithmetic */
            int qy = n0 / g->qw, qx = n0 % g->qw;
            for (int j = 0; j < nt; qx = 0, qy++) {
                const int len = g->qw - qx < nt - j ? g->qw - qx : nt - j;
                const long off = qy * g->oys + qx * g->oxs + g->ooff, st = g->oxs;
                float *yy = y + off;
                if (r)
                    for (int u = 0; u < len; u++) yy[u * st] = r[off + u * st] + v[j + u];
                else
                    for (int u = 0; u < len; u++) yy[u * st] = v[j + u];
                j += len;
            }
        }
    }
}

/* y[u*il + t] = (r ? r[u*il + t] : 0) + c[t*ldc + u] for u < len, t < il (r may be y) */
CLONES static void interleave(const float *c, long ldc, int il, int len, const float *r, float *y)
{
    if (il == 2 && !r) /* constant strides vectorise */
        for (int u = 0; u < len; u++) y[2 * u] = c[u], y[2 * u + 1] = c[ldc + u];
    else if (il == 2)
        for (int u = 0; u < len; u++) y[2 * u] = r[2 * u] + c[u], y[2 * u + 1] = r[2 * u + 1] + c[ldc + u];
    else if (il == 4 && !r)
        for (int u = 0; u < len; u++)
            for (int t = 0; t < 4; t++) y[4 * u + t] = c[t * ldc + u];
    else if (il == 4)
        for (int u = 0; u < len; u++)
            for (int t = 0; t < 4; t++) y[4 * u + t] = r[4 * u + t] + c[t * ldc + u];
    else
        for (int u = 0; u < len; u++)
            for (int t = 0; t < il; t++) y[il * u + t] = (r ? r[il * u + t] : 0.0f) + c[t * ldc + u];
}

/* g->ilv rows at a time: row i + t (t < ilv) goes to the output pixels just after row i's, so
 * each run of an output row is the rows' values interleaved, written in one contiguous pass:
 * every output line is written once and whole, where row-by-row stores would touch it ilv
 * times with a stride. */
static void epilogue_ilv(const nn_gemm *g, float *ct, long ldc, int m0, int mt, int n0, int nt)
{
    const int il = g->ilv;
    const float *res = g->epi ? g->epi->res : NULL;
    row_ops(g, ct, ldc, mt, nt, m0, n0);
    for (int i = 0; i < mt; i += il) {
        int qy = n0 / g->qw, qx = n0 % g->qw;
        for (int j = 0; j < nt; qx = 0, qy++) {
            const int len = g->qw - qx < nt - j ? g->qw - qx : nt - j;
            const long off = g->rowoff[m0 + i] + qy * g->oys + qx * g->oxs;
            interleave(ct + (long)i * ldc + j, ldc, il, len, res ? res + off : NULL, g->y + off);
            j += len;
        }
    }
}

/* ---- the tile loop --------------------------------------------------------------------- */
typedef struct scratch {
    float *bp, *ct, *aw, *ae;
    piece *pieces;
} scratch;

static void run_tile(const nn_gemm *g, const tiling *t, const scratch *s, int m0, int n0)
{
    const int mt = g->M - m0 < t->MT ? g->M - m0 : t->MT, nt = g->N - n0 < t->NT ? g->N - n0 : t->NT;
    const long ldc = rup(t->NT, 64);
    const int npan = (int)cdiv(nt, 64);
    /* Where the output rows are plain rows and nothing is added to them, the kernel writes them
     * in place and the epilogue runs there (the kernel writes whole vectors, so the tile's width
     * must be a multiple of 16; a last group of fewer than six rows still goes through the tile
     * buffer). Otherwise the tile buffer takes the product and the epilogue moves it: a copy of
     * every output that had cost 3-4 % of a Depth Anything pass. */
    const int direct = !g->qw && !g->rowoff && !(g->epi && g->epi->res) && nt % 16 == 0;
    float *const cdir = direct ? g->y + (long)m0 * g->ldy + n0 : NULL;
    /* with the last block of K the epilogue follows each group of rows while it is still in L1 */
    const int egroup = row_unit(g);
    int np = g->bkind == NN_B_CONV ? conv_pieces(g->conv, n0, nt, s->pieces) : 0;
    for (int k0 = 0; k0 < g->K; k0 += t->KC) {
        const int kc = g->K - k0 < t->KC ? g->K - k0 : t->KC, last = k0 + kc == g->K;
        /* B block */
        const float *bp = s->bp;
        long pstride = (long)kc * 64, ldbk = 64; /* floats between panels, between rows */
        switch (g->bkind) {
        case NN_B_ROWS:
            /* A block of at most 64 rows (a 1x1 convolution over 64 channels) is read in place,
             * where its rows already are: its pages stay within reach of the first-level TLB
             * (72 entries) while the kernel steps through them. The packing had been a fifth of
             * the DPT head's 64-channel 1x1 convolution at 148 x 148 (6 % faster without it). */
            if (kc <= 64 && nt % 16 == 0) {
                bp = (const float *)g->b + (long)k0 * g->ldb + n0, pstride = 64, ldbk = g->ldb;
                prefetch_rows(bp, ldbk, kc, nt);
            } else {
                pack_rows(g->b, g->ldb, k0, kc, n0, nt, s->bp);
            }
            break;
        case NN_B_COLS: pack_cols(g->b, g->ldb, k0, kc, n0, nt, s->bp); break;
        case NN_B_CONV: pack_conv(g->conv, k0, kc, s->pieces, np, nt, s->bp); break;
        default:
            /* a tile narrower than 64 columns lies inside one panel, at column n0 % 64 */
            if (g->bt == G3D_DT_F32) {
                bp = (const float *)g->b + ((long)(n0 / 64) * g->K + k0) * 64 + n0 % 64;
                pstride = (long)g->K * 64;
            } else {
                for (int q = 0; q < npan; q++)
                    nn_widen(g->bt, (const uint16_t *)g->b + ((long)(n0 / 64 + q) * g->K + k0) * 64,
                             s->bp + (long)q * kc * 64, (long)kc * 64);
                bp += n0 % 64;
            }
            break;
        }
        /* A block */
        const float *a;
        long lda, ka;
        if (g->a16) {
            for (int i = 0; i < mt; i++) nn_widen(g->a16t, g->a16 + (long)(m0 + i) * g->lda + k0, s->aw + (long)i * kc, kc);
            a = s->aw, lda = kc, ka = 1;
        } else {
            a = g->a + (long)m0 * g->lda + (long)k0 * g->ka, lda = g->lda, ka = g->ka;
        }
        for (int ir = 0, done = 0; ir < mt; ir += NN_MR) {
            const float *ap = a + (long)ir * lda;
            long la = lda, lk = ka;
            int rows = mt - ir;
            float *cp = s->ct + (long)ir * ldc;
            long lc = ldc;
            if (rows < NN_MR && direct && mt >= NN_MR && kc == g->K) {
                /* the last rows in place as the six last ones: the rows shared with the group
                 * before are computed again (the same bits) and their epilogue redone; with
                 * several blocks of K they would be added twice. A 64-channel 1x1 convolution
                 * had sent a sixteenth of its outputs through the tile buffer. */
                ir = done = mt - NN_MR, rows = NN_MR;
                ap = a + (long)ir * lda;
            } else if (rows < NN_MR) {
                /* the last rows: copied so the kernel can read six */
                for (int i = 0; i < NN_MR; i++)
                    for (int k = 0; k < kc; k++) s->ae[(long)i * kc + k] = i < rows ? ap[i * lda + k * ka] : 0.0f;
                ap = s->ae, la = kc, lk = 1;
            }
            if (direct && rows >= NN_MR) cp = cdir + (long)ir * g->ldy, lc = g->ldy;
            for (int q = 0; q < npan; q++) {
                int cols = nt - 64 * q < 64 ? nt - 64 * q : 64;
                nn_kernel(kc, ap, la, lk, bp + q * pstride, ldbk, cp + 64 * q, lc, (cols + 15) / 16, k0 > 0);
            }
            const int end = rows < NN_MR ? mt : ir + NN_MR;
            if (!last || (end % egroup && end < mt)) continue;
            if (!direct) {
                if (g->ilv > 1)
                    epilogue_ilv(g, s->ct + (long)done * ldc, ldc, m0 + done, end - done, n0, nt);
                else
                    epilogue(g, s->ct + (long)done * ldc, ldc, m0 + done, end - done, n0, nt);
            } else {
                if (rows < NN_MR)
                    for (int i = ir; i < mt; i++)
                        memcpy(cdir + (long)i * g->ldy, s->ct + (long)i * ldc, sizeof(float) * nt);
                epilogue(g, cdir + (long)done * g->ldy, g->ldy, m0 + done, end - done, n0, nt);
            }
            done = end;
        }
    }
}

/* A thread's share of the tiles: the range [lo, hi) in one word, so its owner taking tiles from
 * the front and other threads taking them from the back agree by one compare-and-swap. */
typedef struct share {
    _Alignas(64) _Atomic unsigned long long r;
} share;

static int take(share *sh, int back)
{
    unsigned long long w = atomic_load_explicit(&sh->r, memory_order_relaxed);
    for (;;) {
        const unsigned lo = (unsigned)w, hi = (unsigned)(w >> 32);
        if (lo >= hi) return -1;
        const unsigned long long nw = back ? w - (1ull << 32) : w + 1;
        if (atomic_compare_exchange_weak_explicit(&sh->r, &w, nw, memory_order_relaxed, memory_order_relaxed))
            return (int)(back ? hi - 1 : lo);
    }
}

/* The next tile for thread me: the front of its own range, or else the back of the range with
 * the most tiles left; -1 when none is left. */
static int next_tile(share *sh, int nth, int me)
{
    for (;;) {
        int i = take(&sh[me], 0);
        if (i >= 0) return i;
        int best = -1;
        unsigned most = 0;
        for (int t = 0; t < nth; t++) {
            const unsigned long long w = atomic_load_explicit(&sh[t].r, memory_order_relaxed);
            const unsigned lo = (unsigned)w, hi = (unsigned)(w >> 32);
            if (hi > lo && hi - lo > most) most = hi - lo, best = t;
        }
        if (best < 0) return -1;
        i = take(&sh[best], 1);
        if (i >= 0) return i;
    }
}

g3d_status nn_gemm_run(const nn_gemm *g)
{
    if (g->M <= 0 || g->N <= 0) return G3D_OK;
    if (g->K <= 0) return G3D_ERR(G3D_ERR_ARG, "matrix product with an empty inner dimension");
    const tiling t = choose_tiling(g);
    const int tm = (int)cdiv(g->M, t.MT), tn = (int)cdiv(g->N, t.NT), ntiles = tm * tn;
    int nth = omp_in_parallel() ? 1 : omp_get_max_threads();
    if (nth > ntiles) nth = ntiles;
    /* Every thread's scratch in one block taken by the calling thread: the main heap keeps a
     * block that size after the first call, where a worker thread's frees of its own (some
     * hundred KB) went back to the system and were faulted in again on every call. */
    const long ldc = rup(t.NT, 64);
    const size_t f_ct = (size_t)rup(t.MT * ldc, 16), f_bp = (size_t)rup((long)t.KC * ldc, 16);
    const size_t f_ae = (size_t)rup((long)NN_MR * t.KC, 16), f_aw = g->a16 ? (size_t)rup((long)t.MT * t.KC, 16) : 0;
    const size_t f_pc = g->bkind == NN_B_CONV ? (size_t)rup((long)(sizeof(piece) * (t.NT + 8) + 3) / 4, 16) : 0;
    const size_t per = f_ct + f_bp + f_ae + f_aw + f_pc;
    /* Each thread starts on a contiguous range of tiles (in order: along the rows of C, so a
     * thread's tiles share their rows of A and, for a 1x1 convolution, read consecutive pieces
     * of the input's and the output's lines); one that has finished takes tiles from the back
     * of the others' ranges. Shared out one at a time in turn, neighbouring tiles had gone to
     * different cores: a 64-channel 1x1 convolution's CPU time per call grew by a fifth with 2
     * threads. Which thread computes a tile does not change its values. */
    share *sh = aligned_alloc(64, sizeof(share) * nth);
    float *block = sh ? aligned_alloc(64, sizeof(float) * per * nth) : NULL;
    if (!block) {
        free(sh);
        return G3D_ERR(G3D_ERR_NOMEM, "matrix product %dx%dx%d: cannot allocate tile scratch", g->M, g->N, g->K);
    }
    for (int i = 0; i < nth; i++) {
        const unsigned long long lo = (unsigned long long)ntiles * i / nth, hi = (unsigned long long)ntiles * (i + 1) / nth;
        atomic_init(&sh[i].r, hi << 32 | lo);
    }
#pragma omp parallel num_threads(nth)
    {
        const int me = omp_get_thread_num();
        float *mine = block + per * me;
        scratch s = {.ct = mine, .bp = mine + f_ct, .ae = mine + f_ct + f_bp};
        s.aw = g->a16 ? s.ae + f_ae : NULL;
        s.pieces = f_pc ? (piece *)(s.ae + f_ae + f_aw) : NULL;
        for (int i; (i = next_tile(sh, nth, me)) >= 0;) run_tile(g, &t, &s, (i / tn) * t.MT, (i % tn) * t.NT);
    }
    free(block);
    free(sh);
    return G3D_OK;
}

/* ---- public matmul --------------------------------------------------------------------- */
g3d_status g3d_nn_matmul(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda, const float *B,
                         int ldb, float beta, float *C, int ldc)
{
    if (M < 0 || N < 0 || K < 0) return G3D_ERR(G3D_ERR_ARG, "matmul: negative size %dx%dx%d", M, N, K);
    if (beta != 0.0f && beta != 1.0f) return G3D_ERR(G3D_ERR_ARG, "matmul: beta must be 0 or 1, got %g", beta);
    if (M == 0 || N == 0) return G3D_OK;
    if (K == 0) {
        if (beta == 0.0f)
            for (int i = 0; i < M; i++) memset(C + (long)i * ldc, 0, sizeof(float) * N);
        return G3D_OK;
    }
    g3d_nn_epi epi = {.res = beta == 1.0f ? C : NULL};
    nn_gemm g = {.M = M, .N = N, .K = K, .a = A, .lda = ta ? 1 : lda, .ka = ta ? lda : 1,
                 .bkind = tb ? NN_B_COLS : NN_B_ROWS, .b = B, .ldb = ldb, .y = C, .ldy = ldc, .alpha = alpha,
                 .epi = &epi};
    return nn_gemm_run(&g);
}

void nn_ref_matmul(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda, const float *B, int ldb,
                   float beta, float *C, int ldc)
{
    for (int i = 0; i < M; i++)
        for (int j = 0; j < N; j++) {
            double s = 0;
            for (int k = 0; k < K; k++)
                s += (double)(ta ? A[(long)k * lda + i] : A[(long)i * lda + k]) *
                     (tb ? B[(long)j * ldb + k] : B[(long)k * ldb + j]);
            C[(long)i * ldc + j] = (float)(alpha * s + (beta != 0.0f ? beta * C[(long)i * ldc + j] : 0.0));
        }
}
