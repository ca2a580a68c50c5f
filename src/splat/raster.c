/* Differentiable tile rasterizer for 3D Gaussians (see raster.h for the stages).
 *
 * Per-Gaussian work (projection and its backward) runs in double: it is O(N) and cheap next to
 * the O(pixels x depth complexity) blend, and it keeps the covariance/conic chain accurate.
 * The blend runs in float, Gaussian-outer / pixel-inner over a 16x16 tile so the inner loop is a
 * flat 256-wide loop over per-pixel state arrays.
 */
#include "gen3d/raster.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define TILE G3D_RASTER_TILE
#define TPIX (TILE * TILE)
#define ALPHA_MIN (1.0f / 255.0f)
#define ALPHA_MAX 0.99f
#define T_MIN 1e-4f
/* Floats in one per-instance gradient record: dmean2d (2), dconic (3), dopacity, drgb (3), dz. */
#define REC 10
/* Packed per-Gaussian blend record (see pk below). */
enum { PK_MX, PK_MY, PK_A, PK_B, PK_C, PK_O, PK_Z, PK_RGB, PK_EX = PK_RGB + 3, PK_EY, PK = 16 };

static const double SH_C1 = 0.4886025119029199;
static const double SH_C2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                                -1.0925484305920792, 0.5462742152960396};
static const double SH_C3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                                0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                                -0.5900435899266435};

struct g3d_raster_ws {
    /* frame */
    int W, H, gx, gy, deg, valid;
    int64_t n, cap_n, cap_inst, cap_pix, cap_tiles, n_inst;
    g3d_camera cam;
    g3d_raster_params s;
    double wr[9], wt[3], campos[3];   /* world-to-camera rotation (row-major) and translation */
    /* per Gaussian */
    /* (N, PK) one 64-byte record per projected Gaussian, everything the blend reads, so each
     * tile-list entry costs one cache line: mean2d, conic (a, b, c), opacity (sigmoid x
     * compensation), view z, rgb, half-extent (x, y) of the alpha >= 1/255 box */
    float *pk;
    uint8_t *clamped; /* (N, 3) colour channel clamped at 0 */
    int32_t *radii;   /* (N) */
    int32_t *rect;    /* (N, 4) tile x0, y0, x1, y1 (exclusive) */
    int64_t *offs;    /* (N + 1) first instance of each Gaussian in creation order */
    uint32_t *skey;   /* (2N) radix-sort keys (view-depth bits), two ping-pong halves */
    int32_t *sid;     /* (2N) their Gaussian ids */
    /* per instance, sorted by (tile, depth, id) */
    int32_t *inst_gid;  /* (M) Gaussian id */
    int64_t *inst_src;  /* (M) creation-order instance index (gradient record slot) */
    int64_t *inst_tmp;  /* (max(M, tiles)) per-tile fill cursors */
    float *rec;         /* (M, REC) backward gradient records, creation order */
    int64_t *tile_start; /* (tiles + 1) */
    /* per pixel */
    float *final_t;     /* (H, W) */
    int32_t *last;      /* (H, W) index inside the tile list of the last contributor, -1 none */
};

void g3d_raster_params_default(g3d_raster_params *s)
{
    memset(s, 0, sizeof *s);
    s->sh_degree_active = -1;
    s->near_plane = 0.01f;
    s->eps2d = 0.3f;
    s->guard_band = 1.3f;
}

g3d_status g3d_raster_ws_create(g3d_raster_ws **out)
{
    g3d_raster_ws *ws = g3d_calloc(1, sizeof *ws, "raster workspace");
    if (!ws) return G3D_ERR_NOMEM;
    *out = ws;
    return G3D_OK;
}

void g3d_raster_ws_free(g3d_raster_ws *ws)
{
    if (!ws) return;
    free(ws->pk);
    free(ws->clamped); free(ws->radii); free(ws->rect); free(ws->offs); free(ws->skey); free(ws->sid);
    free(ws->inst_gid); free(ws->inst_src); free(ws->inst_tmp); free(ws->rec);
    free(ws->tile_start); free(ws->final_t); free(ws->last);
    free(ws);
}

/* Replaces *p by a buffer of n elements of `size` bytes (contents not kept). */
static int regrow(void *p, size_t n, size_t size)
{
    void **pp = p;
    free(*pp);
    size_t bytes = (n > 0 && size > 0 ? n * size : 1);
    *pp = aligned_alloc(64, (bytes + 63) / 64 * 64);   /* whole cache lines for the packed records */
    return *pp != NULL;
}

static g3d_status ensure_gaussians(g3d_raster_ws *ws, int64_t n)
{
    if (n <= ws->cap_n) return G3D_OK;
    int64_t c = n + n / 4 + 16;
    size_t cn = (size_t)c;
    ws->cap_n = 0;
    if (!regrow(&ws->pk, cn * PK, sizeof(float)) || !regrow(&ws->clamped, cn * 3, 1) ||
        !regrow(&ws->radii, cn, sizeof(int32_t)) || !regrow(&ws->rect, cn * 4, sizeof(int32_t)) ||
        !regrow(&ws->offs, cn + 1, sizeof(int64_t)) || !regrow(&ws->skey, 2 * cn, sizeof(uint32_t)) ||
        !regrow(&ws->sid, 2 * cn, sizeof(int32_t)))
        return G3D_ERR(G3D_ERR_NOMEM, "raster: out of memory for %lld Gaussians", (long long)n);
    ws->cap_n = c;
    return G3D_OK;
}

