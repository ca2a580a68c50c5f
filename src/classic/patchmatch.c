/* Weight-free inpainting: multi-scale exemplar fill (Wexler et al. 2007 style EM over a
 * PatchMatch nearest-neighbour field) and a coarse-to-fine Laplace fill.
 *
 * Why multi-scale: at the finest scale a 7x7 patch cannot see the structure of a hole that is
 * hundreds of pixels wide, so the field is found at a coarse scale first and upsampled; each
 * scale then only refines it. Why the coarse pyramid marks a pixel as hole when ANY of its
 * children is one: a known coarse pixel must never mix in unknown colour, otherwise source
 * patches at coarse scales would copy the starting guess instead of real content.
 *
 * Determinism: every pass is sequential in a fixed scan order and the random search draws
 * from one g3d_rng per scale seeded from (seed, scale); votes are summed in a fixed order.
 */
#include "gen3d/inpaint_classic.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct level {
    int w, h, c;
    float *img;    /* (h, w, c) */
    uint8_t *hole; /* (h, w) 1 = unknown */
} level;

static void level_free(level *L)
{
    free(L->img);
    free(L->hole);
    memset(L, 0, sizeof *L);
}

static g3d_status level_alloc(level *L, int w, int h, int c)
{
    L->w = w;
    L->h = h;
    L->c = c;
    L->img = g3d_calloc((size_t)w * h * c, sizeof(float), "inpaint level");
    L->hole = g3d_calloc((size_t)w * h, 1, "inpaint mask level");
    if (!L->img || !L->hole) {
        level_free(L);
        return G3D_ERR_NOMEM;
    }
    return G3D_OK;
}

/* Halves a level. any_hole: a coarse pixel is a hole when any child is (exemplar pyramid);
 * otherwise only when all children are (diffusion pyramid, which must keep known pixels). */
static g3d_status level_down(const level *F, level *C, int any_hole)
{
    G3D_TRY(level_alloc(C, (F->w + 1) / 2, (F->h + 1) / 2, F->c));
    const int c = F->c;
    for (int y = 0; y < C->h; y++)
        for (int x = 0; x < C->w; x++) {
            int n_known = 0, n_all = 0;
            float sum[16] = {0};
            for (int j = 0; j < 2; j++)
                for (int i = 0; i < 2; i++) {
                    int fx = 2 * x + i, fy = 2 * y + j;
                    if (fx >= F->w || fy >= F->h) continue;
                    n_all++;
                    size_t fi = (size_t)fy * F->w + fx;
                    if (F->hole[fi]) continue;
                    n_known++;
                    for (int k = 0; k < c; k++) sum[k] += F->img[fi * c + k];
                }
            size_t ci = (size_t)y * C->w + x;
            C->hole[ci] = any_hole ? (n_known < n_all) : (n_known == 0);
            if (n_known)
                for (int k = 0; k < c; k++) C->img[ci * c + k] = sum[k] / (float)n_known;
        }
    return G3D_OK;
}

/* Copies coarse colour (nearest parent) into the hole pixels of the fine level. */
static void level_up_fill(const level *C, level *F)
{
    const int c = F->c;
    for (int y = 0; y < F->h; y++)
        for (int x = 0; x < F->w; x++) {
            size_t fi = (size_t)y * F->w + x;
            if (!F->hole[fi]) continue;
            size_t ci = (size_t)(y / 2) * C->w + (x / 2);
            memcpy(F->img + fi * c, C->img + ci * c, (size_t)c * sizeof(float));
        }
}

/* Gauss-Seidel sweeps of the discrete Laplace equation over the hole pixels. */
static void laplace_sweeps(level *L, int sweeps)
{
    const int w = L->w, h = L->h, c = L->c;
    for (int s = 0; s < sweeps; s++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                if (!L->hole[i]) continue;
                float sum[16] = {0};
                int n = 0;
                const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
                for (int k = 0; k < 4; k++) {
                    if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
                    const float *v = L->img + ((size_t)ny[k] * w + nx[k]) * c;
                    for (int ch = 0; ch < c; ch++) sum[ch] += v[ch];
                    n++;
                }
                for (int ch = 0; ch < c; ch++) L->img[i * c + ch] = sum[ch] / (float)n;
            }
}

