/* golden.h - helpers for the tests that check a model against the activations its official
 * code computed (tests/fixtures/<model>_golden.safetensors, and the larger sets in ../shared/golden),
 * and for the tests that feed a loader a checkpoint edited to be wrong.
 *
 *   golden_compare(act, "out.depth", got, n)   relative L2 error of got against a recorded tensor
 *   golden_edit_pickle(file, n, from, to)      a PyTorch zip with `from` replaced in data.pkl
 *   golden_edit_safetensors(file, n, name)     a safetensors file with tensor `name` renamed
 */
#ifndef G3D_GOLDEN_H
#define G3D_GOLDEN_H

#include "testutil.h"

#include "gen3d/ckpt.h"

#include <stdint.h>

#define GOLDEN_TOL 1e-4   /* relative L2 error a float32 implementation must reach */

/* Compares got [n floats] with the recorded tensor `name` (any dtype): the relative L2 error
 * over the entries finite in the reference, which must be at most GOLDEN_TOL, and no entry may
 * be finite in only one of the two. Prints the error; returns it (-1 when nothing compared). */
static inline double golden_compare(const g3d_ckpt *act, const char *name, const float *got, size_t n)
{
    const g3d_tensor_info *t = g3d_ckpt_find(act, name);
    CHECK_MSG(t && (size_t)t->numel == n, "%s: missing or %lld elements, expected %zu", name,
              t ? (long long)t->numel : -1LL, n);
    CHECK_MSG(got != NULL, "%s: no output", name);
    if (!t || (size_t)t->numel != n || !got) return -1;
    float *ref = NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, name, 0, NULL, &ref));
    if (!ref) return -1;
    double num = 0, den = 0;
    size_t bad = 0;
    for (size_t i = 0; i < n; i++) {
        if (isfinite(ref[i]) != isfinite(got[i])) bad++;
        if (!isfinite(ref[i]) || !isfinite(got[i])) continue;
        double d = (double)got[i] - ref[i];
        num += d * d;
        den += (double)ref[i] * ref[i];
    }
    double e = den > 0 ? sqrt(num / den) : sqrt(num);
    printf("  %-22s rel L2 %.3e\n", name, e);
    CHECK_MSG(e <= GOLDEN_TOL, "%s: relative L2 error %.3e > %g", name, e, GOLDEN_TOL);
    CHECK_MSG(bad == 0, "%s: %zu entries finite in only one of the two", name, bad);
    free(ref);
    return e;
}

/* The recorded tensor `name` as float32 (malloc'd) and its element count in *n (n may be NULL);
 * NULL, after a failed check, when it is missing. */
static inline float *golden_floats(const g3d_ckpt *act, const char *name, size_t *n)
{
    const g3d_tensor_info *t = g3d_ckpt_find(act, name);
    float *x = NULL;
    CHECK_MSG(t != NULL, "%s missing", name);
    if (!t) return NULL;
    CHECK_OK(g3d_ckpt_read_alloc(act, name, 0, NULL, &x));
    if (n) *n = (size_t)t->numel;
    return x;
}

/* A recorded U8 picture `name` [h, w, 3] as RGB floats in [0, 1] (malloc'd) and its size;
 * NULL, after a failed check, when it is missing or not [h, w, 3]. */
static inline float *golden_image(const g3d_ckpt *act, const char *name, int *w, int *h)
{
    const g3d_tensor_info *img = act ? g3d_ckpt_find(act, name) : NULL;
    CHECK_MSG(img && img->ndim == 3 && img->shape[2] == 3, "%s: missing or not [h, w, 3]", name);
    if (!img || img->ndim != 3 || img->shape[2] != 3) return NULL;
    *h = (int)img->shape[0];
    *w = (int)img->shape[1];
    size_t n = (size_t)*w * *h * 3;
    float *rgb = malloc(sizeof(float) * n);
    if (!rgb) return NULL;
    CHECK_OK(g3d_ckpt_read(act, name, 0, NULL, rgb));
    for (size_t i = 0; i < n; i++) rgb[i] /= 255.0f;
    return rgb;
}

/* CRC-32 (zip's polynomial), to keep an edited zip entry valid. */
static inline uint32_t golden_crc32(const unsigned char *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++) c = c & 1 ? (c >> 1) ^ 0xEDB88320u : c >> 1;
    }
    return ~c;
}

static inline uint32_t golden_rd32(const unsigned char *p) { return p[0] | p[1] << 8 | p[2] << 16 | (uint32_t)p[3] << 24; }
static inline void golden_wr32(unsigned char *p, uint32_t v) { p[0] = v; p[1] = v >> 8; p[2] = v >> 16; p[3] = v >> 24; }

/* A copy of the PyTorch zip checkpoint `file` [n bytes] with the first occurrence of `from` in
 * its stored data.pkl entry replaced by `to` (same length) and the entry's CRC fixed in both
 * headers. NULL (after a failed check) when `from` does not occur. The caller frees it. */
static inline unsigned char *golden_edit_pickle(const unsigned char *file, size_t n, const char *from, const char *to)
{
    unsigned char *z = malloc(n);
    if (!z) return NULL;
    memcpy(z, file, n);
    size_t len = strlen(from);
    for (size_t c = 0; c + 46 < n; c++) {
        if (golden_rd32(z + c) != 0x02014b50u) continue;    /* central directory entry */
        size_t nlen = z[c + 28] | z[c + 29] << 8;
        if (nlen < 8 || memcmp(z + c + 46 + nlen - 8, "data.pkl", 8)) continue;
        size_t lh = golden_rd32(z + c + 42), size = golden_rd32(z + c + 24);
        size_t data = lh + 30 + (z[lh + 26] | z[lh + 27] << 8) + (z[lh + 28] | z[lh + 29] << 8);
        for (size_t i = data; i + len <= data + size; i++)
            if (!memcmp(z + i, from, len)) {
                memcpy(z + i, to, len);
                uint32_t crc = golden_crc32(z + data, size);
                golden_wr32(z + c + 16, crc);
                golden_wr32(z + lh + 14, crc);
                return z;
            }
    }
    CHECK_MSG(0, "'%s' not found in data.pkl", from);
    free(z);
    return NULL;
}

/* A copy of the safetensors file `file` [n bytes] with tensor `name` renamed in the header
 * (its last letter becomes 'X': same length, so every offset stays valid). NULL (after a
 * failed check) when the header has no such tensor. The caller frees it. */
static inline unsigned char *golden_edit_safetensors(const unsigned char *file, size_t n, const char *name)
{
    unsigned char *copy = malloc(n);
    if (!copy || n < 8) {
        free(copy);
        return NULL;
    }
    memcpy(copy, file, n);
    size_t len = strlen(name), hdr = 8 + (size_t)copy[0] + ((size_t)copy[1] << 8) + ((size_t)copy[2] << 16);
    for (size_t i = 8; i + len + 1 < hdr && i + len < n; i++)
        if (copy[i - 1] == '"' && !memcmp(copy + i, name, len) && copy[i + len] == '"') {
            copy[i + len - 1] = 'X';
            return copy;
        }
    CHECK_MSG(0, "%s not found in the header", name);
    free(copy);
    return NULL;
}

#endif /* G3D_GOLDEN_H */
