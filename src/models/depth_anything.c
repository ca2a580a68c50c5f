/* Depth Anything V2: DINOv2 features through the DPT head (reassemble, RefineNet fusion). */
#include "gen3d/depth_anything.h"

#include "gen3d/nn.h"
#include "gen3d/resize.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PATCH 14

/* A convolution of the head: its float32 weights (owned) described for the layer library, with
 * the 3x3 ones (Winograd) and the transposed ones (phase kernels) prepared at load. */
typedef struct conv {
    float *w, *b;   /* b may be NULL */
    g3d_nn_conv c;
} conv;

typedef struct fusion {
    conv rcu1a, rcu1b, rcu2a, rcu2b, out;
} fusion;

struct g3d_dav2 {
    g3d_dinov2 *backbone;
    int dim, feat, oc[4], layers[4], hidden2;   /* hidden2: output_conv2's width (32 published) */
    conv project[4], resize[4], rn[4], out1, out2a, out2b;
    fusion refine[4];
    float max_depth;   /* > 0: a metric model, output = max_depth * sigmoid(head) in metres */
};

/* Loads NAME.weight [cout, cin, k, k] (and NAME.bias) as a Conv2d with padding k / 2, or with
 * transposed set as a ConvTranspose2d of stride k (its weight [cin, cout, k, k]; square in the
 * head, so the same shape check fits). */
static g3d_status load_conv(const g3d_ckpt *ck, const char *name, int cout, int cin, int k, int stride, int transposed,
                            int bias, conv *c)
{
    char buf[256];
    const int64_t ws[] = {cout, cin, k, k}, bs[] = {cout};
    snprintf(buf, sizeof buf, "%s.weight", name);
    G3D_TRY(g3d_ckpt_read_alloc(ck, buf, 4, ws, &c->w));
    if (bias) {
        snprintf(buf, sizeof buf, "%s.bias", name);
        G3D_TRY(g3d_ckpt_read_alloc(ck, buf, 1, bs, &c->b));
    }
    c->c = g3d_nn_conv_make(cin, cout, k, stride, transposed ? 0 : k / 2, c->w, c->b);
    c->c.transposed = transposed;
    return g3d_nn_conv_prepare(&c->c);
}

static void free_conv(conv *c)
{
    g3d_nn_conv_release(&c->c);
    free(c->w);
    free(c->b);
}

void g3d_dav2_free(g3d_dav2 *m)
{
    if (!m) return;
    g3d_dinov2_free(m->backbone);
    for (int i = 0; i < 4; i++) {
        free_conv(&m->project[i]);
        free_conv(&m->resize[i]);
        free_conv(&m->rn[i]);
        fusion *f = &m->refine[i];
        free_conv(&f->rcu1a); free_conv(&f->rcu1b); free_conv(&f->rcu2a); free_conv(&f->rcu2b); free_conv(&f->out);
    }
    free_conv(&m->out1);
    free_conv(&m->out2a);
    free_conv(&m->out2b);
    free(m);
}

static g3d_status load_head(const g3d_ckpt *ck, g3d_dav2 *m)
{
    char name[128];
    int D = m->dim, F = m->feat;
    for (int i = 0; i < 4; i++) {
        snprintf(name, sizeof name, "depth_head.projects.%d", i);
        G3D_TRY(load_conv(ck, name, m->oc[i], D, 1, 1, 0, 1, &m->project[i]));
    }
    G3D_TRY(load_conv(ck, "depth_head.resize_layers.0", m->oc[0], m->oc[0], 4, 4, 1, 1, &m->resize[0]));
    G3D_TRY(load_conv(ck, "depth_head.resize_layers.1", m->oc[1], m->oc[1], 2, 2, 1, 1, &m->resize[1]));
    G3D_TRY(load_conv(ck, "depth_head.resize_layers.3", m->oc[3], m->oc[3], 3, 2, 0, 1, &m->resize[3]));
    for (int i = 0; i < 4; i++) {
        snprintf(name, sizeof name, "depth_head.scratch.layer%d_rn", i + 1);
        G3D_TRY(load_conv(ck, name, F, m->oc[i], 3, 1, 0, 0, &m->rn[i]));
        static const char *parts[] = {"resConfUnit1.conv1", "resConfUnit1.conv2", "resConfUnit2.conv1",
                                      "resConfUnit2.conv2", "out_conv"};
        fusion *f = &m->refine[i];
        conv *dst[] = {&f->rcu1a, &f->rcu1b, &f->rcu2a, &f->rcu2b, &f->out};
        /* refinenet4 has no skip input, so its first residual unit is never used. */
        for (int j = i == 3 ? 2 : 0; j < 5; j++) {
            snprintf(name, sizeof name, "depth_head.scratch.refinenet%d.%s", i + 1, parts[j]);
            G3D_TRY(load_conv(ck, name, F, F, j == 4 ? 1 : 3, 1, 0, 1, dst[j]));
        }
    }
    G3D_TRY(load_conv(ck, "depth_head.scratch.output_conv1", F / 2, F, 3, 1, 0, 1, &m->out1));
    G3D_TRY(load_conv(ck, "depth_head.scratch.output_conv2.0", m->hidden2, F / 2, 3, 1, 0, 1, &m->out2a));
    return load_conv(ck, "depth_head.scratch.output_conv2.2", 1, m->hidden2, 1, 1, 0, 1, &m->out2b);
}