/* Coarse-to-fine harmonic fill: the coarse solution is a good start, so a few sweeps per
 * scale converge where plain Gauss-Seidel would need O(hole width^2) sweeps. */
static g3d_status diffuse_level(level *L)
{
    if (L->w > 8 && L->h > 8) {
        level C = {0};
        G3D_TRY(level_down(L, &C, 0));
        g3d_status rc = diffuse_level(&C);
        if (rc == G3D_OK) level_up_fill(&C, L);
        level_free(&C);
        G3D_TRY(rc);
        laplace_sweeps(L, 24);
    } else {
        laplace_sweeps(L, 200);
    }
    return G3D_OK;
}

/* Shared input checks. Returns the number of hole pixels in *n_hole. */
static g3d_status check_inputs(const g3d_image *image, const g3d_image *mask, size_t *n_hole)
{
    if (!image || !mask || !image->data || !mask->data)
        return G3D_ERR(G3D_ERR_ARG, "inpaint: image or mask is empty");
    if (image->c < 1 || image->c > 16)
        return G3D_ERR(G3D_ERR_ARG, "inpaint: image has %d channels (1..16 supported)", image->c);
    if (mask->c != 1)
        return G3D_ERR(G3D_ERR_MISMATCH, "inpaint: mask has %d channels, expected 1", mask->c);
    if (mask->w != image->w || mask->h != image->h)
        return G3D_ERR(G3D_ERR_MISMATCH, "inpaint: mask is %dx%d but image is %dx%d", mask->w, mask->h,
                       image->w, image->h);
    size_t n = (size_t)image->w * image->h, holes = 0;
    for (size_t i = 0; i < n; i++) holes += mask->data[i] > 0.5f;
    if (holes == n)
        return G3D_ERR(G3D_ERR_ARG, "inpaint: the mask covers the whole %dx%d image, nothing to copy from",
                       image->w, image->h);
    *n_hole = holes;
    return G3D_OK;
}

static g3d_status level_from_image(level *L, const g3d_image *image, const g3d_image *mask)
{
    G3D_TRY(level_alloc(L, image->w, image->h, image->c));
    memcpy(L->img, image->data, g3d_image_size(image) * sizeof(float));
    size_t n = (size_t)image->w * image->h;
    for (size_t i = 0; i < n; i++) L->hole[i] = mask->data[i] > 0.5f;
    return G3D_OK;
}

static void level_to_image(const level *L, g3d_image *image, const g3d_image *mask)
{
    size_t n = (size_t)L->w * L->h;
    for (size_t i = 0; i < n; i++)
        if (mask->data[i] > 0.5f) memcpy(image->data + i * L->c, L->img + i * L->c, (size_t)L->c * sizeof(float));
}


/* Cheap path for tiny holes (4-connected components of at most `max_px` pixels): a smooth
 * fill is indistinguishable there, and afterwards they count as known. This matters for the
 * speckled disocclusions of a reprojection, which would otherwise leave almost no hole-free
 * source patch. A tiny component's 4-neighbours are all known, so the sweeps read only
 * known values; the start is the mean of those neighbours. */