static g3d_status ensure_instances(g3d_raster_ws *ws, int64_t m)
{
    if (m <= ws->cap_inst) return G3D_OK;
    int64_t c = m + m / 4 + 64;
    size_t cm = (size_t)c;
    ws->cap_inst = 0;
    if (!regrow(&ws->inst_gid, cm, sizeof(int32_t)) || !regrow(&ws->inst_src, cm, sizeof(int64_t)) ||
        !regrow(&ws->inst_tmp, cm, sizeof(int64_t)) || !regrow(&ws->rec, cm * REC, sizeof(float)))
        return G3D_ERR(G3D_ERR_NOMEM, "raster: out of memory for %lld tile instances", (long long)m);
    ws->cap_inst = c;
    return G3D_OK;
}

static g3d_status ensure_pixels(g3d_raster_ws *ws, int64_t pixels, int64_t tiles)
{
    if (pixels > ws->cap_pix) {
        ws->cap_pix = 0;
        if (!regrow(&ws->final_t, (size_t)pixels, sizeof(float)) ||
            !regrow(&ws->last, (size_t)pixels, sizeof(int32_t)))
            return G3D_ERR(G3D_ERR_NOMEM, "raster: out of memory for %lld pixels", (long long)pixels);
        ws->cap_pix = pixels;
    }
    if (tiles + 1 > ws->cap_tiles) {
        ws->cap_tiles = 0;
        if (!regrow(&ws->tile_start, (size_t)tiles + 1, sizeof(int64_t)))
            return G3D_ERR(G3D_ERR_NOMEM, "raster: out of memory for tiles");
        ws->cap_tiles = tiles + 1;
    }
    return G3D_OK;
}

/* The per-Gaussian passes (project_all, gaussian_grads) are built for AVX-512, AVX2 and SSE2
 * with everything they call inlined: the same double arithmetic (no contraction into FMA), but
 * rounding instructions instead of libm calls and wider moves. */
#define PROJ_TARGETS __attribute__((target_clones("avx512f", "avx2", "default")))
#define PROJ_INLINE static inline __attribute__((always_inline))

/* ---- SH ------------------------------------------------------------------------------------ */

/* Real SH basis up to `deg` at direction (x, y, z) (unit), Inria's order and signs. With
 * non-NULL dx/dy/dz also the partial derivatives of each basis function. */
PROJ_INLINE void sh_basis(int deg, double x, double y, double z, double b[16], double *dx, double *dy,
                     double *dz)
{
    b[0] = G3D_SH_C0;
    if (dx) for (int k = 0; k < 16; k++) dx[k] = dy[k] = dz[k] = 0.0;
    if (deg < 1) return;
    const double c1 = SH_C1;
    b[1] = -c1 * y; b[2] = c1 * z; b[3] = -c1 * x;
    if (dx) { dy[1] = -c1; dz[2] = c1; dx[3] = -c1; }
    if (deg < 2) return;
    const double *c2 = SH_C2, xx = x * x, yy = y * y, zz = z * z;
    b[4] = c2[0] * x * y;
    b[5] = c2[1] * y * z;
    b[6] = c2[2] * (2 * zz - xx - yy);
    b[7] = c2[3] * x * z;
    b[8] = c2[4] * (xx - yy);
    if (dx) {
        dx[4] = c2[0] * y; dy[4] = c2[0] * x;
        dy[5] = c2[1] * z; dz[5] = c2[1] * y;
        dx[6] = -2 * c2[2] * x; dy[6] = -2 * c2[2] * y; dz[6] = 4 * c2[2] * z;
        dx[7] = c2[3] * z; dz[7] = c2[3] * x;
        dx[8] = 2 * c2[4] * x; dy[8] = -2 * c2[4] * y;
    }
    if (deg < 3) return;
    const double *c3 = SH_C3;
    b[9] = c3[0] * y * (3 * xx - yy);
    b[10] = c3[1] * x * y * z;
    b[11] = c3[2] * y * (4 * zz - xx - yy);
    b[12] = c3[3] * z * (2 * zz - 3 * xx - 3 * yy);
    b[13] = c3[4] * x * (4 * zz - xx - yy);
    b[14] = c3[5] * z * (xx - yy);
    b[15] = c3[6] * x * (xx - 3 * yy);
    if (dx) {
        dx[9] = c3[0] * 6 * x * y; dy[9] = c3[0] * 3 * (xx - yy);
        dx[10] = c3[1] * y * z; dy[10] = c3[1] * x * z; dz[10] = c3[1] * x * y;
        dx[11] = -2 * c3[2] * x * y; dy[11] = c3[2] * (4 * zz - xx - 3 * yy); dz[11] = 8 * c3[2] * y * z;
        dx[12] = -6 * c3[3] * x * z; dy[12] = -6 * c3[3] * y * z; dz[12] = c3[3] * (6 * zz - 3 * xx - 3 * yy);
        dx[13] = c3[4] * (4 * zz - 3 * xx - yy); dy[13] = -2 * c3[4] * x * y; dz[13] = 8 * c3[4] * x * z;
        dx[14] = 2 * c3[5] * x * z; dy[14] = -2 * c3[5] * y * z; dz[14] = c3[5] * (xx - yy);
        dx[15] = c3[6] * 3 * (xx - yy); dy[15] = -6 * c3[6] * x * y;
    }
}

/* ---- projection ---------------------------------------------------------------------------- */

/* Everything the per-Gaussian forward computes that its backward reuses. */
typedef struct proj {
    double qn[4], qlen, R[9], s[3], Sig[6];   /* unit quaternion, rotation, scales, world cov (xx xy xz yy yz zz) */
    double t[3], xc, yc, xclamped, yclamped;  /* view mean, clamped x/z and y/z, clamp flags */
    double T[6];                              /* J * W, 2x3 row-major */
    double a0, b0, c0, a, b, c, det, comp, sig;
    double dir[3], dlen;
} proj;

