/* Segment Anything's automatic mask generator (SamAutomaticMaskGenerator with one crop layer):
 * a grid of foreground points, three masks each, filtered by predicted IoU and stability,
 * then box non-maximum suppression; and the mask provider built on it. */
#include "sam_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void g3d_sam_amg_params_default(g3d_sam_amg_params *p)
{
    *p = (g3d_sam_amg_params){32, 0.88f, 0.95f, 1.0f, 0.7f, 0};
}

void g3d_sam_masks_free(g3d_sam_masks *s)
{
    if (!s) return;
    free(s->masks); free(s->iou); free(s->stability); free(s->boxes); free(s->area); free(s->points);
    memset(s, 0, sizeof *s);
}

typedef struct cand {
    uint8_t *mask;
    float iou, stability, px, py;
    int box[4], area; /* box: x0, y0, x1, y1 inclusive */
    float rank;       /* what NMS sorts by: the predicted IoU, then (small regions) 1 if unchanged */
    int order;
} cand;

static int by_score(const void *a, const void *b)
{
    const cand *x = a, *y = b;
    if (x->rank != y->rank) return x->rank > y->rank ? -1 : 1;
    return x->order - y->order; /* ties keep their order, as torchvision's stable sort */
}

static float box_iou(const int *a, const int *b)
{
    float ix = (float)((a[2] < b[2] ? a[2] : b[2]) - (a[0] > b[0] ? a[0] : b[0]));
    float iy = (float)((a[3] < b[3] ? a[3] : b[3]) - (a[1] > b[1] ? a[1] : b[1]));
    float inter = (ix > 0 ? ix : 0) * (iy > 0 ? iy : 0);
    float aa = (float)(a[2] - a[0]) * (float)(a[3] - a[1]), ab = (float)(b[2] - b[0]) * (float)(b[3] - b[1]);
    return inter / (aa + ab - inter);
}

/* The bounding box (batched_mask_to_box: 0, 0, 0, 0 when empty) and area of c's mask. */
static void mask_box(cand *c, int w, int h)
{
    int x0 = w, y0 = h, x1 = -1, y1 = -1, area = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            if (!c->mask[(size_t)y * w + x]) continue;
            area++;
            if (x < x0) x0 = x;
            if (x > x1) x1 = x;
            if (y < y0) y0 = y;
            if (y > y1) y1 = y;
        }
    if (!area) x0 = y0 = x1 = y1 = 0;
    c->box[0] = x0; c->box[1] = y0; c->box[2] = x1; c->box[3] = y1;
    c->area = area;
}

/* Greedy box NMS: sorts list by rank (stable) and moves the survivors to its front; returns
 * their count. */
static int nms(cand *list, int nc, float thresh)
{
    for (int i = 0; i < nc; i++) list[i].order = i;
    qsort(list, (size_t)nc, sizeof *list, by_score);
    int nk = 0;
    for (int i = 0; i < nc; i++) {
        int ok = 1;
        for (int j = 0; j < nk && ok; j++) ok = !(box_iou(list[i].box, list[j].box) > thresh);
        if (ok) {
            cand t = list[nk];
            list[nk++] = list[i];
            list[i] = t;
        }
    }
    return nk;
}

/* remove_small_regions: the 8-connected components of the mask (islands) or of its complement
 * (holes) smaller than `area` pixels are removed or filled; when every island is small the
 * largest stays. lab and stack hold w*h ints. Returns 1 if the mask changed. */
