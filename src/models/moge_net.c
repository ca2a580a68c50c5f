/* MoGe-2's network: DINOv2 encoder, ConvStack neck and heads, scale MLP (the forward pass), and
 * the official infer(): metric depth and the camera from the point map (the focal/shift fit
 * itself is geometry: pointmap.h). */
#include "moge_int.h"

#include "gen3d/nn.h"
#include "gen3d/pointmap.h"
#include "gen3d/resize.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- forward ------------------------------------------------------------------------------ */

static float *alloc_f(size_t n) { return malloc(sizeof(float) * (n ? n : 1)); }

#define NOMEM() G3D_ERR(G3D_ERR_NOMEM, "MoGe: out of memory")

/* Work buffers reused through one forward pass: the full-resolution levels need tens of MB
 * per temporary, and fresh allocations of that size are new pages (faults, zeroing) every time. */
enum { SC_A, SC_B, SC_T, SC_COUNT };
typedef struct scratch {
    float *buf[SC_COUNT];
    size_t cap[SC_COUNT];
} scratch;

static float *scratch_get(scratch *sc, int slot, size_t n)
{
    if (sc->cap[slot] < n) {
        free(sc->buf[slot]);
        sc->buf[slot] = alloc_f(n);
        sc->cap[slot] = sc->buf[slot] ? n : 0;
    }
    return sc->buf[slot];
}

static void scratch_free(scratch *sc)
{
    for (int i = 0; i < SC_COUNT; i++) free(sc->buf[i]);
}

/* y = conv(x) (3x3 with replicate padding, or 1x1), then the epilogue; y must not alias x. */
static g3d_status conv_fwd(const conv *c, const float *x, int h, int w, float *y, const g3d_nn_epi *epi)
{
    return g3d_nn_conv_forward(&c->nc, x, h, w, y, epi);
}

/* x += conv(relu(conv(relu(x)))): the inner ReLU and the sum ride in the convolutions' epilogues */
static g3d_status res_block(const conv *c1, const conv *c2, float *x, int h, int w, scratch *sc)
{
    size_t plane = (size_t)h * w;
    float *a = scratch_get(sc, SC_A, (size_t)c1->cin * plane), *b = scratch_get(sc, SC_B, (size_t)c1->cout * plane);
    if (!a || !b) return NOMEM();
    memcpy(a, x, sizeof(float) * c1->cin * plane);
    g3d_nn_relu(a, (size_t)c1->cin * plane);
    const g3d_nn_epi relu = {.act = G3D_ACT_RELU}, sum = {.res = x};
    G3D_TRY(conv_fwd(c1, a, h, w, b, &relu));
    return conv_fwd(c2, b, h, w, x, &sum);
}

/* x [dim[l], h, w] -> *y [dim[l+1], 2h, 2w] (new buffer). */
static g3d_status resample(const stack *s, int l, const float *x, int h, int w, float **y, scratch *sc)
{
    int c = s->dim[l];
    size_t n2 = (size_t)4 * h * w;
    float *t = scratch_get(sc, SC_T, (size_t)(s->rs[l] == RS_CONV_TRANSPOSE ? s->dim[l + 1] : c) * n2);
    *y = alloc_f((size_t)s->dim[l + 1] * n2);
    g3d_status rc = t && *y ? G3D_OK : NOMEM();
    if (rc == G3D_OK) {
        if (s->rs[l] == RS_CONV_TRANSPOSE) {
            rc = conv_fwd(&s->up[l], x, h, w, t, NULL);
        } else if (s->rs[l] == RS_BILINEAR) {
            rc = g3d_nn_resize_bilinear(x, c, h, w, t, 2 * h, 2 * w, 0);
        } else {
            for (int ch = 0; ch < c; ch++)
                for (int r = 0; r < 2 * h; r++)
                    for (int q = 0; q < 2 * w; q++)
                        t[((size_t)ch * 2 * h + r) * 2 * w + q] = x[((size_t)ch * h + r / 2) * w + q / 2];
        }
    }
    if (rc == G3D_OK) rc = conv_fwd(&s->upconv[l], t, 2 * h, 2 * w, *y, NULL);
    if (rc != G3D_OK) {
        free(*y);
        *y = NULL;
    }
    return rc;
}

/* Runs a ConvStack. in[l] is level l's input ([fed channels, rows << l, cols << l]) or NULL.
 * Level outputs go to outs[l] (new buffers) for every level when `all`, else only the last. */
