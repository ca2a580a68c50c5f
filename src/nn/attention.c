/* Multi-head attention with an online softmax (flash-attention style), never storing the
 * score matrix.
 *
 * The unit of work is one head and one block of up to 64 queries. It works on transposed tiles:
 * for a block of keys, S^T [keys x 64 queries] = K_blk (q scale)^T, so the softmax statistics of
 * the 64 queries are vectors across the tile's columns, and O^T [hdv x 64] += V_blk^T P^T. Both
 * products run on the shared kernel with the keys or the value channels as its broadcast
 * operand, read straight from the caller's rows (the values of wide heads through a transposed
 * copy); only the query block is packed. Keeping the queries on the vector side means any head
 * size (40, 80, 160 in SD 1.x) and any key count (77 text tokens) wastes at most a few rows of
 * six. */
#include "nn/nn_int.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#define QB 64  /* most queries per block */
#define KB 240 /* most keys per block (blocks are balanced: 196 keys are one block) */
#define NK_SHORT KB /* key sets of one block */
#define VT_MIN 32768 /* key blocks of more values than this go through a transposed copy */
#define ALL_HEADS_KV 65536 /* most key and value floats (all heads) for tiles of every head */
#define ALL_HEADS_W 1024   /* and most channels of queries and values (all heads): 256 KB of tiles */

static int rup6(int x) { return (x + NN_MR - 1) / NN_MR * NN_MR; }

typedef struct tiles {
    float *qt, *st, *ot, *edge, *m, *l, *t1;
    float *bm; /* the column maxima of a key block's scores, taken by the kernel */
    float *vt; /* [rup6(hdv) x KB]: a key block's values transposed, for wide heads (or NULL) */
    const float *rel[2][KB]; /* per row of the score tile: its rows of the relative-position tables */
} tiles;

/* The next block a thread computes: head h, queries q0 .. q0+n-1 of problem b (n = 0: none;
 * h = -1: rows q0 .. q0+n-1 whole, fetched by the score kernel);
 * and rows kv0 .. kv1-1 of the keys and values of head kvh of problem b, to be fetched while
 * this block computes (kv1 = 0: none). */
typedef struct next_block {
    int b, h, q0, n;
    int kvh, kv0, kv1;
} next_block;

/* Rows i0 .. i1-1 of the next block's queries and outputs, fetched into L2 while the current
 * block computes (a few rows with each group's product): rows that far apart are not followed
 * by the hardware prefetcher, and their misses had stalled the transposes and the stores of
 * short-key attention. Always inlined: GCC takes a function of nothing but prefetches for one
 * without effects and drops the calls. */
static inline __attribute__((always_inline)) void prefetch_rows(const g3d_nn_attn *a, const next_block *nx, int i0, int i1)
{
    for (int i = i0; i < i1 && i < nx->n; i++) {
        const float *qi = a->q + nx->b * a->bsq + (long)(nx->q0 + i) * a->ldq + nx->h * a->hd;
        const float *oi = a->out + nx->b * a->bso + (long)(nx->q0 + i) * a->ldo + nx->h * a->hdv;
        for (int c = 0; c < a->hd; c += 16) __builtin_prefetch(qi + c, 0, 2);
        __builtin_prefetch(qi + a->hd - 1, 0, 2);
        for (int c = 0; c < a->hdv; c += 16) __builtin_prefetch(oi + c, 1, 2);
        __builtin_prefetch(oi + a->hdv - 1, 1, 2);
    }
}

/* Rows j0 .. j1-1 of the keys and values of the next head, fetched into L2 a share with each
 * block of the current head: their first reads had waited on memory (a SAM window's keys and
 * values are 1.2 MB, rows 3 KB apart, one head's part of each row taken at a time). */
