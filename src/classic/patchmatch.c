/* Exemplar inpainting: coarse-to-fine EM over a PatchMatch nearest-neighbour field. */
#include "gen3d/inpaint_classic.h"
#include "gen3d/membrane.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

g3d_patchmatch_params g3d_patchmatch_params_default(void)
{
    g3d_patchmatch_params p = {7, 3, 3, 24};
    return p;
}

/* One pyramid level. */
typedef struct level {
    int w, h;
    float *img;      /* (h, w, 3) */
    uint8_t *hole;   /* (h, w) 1 = unknown */
    uint8_t *src;    /* (h, w) 1 = a valid source patch centre (patch fully known and inside) */
} level;

static void level_free(level *l)
{
    free(l->img);
    free(l->hole);
    free(l->src);
    memset(l, 0, sizeof *l);
}

static g3d_status membrane_colour(float *img, const uint8_t *hole, int w, int h)
{
    size_t n = (size_t)w * h;
    float *ch = malloc(sizeof(float) * n);
    uint8_t *known = malloc(n);
    if (!ch || !known) { free(ch); free(known); return G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory"); }
    for (size_t i = 0; i < n; i++) known[i] = !hole[i];
    g3d_status rc = G3D_OK;
    for (int c = 0; c < 3 && rc == G3D_OK; c++) {
        for (size_t i = 0; i < n; i++) ch[i] = img[3 * i + c];
        rc = g3d_membrane_fill(ch, known, w, h);
        for (size_t i = 0; i < n && rc == G3D_OK; i++) img[3 * i + c] = ch[i];
    }
    free(ch);
    free(known);
    return rc;
}

/* Marks valid source centres: the whole patch inside the image and free of holes. */
static int mark_sources(level *l, int r)
{
    int w = l->w, h = l->h, count = 0;
    /* Integral image of holes for O(1) patch tests. */
    int *ii = calloc((size_t)(w + 1) * (h + 1), sizeof(int));
    if (!ii) return -1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            ii[(size_t)(y + 1) * (w + 1) + x + 1] = l->hole[(size_t)y * w + x] + ii[(size_t)y * (w + 1) + x + 1] +
                                                  ii[(size_t)(y + 1) * (w + 1) + x] - ii[(size_t)y * (w + 1) + x];
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int ok = x >= r && y >= r && x < w - r && y < h - r;
            if (ok) {
                int x0 = x - r, y0 = y - r, x1 = x + r + 1, y1 = y + r + 1;
                ok = ii[(size_t)y1 * (w + 1) + x1] - ii[(size_t)y0 * (w + 1) + x1] - ii[(size_t)y1 * (w + 1) + x0] +
                     ii[(size_t)y0 * (w + 1) + x0] == 0;
            }
            l->src[(size_t)y * w + x] = (uint8_t)ok;
            count += ok;
        }
    free(ii);
    return count;
}

/* Sum of squared differences between the patch at target (tx, ty) and source (sx, sy), over
 * the target patch's pixels inside the image. Stops early past `limit`. */
static float patch_dist(const level *l, int r, int tx, int ty, int sx, int sy, float limit)
{
    int w = l->w, h = l->h;
    float d = 0;
    for (int dy = -r; dy <= r; dy++) {
        int y = ty + dy;
        if (y < 0 || y >= h) continue;
        const float *a = l->img + ((size_t)y * w) * 3, *b = l->img + ((size_t)(sy + dy) * w) * 3;
        for (int dx = -r; dx <= r; dx++) {
            int x = tx + dx;
            if (x < 0 || x >= w) continue;
            const float *pa = a + 3 * x, *pb = b + 3 * (sx + dx);
            float e0 = pa[0] - pb[0], e1 = pa[1] - pb[1], e2 = pa[2] - pb[2];
            d += e0 * e0 + e1 * e1 + e2 * e2;
        }
        if (d > limit) return d;
    }
    return d;
}

/* Target patch centres: pixels within r of a hole pixel. */
static int32_t *list_targets(const level *l, int r, int64_t *count)
{
    int w = l->w, h = l->h;
    uint8_t *t = calloc((size_t)w * h, 1);
    if (!t) return NULL;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            if (!l->hole[(size_t)y * w + x]) continue;
            for (int dy = -r; dy <= r; dy++)
                for (int dx = -r; dx <= r; dx++) {
                    int xx = x + dx, yy = y + dy;
                    if (xx >= 0 && yy >= 0 && xx < w && yy < h) t[(size_t)yy * w + xx] = 1;
                }
        }
    int64_t n = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) n += t[i];
    int32_t *list = malloc(sizeof(int32_t) * (size_t)(n ? n : 1));
    if (list) {
        n = 0;
        for (size_t i = 0; i < (size_t)w * h; i++) if (t[i]) list[n++] = (int32_t)i;
    }
    free(t);
    *count = n;
    return list;
}