static g3d_status fill_tiny_holes(level *L, int max_px)
{
    const int w = L->w, h = L->h, c = L->c;
    const size_t n = (size_t)w * h;
    int32_t *stack = malloc(n * sizeof *stack), *comp = malloc(n * sizeof *comp);
    uint8_t *seen = g3d_calloc(n, 1, "inpaint components");
    level T = {0};
    g3d_status rc = G3D_OK;
    if (!stack || !comp || !seen) {
        rc = G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory for hole components");
        goto out;
    }
    T.w = w;
    T.h = h;
    T.c = c;
    T.img = L->img;
    T.hole = g3d_calloc(n, 1, "inpaint components");
    if (!T.hole) {
        rc = G3D_ERR_NOMEM;
        goto out;
    }
    size_t n_tiny = 0;
    for (size_t s0 = 0; s0 < n; s0++) {
        if (!L->hole[s0] || seen[s0]) continue;
        size_t ns = 0, nc = 0;
        stack[ns++] = (int32_t)s0;
        seen[s0] = 1;
        while (ns) {
            int32_t i = stack[--ns];
            comp[nc++] = i;
            int x = i % w, y = i / w;
            const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
            for (int k = 0; k < 4; k++) {
                if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
                size_t j = (size_t)ny[k] * w + nx[k];
                if (L->hole[j] && !seen[j]) {
                    seen[j] = 1;
                    stack[ns++] = (int32_t)j;
                }
            }
        }
        if (nc > (size_t)max_px) continue;
        float sum[16] = {0};
        int cnt = 0;
        for (size_t k = 0; k < nc; k++) {
            int x = comp[k] % w, y = comp[k] / w;
            const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
            for (int q = 0; q < 4; q++) {
                if (nx[q] < 0 || ny[q] < 0 || nx[q] >= w || ny[q] >= h) continue;
                size_t j = (size_t)ny[q] * w + nx[q];
                if (L->hole[j]) continue;
                for (int ch = 0; ch < c; ch++) sum[ch] += L->img[j * c + ch];
                cnt++;
            }
        }
        for (size_t k = 0; k < nc; k++) {
            for (int ch = 0; ch < c; ch++) L->img[(size_t)comp[k] * c + ch] = cnt ? sum[ch] / (float)cnt : 0.f;
            T.hole[comp[k]] = 1;
        }
        n_tiny += nc;
    }
    if (n_tiny) {
        laplace_sweeps(&T, 2 * max_px);
        for (size_t i = 0; i < n; i++)
            if (T.hole[i]) L->hole[i] = 0;
    }
out:
    free(T.hole);
    free(stack);
    free(comp);
    free(seen);
    return rc;
}

g3d_status g3d_inpaint_diffusion(g3d_image *image, const g3d_image *mask)
{
    size_t n_hole = 0;
    G3D_TRY(check_inputs(image, mask, &n_hole));
    if (!n_hole) return G3D_OK;
    level L = {0};
    G3D_TRY(level_from_image(&L, image, mask));
    g3d_status rc = diffuse_level(&L);
    if (rc == G3D_OK) level_to_image(&L, image, mask);
    level_free(&L);
    return rc;
}

/* ---------------------------------------------------------------------------------------- */
/* Exemplar fill                                                                             */

void g3d_inpaint_params_default(g3d_inpaint_params *p)
{
    p->patch = 7;
    p->em_iters = 4;
    p->pm_passes = 2;
    p->coarse_side = 48;
}

void g3d_inpaint_params_print(const g3d_inpaint_params *p)
{
    g3d_log(G3D_LOG_INFO, "inpaint: patch %d, %d EM iterations x %d PatchMatch passes, coarse side %d", p->patch,
            p->em_iters, p->pm_passes, p->coarse_side);
}

/* Per-scale state of the nearest-neighbour field. */
typedef struct nnf {
    int r;             /* patch radius */
    int32_t *src;      /* (h, w) source centre index for targets, -1 elsewhere */
    float *dist;       /* (h, w) SSD of that match */
    uint8_t *src_ok;   /* (h, w) 1 when the patch centred here is inside and hole-free */
    int32_t *src_list; /* valid centres, in raster order */
    size_t n_src;
} nnf;

static void nnf_free(nnf *f)
{
    free(f->src);
    free(f->dist);
    free(f->src_ok);
    free(f->src_list);
    memset(f, 0, sizeof *f);
}

/* Box count of hole pixels in the (2r+1)^2 window around every pixel (clipped at the
 * border) via an integral image; decides both the valid sources and the targets. */
static g3d_status nnf_alloc(nnf *f, const level *L, int r)
{
    const int w = L->w, h = L->h;
    const size_t n = (size_t)w * h;
    memset(f, 0, sizeof *f);
    f->r = r;
    f->src = malloc(n * sizeof *f->src);
    f->dist = g3d_calloc(n, sizeof *f->dist, "inpaint field");
    f->src_ok = g3d_calloc(n, 1, "inpaint field");
    f->src_list = malloc(n * sizeof *f->src_list);
    uint32_t *integ = g3d_calloc((size_t)(w + 1) * (h + 1), sizeof *integ, "inpaint field");
    if (!f->src || !f->dist || !f->src_ok || !f->src_list || !integ) {
        free(integ);
        nnf_free(f);
        return G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory for a %dx%d field", w, h);
    }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            integ[(size_t)(y + 1) * (w + 1) + x + 1] = L->hole[(size_t)y * w + x] + integ[(size_t)y * (w + 1) + x + 1] +
                                                    integ[(size_t)(y + 1) * (w + 1) + x] - integ[(size_t)y * (w + 1) + x];
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int x0 = x - r < 0 ? 0 : x - r, x1 = x + r >= w ? w - 1 : x + r;
            int y0 = y - r < 0 ? 0 : y - r, y1 = y + r >= h ? h - 1 : y + r;
            uint32_t cnt = integ[(size_t)(y1 + 1) * (w + 1) + x1 + 1] - integ[(size_t)y0 * (w + 1) + x1 + 1] -
                           integ[(size_t)(y1 + 1) * (w + 1) + x0] + integ[(size_t)y0 * (w + 1) + x0];
            size_t i = (size_t)y * w + x;
            int inside = x >= r && y >= r && x < w - r && y < h - r;
            f->src_ok[i] = inside && cnt == 0;
            if (f->src_ok[i]) f->src_list[f->n_src++] = (int32_t)i;
            f->src[i] = cnt ? 0 : -1; /* targets get a real source below */
        }
    free(integ);
    return G3D_OK;
}