static inline __attribute__((always_inline)) void prefetch_kv(const g3d_nn_attn *a, const next_block *nx, int j0, int j1)
{
    for (int j = j0; j < j1; j++) {
        const float *kj = a->k + nx->b * a->bsk + (long)j * a->ldk + nx->kvh * a->hd;
        const float *vj = a->v + nx->b * a->bsv + (long)j * a->ldv + nx->kvh * a->hdv;
        for (int c = 0; c < a->hd; c += 16) __builtin_prefetch(kj + c, 0, 2);
        __builtin_prefetch(kj + a->hd - 1, 0, 2);
        for (int c = 0; c < a->hdv; c += 16) __builtin_prefetch(vj + c, 0, 2);
        __builtin_prefetch(vj + a->hdv - 1, 0, 2);
    }
}

/* Block i of the queries: blocks of QB, except that a last one of at most 16 queries and the
 * block before it split their queries into two of at least 17 (as many vector lanes, but no
 * products one vector wide: SAM's windows of 196 tokens had ended in a block of 4). */
static void query_block(int nq, int i, int *q0, int *n)
{
    const int nqb = (nq + QB - 1) / QB, rem = nq % QB;
    if (nqb < 2 || rem == 0 || rem > 16 || i < nqb - 2) {
        *q0 = i * QB, *n = nq - *q0 < QB ? nq - *q0 : QB;
        return;
    }
    const int first = ((QB + rem) / 2 + 15) / 16 * 16;
    *q0 = (nqb - 2) * QB + (i == nqb - 1 ? first : 0), *n = i == nqb - 1 ? QB + rem - first : first;
}

/* Head h of queries q0 .. q0+nqv-1 of problem b. With all_heads, the caller has put every head's
 * queries in the tile (head h at row h hd) and writes every head's outputs from it at once: this
 * leaves head h's (normalised) at row h hdv of the output tile. */
