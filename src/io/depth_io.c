/* Depth maps: 16-bit PNG, PFM, NPY/NPZ readers and writers; disparity conversion. */
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/npy.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

double g3d_depth_sanitize(g3d_image *depth)
{
    size_t n = g3d_image_size(depth), valid = 0;
    for (size_t i = 0; i < n; i++) {
        float v = depth->data[i];
        if (!(v > 0) || !isfinite(v)) depth->data[i] = 0;
        else valid++;
    }
    return n ? (double)valid / (double)n : 0.0;
}

void g3d_disparity_to_depth(g3d_image *disp, double f, double baseline, double doffs)
{
    size_t n = g3d_image_size(disp);
    for (size_t i = 0; i < n; i++) {
        double d = disp->data[i] + doffs;
        disp->data[i] = isfinite(d) && d > 0 ? (float)(baseline * f / d) : 0.0f;
    }
}

g3d_status g3d_pfm_load(const char *path, g3d_image *img)
{
    unsigned char *buf;
    size_t n;
    memset(img, 0, sizeof *img);
    G3D_TRY(g3d_read_file(path, (size_t)1 << 34, &buf, &n));
    /* Header: four whitespace-separated tokens ("Pf"/"PF", width, height, scale), then
     * exactly one whitespace byte before the raster. */
    char tok[4][64];
    size_t p = 0;
    for (int t = 0; t < 4; t++) {
        int k = 0;
        while (p < n && (buf[p] == ' ' || buf[p] == '\n' || buf[p] == '\r' || buf[p] == '\t')) p++;
        while (p < n && k < 63 && buf[p] > ' ') tok[t][k++] = (char)buf[p++];
        tok[t][k] = 0;
    }
    p++;
    int channels = !strcmp(tok[0], "Pf") ? 1 : !strcmp(tok[0], "PF") ? 3 : 0;
    char *ew, *eh, *es;
    long w = strtol(tok[1], &ew, 10), h = strtol(tok[2], &eh, 10);
    double scale = strtod(tok[3], &es);
    if (!channels || !tok[1][0] || *ew || !tok[2][0] || *eh || !tok[3][0] || *es || scale == 0 || !isfinite(scale)) {
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: not a PFM file (bad header)", path);
    }
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE) {
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: PFM size %ldx%ld out of range (sides 1..%d)", path, w, h, G3D_MAX_IMAGE_SIDE);
    }
    size_t count = (size_t)w * (size_t)h * (size_t)channels;
    if (p > n || (n - p) / 4 < count) {
        free(buf);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: truncated PFM data (%zu of %zu bytes)", path, p > n ? 0 : n - p, count * 4);
    }
    g3d_status rc = g3d_image_create(img, (int)w, (int)h, channels);
    if (rc != G3D_OK) { free(buf); return rc; }
    int big = scale > 0;
    size_t row = (size_t)w * (size_t)channels;
    for (long y = 0; y < h; y++) {
        const unsigned char *src = buf + p + (size_t)(h - 1 - y) * row * 4; /* bottom-to-top */
        for (size_t i = 0; i < row; i++) {
            unsigned char b[4];
            for (int k = 0; k < 4; k++) b[k] = big ? src[4 * i + 3 - k] : src[4 * i + k];
            memcpy(&img->data[(size_t)y * row + i], b, 4);
        }
    }
    free(buf);
    return G3D_OK;
}

static g3d_status pfm_save(const char *path, const g3d_image *img)
{
    g3d_atomic_file af;
    if (img->c != 1 && img->c != 3) return G3D_ERR(G3D_ERR_ARG, "%s: PFM needs 1 or 3 channels", path);
    G3D_TRY(g3d_atomic_open(&af, path));
    fprintf(af.fp, "%s\n%d %d\n-1\n", img->c == 1 ? "Pf" : "PF", img->w, img->h);
    size_t row = (size_t)img->w * (size_t)img->c;
    for (int y = img->h - 1; y >= 0; y--) fwrite(img->data + (size_t)y * row, sizeof(float), row, af.fp);
    return g3d_atomic_commit(&af);
}