/* SSD between the patch at target p (clipped to the image) and the patch at source q (always
 * inside); stops once it exceeds `stop`. */
static float patch_dist(const level *L, int r, int px, int py, int qx, int qy, float stop)
{
    const int w = L->w, c = L->c;
    int x0 = px - r < 0 ? -px : -r, x1 = px + r >= w ? w - 1 - px : r;
    int y0 = py - r < 0 ? -py : -r, y1 = py + r >= L->h ? L->h - 1 - py : r;
    float d = 0.f;
    const int len = (x1 - x0 + 1) * c;
    for (int dy = y0; dy <= y1; dy++) {
        const float *a = L->img + ((size_t)(py + dy) * w + px + x0) * c;
        const float *b = L->img + ((size_t)(qy + dy) * w + qx + x0) * c;
        for (int k = 0; k < len; k++) {
            float e = a[k] - b[k];
            d += e * e;
        }
        if (d > stop) return d;
    }
    return d;
}

static int32_t random_source(const nnf *f, g3d_rng *rng)
{
    return f->src_list[g3d_rng_below(rng, (uint32_t)f->n_src)];
}

static void try_candidate(const level *L, nnf *f, int px, int py, int qx, int qy)
{
    const int w = L->w, r = f->r;
    if (qx < r || qy < r || qx >= w - r || qy >= L->h - r) return;
    size_t q = (size_t)qy * w + qx, p = (size_t)py * w + px;
    if (!f->src_ok[q] || (int32_t)q == f->src[p]) return;
    float d = patch_dist(L, r, px, py, qx, qy, f->dist[p]);
    if (d < f->dist[p]) {
        f->dist[p] = d;
        f->src[p] = (int32_t)q;
    }
}

/* One PatchMatch pass: propagation from the already-visited neighbours, then random search
 * in windows halving from the whole image down to one pixel. */
static void pm_pass(const level *L, nnf *f, int backward, g3d_rng *rng)
{
    const int w = L->w, h = L->h, s = backward ? -1 : 1;
    const int maxr = w > h ? w : h;
    for (int k = 0; k < h * w; k++) {
        int i = backward ? w * h - 1 - k : k;
        if (f->src[i] < 0) continue;
        int px = i % w, py = i / w;
        int nx = px - s, ny = py - s;
        if (nx >= 0 && nx < w && f->src[(size_t)py * w + nx] >= 0) {
            int32_t q = f->src[(size_t)py * w + nx];
            try_candidate(L, f, px, py, q % w + s, q / w);
        }
        if (ny >= 0 && ny < h && f->src[(size_t)ny * w + px] >= 0) {
            int32_t q = f->src[(size_t)ny * w + px];
            try_candidate(L, f, px, py, q % w, q / w + s);
        }
        for (int R = maxr; R >= 1; R /= 2) {
            int bx = f->src[i] % w, by = f->src[i] / w;
            int rx = bx + (int)g3d_rng_below(rng, 2u * R + 1) - R;
            int ry = by + (int)g3d_rng_below(rng, 2u * R + 1) - R;
            try_candidate(L, f, px, py, rx, ry);
        }
    }
}

/* Recomputes every target's distance against the current image (the hole changed). */
static void refresh_dist(const level *L, nnf *f)
{
    const int w = L->w;
    for (size_t i = 0; i < (size_t)w * L->h; i++)
        if (f->src[i] >= 0)
            f->dist[i] = patch_dist(L, f->r, (int)(i % w), (int)(i / w), f->src[i] % w, f->src[i] / w, INFINITY);
}