/* A random valid source centre (rejection sampling, with a scan as the fallback). */
static int32_t random_source(const level *l, g3d_rng *rng)
{
    size_t n = (size_t)l->w * l->h;
    for (int k = 0; k < 64; k++) {
        size_t i = g3d_rng_below(rng, (uint32_t)n);
        if (l->src[i]) return (int32_t)i;
    }
    size_t start = g3d_rng_below(rng, (uint32_t)n);
    for (size_t k = 0; k < n; k++) {
        size_t i = (start + k) % n;
        if (l->src[i]) return (int32_t)i;
    }
    return -1;
}

/* nnf[p] (for every pixel; only target pixels are used) = source centre index. */
static void patchmatch(const level *l, int r, const int32_t *targets, int64_t nt, int32_t *nnf, float *dist, int iters,
                       g3d_rng *rng)
{
    int w = l->w, h = l->h;
    for (int64_t k = 0; k < nt; k++) {
        int32_t t = targets[k];
        dist[t] = patch_dist(l, r, t % w, t / w, nnf[t] % w, nnf[t] / w, INFINITY);
    }
    for (int it = 0; it < iters; it++) {
        int fwd = !(it & 1);
        for (int64_t kk = 0; kk < nt; kk++) {
            int32_t t = targets[fwd ? kk : nt - 1 - kk];
            int tx = t % w, ty = t / w, step = fwd ? -1 : 1;
            /* Propagation: shift the neighbours' matches by one pixel. */
            for (int a = 0; a < 2; a++) {
                int nx = tx + (a == 0 ? step : 0), ny = ty + (a == 1 ? step : 0);
                if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                int32_t s = nnf[(size_t)ny * w + nx];
                int sx = s % w - (a == 0 ? step : 0), sy = s / w - (a == 1 ? step : 0);
                if (sx < 0 || sy < 0 || sx >= w || sy >= h || !l->src[(size_t)sy * w + sx]) continue;
                float d = patch_dist(l, r, tx, ty, sx, sy, dist[t]);
                if (d < dist[t]) { dist[t] = d; nnf[t] = sy * w + sx; }
            }
            /* Random search in shrinking windows around the current match. */
            int bx = nnf[t] % w, by = nnf[t] / w;
            for (int rad = w > h ? w : h; rad >= 1; rad /= 2) {
                int sx = bx + (int)g3d_rng_below(rng, (uint32_t)(2 * rad + 1)) - rad;
                int sy = by + (int)g3d_rng_below(rng, (uint32_t)(2 * rad + 1)) - rad;
                if (sx < 0 || sy < 0 || sx >= w || sy >= h || !l->src[(size_t)sy * w + sx]) continue;
                float d = patch_dist(l, r, tx, ty, sx, sy, dist[t]);
                if (d < dist[t]) { dist[t] = d; nnf[t] = sy * w + sx; bx = sx; by = sy; }
            }
        }
    }
}