g3d_status g3d_dav2_load(const g3d_ckpt *ck, g3d_dav2 **out)
{
    *out = NULL;
    const g3d_tensor_info *rn = g3d_ckpt_find(ck, "depth_head.scratch.layer1_rn.weight");
    if (!rn || rn->ndim != 4)
        return G3D_ERR(G3D_ERR_MODEL, "%s: not a Depth Anything V2 checkpoint: tensor "
                       "depth_head.scratch.layer1_rn.weight %s", g3d_ckpt_path(ck), rn ? "is not 4-D" : "is missing");
    /* Variants of the head that no published checkpoint uses: the class-token readout
     * (use_clstoken) and batch norm in the fusion blocks (use_bn). */
    static const char *const variants[] = {"depth_head.readout_projects.0.0.weight",
                                           "depth_head.scratch.refinenet1.resConfUnit1.bn1.weight"};
    for (int i = 0; i < 2; i++)
        if (g3d_ckpt_find(ck, variants[i]))
            return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: tensor %s: this Depth Anything V2 head variant (%s) is not supported",
                           g3d_ckpt_path(ck), variants[i], i ? "use_bn" : "use_clstoken");
    const g3d_tensor_info *o2 = g3d_ckpt_find(ck, "depth_head.scratch.output_conv2.0.weight");
    if (!o2 || o2->ndim != 4)
        return G3D_ERR(G3D_ERR_MODEL, "%s: tensor depth_head.scratch.output_conv2.0.weight %s", g3d_ckpt_path(ck),
                       o2 ? "is not 4-D" : "is missing");
    g3d_dav2 *m = calloc(1, sizeof *m);
    if (!m) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_status rc = g3d_dinov2_load(ck, "pretrained.", &m->backbone);
    if (rc == G3D_OK && g3d_dinov2_patch(m->backbone) != PATCH)
        rc = G3D_ERR(G3D_ERR_MODEL, "%s: tensor pretrained.patch_embed.proj.weight has %d-pixel patches; the Depth "
                     "Anything V2 head works on %d-pixel patches", g3d_ckpt_path(ck), g3d_dinov2_patch(m->backbone), PATCH);
    if (rc == G3D_OK) {
        m->dim = g3d_dinov2_width(m->backbone);
        m->feat = (int)rn->shape[0];
        m->hidden2 = (int)o2->shape[0];
        /* The blocks feeding the head. The official lists (ViT-S and B [2, 5, 8, 11], ViT-L
         * [4, 11, 17, 23], ViT-g [9, 19, 29, 39]) take the last block of each quarter of the
         * encoder, except ViT-L's first, which is block 4; every other depth follows the rule. */
        int depth = g3d_dinov2_depth(m->backbone);
        if (depth < 4)
            rc = G3D_ERR(G3D_ERR_MODEL, "%s: the backbone has %d blocks (pretrained.blocks.*); the head needs 4",
                         g3d_ckpt_path(ck), depth);
        for (int i = 0; i < 4; i++) m->layers[i] = depth * (i + 1) / 4 - 1;
        if (depth == 24) m->layers[0] = 4;
        for (int i = 0; i < 4 && rc == G3D_OK; i++) {
            char name[64];
            snprintf(name, sizeof name, "depth_head.projects.%d.weight", i);
            const g3d_tensor_info *t = g3d_ckpt_find(ck, name);
            if (!t || t->ndim != 4) rc = G3D_ERR(G3D_ERR_MODEL, "%s: tensor %s is missing or not 4-D", g3d_ckpt_path(ck), name);
            else m->oc[i] = (int)t->shape[0];
        }
    }
    if (rc == G3D_OK) rc = load_head(ck, m);
    if (rc != G3D_OK) {
        g3d_dav2_free(m);
        return rc;
    }
    *out = m;
    return G3D_OK;
}