/* Each hole pixel becomes the weighted mean of what every overlapping target patch's match
 * says about it. Weights exp(-d / 2 sigma^2) with sigma^2 the 75th percentile of the mean
 * per-value patch error, so poor matches barely vote (keeps the fill sharp). */
static g3d_status vote(level *L, const nnf *f, int sharp)
{
    const int w = L->w, h = L->h, c = L->c, r = f->r;
    const size_t n = (size_t)w * h;
    float *acc = g3d_calloc(n * c, sizeof *acc, "inpaint votes");
    float *wsum = g3d_calloc(n, sizeof *wsum, "inpaint votes");
    float *dn = malloc(n * sizeof *dn);
    if (!acc || !wsum || !dn) {
        free(acc);
        free(wsum);
        free(dn);
        return G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory for votes");
    }
    size_t nt = 0;
    for (size_t i = 0; i < n; i++)
        if (f->src[i] >= 0) dn[nt++] = f->dist[i] / (float)(c * (2 * r + 1) * (2 * r + 1));
    g3d_sort_f32(dn, nt);
    float s2 = nt ? dn[(nt * 3) / 4] : 0.f;
    if (s2 < 1e-6f) s2 = 1e-6f;
    for (size_t i = 0; i < n; i++) {
        if (f->src[i] < 0) continue;
        int px = (int)(i % w), py = (int)(i / w), qx = f->src[i] % w, qy = f->src[i] / w;
        float wt = expf(-(f->dist[i] / (float)(c * (2 * r + 1) * (2 * r + 1))) / (2.f * s2));
        if (sharp) wt = 1.f / (f->dist[i] + 1e-9f);
        for (int dy = -r; dy <= r; dy++) {
            int y = py + dy;
            if (y < 0 || y >= h) continue;
            for (int dx = -r; dx <= r; dx++) {
                int x = px + dx;
                if (x < 0 || x >= w) continue;
                size_t t = (size_t)y * w + x;
                if (!L->hole[t]) continue;
                const float *v = L->img + ((size_t)(qy + dy) * w + qx + dx) * c;
                if (sharp) {
                    /* keep only the single best-matching patch's value: no averaging blur */
                    if (wt > wsum[t]) {
                        memcpy(acc + t * c, v, (size_t)c * sizeof(float));
                        wsum[t] = wt;
                    }
                    continue;
                }
                for (int k = 0; k < c; k++) acc[t * c + k] += wt * v[k];
                wsum[t] += wt;
            }
        }
    }
    for (size_t t = 0; t < n; t++)
        if (L->hole[t] && wsum[t] > 0.f)
            for (int k = 0; k < c; k++) L->img[t * c + k] = sharp ? acc[t * c + k] : acc[t * c + k] / wsum[t];
    free(acc);
    free(wsum);
    free(dn);
    return G3D_OK;
}

/* Initial field: from the coarser scale's field when given (parent match doubled plus the
 * child's offset), else random valid sources. */
static void nnf_init(const level *L, nnf *f, const level *C, const nnf *fc, g3d_rng *rng)
{
    const int w = L->w, r = f->r;
    for (size_t i = 0; i < (size_t)w * L->h; i++) {
        if (f->src[i] < 0) continue;
        int32_t q = -1;
        if (fc) {
            int px = (int)(i % w), py = (int)(i / w);
            int32_t qc = fc->src[(size_t)(py / 2) * C->w + px / 2];
            if (qc >= 0) {
                int qx = 2 * (qc % C->w) + (px & 1), qy = 2 * (qc / C->w) + (py & 1);
                if (qx >= r && qy >= r && qx < w - r && qy < L->h - r && f->src_ok[(size_t)qy * w + qx])
                    q = (int32_t)((size_t)qy * w + qx);
            }
        }
        f->src[i] = q >= 0 ? q : random_source(f, rng);
    }
}


/* Onion-peel start for the coarsest scale: fills the hole layer by layer from its boundary,
 * each pixel taking the centre of the source patch that best matches the pixels known before
 * that layer. Unlike a smooth start, this gives wide border bands real texture for the EM
 * iterations to refine (a smooth start makes the search prefer flat source patches). The
 * search is exhaustive over a subset of the sources drawn with the scale's rng. */