static g3d_status stack_forward(const stack *s, float *const *in, int rows, int cols, int all, float **outs, scratch *sc)
{
    float *x = NULL;
    g3d_status rc = G3D_OK;
    for (int l = 0; l < s->nlev; l++) outs[l] = NULL;
    for (int l = 0; l < s->nlev && rc == G3D_OK; l++) {
        int h = rows << l, w = cols << l;
        size_t plane = (size_t)h * w, n = (size_t)s->dim[l] * plane;
        if (in[l] && x) {
            /* x += input block (in[l]): the sum rides in the 1x1 convolution's epilogue */
            const g3d_nn_epi sum = {.res = x};
            if (s->din[l] > 0) rc = conv_fwd(&s->in[l], in[l], h, w, x, &sum);
            else g3d_nn_add(x, in[l], n);
        } else if (in[l]) {
            if (!(x = alloc_f(n))) rc = NOMEM();
            else if (s->din[l] > 0) rc = conv_fwd(&s->in[l], in[l], h, w, x, NULL);
            else memcpy(x, in[l], sizeof(float) * n);
        } else if (!x) {
            rc = G3D_ERR(G3D_ERR_INTERNAL, "MoGe: ConvStack level %d has no input", l);
        }
        for (int j = 0; j < s->nres[l] && rc == G3D_OK; j++) rc = res_block(&s->res[l][2 * j], &s->res[l][2 * j + 1], x, h, w, sc);
        if (rc == G3D_OK && (all || l == s->nlev - 1)) {
            int oc = stack_out_ch(s, l);
            if (!(outs[l] = alloc_f((size_t)oc * plane))) rc = NOMEM();
            else if (s->dout[l] > 0) rc = conv_fwd(&s->out[l], x, h, w, outs[l], NULL);
            else memcpy(outs[l], x, sizeof(float) * n);
        }
        if (rc == G3D_OK && l + 1 < s->nlev) {
            float *y;
            rc = resample(s, l, x, h, w, &y, sc);
            free(x);
            x = rc == G3D_OK ? y : NULL;
        }
    }
    free(x);
    if (rc != G3D_OK)
        for (int l = 0; l < s->nlev; l++) {
            free(outs[l]);
            outs[l] = NULL;
        }
    return rc;
}
/* The view-plane UV grid [2, h, w] of the official normalized_view_plane_uv (pointmap.h). */
static g3d_status view_plane_uv(int w, int h, double aspect, float *uv)
{
    float *u = alloc_f((size_t)w), *v = alloc_f((size_t)h);
    if (!u || !v) {
        free(u);
        free(v);
        return NOMEM();
    }
    g3d_view_plane_uv(w, h, aspect, u, v);
    size_t plane = (size_t)w * h;
    for (int r = 0; r < h; r++)
        for (int q = 0; q < w; q++) {
            uv[(size_t)r * w + q] = u[q];
            uv[plane + (size_t)r * w + q] = v[r];
        }
    free(u);
    free(v);
    return G3D_OK;
}

void g3d_moge_trace_free(g3d_moge_trace *t)
{
    if (!t) return;
    free(t->image14);
    free(t->features);
    free(t->cls);
    t->image14 = t->features = t->cls = NULL;
    for (int i = 0; i < 5; i++) {
        free(t->neck[i]);
        t->neck[i] = NULL;
    }
}

void g3d_moge_output_free(g3d_moge_output *o)
{
    if (!o) return;
    free(o->points);
    free(o->mask);
    free(o->normal);
    memset(o, 0, sizeof *o);
}

static float *dup_f(const float *x, size_t n)
{
    float *y = alloc_f(n);
    if (y) memcpy(y, x, sizeof(float) * n);
    return y;
}

/* Encoder: resize + normalise, backbone, summed projections [dim_out, rows*cols] and the
 * class token of the last intermediate layer [D]. */