PROJ_INLINE void quat_to_rot(const double q[4], double R[9])
{
    double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - w * z);     R[2] = 2 * (x * z + w * y);
    R[3] = 2 * (x * y + w * z);     R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - w * x);
    R[6] = 2 * (x * z - w * y);     R[7] = 2 * (y * z + w * x);     R[8] = 1 - 2 * (x * x + y * y);
}

/* Projects Gaussian i; returns 0 if it is culled (then nothing else is valid). */
PROJ_INLINE int project_one(const g3d_raster_ws *ws, const g3d_gaussians *g, int64_t i, proj *p)
{
    const float *m = g->means + 3 * i;
    const double *wr = ws->wr;
    for (int r = 0; r < 3; r++)
        p->t[r] = wr[3 * r] * m[0] + wr[3 * r + 1] * m[1] + wr[3 * r + 2] * m[2] + ws->wt[r];
    if (!(p->t[2] > ws->s.near_plane)) return 0;
    const g3d_intrinsics *K = &ws->cam.K;
    const double tz = p->t[2];

    const float *q = g->rots + 4 * i;
    double ql = sqrt((double)q[0] * q[0] + (double)q[1] * q[1] + (double)q[2] * q[2] + (double)q[3] * q[3]);
    if (!(ql > 0)) return 0;
    p->qlen = ql;
    for (int k = 0; k < 4; k++) p->qn[k] = q[k] / ql;
    quat_to_rot(p->qn, p->R);
    for (int k = 0; k < 3; k++) p->s[k] = exp((double)g->log_scales[3 * i + k]);
    /* Sigma = M M^T with M = R diag(s) */
    double M[9];
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 3; k++) M[3 * r + k] = p->R[3 * r + k] * p->s[k];
    static const int ij[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
    for (int e = 0; e < 6; e++) {
        int r = ij[e][0], c = ij[e][1];
        p->Sig[e] = M[3 * r] * M[3 * c] + M[3 * r + 1] * M[3 * c + 1] + M[3 * r + 2] * M[3 * c + 2];
    }

    /* guard band on the Jacobian's direction (gsplat form, valid for off-centre principal points) */
    const double gb = ws->s.guard_band - 1.0;
    double tanx = 0.5 * K->width / K->fx, tany = 0.5 * K->height / K->fy;
    double xlo = -(K->cx + 0.5) / K->fx - gb * tanx, xhi = (K->width - 0.5 - K->cx) / K->fx + gb * tanx;
    double ylo = -(K->cy + 0.5) / K->fy - gb * tany, yhi = (K->height - 0.5 - K->cy) / K->fy + gb * tany;
    double xr = p->t[0] / tz, yr = p->t[1] / tz;
    p->xclamped = xr < xlo || xr > xhi;
    p->yclamped = yr < ylo || yr > yhi;
    p->xc = xr < xlo ? xlo : xr > xhi ? xhi : xr;
    p->yc = yr < ylo ? ylo : yr > yhi ? yhi : yr;
    double J[6] = {K->fx / tz, 0, -K->fx * p->xc / tz, 0, K->fy / tz, -K->fy * p->yc / tz};
    for (int r = 0; r < 2; r++)
        for (int c = 0; c < 3; c++)
            p->T[3 * r + c] = J[3 * r] * wr[c] + J[3 * r + 1] * wr[3 + c] + J[3 * r + 2] * wr[6 + c];
    /* Sigma2 = T Sigma T^T */
    const double *S = p->Sig;
    double Sf[9] = {S[0], S[1], S[2], S[1], S[3], S[4], S[2], S[4], S[5]};
    double TS[6];
    for (int r = 0; r < 2; r++)
        for (int c = 0; c < 3; c++)
            TS[3 * r + c] = p->T[3 * r] * Sf[c] + p->T[3 * r + 1] * Sf[3 + c] + p->T[3 * r + 2] * Sf[6 + c];
    p->a0 = TS[0] * p->T[0] + TS[1] * p->T[1] + TS[2] * p->T[2];
    p->b0 = TS[0] * p->T[3] + TS[1] * p->T[4] + TS[2] * p->T[5];
    p->c0 = TS[3] * p->T[3] + TS[4] * p->T[4] + TS[5] * p->T[5];
    const double eps = ws->s.eps2d;
    p->a = p->a0 + eps; p->b = p->b0; p->c = p->c0 + eps;
    p->det = p->a * p->c - p->b * p->b;
    if (!(p->det > 0)) return 0;
    p->comp = 1.0;
    if (ws->s.antialiased) {
        double det0 = p->a0 * p->c0 - p->b0 * p->b0;
        p->comp = det0 > 0 ? sqrt(det0 / p->det) : 0.0;
    }
    p->sig = 1.0 / (1.0 + exp(-(double)g->opacity_logits[i]));
    /* view direction for SH, from the camera centre */
    double d[3] = {m[0] - ws->campos[0], m[1] - ws->campos[1], m[2] - ws->campos[2]};
    p->dlen = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double il = p->dlen > 0 ? 1.0 / p->dlen : 0.0;
    for (int k = 0; k < 3; k++) p->dir[k] = d[k] * il;
    return 1;
}