static int remove_small(uint8_t *mask, int w, int h, int area, int holes, int *lab, int *stack, int **sizes, int *cap)
{
    const size_t npx = (size_t)w * h;
    memset(lab, 0, sizeof(int) * npx);
    int n = 0, any_small = 0;
    for (size_t s0 = 0; s0 < npx; s0++) {
        if ((mask[s0] != 0) == holes || lab[s0]) continue;
        if (n + 1 >= *cap) {
            int nc = 2 * *cap + 64, *ns = realloc(*sizes, sizeof(int) * (size_t)nc);
            if (!ns) return -1;
            *sizes = ns;
            *cap = nc;
        }
        int L = ++n, top = 0, count = 0;
        lab[s0] = L;
        stack[top++] = (int)s0;
        while (top) {
            int p = stack[--top], px = p % w, py = p / w;
            count++;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    int qx = px + dx, qy = py + dy;
                    if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
                    size_t q = (size_t)qy * w + qx;
                    if ((mask[q] != 0) == holes || lab[q]) continue;
                    lab[q] = L;
                    stack[top++] = (int)q;
                }
        }
        (*sizes)[L] = count;
        any_small |= count < area;
    }
    if (!any_small) return 0;
    int biggest = 0, kept = 0;
    for (int L = 1; L <= n; L++) {
        if ((*sizes)[L] > (biggest ? (*sizes)[biggest] : -1)) biggest = L;
        kept += (*sizes)[L] >= area;
    }
    for (size_t i = 0; i < npx; i++) {
        int L = lab[i];
        if (holes)
            mask[i] = !L || (*sizes)[L] < area;
        else
            mask[i] = L && (kept ? (*sizes)[L] >= area : L == biggest);
    }
    return 1;
}

/* postprocess_small_regions on the generator's masks: each mask's small holes filled and small
 * islands removed; NMS again, preferring the masks that needed no change. Returns the count
 * kept (at the front of list), or -1 when out of memory. */
static int small_regions(cand *list, int nc, int w, int h, int area, float thresh)
{
    size_t npx = (size_t)w * h;
    int *lab = malloc(sizeof(int) * npx), *stack = malloc(sizeof(int) * npx), *sizes = NULL, cap = 0, bad = !lab || !stack;
    for (int i = 0; i < nc && !bad; i++) {
        int a = remove_small(list[i].mask, w, h, area, 1, lab, stack, &sizes, &cap);
        int b = a < 0 ? -1 : remove_small(list[i].mask, w, h, area, 0, lab, stack, &sizes, &cap);
        bad = a < 0 || b < 0;
        list[i].rank = a || b ? 0.0f : 1.0f;
        mask_box(&list[i], w, h);
    }
    free(lab);
    free(stack);
    free(sizes);
    return bad ? -1 : nms(list, nc, thresh);
}

/* Keeps the candidate masks of one prediction that pass the thresholds (appended to *list). */
static g3d_status collect(const g3d_sam_amg_params *p, const g3d_sam_prediction *pr, float px, float py, cand **list,
                          int *n, int *cap)
{
    const size_t npx = (size_t)pr->w * pr->h;
    for (int k = 0; k < pr->n; k++) {
        if (p->pred_iou_thresh > 0 && !(pr->iou[k] > p->pred_iou_thresh)) continue;
        const float *lg = pr->logits + (size_t)k * npx;
        long inter = 0, uni = 0;
        for (size_t i = 0; i < npx; i++) {
            inter += lg[i] > p->stability_score_offset;
            uni += lg[i] > -p->stability_score_offset;
        }
        float stab = (float)inter / (float)uni;
        if (p->stability_score_thresh > 0 && !(stab >= p->stability_score_thresh)) continue;
        if (*n == *cap) {
            int nc = *cap ? 2 * *cap : 64;
            cand *l = realloc(*list, sizeof(cand) * (size_t)nc);
            if (!l) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            *list = l;
            *cap = nc;
        }
        cand *c = &(*list)[*n];
        if (!(c->mask = malloc(npx))) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        for (size_t i = 0; i < npx; i++) c->mask[i] = lg[i] > 0;
        mask_box(c, pr->w, pr->h);
        c->iou = c->rank = pr->iou[k];
        c->stability = stab;
        c->px = px;
        c->py = py;
        c->order = (*n)++;
    }
    return G3D_OK;
}