static g3d_status encode(const g3d_moge *m, const float *rgb, int w, int h, int rows, int cols, float *feat, float *cls,
                         g3d_moge_trace *trace)
{
    int H = rows * PATCH, W = cols * PATCH, np = rows * cols, D = m->D;
    size_t plane = (size_t)W * H;
    float *rs = alloc_f(3 * plane), *x = alloc_f(3 * plane), *tok = alloc_f((size_t)np * D), *p = alloc_f((size_t)m->dim_out * np);
    float *feats[MAX_LAYERS] = {0}, *clss[MAX_LAYERS] = {0};
    g3d_status rc = rs && x && tok && p ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "MoGe: out of memory at %dx%d", W, H);
    if (rc == G3D_OK) rc = g3d_resize_buffer(rgb, w, h, 3, rs, W, H, G3D_RESIZE_BILINEAR_AA);
    if (rc == G3D_OK) {
        for (size_t i = 0; i < plane; i++)
            for (int c = 0; c < 3; c++) x[c * plane + i] = (rs[i * 3 + c] - m->mean[c]) / m->std[c];
        if (trace && !(trace->image14 = dup_f(x, 3 * plane))) rc = NOMEM();
    }
    if (rc == G3D_OK) rc = g3d_dinov2_forward(m->backbone, x, H, W, m->layers, m->nlayers, feats, clss, NULL);
    for (int i = 0; i < m->nlayers && rc == G3D_OK; i++) {
        for (int t = 0; t < np; t++)
            for (int c = 0; c < D; c++) tok[(size_t)c * np + t] = feats[i][(size_t)t * D + c];
        rc = conv_fwd(&m->proj[i], tok, rows, cols, i ? p : feat, NULL);
        if (rc == G3D_OK && i) g3d_nn_add(feat, p, (size_t)m->dim_out * np);
    }
    if (rc == G3D_OK) memcpy(cls, clss[m->nlayers - 1], sizeof(float) * D);
    for (int i = 0; i < m->nlayers; i++) {
        free(feats[i]);
        free(clss[i]);
    }
    free(rs);
    free(x);
    free(tok);
    free(p);
    return rc;
}

/* levels: the number of neck levels; the finest runs at 2^(levels-1) times the token grid. */
static g3d_status token_grid(int w, int h, int num_tokens, int levels, int *rows, int *cols)
{
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_ARG, "MoGe: image size %dx%d is outside 1..%d", w, h, G3D_MAX_IMAGE_SIDE);
    double a = (double)w / h;
    /* Python's round(): half to even, as nearbyint in the default rounding mode */
    double r = nearbyint(sqrt(num_tokens / a)), c = nearbyint(sqrt(num_tokens * a));
    int up = 1 << (levels - 1), f = up > PATCH ? up : PATCH;
    if (r < 1 || c < 1 || r * f > G3D_MAX_IMAGE_SIDE || c * f > G3D_MAX_IMAGE_SIDE || num_tokens > G3D_MOGE_MAX_TOKENS)
        return G3D_ERR(G3D_ERR_ARG, "MoGe: %d tokens on a %dx%d image give a %.0fx%.0f token grid (each side must be "
                       "1..%d, at most %d tokens)", num_tokens, w, h, c, r, G3D_MAX_IMAGE_SIDE / f, G3D_MOGE_MAX_TOKENS);
    *rows = (int)r;
    *cols = (int)c;
    return G3D_OK;
}