PROJ_TARGETS
static void project_all(g3d_raster_ws *ws, const g3d_gaussians *g)
{
    const int64_t n = g->n;
    const int K = G3D_SH_COEFFS(g->sh_degree), nb = G3D_SH_COEFFS(ws->deg);
    const g3d_intrinsics *Kin = &ws->cam.K;
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; i++) {
        proj p;
        ws->radii[i] = 0;
        int32_t *rc = ws->rect + 4 * i;
        rc[0] = rc[1] = rc[2] = rc[3] = 0;
        if (!project_one(ws, g, i, &p)) continue;
        double mid = 0.5 * (p.a + p.c), disc = mid * mid - p.det;
        double lam = mid + sqrt(disc > 0.1 ? disc : 0.1);
        int r = (int)ceil(3.0 * sqrt(lam));
        double u = Kin->fx * p.t[0] / p.t[2] + Kin->cx, v = Kin->fy * p.t[1] / p.t[2] + Kin->cy;
        /* alpha = o exp(-d^T conic d / 2) >= 1/255 exactly inside the ellipse
         * d^T conic d <= 2 ln(255 o), whose box has half-sides sqrt(2 ln(255 o) Sigma'_xx) etc.
         * Tiles and pixels outside that box cannot contribute, so they are not visited; unlike
         * a fixed 3-sigma cut this changes no pixel value. */
        double o = p.sig * p.comp, lvl = 2.0 * log(255.0 * o);
        if (!(lvl > 0)) continue;
        double ex = sqrt(lvl * p.a) * 1.0001 + 1e-3, ey = sqrt(lvl * p.c) * 1.0001 + 1e-3;
        double x0 = floor((u - ex) / TILE), x1 = floor((u + ex) / TILE) + 1;
        double y0 = floor((v - ey) / TILE), y1 = floor((v + ey) / TILE) + 1;
        if (x0 < 0) x0 = 0;
        if (y0 < 0) y0 = 0;
        if (x1 > ws->gx) x1 = ws->gx;
        if (y1 > ws->gy) y1 = ws->gy;
        if (x1 <= x0 || y1 <= y0) continue;
        rc[0] = (int32_t)x0; rc[1] = (int32_t)y0; rc[2] = (int32_t)x1; rc[3] = (int32_t)y1;
        ws->radii[i] = r;
        float *q = ws->pk + PK * i;
        q[PK_MX] = (float)u;
        q[PK_MY] = (float)v;
        q[PK_A] = (float)(p.c / p.det);
        q[PK_B] = (float)(-p.b / p.det);
        q[PK_C] = (float)(p.a / p.det);
        q[PK_O] = (float)o;
        q[PK_Z] = (float)p.t[2];
        q[PK_EX] = (float)ex;
        q[PK_EY] = (float)ey;
        double basis[16];
        sh_basis(ws->deg, p.dir[0], p.dir[1], p.dir[2], basis, NULL, NULL, NULL);
        const float *sh = g->sh + (size_t)i * K * 3;
        for (int ch = 0; ch < 3; ch++) {
            double col = 0.5;
            for (int k = 0; k < nb; k++) col += basis[k] * sh[3 * k + ch];
            ws->clamped[3 * i + ch] = col < 0;
            q[PK_RGB + ch] = col < 0 ? 0.0f : (float)col;
        }
    }
}

/* ---- binning and sort ---------------------------------------------------------------------- */

/* One instance per (Gaussian, touched tile), grouped by tile and ordered inside a tile by
 * (view depth, Gaussian id): a total, deterministic order. The Gaussians are sorted once by a
 * stable radix sort of their depth bits (view depth > near > 0, so the IEEE bits order like the
 * floats; stability keeps ids ascending among equal depths), then dealt out to their tiles in
 * that order, so every tile list comes out sorted. */
static g3d_status bin_and_sort(g3d_raster_ws *ws, int64_t n)
{
    const int64_t ntiles = (int64_t)ws->gx * ws->gy;
    ws->offs[0] = 0;
    for (int64_t i = 0; i < n; i++) {
        const int32_t *rc = ws->rect + 4 * i;
        ws->offs[i + 1] = ws->offs[i] + (int64_t)(rc[2] - rc[0]) * (rc[3] - rc[1]);
    }
    const int64_t m = ws->offs[n];
    G3D_TRY(ensure_instances(ws, m > ntiles ? m : ntiles));   /* the cursors need ntiles slots */
    ws->n_inst = m;
    int64_t *start = ws->tile_start;
    memset(start, 0, sizeof(int64_t) * (size_t)(ntiles + 1));
    uint32_t *key = ws->skey, *key2 = ws->skey + n;
    int32_t *id = ws->sid, *id2 = ws->sid + n;
    int64_t nv = 0;
    for (int64_t i = 0; i < n; i++) {
        const int32_t *rc = ws->rect + 4 * i;
        if (ws->offs[i + 1] == ws->offs[i]) continue;
        for (int ty = rc[1]; ty < rc[3]; ty++)
            for (int tx = rc[0]; tx < rc[2]; tx++) start[(int64_t)ty * ws->gx + tx + 1]++;
        memcpy(&key[nv], &ws->pk[PK * i + PK_Z], 4);
        id[nv++] = (int32_t)i;
    }
    for (int64_t t = 0; t < ntiles; t++) start[t + 1] += start[t];
    for (int shift = 0; shift < 32 && nv > 0; shift += 8) {
        int64_t count[257] = {0};
        for (int64_t r = 0; r < nv; r++) count[((key[r] >> shift) & 255) + 1]++;
        if (count[((key[0] >> shift) & 255) + 1] == nv) continue;   /* one bucket: already in order */
        for (int b = 0; b < 256; b++) count[b + 1] += count[b];
        for (int64_t r = 0; r < nv; r++) {
            int64_t d = count[(key[r] >> shift) & 255]++;
            key2[d] = key[r];
            id2[d] = id[r];
        }
        uint32_t *tk = key; key = key2; key2 = tk;
        int32_t *ti = id; id = id2; id2 = ti;
    }
    int64_t *cur = ws->inst_tmp;
    memcpy(cur, start, sizeof(int64_t) * (size_t)ntiles);
    for (int64_t r = 0; r < nv; r++) {
        const int32_t gi = id[r];
        const int32_t *rc = ws->rect + 4 * gi;
        int64_t src = ws->offs[gi];
        for (int ty = rc[1]; ty < rc[3]; ty++)
            for (int tx = rc[0]; tx < rc[2]; tx++) {
                const int64_t k = cur[(int64_t)ty * ws->gx + tx]++;
                ws->inst_gid[k] = gi;
                ws->inst_src[k] = src++;
            }
    }
    return G3D_OK;
}