static g3d_status onion_init(level *L, const nnf *f, g3d_rng *rng)
{
    const int w = L->w, h = L->h, c = L->c, r = f->r;
    const size_t n = (size_t)w * h;
    uint8_t *known = malloc(n), *next = malloc(n);
    int32_t *cand = malloc(f->n_src * sizeof *cand);
    if (!known || !next || !cand) {
        free(known);
        free(next);
        free(cand);
        return G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory for the coarse start");
    }
    size_t left = 0;
    for (size_t i = 0; i < n; i++) {
        known[i] = !L->hole[i];
        left += L->hole[i];
    }
    /* Bounded work: at most ~4e6 patch comparisons, so a coarsest scale that stayed large
     * (speckled masks stop the pyramid early) cannot blow up; at least 16 candidates. */
    size_t max_c = 4000000 / (left ? left : 1);
    if (max_c > 4096) max_c = 4096;
    if (max_c < 16) max_c = 16;
    size_t nc = 0;
    for (size_t k = 0; k < f->n_src; k++)
        if (f->n_src <= max_c || g3d_rng_below(rng, (uint32_t)f->n_src) < max_c) cand[nc++] = f->src_list[k];
    if (!nc) cand[nc++] = f->src_list[0];
    while (left) {
        memcpy(next, known, n);
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                if (known[i]) continue;
                int edge = (x > 0 && known[i - 1]) || (x + 1 < w && known[i + 1]) || (y > 0 && known[i - w]) ||
                           (y + 1 < h && known[i + w]);
                if (!edge) continue;
                float best = INFINITY;
                int32_t bq = cand[0];
                for (size_t k = 0; k < nc; k++) {
                    int qx = cand[k] % w, qy = cand[k] / w;
                    float d = 0.f;
                    for (int dy = -r; dy <= r && d < best; dy++) {
                        int yy = y + dy;
                        if (yy < 0 || yy >= h) continue;
                        for (int dx = -r; dx <= r; dx++) {
                            int xx = x + dx;
                            if (xx < 0 || xx >= w || !known[(size_t)yy * w + xx]) continue;
                            const float *a = L->img + ((size_t)yy * w + xx) * c;
                            const float *b = L->img + ((size_t)(qy + dy) * w + qx + dx) * c;
                            for (int ch = 0; ch < c; ch++) d += (a[ch] - b[ch]) * (a[ch] - b[ch]);
                        }
                    }
                    if (d < best) {
                        best = d;
                        bq = cand[k];
                    }
                }
                memcpy(L->img + i * c, L->img + (size_t)bq * c, (size_t)c * sizeof(float));
                next[i] = 1;
                left--;
            }
        memcpy(known, next, n);
    }
    free(known);
    free(next);
    free(cand);
    return G3D_OK;
}

static g3d_status solve_scale(level *L, nnf *f, const g3d_inpaint_params *p, g3d_rng *rng, int final)
{
    for (int it = 0; it < p->em_iters; it++) {
        refresh_dist(L, f);
        for (int pass = 0; pass < p->pm_passes; pass++) pm_pass(L, f, pass & 1, rng);
        G3D_TRY(vote(L, f, 0));
    }
    if (final) {
        /* One more search against the converged image, then a best-patch reconstruction. */
        refresh_dist(L, f);
        for (int pass = 0; pass < p->pm_passes; pass++) pm_pass(L, f, pass & 1, rng);
        G3D_TRY(vote(L, f, 1));
    }
    return G3D_OK;
}

static size_t count_sources(const level *L, int r)
{
    nnf f;
    if (nnf_alloc(&f, L, r) != G3D_OK) return 0;
    size_t n = f.n_src;
    nnf_free(&f);
    return n;
}

#define MAX_LEVELS 16

static g3d_status check_params(const g3d_inpaint_params *p)
{
    if (p->patch < 3 || p->patch > 15 || !(p->patch & 1))
        return G3D_ERR(G3D_ERR_ARG, "inpaint: patch size %d must be odd and in 3..15", p->patch);
    if (p->em_iters < 1 || p->em_iters > 100 || p->pm_passes < 1 || p->pm_passes > 100 || p->coarse_side < 8)
        return G3D_ERR(G3D_ERR_ARG, "inpaint: iterations %d/%d must be in 1..100 and coarse side %d >= 8",
                       p->em_iters, p->pm_passes, p->coarse_side);
    return G3D_OK;
}