g3d_status g3d_moge_forward(const g3d_moge *m, const float *rgb, int w, int h, int num_tokens, g3d_moge_output *out,
                            g3d_moge_trace *trace)
{
    memset(out, 0, sizeof *out);
    if (trace && !trace->want) trace = NULL;
    if (trace) {
        memset(trace, 0, sizeof *trace);
        trace->want = 1;
    }
    if (num_tokens <= 0) num_tokens = m->tokens_max;
    int rows = 0, cols = 0;
    G3D_TRY(token_grid(w, h, num_tokens, m->neck.nlev, &rows, &cols));
    int nlev = m->neck.nlev, np = rows * cols;
    double aspect = (double)w / h;
    float *level_in[MAX_LEVELS] = {0}, *neck_out[MAX_LEVELS] = {0}, *head_out[NHEADS][MAX_LEVELS] = {{0}};
    float *cls = alloc_f((size_t)m->D);
    float *feat = NULL;
    g3d_status rc = cls ? G3D_OK : NOMEM();
    /* level 0 input: [features; uv], level l > 0: uv at (rows << l, cols << l) */
    for (int l = 0; l < nlev && rc == G3D_OK; l++) {
        size_t plane = ((size_t)rows << l) * ((size_t)cols << l);
        int c0 = l ? 0 : m->dim_out;
        if (!(level_in[l] = alloc_f((size_t)(c0 + 2) * plane))) rc = NOMEM();
        else rc = view_plane_uv(cols << l, rows << l, aspect, level_in[l] + (size_t)c0 * plane);
    }
    if (rc == G3D_OK) {
        if (trace) {
            trace->rows = rows;
            trace->cols = cols;
        }
        feat = level_in[0];
        rc = encode(m, rgb, w, h, rows, cols, feat, cls, trace);
    }
    if (rc == G3D_OK && trace) {
        trace->features_c = m->dim_out;
        if (!(trace->features = dup_f(feat, (size_t)m->dim_out * np)) || !(trace->cls = dup_f(cls, (size_t)m->D)))
            rc = NOMEM();
    }
    scratch sc;
    memset(&sc, 0, sizeof sc);
    if (rc == G3D_OK) rc = stack_forward(&m->neck, level_in, rows, cols, 1, neck_out, &sc);
    for (int hd = 0; hd < NHEADS && rc == G3D_OK; hd++)
        if (m->has_head[hd]) rc = stack_forward(&m->head[hd], neck_out, rows, cols, 0, head_out[hd], &sc);
    scratch_free(&sc);

    /* Heads -> image size (bilinear, no antialiasing), channels last, output remaps. */
    int lh = rows << (nlev - 1), lw = cols << (nlev - 1);
    size_t npx = (size_t)w * h;
    float *planes = NULL;
    if (rc == G3D_OK && !(planes = alloc_f(3 * npx))) rc = NOMEM();
    float **dst[NHEADS] = {&out->points, &out->normal, &out->mask};
    for (int hd = 0; hd < NHEADS && rc == G3D_OK; hd++) {
        if (!m->has_head[hd]) continue;
        int c = HEAD_CH[hd];
        rc = g3d_nn_resize_bilinear(head_out[hd][nlev - 1], c, lh, lw, planes, h, w, 0);
        if (rc == G3D_OK && !(*dst[hd] = alloc_f((size_t)c * npx))) rc = NOMEM();
        if (rc != G3D_OK) break;
        float *o = *dst[hd];
        for (size_t i = 0; i < npx; i++)
            for (int k = 0; k < c; k++) o[i * c + k] = planes[k * npx + i];
    }
    if (rc == G3D_OK) {
        float *p = out->points;
        for (size_t i = 0; i < npx; i++) {
            float *q = p + 3 * i;
            switch (m->remap) {
            case REMAP_LINEAR: break;
            case REMAP_SINH: for (int k = 0; k < 3; k++) q[k] = sinhf(q[k]); break;
            case REMAP_EXP: q[2] = expf(q[2]); q[0] *= q[2]; q[1] *= q[2]; break;
            case REMAP_SINH_EXP: q[0] = sinhf(q[0]); q[1] = sinhf(q[1]); q[2] = expf(q[2]); break;
            }
        }
        if (out->normal)
            for (size_t i = 0; i < npx; i++) {
                float *q = out->normal + 3 * i;
                /* F.normalize: divide by max(|n|, 1e-12) */
                float len = sqrtf(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
                len = len > 1e-12f ? len : 1e-12f;
                for (int k = 0; k < 3; k++) q[k] /= len;
            }
        if (out->mask)
            for (size_t i = 0; i < npx; i++) out->mask[i] = 1.0f / (1.0f + expf(-out->mask[i]));
        if (m->nmlp) {
            float *a = cls, *b = NULL;
            for (int i = 0; i < m->nmlp && rc == G3D_OK; i++) {
                if (!(b = alloc_f((size_t)m->mlp_dims[i + 1]))) {
                    rc = NOMEM();
                    break;
                }
                g3d_nn_linear(a, 1, m->mlp_dims[i], m->mlp_w[i], m->mlp_b[i], m->mlp_dims[i + 1], b);
                if (i + 1 < m->nmlp) g3d_nn_relu(b, (size_t)m->mlp_dims[i + 1]);
                if (a != cls) free(a);
                a = b;
            }
            if (rc == G3D_OK) out->metric_scale = expf(a[0]);
            if (a != cls) free(a);
        }
        out->w = w;
        out->h = h;
    }
    if (rc == G3D_OK && trace)
        for (int l = 0; l < nlev && l < 5; l++) {
            trace->neck[l] = neck_out[l];
            trace->neck_c[l] = stack_out_ch(&m->neck, l);
            neck_out[l] = NULL;
        }
    for (int l = 0; l < MAX_LEVELS; l++) {
        free(level_in[l]);
        free(neck_out[l]);
        for (int hd = 0; hd < NHEADS; hd++) free(head_out[hd][l]);
    }
    free(planes);
    free(cls);
    if (rc != G3D_OK) {
        g3d_moge_output_free(out);
        g3d_moge_trace_free(trace);
    }
    return rc;
}
void g3d_moge_result_free(g3d_moge_result *r)
{
    if (!r) return;
    free(r->points);
    free(r->depth);
    free(r->mask);
    free(r->normal);
    memset(r, 0, sizeof *r);
}

g3d_status g3d_moge_infer(const g3d_moge *m, const float *rgb, int w, int h, int num_tokens, double fov_x_deg,
                          g3d_moge_result *out)
{
    memset(out, 0, sizeof *out);
    if (!(fov_x_deg < 180)) return G3D_ERR(G3D_ERR_ARG, "MoGe: horizontal field of view %g is not below 180 degrees", fov_x_deg);
    g3d_moge_output o;
    G3D_TRY(g3d_moge_forward(m, rgb, w, h, num_tokens, &o, NULL));
    size_t npx = (size_t)w * h;
    double a = (double)w / h, diag = sqrt(1 + a * a);
    g3d_status rc = G3D_OK;
    out->w = w;
    out->h = h;
    out->mask = malloc(npx);
    out->depth = alloc_f(npx);
    if (!out->mask || !out->depth) rc = NOMEM();
    if (rc == G3D_OK) {
        for (size_t i = 0; i < npx; i++) out->mask[i] = o.mask ? o.mask[i] > 0.5f : 1;
        /* the official code holds a given focal in float32 */
        double focal_in = fov_x_deg > 0 ? (double)(float)(a / diag / tan(fov_x_deg * M_PI / 360.0)) : 0;
        rc = g3d_pointmap_focal_shift(o.points, o.mask ? out->mask : NULL, w, h, focal_in, &out->focal, &out->shift);
    }
    if (rc == G3D_OK) {
        float fx = (float)(out->focal / 2.0 * diag / a), fy = (float)(out->focal / 2.0 * diag);
        float K[9] = {fx, 0, 0.5f, 0, fy, 0.5f, 0, 0, 1};
        memcpy(out->intrinsics, K, sizeof K);
        float s = o.metric_scale > 0 ? o.metric_scale : 1.0f;
        out->metric_scale = s;
        float *u = NULL, *v = NULL;
        if (!(u = alloc_f((size_t)w)) || !(v = alloc_f((size_t)h))) rc = NOMEM();
        if (rc == G3D_OK) {
            /* pixel centres of the unit image, then x = (u - cx) / fx * z (force_projection) */
            g3d_linspace_f(0.5f / w, 1.0f - 0.5f / w, w, u);
            g3d_linspace_f(0.5f / h, 1.0f - 0.5f / h, h, v);
            float *pts = o.points;
            for (int r = 0; r < h; r++)
                for (int q = 0; q < w; q++) {
                    size_t i = (size_t)r * w + q;
                    float z = pts[3 * i + 2] + out->shift;
                    if (!(z > 0)) out->mask[i] = 0;
                    float d = z * s;
                    if (out->mask[i]) {
                        out->depth[i] = d;
                        pts[3 * i] = (u[q] - 0.5f) / fx * d;
                        pts[3 * i + 1] = (v[r] - 0.5f) / fy * d;
                        pts[3 * i + 2] = d;
                    } else {
                        out->depth[i] = INFINITY;
                        pts[3 * i] = pts[3 * i + 1] = pts[3 * i + 2] = INFINITY;
                        if (o.normal) o.normal[3 * i] = o.normal[3 * i + 1] = o.normal[3 * i + 2] = 0;
                    }
                }
            out->points = o.points;
            out->normal = o.normal;
            o.points = o.normal = NULL;
        }
        free(u);
        free(v);
    }
    g3d_moge_output_free(&o);
    if (rc != G3D_OK) g3d_moge_result_free(out);
    return rc;
}

g3d_intrinsics g3d_moge_intrinsics_pixels(const g3d_moge_result *r)
{
    return g3d_intrinsics_make((double)r->intrinsics[0] * r->w, (double)r->intrinsics[4] * r->h,
                               (double)r->intrinsics[2] * r->w - 0.5, (double)r->intrinsics[5] * r->h - 0.5, r->w, r->h);
}