/* ---- blend --------------------------------------------------------------------------------- */

/* The blend works on tile rows as GCC vectors (raster_rows.inc): every lane does the same
 * operations as the scalar formula would, in the same order per pixel, so results do not depend
 * on the vector width; conditions become lane masks. The per-pixel state of a tile lives in
 * these structs, row-major, so a row loop can take any run of lanes of it. */
#define VINLINE static inline __attribute__((always_inline))

typedef struct fwd_tile {
    float T[TILE][TILE], C[4][TILE][TILE];   /* transmittance; rgb and depth accumulated */
    int32_t last[TILE][TILE], done[TILE][TILE];
} __attribute__((aligned(64))) fwd_tile;

typedef struct bwd_tile {
    /* transmittance now and final, colour+depth accumulated behind, the previous
     * (nearer-behind) contributor's alpha and colour, the output gradients */
    float T[TILE][TILE], Tf[TILE][TILE], acc[4][TILE][TILE], lastal[TILE][TILE], lastc[4][TILE][TILE];
    float dp[4][TILE][TILE], da[TILE][TILE];
    int32_t last[TILE][TILE];
} __attribute__((aligned(64))) bwd_tile;

/* Footprints at most HALF pixels wide take the half-row path. The widths are literal
 * numbers: the included file pastes them into its function names. */
#define HALF 8
_Static_assert(TILE == 2 * HALF, "the row loops are built for 16-pixel tiles");
#define LANES 16
#include "raster_rows.inc"
#undef LANES
#define LANES 8
#include "raster_rows.inc"
#undef LANES

/* The first lane of the half row that holds lanes lx0..lx1 (lx1 - lx0 < HALF). */
static inline int half_offset(int lx0) { return lx0 < TILE - HALF ? lx0 : TILE - HALF; }

/* Pixel box of Gaussian gi inside tile (tx, ty), tile-local inclusive bounds. Inlined into the
 * instruction-set builds of the blends: the baseline build has no rounding instruction and
 * calls libm for ceilf / floorf, which cost as much as a small Gaussian's rows. */
VINLINE void local_box(const g3d_raster_ws *ws, int32_t gi, int tx, int ty, int *x0, int *x1, int *y0, int *y1)
{
    const float *q = ws->pk + (size_t)PK * gi;
    const float mx = q[PK_MX] - (float)(tx * TILE), my = q[PK_MY] - (float)(ty * TILE);
    const float ex = q[PK_EX], ey = q[PK_EY];
    float fx0 = ceilf(mx - ex), fx1 = floorf(mx + ex), fy0 = ceilf(my - ey), fy1 = floorf(my + ey);
    *x0 = fx0 < 0 ? 0 : (int)fx0;
    *y0 = fy0 < 0 ? 0 : (int)fy0;
    *x1 = fx1 > TILE - 1 ? TILE - 1 : (int)fx1;
    *y1 = fy1 > TILE - 1 ? TILE - 1 : (int)fy1;
}

/* The tile lists visit the Gaussians' records in depth order, all over memory (64 bytes each,
 * megabytes at 50 k Gaussians): the blends ask for the record this many entries ahead. */
#define PREFETCH 8

/* Built for three instruction sets, picked at run time: 16-lane rows are one AVX-512 register,
 * two AVX2 registers, or four SSE2 registers. */
#define BLEND_TARGETS __attribute__((target_clones("avx512f", "avx2", "default")))

BLEND_TARGETS
static void blend_tile(g3d_raster_ws *ws, int64_t tile, float *rgb, float *alpha, float *depth)
{
    const int W = ws->W, H = ws->H;
    const int tx = (int)(tile % ws->gx), ty = (int)(tile / ws->gx), xt = tx * TILE, yt = ty * TILE;
    fwd_tile st;
    int active = 0;
    for (int ly = 0; ly < TILE; ly++)
        for (int i = 0; i < TILE; i++) {
            int out = !(xt + i < W && yt + ly < H);
            st.T[ly][i] = 1.0f;
            st.C[0][ly][i] = st.C[1][ly][i] = st.C[2][ly][i] = st.C[3][ly][i] = 0.0f;
            st.last[ly][i] = -1;
            st.done[ly][i] = -out;
            active += !out;
        }
    const int64_t a = ws->tile_start[tile], b = ws->tile_start[tile + 1];
    for (int64_t k = a; k < b && active > 0; k++) {
        const int32_t gi = ws->inst_gid[k];
        const float *q = ws->pk + (size_t)PK * gi;
        if (k + PREFETCH < b) __builtin_prefetch(ws->pk + (size_t)PK * ws->inst_gid[k + PREFETCH]);
        int lx0, lx1, ly0, ly1;
        local_box(ws, gi, tx, ty, &lx0, &lx1, &ly0, &ly1);
        if (lx0 > lx1) continue;
        if (lx1 - lx0 < HALF)
            active += fwd_rows_8(&st, q, xt, yt, half_offset(lx0), lx0, lx1, ly0, ly1, (int32_t)(k - a));
        else
            active += fwd_rows_16(&st, q, xt, yt, 0, lx0, lx1, ly0, ly1, (int32_t)(k - a));
    }
    const float *bg = ws->s.bg;
    for (int ly = 0; ly < TILE; ly++) {
        int y = yt + ly;
        if (y >= H) break;
        for (int i = 0; i < TILE; i++) {
            int x = xt + i;
            if (x >= W) break;
            size_t pix = (size_t)y * W + x;
            float t = st.T[ly][i];
            rgb[3 * pix] = st.C[0][ly][i] + t * bg[0];
            rgb[3 * pix + 1] = st.C[1][ly][i] + t * bg[1];
            rgb[3 * pix + 2] = st.C[2][ly][i] + t * bg[2];
            if (alpha) alpha[pix] = 1.0f - t;
            if (depth) depth[pix] = st.C[3][ly][i];
            ws->final_t[pix] = t;
            ws->last[pix] = st.last[ly][i];
        }
    }
}