static int cmp_f(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* Each hole pixel becomes the weighted mean of what the overlapping target patches' sources
 * put there; patches that match well weigh more. */
static void vote(level *l, int r, const int32_t *targets, int64_t nt, const int32_t *nnf, const float *dist)
{
    int w = l->w, h = l->h;
    size_t n = (size_t)w * h;
    float *ds = malloc(sizeof(float) * (size_t)(nt ? nt : 1));
    double *acc = calloc(n * 4, sizeof(double));
    if (!ds || !acc) { free(ds); free(acc); return; }
    for (int64_t k = 0; k < nt; k++) ds[k] = dist[targets[k]];
    qsort(ds, (size_t)nt, sizeof *ds, cmp_f);
    float sigma2 = fmaxf(ds[nt / 2], 1e-6f); /* median patch distance sets the weight scale */
    free(ds);
    for (int64_t k = 0; k < nt; k++) {
        int32_t t = targets[k];
        int tx = t % w, ty = t / w, sx = nnf[t] % w, sy = nnf[t] / w;
        double wt = exp(-0.5 * dist[t] / sigma2);
        for (int dy = -r; dy <= r; dy++)
            for (int dx = -r; dx <= r; dx++) {
                int x = tx + dx, y = ty + dy;
                if (x < 0 || y < 0 || x >= w || y >= h || !l->hole[(size_t)y * w + x]) continue;
                const float *s = l->img + ((size_t)(sy + dy) * w + (sx + dx)) * 3;
                double *a = acc + 4 * ((size_t)y * w + x);
                a[0] += wt * s[0];
                a[1] += wt * s[1];
                a[2] += wt * s[2];
                a[3] += wt;
            }
    }
    for (size_t i = 0; i < n; i++)
        if (l->hole[i] && acc[4 * i + 3] > 0)
            for (int c = 0; c < 3; c++) l->img[3 * i + c] = (float)(acc[4 * i + c] / acc[4 * i + 3]);
    free(acc);
}

g3d_status g3d_inpaint_smooth(g3d_image *image, const g3d_image *mask)
{
    if (image->c != 3 || mask->w != image->w || mask->h != image->h)
        return G3D_ERR(G3D_ERR_MISMATCH, "inpaint: mask %dx%d does not match the %dx%d colour image", mask->w, mask->h, image->w, image->h);
    size_t n = (size_t)image->w * image->h;
    uint8_t *hole = malloc(n);
    if (!hole) return G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory");
    for (size_t i = 0; i < n; i++) hole[i] = mask->data[i] > 0.5f;
    g3d_status rc = membrane_colour(image->data, hole, image->w, image->h);
    free(hole);
    return rc;
}

g3d_status g3d_inpaint_patchmatch(g3d_image *image, const g3d_image *mask, const g3d_patchmatch_params *pp, uint64_t seed)
{
    g3d_patchmatch_params def = g3d_patchmatch_params_default();
    if (!pp) pp = &def;
    if (image->c != 3 || mask->w != image->w || mask->h != image->h || mask->c != 1)
        return G3D_ERR(G3D_ERR_MISMATCH, "inpaint: mask %dx%d does not match the %dx%d colour image", mask->w, mask->h, image->w, image->h);
    if (pp->patch < 3 || pp->patch > 31 || !(pp->patch & 1)) return G3D_ERR(G3D_ERR_ARG, "inpaint: patch size must be odd, 3..31");
    int r = pp->patch / 2, W = image->w, H = image->h;
    size_t n0 = (size_t)W * H, holes = 0;
    for (size_t i = 0; i < n0; i++) holes += mask->data[i] > 0.5f;
    if (holes == 0) return G3D_OK;
    if (holes == n0) return G3D_ERR(G3D_ERR_ARG, "inpaint: the mask covers the whole image; nothing to copy texture from");

    /* Pyramid: level 0 is the input; a coarse pixel is a hole if any of its children is. */
    level lv[16];
    int nl = 0;
    memset(lv, 0, sizeof lv);
    g3d_status rc = G3D_OK;
    lv[0].w = W;
    lv[0].h = H;
    lv[0].img = malloc(sizeof(float) * 3 * n0);
    lv[0].hole = malloc(n0);
    lv[0].src = malloc(n0);
    if (!lv[0].img || !lv[0].hole || !lv[0].src) { rc = G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory"); goto done; }
    memcpy(lv[0].img, image->data, sizeof(float) * 3 * n0);
    for (size_t i = 0; i < n0; i++) lv[0].hole[i] = mask->data[i] > 0.5f;
    nl = 1;
    while (nl < 16 && (lv[nl - 1].w < lv[nl - 1].h ? lv[nl - 1].w : lv[nl - 1].h) / 2 >= pp->min_size) {
        level *a = &lv[nl - 1], *b = &lv[nl];
        b->w = (a->w + 1) / 2;
        b->h = (a->h + 1) / 2;
        size_t nb = (size_t)b->w * b->h;
        b->img = calloc(3 * nb, sizeof(float));
        b->hole = calloc(nb, 1);
        b->src = malloc(nb);
        nl++;
        if (!b->img || !b->hole || !b->src) { rc = G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory"); goto done; }
        for (int y = 0; y < b->h; y++)
            for (int x = 0; x < b->w; x++) {
                float s[3] = {0, 0, 0};
                int c = 0, any_hole = 0;
                for (int dy = 0; dy < 2; dy++)
                    for (int dx = 0; dx < 2; dx++) {
                        int xx = 2 * x + dx, yy = 2 * y + dy;
                        if (xx >= a->w || yy >= a->h) continue;
                        size_t i = (size_t)yy * a->w + xx;
                        if (a->hole[i]) { any_hole = 1; continue; }
                        for (int k = 0; k < 3; k++) s[k] += a->img[3 * i + k];
                        c++;
                    }
                size_t j = (size_t)y * b->w + x;
                b->hole[j] = (uint8_t)(any_hole || c == 0);
                if (c) for (int k = 0; k < 3; k++) b->img[3 * j + k] = s[k] / c;
            }
    }

    g3d_rng rng;
    g3d_rng_seed(&rng, seed, 0x1a9);
    int32_t *nnf = NULL;
    float *dist = NULL;
    int prev_w = 0;
    for (int L = nl - 1; L >= 0 && rc == G3D_OK; L--) {
        level *l = &lv[L];
        size_t n = (size_t)l->w * l->h;
        /* Patches must fit: shrink the radius on tiny levels. */
        int rr = r;
        while (rr > 1 && (2 * rr + 1) * 2 > (l->w < l->h ? l->w : l->h)) rr--;
        if (mark_sources(l, rr) <= 0) {
            /* No complete source patch at this scale (the hole covers nearly everything):
             * the smooth fill is the best this level can do. */
            rc = membrane_colour(l->img, l->hole, l->w, l->h);
        } else if (L == nl - 1 || !nnf) {
            rc = membrane_colour(l->img, l->hole, l->w, l->h);
        }
        if (rc != G3D_OK) break;
        if (L < nl - 1) {
            /* Start from the coarser solution: upsample its colours into the hole. */
            level *c = &lv[L + 1];
            for (int y = 0; y < l->h; y++)
                for (int x = 0; x < l->w; x++) {
                    size_t i = (size_t)y * l->w + x;
                    if (!l->hole[i]) continue;
                    int cx = x / 2 < c->w ? x / 2 : c->w - 1, cy = y / 2 < c->h ? y / 2 : c->h - 1;
                    memcpy(l->img + 3 * i, c->img + 3 * ((size_t)cy * c->w + cx), 3 * sizeof(float));
                }
        }
        int64_t nt;
        int32_t *targets = list_targets(l, rr, &nt);
        int32_t *nnf_l = malloc(sizeof(int32_t) * n);
        float *dist_l = malloc(sizeof(float) * n);
        if (!targets || !nnf_l || !dist_l) { free(targets); free(nnf_l); free(dist_l); rc = G3D_ERR(G3D_ERR_NOMEM, "inpaint: out of memory"); break; }
        /* Only target pixels get a match; the rest stay -1 so that the next level never
         * upsamples an unset entry. */
        for (size_t i = 0; i < n; i++) nnf_l[i] = -1;
        int have_sources = 0;
        for (size_t i = 0; i < n; i++) have_sources |= l->src[i];
        if (have_sources) {
            /* Initial field: the coarser field scaled up where it points at a valid source,
             * else a random source. */
            for (int64_t k = 0; k < nt; k++) {
                int32_t t = targets[k];
                int32_t s = -1;
                if (nnf && prev_w) {
                    int cx = (t % l->w) / 2, cy = (t / l->w) / 2;
                    int32_t cs = nnf[(size_t)cy * prev_w + cx];
                    int sx = 2 * (cs % prev_w) + (t % l->w) % 2, sy = 2 * (cs / prev_w) + (t / l->w) % 2;
                    if (cs >= 0 && sx < l->w && sy < l->h && l->src[(size_t)sy * l->w + sx]) s = sy * l->w + sx;
                }
                nnf_l[t] = s >= 0 ? s : random_source(l, &rng);
            }
            int em = pp->em_iters + (L > 0 ? 1 : 0) + (L == nl - 1 ? 2 : 0);
            for (int e = 0; e < em; e++) {
                patchmatch(l, rr, targets, nt, nnf_l, dist_l, pp->pm_iters, &rng);
                vote(l, rr, targets, nt, nnf_l, dist_l);
            }
        }
        free(targets);
        free(nnf);
        free(dist);
        nnf = have_sources ? nnf_l : NULL;
        if (!have_sources) free(nnf_l);
        dist = dist_l;
        prev_w = l->w;
    }
    free(nnf);
    free(dist);
    if (rc == G3D_OK)
        for (size_t i = 0; i < n0; i++)
            if (lv[0].hole[i]) memcpy(image->data + 3 * i, lv[0].img + 3 * i, 3 * sizeof(float));
done:
    for (int i = 0; i < nl; i++) level_free(&lv[i]);
    return rc;
}

static g3d_status classic_inpaint(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt, uint64_t seed)
{
    (void)prompt; /* exemplar filling has no use for text */
    return g3d_inpaint_patchmatch(image, mask, ctx, seed);
}

static void classic_free(void *ctx) { free(ctx); }

g3d_status g3d_inpainter_classic_create(const g3d_patchmatch_params *params, g3d_inpainter *out)
{
    g3d_patchmatch_params *p = malloc(sizeof *p);
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    *p = params ? *params : g3d_patchmatch_params_default();
    out->name = "patchmatch";
    out->ctx = p;
    out->inpaint = classic_inpaint;
    out->free = classic_free;
    return G3D_OK;
}