/* The first nk candidates as the public result (boxes as x, y, w, h). */
static g3d_status to_masks(const cand *list, int nk, int w, int h, g3d_sam_masks *out)
{
    size_t npx = (size_t)w * h;
    out->w = w;
    out->h = h;
    if (!nk) return G3D_OK;
    out->masks = malloc(npx * nk);
    out->iou = malloc(sizeof(float) * nk);
    out->stability = malloc(sizeof(float) * nk);
    out->boxes = malloc(sizeof(int) * 4 * nk);
    out->area = malloc(sizeof(int) * nk);
    out->points = malloc(sizeof(float) * 2 * nk);
    if (!out->masks || !out->iou || !out->stability || !out->boxes || !out->area || !out->points)
        return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (int i = 0; i < nk; i++) {
        const cand *c = &list[i];
        memcpy(out->masks + npx * i, c->mask, npx);
        out->iou[i] = c->iou;
        out->stability[i] = c->stability;
        int *b = out->boxes + 4 * i;
        b[0] = c->box[0]; b[1] = c->box[1]; b[2] = c->box[2] - c->box[0]; b[3] = c->box[3] - c->box[1];
        out->area[i] = c->area;
        out->points[2 * i] = c->px;
        out->points[2 * i + 1] = c->py;
    }
    out->n = nk;
    return G3D_OK;
}

g3d_status g3d_sam_prediction_masks(const g3d_sam_prediction *pr, float stability_offset, float px, float py,
                                    g3d_sam_masks *out)
{
    memset(out, 0, sizeof *out);
    g3d_sam_amg_params p = {.stability_score_offset = stability_offset};
    cand *list = NULL;
    int nc = 0, cap = 0;
    g3d_status rc = collect(&p, pr, px, py, &list, &nc, &cap);
    if (rc == G3D_OK) rc = to_masks(list, nc, pr->w, pr->h, out);
    for (int i = 0; i < nc; i++) free(list[i].mask);
    free(list);
    if (rc != G3D_OK) g3d_sam_masks_free(out);
    return rc;
}

g3d_status g3d_sam_generate(const g3d_sam *m, const g3d_sam_image *img, const g3d_sam_amg_params *params,
                            const g3d_progress *progress, g3d_sam_masks *out)
{
    memset(out, 0, sizeof *out);
    g3d_sam_amg_params p;
    if (params)
        p = *params;
    else
        g3d_sam_amg_params_default(&p);
    if (p.points_per_side < 1 || p.points_per_side > 256 || !(p.stability_score_offset >= 0) || p.min_mask_region_area < 0 ||
        !(p.box_nms_thresh >= 0 && p.box_nms_thresh <= 1))
        return G3D_ERR(G3D_ERR_ARG, "SAM generator: points per side must be 1..256, the stability offset and the "
                                    "minimum region area >= 0 and the NMS threshold in [0, 1]");
    const int n = p.points_per_side, total = n * n;
    /* build_point_grid: np.linspace(offset, 1 - offset, n) along each axis, x fastest */
    double offset = 1.0 / (2 * n), step = n > 1 ? ((1 - offset) - offset) / (n - 1) : 0;
    double sx = (double)img->in_w / img->w, sy = (double)img->in_h / img->h;
    cand *list = NULL;
    int nc = 0, cap = 0;
    g3d_status rc = G3D_OK;
    const float iou_floor = p.pred_iou_thresh > 0 ? p.pred_iou_thresh : -INFINITY;
    /* Points are decoded in parallel, each on one thread (the operators then run serially: no
     * synchronisation inside the small products), and their masks gathered in grid order. */
    enum { CHUNK = 32 };
    typedef struct point_out {
        cand *list;
        int n, cap;
        g3d_status rc;
        char msg[256];
    } point_out;
    point_out po[CHUNK];
    for (int k0 = 0; k0 < total && rc == G3D_OK; k0 += CHUNK) {
        int cn = total - k0 < CHUNK ? total - k0 : CHUNK;
        memset(po, 0, sizeof po);
#pragma omp parallel for schedule(dynamic, 1)
        for (int j = 0; j < cn; j++) {
            int k = k0 + j, label = 1;
            double gx = k % n == n - 1 ? 1 - offset : offset + (k % n) * step;
            double gy = k / n == n - 1 ? 1 - offset : offset + (k / n) * step;
            double px = gx * img->w, py = gy * img->h, pt[2] = {px * sx, py * sy};
            g3d_sam_prediction pr;
            g3d_status r = sam_predict_scaled(m, img, 1, pt, &label, NULL, NULL, 1, 0, iou_floor, &pr, NULL);
            if (r == G3D_OK) r = collect(&p, &pr, (float)px, (float)py, &po[j].list, &po[j].n, &po[j].cap);
            g3d_sam_prediction_free(&pr);
            if ((po[j].rc = r) != G3D_OK) snprintf(po[j].msg, sizeof po[j].msg, "%s", g3d_error_message());
        }
        for (int j = 0; j < cn; j++) {
            if (rc == G3D_OK && po[j].rc != G3D_OK) rc = G3D_ERR(po[j].rc, "%s", po[j].msg);
            if (rc == G3D_OK && nc + po[j].n > cap) {
                int ncap = 2 * (nc + po[j].n) + 64;
                cand *l = realloc(list, sizeof(cand) * (size_t)ncap);
                if (l) {
                    list = l;
                    cap = ncap;
                } else
                    rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            }
            for (int i = 0; i < po[j].n; i++) {
                if (rc == G3D_OK) {
                    list[nc] = po[j].list[i];
                    list[nc].order = nc;
                    nc++;
                } else
                    free(po[j].list[i].mask);
            }
            free(po[j].list);
        }
        if (rc == G3D_OK && g3d_progress_report(progress, "masks", k0 + cn, total, NULL)) rc = G3D_CANCELLED;
    }
    if (rc == G3D_OK && nc) {
        int nk = nms(list, nc, p.box_nms_thresh);
        /* the official second NMS uses the larger of box_nms_thresh and crop_nms_thresh (0.7) */
        if (p.min_mask_region_area > 0 &&
            (nk = small_regions(list, nk, img->w, img->h, p.min_mask_region_area,
                                p.box_nms_thresh > 0.7f ? p.box_nms_thresh : 0.7f)) < 0) {
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            nk = 0;
        }
        if (rc == G3D_OK) rc = to_masks(list, nk, img->w, img->h, out);
    }
    for (int i = 0; i < nc; i++) free(list[i].mask);
    free(list);
    out->w = img->w;
    out->h = img->h;
    if (rc != G3D_OK) g3d_sam_masks_free(out);
    return rc;
}