g3d_status g3d_raster_fwd(g3d_raster_ws *ws, const g3d_gaussians *g, const g3d_camera *cam,
                          const g3d_raster_params *s, float *rgb, float *alpha, float *depth,
                          int32_t *radii)
{
    const int W = cam->K.width, H = cam->K.height;
    ws->valid = 0;
    if (W < 1 || H < 1 || W > G3D_MAX_IMAGE_SIDE || H > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "raster: image size %dx%d out of range 1..%d", W, H, G3D_MAX_IMAGE_SIDE);
    if (!rgb) return G3D_ERR(G3D_ERR_ARG, "raster: rgb output is required");
    if (g->n > INT32_MAX) return G3D_ERR(G3D_ERR_ARG, "raster: too many Gaussians (%lld)", (long long)g->n);
    if (!(cam->K.fx > 0 && cam->K.fy > 0))
        return G3D_ERR(G3D_ERR_ARG, "raster: focal lengths must be positive (fx %g, fy %g)", cam->K.fx, cam->K.fy);
    ws->W = W; ws->H = H;
    ws->gx = (W + TILE - 1) / TILE; ws->gy = (H + TILE - 1) / TILE;
    ws->n = g->n;
    ws->cam = *cam;
    ws->s = *s;
    ws->deg = (s->sh_degree_active < 0 || s->sh_degree_active > g->sh_degree) ? g->sh_degree : s->sh_degree_active;
    g3d_mat4 w2c = g3d_mat4_inverse_rigid(cam->c2w);
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++) ws->wr[3 * r + c] = w2c.m[r][c];
        ws->wt[r] = w2c.m[r][3];
        ws->campos[r] = cam->c2w.m[r][3];
    }
    int64_t ntiles = (int64_t)ws->gx * ws->gy;
    G3D_TRY(ensure_gaussians(ws, g->n));
    G3D_TRY(ensure_pixels(ws, (int64_t)W * H, ntiles));
    project_all(ws, g);
    G3D_TRY(bin_and_sort(ws, g->n));
#pragma omp parallel for schedule(dynamic, 1)
    for (int64_t t = 0; t < ntiles; t++) blend_tile(ws, t, rgb, alpha, depth);
    if (radii) memcpy(radii, ws->radii, sizeof(int32_t) * (size_t)g->n);
    ws->valid = 1;
    return G3D_OK;
}

/* ---- backward ------------------------------------------------------------------------------ */

/* Blend backward of one tile: walks each pixel's list back to front from its final T, and writes
 * one gradient record per instance of the tile (each instance belongs to exactly one tile, so
 * tiles never write the same record). A Gaussian's sums over its pixels are kept per lane and
 * added across lanes at the end, in a fixed order. */
BLEND_TARGETS
static void blend_tile_bwd(g3d_raster_ws *ws, int64_t tile, const float *d_rgb, const float *d_alpha,
                           const float *d_depth)
{
    const int W = ws->W, H = ws->H;
    const int tx = (int)(tile % ws->gx), ty = (int)(tile / ws->gx), xt = tx * TILE, yt = ty * TILE;
    bwd_tile st;
    int32_t maxlast = -1;
    for (int ly = 0; ly < TILE; ly++) {
        const int y = yt + ly;
        for (int i = 0; i < TILE; i++) {
            const int x = xt + i;
            for (int c = 0; c < 4; c++) st.acc[c][ly][i] = st.lastc[c][ly][i] = 0.0f;
            st.lastal[ly][i] = 0.0f;
            if (x < W && y < H) {
                size_t pix = (size_t)y * W + x;
                st.T[ly][i] = st.Tf[ly][i] = ws->final_t[pix];
                st.last[ly][i] = ws->last[pix];
                for (int c = 0; c < 3; c++) st.dp[c][ly][i] = d_rgb[3 * pix + c];
                st.dp[3][ly][i] = d_depth ? d_depth[pix] : 0.0f;
                st.da[ly][i] = d_alpha ? d_alpha[pix] : 0.0f;
            } else {
                st.T[ly][i] = st.Tf[ly][i] = 1.0f;
                st.last[ly][i] = -1;
                st.dp[0][ly][i] = st.dp[1][ly][i] = st.dp[2][ly][i] = st.dp[3][ly][i] = st.da[ly][i] = 0.0f;
            }
            if (st.last[ly][i] > maxlast) maxlast = st.last[ly][i];
        }
    }
    const float *bg = ws->s.bg;
    const int64_t a = ws->tile_start[tile], b = ws->tile_start[tile + 1];
    /* instances behind every pixel's last contributor are never visited: zero records */
    for (int64_t k = a + maxlast + 1; k < b; k++)
        memset(ws->rec + (size_t)ws->inst_src[k] * REC, 0, sizeof(float) * REC);
    for (int64_t k = a + maxlast; k >= a; k--) {
        const int32_t gi = ws->inst_gid[k];
        const float *q = ws->pk + (size_t)PK * gi;
        if (k - PREFETCH >= a) __builtin_prefetch(ws->pk + (size_t)PK * ws->inst_gid[k - PREFETCH]);
        int lx0, lx1, ly0, ly1;
        local_box(ws, gi, tx, ty, &lx0, &lx1, &ly0, &ly1);
        float *r = ws->rec + (size_t)ws->inst_src[k] * REC;
        if (lx0 > lx1 || ly0 > ly1) {
            for (int c = 0; c < REC; c++) r[c] = 0.0f;
            continue;
        }
        if (lx1 - lx0 < HALF)
            bwd_rows_8(&st, q, xt, yt, half_offset(lx0), lx0, lx1, ly0, ly1, (int32_t)(k - a), bg, r);
        else
            bwd_rows_16(&st, q, xt, yt, 0, lx0, lx1, ly0, ly1, (int32_t)(k - a), bg, r);
    }
}

