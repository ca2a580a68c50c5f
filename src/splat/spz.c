/* spz.c - .spz version 2 writer and reader (gzip via zlib). */
#include "gen3d/spz.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#define SPZ_MAGIC 0x5053474eu
#define SPZ_FRAC_BITS 12
#define SPZ_COLOR_SCALE 0.15f
#define SPZ_MAX_FILE ((size_t)1 << 31)

/* SH coefficients (k >= 1) whose basis function is odd in y or z: they flip with RDF <-> RUB. */
static int sh_flips(int k)
{
    return k == 1 || k == 2 || k == 4 || k == 7 || k == 9 || k == 11 || k == 12 || k == 14;
}

static uint8_t to_u8(float x)
{
    float r = roundf(x);
    return (uint8_t)(r < 0 ? 0 : r > 255 ? 255 : r);
}

static uint8_t quantize_sh(float v, int bucket)
{
    float q = roundf(v * 128.0f + 128.0f);
    q = floorf((q + bucket / 2) / bucket) * bucket;
    return (uint8_t)(q < 0 ? 0 : q > 255 ? 255 : q);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static size_t payload_size(size_t n, int deg)
{
    return 16 + n * (9 + 1 + 3 + 3 + 3 + 3 * (size_t)(G3D_SH_COEFFS(deg) - 1));
}

g3d_status g3d_spz_encode(const g3d_gaussians *g, const char *label, uint8_t **data, size_t *size)
{
    *data = NULL;
    *size = 0;
    const size_t n = (size_t)g->n;
    const int K = G3D_SH_COEFFS(g->sh_degree);
    if (g->n > 0xffffffffLL) return G3D_ERR(G3D_ERR_ARG, "%s: too many Gaussians for .spz", label);
    const double lim = (double)(1 << 23) / (1 << SPZ_FRAC_BITS);
    for (size_t i = 0; i < n * 3; i++)
        if (!(fabs(g->means[i]) < lim))
            return G3D_ERR(G3D_ERR_ARG, "%s: Gaussian %zu lies beyond the .spz range of +-%g m",
                           label, i / 3, lim);
    size_t raw_n = payload_size(n, g->sh_degree);
    uint8_t *raw = g3d_calloc(raw_n, 1, ".spz buffer");
    if (!raw) return G3D_ERR_NOMEM;
    put_u32(raw, SPZ_MAGIC);
    put_u32(raw + 4, 2);
    put_u32(raw + 8, (uint32_t)n);
    raw[12] = (uint8_t)g->sh_degree;
    raw[13] = SPZ_FRAC_BITS;
    uint8_t *pos = raw + 16, *alpha = pos + 9 * n, *col = alpha + n, *scl = col + 3 * n,
            *rot = scl + 3 * n, *sh = rot + 3 * n;
    for (size_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            float v = g->means[i * 3 + a] * (a == 0 ? 1.0f : -1.0f);
            int32_t f = (int32_t)lround((double)v * (1 << SPZ_FRAC_BITS));
            for (int b = 0; b < 3; b++) pos[i * 9 + a * 3 + b] = (uint8_t)((uint32_t)f >> (8 * b));
            scl[i * 3 + a] = to_u8((g->log_scales[i * 3 + a] + 10.0f) * 16.0f);
            col[i * 3 + a] = to_u8(g->sh[i * K * 3 + a] * (SPZ_COLOR_SCALE * 255.0f) + 127.5f);
        }
        alpha[i] = to_u8(255.0f / (1.0f + expf(-g->opacity_logits[i])));
        const float *q = g->rots + i * 4;
        float len = sqrtf(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        float s = (len > 0 ? 1.0f / len : 0.0f) * (q[0] < 0 ? -1.0f : 1.0f);
        rot[i * 3 + 0] = to_u8(q[1] * s * 127.5f + 127.5f);
        rot[i * 3 + 1] = to_u8(-q[2] * s * 127.5f + 127.5f);
        rot[i * 3 + 2] = to_u8(-q[3] * s * 127.5f + 127.5f);
        for (int k = 1; k < K; k++)
            for (int c = 0; c < 3; c++) {
                float v = g->sh[(i * K + k) * 3 + c] * (sh_flips(k) ? -1.0f : 1.0f);
                *sh++ = quantize_sh(v, k < 4 ? 8 : 16);
            }
    }

    /* gzip into memory (windowBits 15 + 16 selects the gzip wrapper) */
    z_stream zs;
    memset(&zs, 0, sizeof zs);
    if (deflateInit2(&zs, 9, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
        free(raw);
        return G3D_ERR(G3D_ERR_NOMEM, "%s: zlib initialisation failed", label);
    }
    uLong cap = deflateBound(&zs, (uLong)raw_n);
    uint8_t *out = g3d_calloc(cap, 1, ".spz buffer");
    g3d_status rc = G3D_OK;
    if (!out) {
        rc = G3D_ERR_NOMEM;
    } else {
        zs.next_in = raw;
        zs.avail_in = (uInt)raw_n;
        zs.next_out = out;
        zs.avail_out = (uInt)cap;
        if (deflate(&zs, Z_FINISH) != Z_STREAM_END) {
            rc = G3D_ERR(G3D_ERR_INTERNAL, "%s: gzip compression failed", label);
        } else {
            *data = out;
            *size = zs.total_out;
            out = NULL;
        }
    }
    deflateEnd(&zs);
    free(out);
    free(raw);
    return rc;
}

g3d_status g3d_spz_save(const char *path, const g3d_gaussians *g)
{
    uint8_t *data;
    size_t n;
    G3D_TRY(g3d_spz_encode(g, path, &data, &n));
    g3d_status rc = g3d_write_file_atomic(path, data, n);
    free(data);
    return rc;
}

g3d_status g3d_spz_load(const char *path, g3d_gaussians *g)
{
    memset(g, 0, sizeof *g);
    unsigned char *file = NULL;
    size_t file_n = 0;
    G3D_TRY(g3d_read_file(path, SPZ_MAX_FILE, &file, &file_n));
    z_stream zs;
    memset(&zs, 0, sizeof zs);
    if (inflateInit2(&zs, 15 + 16) != Z_OK) {
        free(file);
        return G3D_ERR(G3D_ERR_NOMEM, "%s: zlib initialisation failed", path);
    }
    size_t cap = 1 << 16, len = 0;
    uint8_t *raw = malloc(cap);
    g3d_status rc = G3D_OK;
    zs.next_in = file;
    zs.avail_in = (uInt)file_n;
    int zr = Z_OK;
    while (raw && zr == Z_OK) {
        if (len == cap) {
            if (cap >= SPZ_MAX_FILE) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: decompressed data too large", path); break; }
            uint8_t *bigger = realloc(raw, cap * 2);
            if (!bigger) break;
            raw = bigger;
            cap *= 2;
        }
        zs.next_out = raw + len;
        zs.avail_out = (uInt)(cap - len);
        zr = inflate(&zs, Z_NO_FLUSH);
        len = cap - zs.avail_out;
        if (zr == Z_BUF_ERROR && zs.avail_in > 0) zr = Z_OK;
    }
    inflateEnd(&zs);
    free(file);
    if (rc == G3D_OK && !raw) rc = G3D_ERR(G3D_ERR_NOMEM, "%s: out of memory", path);
    if (rc == G3D_OK && zr != Z_STREAM_END)
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a valid gzip stream (truncated or corrupt)", path);
    if (rc == G3D_OK && len < 16) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: truncated .spz header", path);
    if (rc == G3D_OK && get_u32(raw) != SPZ_MAGIC)
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not an .spz file (bad magic)", path);
    if (rc == G3D_OK && get_u32(raw + 4) != 2)
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: .spz version %u (only version 2 is read)", path,
                     get_u32(raw + 4));
    if (rc == G3D_OK && raw[12] > G3D_SH_MAX_DEGREE)
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: SH degree %d (at most %d)", path, raw[12], G3D_SH_MAX_DEGREE);
    if (rc == G3D_OK && raw[13] > 23)
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %d fractional bits in a 24-bit position", path, raw[13]);
    size_t n = rc == G3D_OK ? get_u32(raw + 8) : 0;
    if (rc == G3D_OK && payload_size(n, raw[12]) != len)
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: %zu bytes of data for %zu Gaussians of SH degree %d (expected %zu)",
                     path, len, n, raw[12], payload_size(n, raw[12]));
    if (rc == G3D_OK) rc = g3d_gaussians_create(g, (int64_t)n, raw[12]);
    if (rc != G3D_OK) {
        free(raw);
        return rc;
    }
    g->n = (int64_t)n;
    const int K = G3D_SH_COEFFS(g->sh_degree);
    const float pscale = 1.0f / (float)(1 << raw[13]);
    const uint8_t *pos = raw + 16, *alpha = pos + 9 * n, *col = alpha + n, *scl = col + 3 * n,
                  *rot = scl + 3 * n, *sh = rot + 3 * n;
    for (size_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            const uint8_t *b = pos + i * 9 + a * 3;
            int32_t f = (int32_t)((uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16);
            if (f & 0x800000) f -= 0x1000000;
            g->means[i * 3 + a] = (float)f * pscale * (a == 0 ? 1.0f : -1.0f);
            g->log_scales[i * 3 + a] = scl[i * 3 + a] / 16.0f - 10.0f;
            g->sh[i * K * 3 + a] = (col[i * 3 + a] / 255.0f - 0.5f) / SPZ_COLOR_SCALE;
        }
        /* alphas 0 and 255 would be infinite logits: keep them half a step inside */
        float op = alpha[i] / 255.0f;
        if (op < 0.5f / 255.0f) op = 0.5f / 255.0f;
        if (op > 254.5f / 255.0f) op = 254.5f / 255.0f;
        g->opacity_logits[i] = logf(op / (1.0f - op));
        float x = rot[i * 3] / 127.5f - 1.0f, y = -(rot[i * 3 + 1] / 127.5f - 1.0f),
              z = -(rot[i * 3 + 2] / 127.5f - 1.0f);
        float w2 = 1.0f - (x * x + y * y + z * z);
        g->rots[i * 4 + 0] = w2 > 0 ? sqrtf(w2) : 0.0f;
        g->rots[i * 4 + 1] = x;
        g->rots[i * 4 + 2] = y;
        g->rots[i * 4 + 3] = z;
        for (int k = 1; k < K; k++)
            for (int c = 0; c < 3; c++)
                g->sh[(i * K + k) * 3 + c] = (*sh++ - 128.0f) / 128.0f * (sh_flips(k) ? -1.0f : 1.0f);
    }
    free(raw);
    return G3D_OK;
}