static void task(const g3d_nn_attn *in, tiles *T, int b, int h, int q0, int nqv, const next_block *nx, int all_heads)
{
    /* problem b of a batch: the same descriptor with its pointers moved */
    g3d_nn_attn pb = *in;
    pb.q += b * in->bsq, pb.k += b * in->bsk, pb.v += b * in->bsv, pb.out += b * in->bso;
    const g3d_nn_attn *a = &pb;
    const int hd = a->hd, hdv = a->hdv;
    const int nvq = (nqv + 15) / 16, QW = 16 * nvq;
    float *qt = T->qt, *st = T->st, *ot = T->ot, *m = T->m, *l = T->l, *corr = T->t1;
    if (all_heads)
        qt += (size_t)h * hd * QB, ot += (size_t)h * hdv * QB;
    else /* queries of the block, scaled, as columns */
        nn_transpose_tile(a->q + (long)q0 * a->ldq + h * hd, a->ldq, nqv, hd, qt, QB, QW, a->scale, NULL);
    for (int i = 0; i < QB; i++) m[i] = -INFINITY, l[i] = 0.0f;
    /* causal: query q0+i sees keys j <= q0 + i + shift */
    const int shift = a->nk - a->nq;
    int kend = a->nk;
    if (a->causal && q0 + nqv - 1 + shift + 1 < kend) kend = q0 + nqv + shift;
    const int nkb = (kend + KB - 1) / KB, kbs = nkb ? (kend + nkb - 1) / nkb : 0;
    /* SAM's relative positions are added by the kernel while the scores are in registers, and
     * without a mask or another bias the kernel takes the column maxima too: the bias pass and
     * the softmax's pass for the maxima had each read and written the tile again (a 196-key tile
     * does not fit in L1). */
    const g3d_nn_bias_relpos *rp = a->bias == g3d_nn_bias_relpos_fn ? a->bias_ctx : NULL;
    const int fuse = !a->causal && (!a->bias || rp);
    const float *rh = NULL, *rw = NULL;
    if (rp) {
        const long hb = (long)b * rp->heads + h;
        rh = rp->rh + hb * rp->kh * rp->nq + q0, rw = rp->rw + hb * rp->kw * rp->nq + q0;
    }
    for (int k0 = 0; k0 < kend; k0 += kbs) {
        const int kb = kend - k0 < kbs ? kend - k0 : kbs;
        float *bm = fuse && kb >= NN_MR ? T->bm : NULL; /* not with the zero keys of a short block */
        if (bm)
            for (int i = 0; i < QW; i++) bm[i] = -INFINITY;
        const float *const *r0 = rp ? T->rel[0] : NULL, *const *r1 = T->rel[1];
        if (rp)
            for (int j = 0, ky = k0 / rp->kw, kx = k0 % rp->kw; j < (kb > NN_MR ? kb : NN_MR); j++) {
                /* rows past a short block's keys are not used; any table row will do */
                T->rel[0][j] = rh + (long)(j < kb ? ky : 0) * rp->nq, T->rel[1][j] = rw + (long)(j < kb ? kx : 0) * rp->nq;
                if (++kx == rp->kw) kx = 0, ky++;
            }
        /* S^T = K_blk (scale q)^T: the whole groups of six keys in one kernel call (in runs of
         * four with the prefetches of the next block between them, where there is one) */
        const int nfull = kb / NN_MR, run = nx->n && nx->h >= 0 ? 4 : nfull;
        /* whole rows of the next block: consecutive, so the kernel fetches them a line per step */
        const char *pf0 = NULL, *pf1 = NULL;
        int npf = 0;
        if (k0 == 0 && nx->n && nx->h < 0) {
            pf0 = (const char *)(in->q + nx->b * in->bsq + (long)nx->q0 * in->ldq);
            pf1 = (const char *)(in->out + nx->b * in->bso + (long)nx->q0 * in->ldo);
            npf = (int)((sizeof(float) * (size_t)nx->n * (size_t)(in->ldq > in->ldo ? in->ldq : in->ldo) + 63) / 64);
        }
        for (int g0 = 0; g0 < nfull; g0 += run) {
            const int ng = nfull - g0 < run ? nfull - g0 : run;
            nn_kernel_scores(hd, a->k + (long)(k0 + NN_MR * g0) * a->ldk + h * hd, a->ldk, 1, NN_MR * a->ldk, qt, QB,
                             st + NN_MR * g0 * QB, QB, NN_MR * QB, nvq, ng, r0 ? r0 + NN_MR * g0 : NULL,
                             r1 + NN_MR * g0, nqv, bm, pf0, pf1, npf);
            if (k0 == 0 && nx->h >= 0) {
                prefetch_rows(in, nx, NN_MR * g0, g0 + ng == nfull ? QB : NN_MR * (g0 + ng));
                const int kvn = nx->kv1 - nx->kv0;
                prefetch_kv(in, nx, nx->kv0 + kvn * g0 / nfull, nx->kv0 + kvn * (g0 + ng) / nfull);
            }
        }
        if (kb % NN_MR) {
            /* a last partial group of keys is redone as the six last keys (the values it writes
             * twice come out the same) rather than copied */
            const int r = kb >= NN_MR ? kb - NN_MR : 0;
            const float *ka = a->k + (long)(k0 + r) * a->ldk + h * hd;
            long lda = a->ldk;
            if (kb < NN_MR) {
                for (int i = 0; i < NN_MR; i++)
                    for (int d = 0; d < hd; d++) T->edge[i * hd + d] = i < kb ? ka[i * a->ldk + d] : 0.0f;
                ka = T->edge, lda = hd;
                if (k0 == 0 && nx->h >= 0) prefetch_rows(in, nx, 0, QB), prefetch_kv(in, nx, nx->kv0, nx->kv1);
            }
            nn_kernel_scores(hd, ka, lda, 1, 0, qt, QB, st + r * QB, QB, 0, nvq, 1, r0 ? r0 + r : NULL, r1 + r, nqv, bm,
                             nfull ? NULL : pf0, pf1, nfull ? 0 : npf);
        }
        if (a->bias && !rp) a->bias(a->bias_ctx, b, h, q0, nqv, k0, kb, st, 1, QB);
        if (a->causal)
            for (int j = 0; j < kb; j++) {
                int lim = k0 + j - q0 - shift; /* queries i < lim must not see key k0+j */
                for (int i = 0; i < QW && i < lim; i++) st[j * QB + i] = -INFINITY;
            }
        /* online softmax: new running maximum, rescale what was accumulated */
        nn_online_softmax(st, QB, kb, QW, bm, m, l, corr);
        /* the first block starts the sums (acc = 0 below) instead of scaling zeros */
        if (k0)
            for (int d = 0; d < hdv; d++)
                for (int i = 0; i < QW; i++) ot[d * QB + i] *= corr[i];
        /* O^T += V^T P^T, six value channels at a time, in one call. With wide heads (the VAE's
         * 512 channels) the key block's values are first transposed into consecutive rows: read in
         * place, each group of six channels took one value from each of the block's rows (480 KB
         * apart from one another), and the block came from memory 86 times at the pace of its
         * misses (the value product ran at 68 % of the sgemm rate, 110 % from the copy). Else a last
         * partial group reads the next head's first channels into the tile's spare rows, or for the
         * last head (whose row may end there) goes through a zero-padded copy. */
        const float *va = a->v + (long)k0 * a->ldv + h * hdv;
        if (T->vt && kb * hdv > VT_MIN) {
            nn_transpose_tile(va, a->ldv, kb, hdv, T->vt, KB, kb, 1.0f, NULL);
            nn_kernel_groups(kb, T->vt, KB, 1, NN_MR * KB, st, QB, ot, QB, NN_MR * QB, nvq, rup6(hdv) / NN_MR, k0 > 0);
        } else {
            const int direct = h * hdv + rup6(hdv) <= a->heads * hdv, ngv = direct ? rup6(hdv) / NN_MR : hdv / NN_MR;
            nn_kernel_groups(kb, va, 1, a->ldv, NN_MR, st, QB, ot, QB, NN_MR * QB, nvq, ngv, k0 > 0);
            if (!direct && hdv % NN_MR) {
                const int d0 = ngv * NN_MR;
                for (int i = 0; i < NN_MR; i++)
                    for (int j = 0; j < kb; j++) T->edge[i * KB + j] = i < hdv - d0 ? va[d0 + i + (long)j * a->ldv] : 0.0f;
                nn_kernel(kb, T->edge, KB, 1, st, QB, ot + d0 * QB, QB, nvq, k0 > 0);
            }
        }
    }
    if (kend <= 0) memset(ot, 0, sizeof(float) * (size_t)hdv * QB);
    for (int i = 0; i < nqv; i++) corr[i] = l[i] > 0.0f ? 1.0f / l[i] : 0.0f;
    if (!all_heads) {
        nn_transpose_tile(ot, QB, hdv, nqv, a->out + (long)q0 * a->ldo + h * hdv, a->ldo, hdv, 1.0f, corr);
        return;
    }
    for (int d = 0; d < hdv; d++)
        for (int i = 0; i < QW; i++) ot[d * QB + i] *= corr[i];
}