/* Gradient of one Gaussian from its summed screen-space gradient `r` (REC floats). */
PROJ_INLINE void project_bwd(const g3d_raster_ws *ws, const g3d_gaussians *g, int64_t i, const double r[REC],
                        g3d_gaussians *gr, float *grad2d)
{
    proj p;
    if (!project_one(ws, g, i, &p)) return;
    const g3d_intrinsics *K = &ws->cam.K;
    const double *wr = ws->wr;
    const double tz = p.t[2];
    double dt[3] = {0, 0, 0}, dmean[3] = {0, 0, 0};

    /* 2D mean: u = fx tx / tz + cx */
    dt[0] += r[0] * K->fx / tz;
    dt[1] += r[1] * K->fy / tz;
    dt[2] += -(r[0] * K->fx * p.t[0] + r[1] * K->fy * p.t[1]) / (tz * tz);
    if (grad2d) {
        double gx = r[0] * 0.5 * ws->W, gy = r[1] * 0.5 * ws->H;
        grad2d[i] += (float)sqrt(gx * gx + gy * gy);
    }
    /* depth output */
    dt[2] += r[9];

    /* opacity: o = sigmoid(logit) * comp */
    double dop = r[5];
    gr->opacity_logits[i] += (float)(dop * p.comp * p.sig * (1.0 - p.sig));

    /* conic (A, B, C) = (c, -b, a) / det -> dilated covariance (a, b, c) */
    double A = p.c / p.det, B = -p.b / p.det, C = p.a / p.det;
    double gA = r[2], gB = 0.5 * r[3], gC = r[4];   /* symmetric matrix gradient of the conic */
    /* dSigma' = -Conic * G * Conic */
    double m00 = A * gA + B * gB, m01 = A * gB + B * gC, m10 = B * gA + C * gB, m11 = B * gB + C * gC;
    double ds_a = -(m00 * A + m01 * B), ds_b = -(m00 * B + m01 * C), ds_c = -(m10 * B + m11 * C);
    double da = ds_a, db = 2.0 * ds_b, dc = ds_c;  /* b appears twice in the symmetric matrix */
    if (ws->s.antialiased && p.comp > 0) {
        double det0 = p.a0 * p.c0 - p.b0 * p.b0;
        double dcomp = dop * p.sig, h = 0.5 * p.comp * dcomp;
        da += h * (p.c0 / det0 - p.c / p.det);
        dc += h * (p.a0 / det0 - p.a / p.det);
        db += h * (-2.0 * p.b0 / det0 + 2.0 * p.b / p.det);
    }
    /* Sigma2 = T Sigma T^T: dSigma = T^T G2 T, dT = 2 G2 T Sigma */
    double G2[4] = {da, 0.5 * db, 0.5 * db, dc};
    const double *T = p.T, *S = p.Sig;
    double Sf[9] = {S[0], S[1], S[2], S[1], S[3], S[4], S[2], S[4], S[5]};
    double GT[6];
    for (int rr = 0; rr < 2; rr++)
        for (int c = 0; c < 3; c++) GT[3 * rr + c] = G2[2 * rr] * T[c] + G2[2 * rr + 1] * T[3 + c];
    double dSig[9];
    for (int rr = 0; rr < 3; rr++)
        for (int c = 0; c < 3; c++) dSig[3 * rr + c] = T[rr] * GT[c] + T[3 + rr] * GT[3 + c];
    double dT[6];
    for (int rr = 0; rr < 2; rr++)
        for (int c = 0; c < 3; c++)
            dT[3 * rr + c] = 2.0 * (GT[3 * rr] * Sf[c] + GT[3 * rr + 1] * Sf[3 + c] + GT[3 * rr + 2] * Sf[6 + c]);
    /* T = J W: dJ = dT W^T */
    double dJ[6];
    for (int rr = 0; rr < 2; rr++)
        for (int c = 0; c < 3; c++)
            dJ[3 * rr + c] = dT[3 * rr] * wr[3 * c] + dT[3 * rr + 1] * wr[3 * c + 1] + dT[3 * rr + 2] * wr[3 * c + 2];
    /* J = [fx/tz, 0, -fx xc/tz; 0, fy/tz, -fy yc/tz], xc = clamp(tx/tz) */
    dt[2] += -K->fx / (tz * tz) * dJ[0] - K->fy / (tz * tz) * dJ[4];
    dt[2] += K->fx * p.xc / (tz * tz) * dJ[2] + K->fy * p.yc / (tz * tz) * dJ[5];
    double dxc = -K->fx / tz * dJ[2], dyc = -K->fy / tz * dJ[5];
    if (!p.xclamped) { dt[0] += dxc / tz; dt[2] -= dxc * p.t[0] / (tz * tz); }
    if (!p.yclamped) { dt[1] += dyc / tz; dt[2] -= dyc * p.t[1] / (tz * tz); }
    /* view mean t = Wr m + wt */
    for (int c = 0; c < 3; c++) dmean[c] += wr[c] * dt[0] + wr[3 + c] * dt[1] + wr[6 + c] * dt[2];

    /* Sigma = M M^T, M = R diag(s): dM = 2 dSigma M */
    double M[9], dM[9];
    for (int rr = 0; rr < 3; rr++)
        for (int k = 0; k < 3; k++) M[3 * rr + k] = p.R[3 * rr + k] * p.s[k];
    for (int rr = 0; rr < 3; rr++)
        for (int k = 0; k < 3; k++)
            dM[3 * rr + k] = 2.0 * (dSig[3 * rr] * M[k] + dSig[3 * rr + 1] * M[3 + k] + dSig[3 * rr + 2] * M[6 + k]);
    double dR[9];
    for (int k = 0; k < 3; k++) {
        double ds = dM[k] * p.R[k] + dM[3 + k] * p.R[3 + k] + dM[6 + k] * p.R[6 + k];
        gr->log_scales[3 * i + k] += (float)(ds * p.s[k]);
        for (int rr = 0; rr < 3; rr++) dR[3 * rr + k] = dM[3 * rr + k] * p.s[k];
    }
    const double w = p.qn[0], x = p.qn[1], y = p.qn[2], z = p.qn[3];
    double dq[4];
    dq[0] = 2 * (-z * dR[1] + y * dR[2] + z * dR[3] - x * dR[5] - y * dR[6] + x * dR[7]);
    dq[1] = 2 * (y * dR[1] + z * dR[2] + y * dR[3] - 2 * x * dR[4] - w * dR[5] + z * dR[6] + w * dR[7] - 2 * x * dR[8]);
    dq[2] = 2 * (-2 * y * dR[0] + x * dR[1] + w * dR[2] + x * dR[3] + z * dR[5] - w * dR[6] + z * dR[7] - 2 * y * dR[8]);
    dq[3] = 2 * (-2 * z * dR[0] - w * dR[1] + x * dR[2] + w * dR[3] - 2 * z * dR[4] + y * dR[5] + x * dR[6] + y * dR[7]);
    double qd = p.qn[0] * dq[0] + p.qn[1] * dq[1] + p.qn[2] * dq[2] + p.qn[3] * dq[3];
    for (int k = 0; k < 4; k++) gr->rots[4 * i + k] += (float)((dq[k] - p.qn[k] * qd) / p.qlen);

    /* SH colour and its view direction */
    const int K_all = G3D_SH_COEFFS(g->sh_degree), nb = G3D_SH_COEFFS(ws->deg);
    double b[16], bx[16], by[16], bz[16];
    sh_basis(ws->deg, p.dir[0], p.dir[1], p.dir[2], b, bx, by, bz);
    const float *sh = g->sh + (size_t)i * K_all * 3;
    float *dsh = gr->sh + (size_t)i * K_all * 3;
    double ddir[3] = {0, 0, 0};
    for (int ch = 0; ch < 3; ch++) {
        if (ws->clamped[3 * i + ch]) continue;
        double dcol = r[6 + ch];
        for (int k = 0; k < nb; k++) {
            dsh[3 * k + ch] += (float)(b[k] * dcol);
            ddir[0] += bx[k] * sh[3 * k + ch] * dcol;
            ddir[1] += by[k] * sh[3 * k + ch] * dcol;
            ddir[2] += bz[k] * sh[3 * k + ch] * dcol;
        }
    }
    if (p.dlen > 0) {
        double dd = p.dir[0] * ddir[0] + p.dir[1] * ddir[1] + p.dir[2] * ddir[2];
        for (int c = 0; c < 3; c++) dmean[c] += (ddir[c] - p.dir[c] * dd) / p.dlen;
    }
    for (int c = 0; c < 3; c++) gr->means[3 * i + c] += (float)dmean[c];
}