void g3d_dav2_set_metric(g3d_dav2 *m, float max_depth)
{
    m->max_depth = max_depth > 0 ? max_depth : 0;
}

float g3d_dav2_max_depth(const g3d_dav2 *m)
{
    return m->max_depth;
}

float g3d_dav2_metric_default(const char *path)
{
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    if (strstr(base, "metric_hypersim") || strstr(base, "Metric-Hypersim")) return 20.0f;
    if (strstr(base, "metric_vkitti") || strstr(base, "Metric-VKITTI")) return 80.0f;
    return 0.0f;
}

g3d_status g3d_dav2_load_file(const char *path, g3d_dav2 **out)
{
    g3d_ckpt *ck;
    *out = NULL;
    G3D_TRY(g3d_ckpt_open(path, &ck));
    g3d_status rc = g3d_dav2_load(ck, out);
    g3d_ckpt_free(ck);
    return rc;
}

void g3d_dav2_trace_free(g3d_dav2_trace *t)
{
    if (!t) return;
    free(t->input);
    t->input = NULL;
    g3d_dinov2_trace_free(&t->backbone);
    for (int i = 0; i < 4; i++) {
        free(t->feature[i]);
        free(t->path[i]);
        t->feature[i] = t->path[i] = NULL;
    }
    free(t->depth);
    t->depth = NULL;
}

/* numpy's round (half to even) for the multiple-of-14 rule. */
static int constrain14(double x, int min_val)
{
    int y = (int)(nearbyint(x / PATCH) * PATCH);
    if (y < min_val) y = (int)(ceil(x / PATCH) * PATCH);
    return y;
}

g3d_status g3d_dav2_net_size(int w, int h, int input_size, int *net_w, int *net_h)
{
    if (w <= 0 || h <= 0 || w > 32768 || h > 32768)
        return G3D_ERR(G3D_ERR_ARG, "image size %dx%d is outside 1..32768", w, h);
    if (input_size < PATCH || input_size > 32768)
        return G3D_ERR(G3D_ERR_ARG, "input size %d is outside %d..32768", input_size, PATCH);
    double sh = (double)input_size / h, sw = (double)input_size / w;
    double s = sw > sh ? sw : sh;
    *net_w = constrain14(s * w, input_size);
    *net_h = constrain14(s * h, input_size);
    if (*net_w > 32768 || *net_h > 32768)
        return G3D_ERR(G3D_ERR_ARG, "image %dx%d at input size %d needs a %dx%d network input (over 32768)", w, h,
                       input_size, *net_w, *net_h);
    return G3D_OK;
}

/* Bilinear align_corners=True resize of c planes [c, sh, sw] -> [c, dh, dw]. */
static g3d_status resize_planes(const float *src, int c, int sh, int sw, float *dst, int dh, int dw)
{
    return g3d_nn_resize_bilinear(src, c, sh, sw, dst, dh, dw, 1);
}

static float *alloc_f(size_t n) { return malloc(sizeof(float) * (n ? n : 1)); }

static g3d_status run_conv(const conv *c, const float *x, int h, int w, float *y, const g3d_nn_epi *epi)
{
    return g3d_nn_conv_forward(&c->c, x, h, w, y, epi);
}

/* res + conv2(relu(conv1(relu(x)))) into y (res may be y itself); tmp holds 2 * F*h*w floats. */
static g3d_status residual_unit(const conv *c1, const conv *c2, const float *x, const float *res, int h, int w,
                                float *tmp, float *y)
{
    size_t n = (size_t)c1->c.cin * h * w;
    float *a = tmp, *b = tmp + n;
    memcpy(a, x, sizeof(float) * n);
    g3d_nn_relu(a, n);
    const g3d_nn_epi relu = {.act = G3D_ACT_RELU}, add = {.res = res};
    G3D_TRY(run_conv(c1, a, h, w, b, &relu));
    return run_conv(c2, b, h, w, y, &add);
}