/* The descriptor with its defaults filled in, or an error. */
static g3d_status normalise(const g3d_nn_attn *in, g3d_nn_attn *a)
{
    *a = *in;
    if (!a->hdv) a->hdv = a->hd;
    if (!a->batch) a->batch = 1;
    if (a->nq < 0 || a->nk < 0 || a->heads <= 0 || a->hd <= 0 || a->hdv <= 0 || a->batch < 0)
        return G3D_ERR(G3D_ERR_ARG, "attention: bad sizes (%d queries, %d keys, %d heads of %d/%d)", a->nq, a->nk,
                       a->heads, a->hd, a->hdv);
    if (!a->ldq) a->ldq = (long)a->heads * a->hd;
    if (!a->ldk) a->ldk = (long)a->heads * a->hd;
    if (!a->ldv) a->ldv = (long)a->heads * a->hdv;
    if (!a->ldo) a->ldo = (long)a->heads * a->hdv;
    if (a->ldq < (long)a->heads * a->hd || a->ldk < (long)a->heads * a->hd || a->ldv < (long)a->heads * a->hdv ||
        a->ldo < (long)a->heads * a->hdv)
        return G3D_ERR(G3D_ERR_ARG, "attention: a row stride is shorter than heads x head size");
    return G3D_OK;
}