/* Integer arrays hold scaled units (e.g. millimetres); float arrays hold metres. */
static g3d_status array_to_depth(const char *path, g3d_array *a, double scale, int is_int, g3d_image *depth)
{
    int64_t h, w;
    if (a->ndim == 2 || (a->ndim == 3 && a->shape[2] == 1)) { h = a->shape[0]; w = a->shape[1]; }
    else if (a->ndim == 3 && a->shape[0] == 1) { h = a->shape[1]; w = a->shape[2]; }
    else return G3D_ERR(G3D_ERR_FORMAT, "%s: depth array must have shape (H, W), got rank %d", path, a->ndim);
    if (w < 1 || h < 1 || w > G3D_MAX_IMAGE_SIDE || h > G3D_MAX_IMAGE_SIDE)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: depth array size %lldx%lld out of range", path, (long long)w, (long long)h);
    G3D_TRY(g3d_image_create(depth, (int)w, (int)h, 1));
    for (size_t i = 0; i < (size_t)(w * h); i++) depth->data[i] = is_int ? (float)(a->data[i] / scale) : a->data[i];
    return G3D_OK;
}

g3d_status g3d_depth_load_raw(const char *path, double scale, g3d_image *depth)
{
    char ext[16];
    g3d_status rc;
    memset(depth, 0, sizeof *depth);
    if (scale <= 0) scale = 1000.0;
    g3d_path_ext(path, ext, sizeof ext);
    if (!strcmp(ext, "png")) {
        G3D_TRY(g3d_image_load_u16(path, depth));
        size_t n = g3d_image_size(depth);
        for (size_t i = 0; i < n; i++) depth->data[i] = (float)(depth->data[i] / scale);
    } else if (!strcmp(ext, "pfm")) {
        G3D_TRY(g3d_pfm_load(path, depth));
        if (depth->c != 1) {
            g3d_image_free(depth);
            return G3D_ERR(G3D_ERR_FORMAT, "%s: depth PFM must have one channel ('Pf'), not three", path);
        }
    } else if (!strcmp(ext, "npy") || !strcmp(ext, "npz")) {
        g3d_array a;
        G3D_TRY(!strcmp(ext, "npy") ? g3d_npy_load(path, &a) : g3d_npz_load(path, NULL, &a));
        rc = array_to_depth(path, &a, scale, a.integer, depth);
        g3d_array_free(&a);
        if (rc != G3D_OK) return rc;
    } else {
        return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: unknown depth format '.%s' (use .png, .pfm, .npy or .npz)", path, ext);
    }
    return G3D_OK;
}

g3d_status g3d_depth_load(const char *path, double scale, g3d_image *depth)
{
    G3D_TRY(g3d_depth_load_raw(path, scale, depth));
    g3d_depth_sanitize(depth);
    return G3D_OK;
}

g3d_status g3d_depth_save(const char *path, const g3d_image *depth)
{
    char ext[16];
    g3d_path_ext(path, ext, sizeof ext);
    if (depth->c != 1) return G3D_ERR(G3D_ERR_ARG, "%s: depth must have one channel", path);
    if (!strcmp(ext, "png")) {
        g3d_image mm;
        G3D_TRY(g3d_image_clone(&mm, depth));
        for (size_t i = 0; i < g3d_image_size(&mm); i++) mm.data[i] *= 1000.0f;
        g3d_status rc = g3d_image_save_png_u16(path, &mm);
        g3d_image_free(&mm);
        return rc;
    }
    if (!strcmp(ext, "pfm")) return pfm_save(path, depth);
    if (!strcmp(ext, "npy")) {
        int64_t shape[2] = {depth->h, depth->w};
        return g3d_npy_save(path, depth->data, 2, shape);
    }
    return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: unknown depth format '.%s' (use .png, .pfm or .npy)", path, ext);
}