/* One RefineNet block: (path + rcu1(skip)) -> rcu2 -> bilinear to (oh, ow) -> 1x1 out_conv.
 * skip may be NULL. Returns a new [F, oh, ow] buffer in *out. The 1x1 convolution runs before
 * the resize: both are linear, the resize's weights sum to one (so the bias commutes too), and
 * at the input's size it has a quarter of the pixels. */
static g3d_status fuse(const fusion *f, const float *path, const float *skip, int h, int w, int oh, int ow,
                       float **out)
{
    int F = f->out.c.cin;
    size_t n = (size_t)F * h * w;
    float *tmp = alloc_f(2 * n), *acc = alloc_f(n), *r = alloc_f(n), *res = alloc_f((size_t)F * oh * ow);
    g3d_status rc = tmp && acc && r && res ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    if (rc == G3D_OK) {
        /* acc = path + (skip + rcu1's product), the second sum in the product's epilogue */
        memcpy(acc, path, sizeof(float) * n);
        if (skip) {
            g3d_nn_add(acc, skip, n);
            rc = residual_unit(&f->rcu1a, &f->rcu1b, skip, acc, h, w, tmp, acc);
        }
    }
    if (rc == G3D_OK) rc = residual_unit(&f->rcu2a, &f->rcu2b, acc, acc, h, w, tmp, r);
    if (rc == G3D_OK) rc = run_conv(&f->out, r, h, w, acc, NULL);
    if (rc == G3D_OK) rc = resize_planes(acc, F, h, w, res, oh, ow);
    free(tmp); free(acc); free(r);
    if (rc != G3D_OK) {
        free(res);
        res = NULL;
    }
    *out = res;
    return rc;
}