g3d_status g3d_nn_attend(const g3d_nn_attn *desc)
{
    g3d_nn_attn a;
    G3D_TRY(normalise(desc, &a));
    if (a.nq == 0) return G3D_OK;
    int nth = omp_in_parallel() ? 1 : omp_get_max_threads();
    /* With long key sets a task is one head and one block of 64 queries (consecutive tasks share
     * the head's keys and values). With short ones the per-block work is small and the rows of
     * the queries and outputs weigh: a task is every head of up to 4 blocks, so those rows stay in
     * cache from one head to the next and the next block's are fetched ahead; fewer blocks where
     * that would leave less than 16 tasks per thread (the last task keeps the others waiting). */
    const int shortk = a.nk <= NK_SHORT, nqb = (a.nq + QB - 1) / QB;
    /* Where every head's keys and values fit in L2 together (SD's text cross-attention: 200 KB),
     * a block's queries and outputs go through their tiles for all heads at once (80 KB each for
     * SD): whole rows in and out and 16-wide blocks only, where a head at a time had transposed
     * 40-wide slices (a third of the blocks half empty) and had written each output line in
     * parts. */
    const int all_heads = shortk && (long)a.nk * a.heads * (a.hd + a.hdv) <= ALL_HEADS_KV &&
                          (long)a.heads * (a.hd + a.hdv) <= ALL_HEADS_W;
    int g = a.batch * nqb / (16 * nth);
    g = g < 1 ? 1 : g > 4 ? 4 : g;
    /* Many problems (windows) with a head at a time: a task is a group of heads of one problem
     * and all its query blocks, as few groups as give 16 tasks per thread, so each head's keys
     * and values are read by one task (with SAM's windows in blocks of 3 + 1 for two threads,
     * both tasks of a window had read its 1.2 MB of keys and values). */
    int hg = 0;
    if (shortk && !all_heads && a.batch * a.heads >= 16 * nth) {
        hg = (16 * nth + a.batch - 1) / a.batch;
        hg = hg > a.heads ? a.heads : hg;
        g = nqb;
    }
    const int nch = hg ? hg : (nqb + g - 1) / g, ntask = shortk ? a.batch * nch : a.batch * a.heads * nqb;
    if (nth > ntask) nth = ntask;
    const int edge = NN_MR * (a.hd > KB ? a.hd : KB);
    int failed = 0;
#pragma omp parallel num_threads(nth)
    {
        tiles T = {0};
        const size_t nvt = a.hdv * KB > VT_MIN ? (size_t)rup6(a.hdv) * KB : 0;
        const size_t nqt = all_heads ? (size_t)a.heads * a.hd : (size_t)a.hd,
                     not = all_heads ? (size_t)a.heads * a.hdv + NN_MR : (size_t)rup6(a.hdv);
        size_t nbuf = (nqt + KB + not + 4) * QB + edge + nvt;
        float *buf = aligned_alloc(64, (sizeof(float) * nbuf + 63) / 64 * 64);
        if (!buf) {
#pragma omp atomic write
            failed = 1;
        } else {
            T.qt = buf, T.st = T.qt + nqt * QB, T.ot = T.st + (size_t)KB * QB;
            T.m = T.ot + not * QB, T.l = T.m + QB, T.t1 = T.l + QB, T.bm = T.t1 + QB;
            T.edge = T.bm + QB;
            if (nvt) {
                /* its rows past hdv feed only the tile's spare rows, but must be numbers */
                T.vt = T.edge + edge;
                memset(T.vt + (size_t)a.hdv * KB, 0, sizeof(float) * (nvt - (size_t)a.hdv * KB));
            }
        }
#pragma omp for schedule(dynamic, 1)
        for (int t = 0; t < ntask; t++) {
            if (!buf) continue;
            int q0, n;
            if (!shortk) {
                const next_block none = {0};
                query_block(a.nq, t % nqb, &q0, &n);
                task(&a, &T, t / (a.heads * nqb), t / nqb % a.heads, q0, n, &none, 0);
                continue;
            }
            const int b = t / nch, i0 = hg ? 0 : t % nch * g, i1 = hg ? nqb : nqb - i0 < g ? nqb : i0 + g;
            const int h0 = hg ? t % nch * a.heads / hg : 0, h1 = hg ? (t % nch + 1) * a.heads / hg : a.heads;
            if (all_heads) {
                for (int i = i0; i < i1; i++) {
                    query_block(a.nq, i, &q0, &n);
                    nn_transpose_tile(a.q + b * a.bsq + (long)q0 * a.ldq, a.ldq, n, a.heads * a.hd, T.qt, QB,
                                      (n + 15) / 16 * 16, a.scale, NULL);
                    int nq0 = 0, nn = 0;
                    if (i + 1 < i1) query_block(a.nq, i + 1, &nq0, &nn);
                    for (int h = 0; h < a.heads; h++) {
                        /* a share of the next block's whole rows (consecutive in memory, as the
                         * hardware prefetcher follows them) with each head */
                        const int r0 = nn * h / a.heads, r1 = nn * (h + 1) / a.heads;
                        const next_block nx = {b, -1, nq0 + r0, r1 - r0, 0, 0, 0};
                        task(&a, &T, b, h, q0, n, &nx, 1);
                    }
                    nn_transpose_tile(T.ot, QB, a.heads * a.hdv, n, a.out + b * a.bso + (long)q0 * a.ldo, a.ldo,
                                      a.heads * a.hdv, 1.0f, NULL);
                }
                continue;
            }
            for (int h = h0; h < h1; h++)
                for (int i = i0; i < i1; i++) {
                    /* the next block of this head, else the first of the next head */
                    next_block nx = {b, i + 1 < i1 ? h : h + 1, 0, 0, h + 1, 0, 0};
                    /* a task's keys and values come from memory only with groups of heads (one
                     * problem's are shared by all tasks, and fetching them ahead had cost 1 %) */
                    if (hg && h + 1 < h1) nx.kv0 = (i - i0) * a.nk / (i1 - i0), nx.kv1 = (i + 1 - i0) * a.nk / (i1 - i0);
                    if (nx.h < h1) query_block(a.nq, i + 1 < i1 ? i + 1 : i0, &nx.q0, &nx.n);
                    query_block(a.nq, i, &q0, &n);
                    task(&a, &T, b, h, q0, n, &nx, 0);
                }
        }
        free(buf);
    }
    if (failed) return G3D_ERR(G3D_ERR_NOMEM, "attention: cannot allocate the per-thread tiles");
    return G3D_OK;
}