/* ---- mask provider ------------------------------------------------------------------------ */

typedef struct sam_provider {
    g3d_sam *model;
    g3d_sam_amg_params params;
} sam_provider;

static void provider_free(void *ctx)
{
    sam_provider *s = ctx;
    g3d_sam_free(s->model);
    free(s);
}

static g3d_status provider_propose(void *ctx, const g3d_image *rgb, const g3d_image *depth, g3d_mask_set *out)
{
    (void)depth;
    sam_provider *s = ctx;
    memset(out, 0, sizeof *out);
    uint8_t *px = g3d_sam_rgb8(rgb);
    if (!px) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_sam_image img;
    g3d_sam_masks mk;
    g3d_status rc = g3d_sam_set_image(s->model, px, rgb->w, rgb->h, &img, NULL);
    free(px);
    if (rc != G3D_OK) return rc;
    rc = g3d_sam_generate(s->model, &img, &s->params, NULL, &mk);
    g3d_sam_image_free(&img);
    if (rc != G3D_OK) return rc;
    out->n = mk.n;
    out->w = mk.w;
    out->h = mk.h;
    out->masks = mk.masks;
    out->scores = mk.iou;
    mk.masks = NULL;
    mk.iou = NULL;
    /* the predicted IoU may stray a little outside [0, 1] */
    for (int i = 0; i < out->n; i++) out->scores[i] = out->scores[i] < 0 ? 0 : out->scores[i] > 1 ? 1 : out->scores[i];
    g3d_sam_masks_free(&mk);
    return G3D_OK;
}

g3d_status g3d_mask_provider_sam_create(const char *path, const g3d_sam_amg_params *params, g3d_mask_provider *out)
{
    memset(out, 0, sizeof *out);
    sam_provider *s = calloc(1, sizeof *s);
    if (!s) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (params)
        s->params = *params;
    else
        g3d_sam_amg_params_default(&s->params);
    g3d_status rc = g3d_sam_load_file(path, &s->model);
    if (rc != G3D_OK) {
        free(s);
        return rc;
    }
    *out = (g3d_mask_provider){"sam", s, provider_propose, provider_free};
    return G3D_OK;
}