g3d_status g3d_inpaint_patchmatch(g3d_image *image, const g3d_image *mask, const g3d_inpaint_params *params,
                                  uint64_t seed)
{
    g3d_inpaint_params p;
    if (params) p = *params;
    else g3d_inpaint_params_default(&p);
    G3D_TRY(check_params(&p));
    size_t n_hole = 0;
    G3D_TRY(check_inputs(image, mask, &n_hole));
    if (!n_hole) return G3D_OK;
    const int r = p.patch / 2;

    level lv[MAX_LEVELS];
    memset(lv, 0, sizeof lv);
    nnf fields[2];
    memset(fields, 0, sizeof fields);
    int nl = 1;
    g3d_status rc = level_from_image(&lv[0], image, mask);
    if (rc != G3D_OK) return rc;

    rc = fill_tiny_holes(&lv[0], (r + 1) * (r + 1));
    if (rc != G3D_OK) goto done;
    {
        size_t left = 0;
        for (size_t i = 0; i < (size_t)lv[0].w * lv[0].h; i++) left += lv[0].hole[i];
        if (!left) goto done;
    }
    if (count_sources(&lv[0], r) == 0) {
        /* Too small or too holey for a single full patch: a smooth fill is the best we can do. */
        rc = diffuse_level(&lv[0]);
        goto done;
    }
    /* A coarser scale is kept only while it still has a usable number of source patches. */
    while (nl < MAX_LEVELS) {
        const level *F = &lv[nl - 1];
        int mside = F->w < F->h ? F->w : F->h;
        /* At least one halving when possible: the onion start drifts on fine, regular
         * texture, and a coarse start fixes the layout before the details are copied. */
        if (mside / 2 < (nl == 1 ? 16 : p.coarse_side)) break;
        rc = level_down(F, &lv[nl], 1);
        if (rc != G3D_OK) goto done;
        if (count_sources(&lv[nl], r) < 64) {
            level_free(&lv[nl]);
            break;
        }
        nl++;
    }

    for (int l = nl - 1; l >= 0; l--) {
        nnf *cur = &fields[l & 1], *prev = l + 1 < nl ? &fields[(l + 1) & 1] : NULL;
        g3d_rng rng;
        g3d_rng_seed(&rng, seed, (uint64_t)l);
        if (prev) level_up_fill(&lv[l + 1], &lv[l]);
        rc = nnf_alloc(cur, &lv[l], r);
        if (rc != G3D_OK) goto done;
        if (!prev) {
            rc = onion_init(&lv[l], cur, &rng);
            if (rc != G3D_OK) goto done;
        }
        nnf_init(&lv[l], cur, prev ? &lv[l + 1] : NULL, prev, &rng);
        if (prev) nnf_free(prev);
        rc = solve_scale(&lv[l], cur, &p, &rng, l == 0);
        if (rc != G3D_OK) goto done;
    }
done:
    if (rc == G3D_OK) level_to_image(&lv[0], image, mask);
    for (int l = 0; l < MAX_LEVELS; l++) level_free(&lv[l]);
    nnf_free(&fields[0]);
    nnf_free(&fields[1]);
    return rc;
}

/* ---------------------------------------------------------------------------------------- */
/* Provider                                                                                  */

static g3d_status classic_inpaint(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt,
                                  uint64_t seed)
{
    (void)prompt;
    if (image && image->c != 3)
        return G3D_ERR(G3D_ERR_MISMATCH, "inpaint: image has %d channels, the inpainter takes RGB (3)", image->c);
    return g3d_inpaint_patchmatch(image, mask, (const g3d_inpaint_params *)ctx, seed);
}

g3d_status g3d_inpainter_classic_create(const g3d_inpaint_params *params, g3d_inpainter *out)
{
    if (params) G3D_TRY(check_params(params));
    g3d_inpaint_params *ctx = g3d_calloc(1, sizeof *ctx, "inpainter");
    if (!ctx) return G3D_ERR_NOMEM;
    if (params) *ctx = *params;
    else g3d_inpaint_params_default(ctx);
    g3d_inpaint_params_print(ctx);
    out->name = "classic";
    out->ctx = ctx;
    out->inpaint = classic_inpaint;
    out->free = free;
    return G3D_OK;
}