g3d_status g3d_nn_attention(const float *qkv, int n, int heads, int hd, float scale, float *out)
{
    const int d = heads * hd;
    g3d_nn_attn a = {.nq = n, .nk = n, .heads = heads, .hd = hd, .q = qkv, .k = qkv + d, .v = qkv + 2 * d,
                     .ldq = 3 * d, .ldk = 3 * d, .ldv = 3 * d, .out = out, .scale = scale};
    return g3d_nn_attend(&a);
}

/* ---- biases ------------------------------------------------------------------------------- */
void g3d_nn_bias_dense_fn(void *ctx, int batch, int head, int q0, int nq, int k0, int nk, float *s, long qs, long ks)
{
    const g3d_nn_bias_dense *d = ctx;
    (void)batch;
    for (int i = 0; i < nq; i++) {
        const float *b = d->b + head * d->head_stride + (long)(q0 + i) * d->ld + k0;
        for (int j = 0; j < nk; j++) s[i * qs + j * ks] += b[j];
    }
}

/* vectorised for the instruction sets of the kernels (it had been 6-10 % of SAM's attention) */
__attribute__((target_clones("avx512f", "avx2", "default"))) static void
relpos_add(void *ctx, int batch, int head, int q0, int nq, int k0, int nk, float *s, long qs, long ks)
{
    const g3d_nn_bias_relpos *r = ctx;
    /* tables are key-major, so the queries of one key are contiguous like the tile's columns */
    const long hb = (long)batch * r->heads + head;
    const float *rh = r->rh + hb * r->kh * r->nq + q0, *rw = r->rw + hb * r->kw * r->nq + q0;
    /* the key's grid position by counting, not by a division per key */
    for (int j = 0, ky = k0 / r->kw, kx = k0 % r->kw; j < nk; j++) {
        const float *restrict h = rh + (long)ky * r->nq, *restrict w = rw + (long)kx * r->nq;
        float *restrict sj = s + j * ks;
        if (qs == 1)
            for (int i = 0; i < nq; i++) sj[i] += h[i] + w[i];
        else
            for (int i = 0; i < nq; i++) sj[i * qs] += h[i] + w[i];
        if (++kx == r->kw) kx = 0, ky++;
    }
}