/* DPT head: features [4][h*w, D] -> depth [14h, 14w] (after the final ReLU). */
static g3d_status head(const g3d_dav2 *m, float *const *feats, int h, int w, float *depth, g3d_dav2_trace *trace)
{
    int D = m->dim, F = m->feat, np = h * w;
    int lh[4] = {4 * h, 2 * h, h, (h + 1) / 2}, lw[4] = {4 * w, 2 * w, w, (w + 1) / 2};
    float *rn[4] = {0}, *path[4] = {0};
    float *tok = alloc_f((size_t)np * D), *proj = NULL, *rs = NULL, *o1 = NULL, *o1up = NULL, *o2 = NULL;
    g3d_status rc = tok ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    for (int i = 0; i < 4 && rc == G3D_OK; i++) {
        /* tokens [h*w, D] -> map [D, h, w] */
        for (int t = 0; t < np; t++)
            for (int c = 0; c < D; c++) tok[(size_t)c * np + t] = feats[i][(size_t)t * D + c];
        int oc = m->oc[i];
        proj = alloc_f((size_t)oc * np);
        rs = alloc_f((size_t)oc * lh[i] * lw[i]);
        rn[i] = alloc_f((size_t)F * lh[i] * lw[i]);
        if (!proj || !rs || !rn[i]) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        if (rc == G3D_OK) rc = run_conv(&m->project[i], tok, h, w, proj, NULL);
        if (rc == G3D_OK) {
            if (i == 2) memcpy(rs, proj, sizeof(float) * (size_t)oc * np);
            else rc = run_conv(&m->resize[i], proj, h, w, rs, NULL);
        }
        if (rc == G3D_OK) rc = run_conv(&m->rn[i], rs, lh[i], lw[i], rn[i], NULL);
        free(proj);
        free(rs);
        proj = rs = NULL;
    }
    /* refinenet4 (layer4 -> layer3 size) ... refinenet1 (-> twice layer1's size) */
    if (rc == G3D_OK) rc = fuse(&m->refine[3], rn[3], NULL, lh[3], lw[3], lh[2], lw[2], &path[3]);
    for (int i = 2; i >= 0 && rc == G3D_OK; i--) {
        int oh = i ? lh[i - 1] : 2 * lh[0], ow = i ? lw[i - 1] : 2 * lw[0];
        rc = fuse(&m->refine[i], path[i + 1], rn[i], lh[i], lw[i], oh, ow, &path[i]);
    }
    int ph = 8 * h, pw = 8 * w, H = PATCH * h, W = PATCH * w;
    if (rc == G3D_OK) {
        o1 = alloc_f((size_t)(F / 2) * ph * pw);
        o1up = alloc_f((size_t)(F / 2) * H * W);
        o2 = alloc_f((size_t)m->hidden2 * H * W);
        if (!o1 || !o1up || !o2) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    const g3d_nn_epi relu = {.act = G3D_ACT_RELU};
    if (rc == G3D_OK) rc = run_conv(&m->out1, path[0], ph, pw, o1, NULL);
    if (rc == G3D_OK) rc = resize_planes(o1, F / 2, ph, pw, o1up, H, W);
    if (rc == G3D_OK) rc = run_conv(&m->out2a, o1up, H, W, o2, &relu);
    if (rc == G3D_OK) rc = run_conv(&m->out2b, o2, H, W, depth, m->max_depth > 0 ? NULL : &relu);
    if (rc == G3D_OK && m->max_depth > 0)
        for (size_t i = 0; i < (size_t)H * W; i++) depth[i] = m->max_depth / (1.0f + expf(-depth[i]));
    if (rc == G3D_OK && trace && trace->want) {
        int hs[4] = {ph, 4 * h, 2 * h, h}, ws[4] = {pw, 4 * w, 2 * w, w};
        for (int i = 0; i < 4; i++) {
            trace->path[i] = path[i];
            trace->path_h[i] = hs[i];
            trace->path_w[i] = ws[i];
            path[i] = NULL;
        }
    }
    for (int i = 0; i < 4; i++) {
        free(rn[i]);
        free(path[i]);
    }
    free(tok); free(proj); free(rs); free(o1); free(o1up); free(o2);
    return rc;
}

g3d_status g3d_dav2_predict(const g3d_dav2 *m, const float *rgb, int w, int h, int input_size, float *depth,
                            g3d_dav2_trace *trace)
{
    int W, H;
    G3D_TRY(g3d_dav2_net_size(w, h, input_size, &W, &H));
    static const float mean[3] = {0.485f, 0.456f, 0.406f}, stdv[3] = {0.229f, 0.224f, 0.225f};
    size_t plane = (size_t)W * H;
    float *rs = alloc_f(3 * plane), *x = alloc_f(3 * plane), *net = alloc_f(plane);
    float *feats[4] = {0};
    g3d_status rc = rs && x && net ? G3D_OK : G3D_ERR(G3D_ERR_NOMEM, "Depth Anything: out of memory at %dx%d", W, H);
    if (rc == G3D_OK) rc = g3d_resize_buffer(rgb, w, h, 3, rs, W, H, G3D_RESIZE_CUBIC_OPENCV);
    if (rc == G3D_OK) {
        for (size_t i = 0; i < plane; i++)
            for (int c = 0; c < 3; c++) x[c * plane + i] = (float)(((double)rs[i * 3 + c] - mean[c]) / stdv[c]);
        if (trace && trace->want) {
            memset(trace->feature, 0, sizeof trace->feature);
            memset(trace->path, 0, sizeof trace->path);
            trace->net_w = W;
            trace->net_h = H;
            trace->backbone.want = 1;
            trace->depth = NULL;
            trace->input = alloc_f(3 * plane);
            if (!trace->input) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
            else memcpy(trace->input, x, sizeof(float) * 3 * plane);
        }
    }
    if (rc == G3D_OK)
        rc = g3d_dinov2_forward(m->backbone, x, H, W, m->layers, 4, feats, NULL, trace && trace->want ? &trace->backbone : NULL);
    if (rc == G3D_OK) rc = head(m, feats, H / PATCH, W / PATCH, net, trace);
    if (rc == G3D_OK) rc = resize_planes(net, 1, H, W, depth, h, w);
    if (rc == G3D_OK && trace && trace->want) {
        memcpy(trace->feature, feats, sizeof feats);
        memset(feats, 0, sizeof feats);
        trace->depth = net;
        net = NULL;
    }
    for (int i = 0; i < 4; i++) free(feats[i]);
    free(rs); free(x); free(net);
    if (rc != G3D_OK && trace) g3d_dav2_trace_free(trace);
    return rc;
}