/* Sums each visible Gaussian's records and chains them through its projection. */
PROJ_TARGETS
static void gaussian_grads(const g3d_raster_ws *ws, const g3d_gaussians *g, g3d_gaussians *grads, float *grad2d)
{
    const int64_t n = g->n;
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; i++) {
        if (ws->radii[i] <= 0) continue;
        double r[REC] = {0};
        int any = 0;
        for (int64_t k = ws->offs[i]; k < ws->offs[i + 1]; k++)
            for (int c = 0; c < REC; c++) {
                r[c] += ws->rec[(size_t)k * REC + c];
                any |= ws->rec[(size_t)k * REC + c] != 0.0f;
            }
        /* hidden everywhere (behind saturated pixels, or outside every pixel's list): every
         * gradient term would be a zero */
        if (any) project_bwd(ws, g, i, r, grads, grad2d);
    }
}

g3d_status g3d_raster_bwd(g3d_raster_ws *ws, const g3d_gaussians *g, const float *d_rgb,
                          const float *d_alpha, const float *d_depth, g3d_gaussians *grads,
                          float *grad2d)
{
    if (!ws->valid) return G3D_ERR(G3D_ERR_ARG, "raster backward: no forward pass on this workspace");
    if (!d_rgb) return G3D_ERR(G3D_ERR_ARG, "raster backward: d_rgb is required");
    if (g->n != ws->n)
        return G3D_ERR(G3D_ERR_MISMATCH, "raster backward: model has %lld Gaussians, forward had %lld",
                       (long long)g->n, (long long)ws->n);
    if (grads->sh_degree != g->sh_degree || grads->capacity < g->n)
        return G3D_ERR(G3D_ERR_MISMATCH, "raster backward: gradient holder (capacity %lld, SH degree %d) "
                       "does not fit the model (%lld Gaussians, SH degree %d)", (long long)grads->capacity,
                       grads->sh_degree, (long long)g->n, g->sh_degree);
    const int64_t ntiles = (int64_t)ws->gx * ws->gy;
#pragma omp parallel for schedule(dynamic, 1)
    for (int64_t t = 0; t < ntiles; t++) blend_tile_bwd(ws, t, d_rgb, d_alpha, d_depth);
    gaussian_grads(ws, g, grads, grad2d);
    return G3D_OK;
}