/* A plain function, not the clones themselves: g3d_nn_attend recognises it by its address and
 * adds the terms inside the kernel instead. */
void g3d_nn_bias_relpos_fn(void *ctx, int batch, int head, int q0, int nq, int k0, int nk, float *s, long qs, long ks)
{
    relpos_add(ctx, batch, head, q0, nq, k0, nk, s, qs, ks);
}

g3d_status g3d_nn_relpos_tables(const float *q, long ldq, int heads, int hd, int qh, int qw, int kh, int kw,
                                const float *rel_h, const float *rel_w, float *rh, float *rw)
{
    if (qh != kh || qw != kw)
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "relative positions: query grid %dx%d differs from key grid %dx%d", qw, qh,
                       kw, kh);
    const int nq = qh * qw;
#pragma omp parallel for schedule(static)
    for (long t = 0; t < (long)heads * nq; t++) {
        int h = (int)(t / nq), i = (int)(t % nq), qy = i / qw, qx = i % qw;
        const float *qi = q + (long)i * ldq + h * hd;
        for (int ky = 0; ky < kh; ky++) {
            const float *r = rel_h + (long)(qy - ky + kh - 1) * hd;
            float s = 0;
            for (int c = 0; c < hd; c++) s += qi[c] * r[c];
            rh[((long)h * kh + ky) * nq + i] = s;
        }
        for (int kx = 0; kx < kw; kx++) {
            const float *r = rel_w + (long)(qx - kx + kw - 1) * hd;
            float s = 0;
            for (int c = 0; c < hd; c++) s += qi[c] * r[c];
            rw[((long)h * kw + kx) * nq + i] = s;
        }
    }
    return G3D_OK;
}

/* ---- reference -------------------------------------------------------------------------------- */
void nn_ref_attend(const g3d_nn_attn *desc)
{
    g3d_nn_attn a;
    if (normalise(desc, &a) != G3D_OK) return;
    float *s = malloc(sizeof(float) * (size_t)(a.nk ? a.nk : 1));
    double *p = malloc(sizeof(double) * (size_t)(a.nk ? a.nk : 1));
    if (!s || !p) {
        free(s), free(p);
        return;
    }
    for (int t = 0; t < a.batch * a.heads * a.nq; t++) {
        const int b = t / (a.heads * a.nq), h = t / a.nq % a.heads, i = t % a.nq;
        const float *qi = a.q + b * a.bsq + (long)i * a.ldq + h * a.hd, *kb = a.k + b * a.bsk;
        for (int j = 0; j < a.nk; j++) {
            double d = 0;
            for (int c = 0; c < a.hd; c++) d += (double)qi[c] * kb[(long)j * a.ldk + h * a.hd + c];
            s[j] = (float)(d * a.scale);
        }
        if (a.bias) a.bias(a.bias_ctx, b, h, i, 1, 0, a.nk, s, 0, 1);
        double mx = -INFINITY, sum = 0;
        for (int j = 0; j < a.nk; j++) {
            if (a.causal && j > i + a.nk - a.nq) s[j] = -INFINITY;
            mx = s[j] > mx ? s[j] : mx;
        }
        for (int j = 0; j < a.nk; j++) sum += p[j] = mx == -INFINITY ? 0.0 : exp(s[j] - mx);
        float *o = a.out + b * a.bso + (long)i * a.ldo + h * a.hdv;
        const float *vb = a.v + b * a.bsv;
        for (int c = 0; c < a.hdv; c++) {
            double acc = 0;
            for (int j = 0; j < a.nk; j++) acc += p[j] * vb[(long)j * a.ldv + h * a.hdv + c];
            o[c] = sum > 0 ? (float)(acc / sum) : 0.0f;
        }
    }
    free(s), free(p);
}
