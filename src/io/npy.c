/* NumPy .npy / .npz arrays: a strict header parser and a float32 writer. */
#include "gen3d/npy.h"
#include "gen3d/zip.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_NPY_BYTES ((uint64_t)1 << 34)

void g3d_array_free(g3d_array *a)
{
    if (!a) return;
    free(a->data);
    memset(a, 0, sizeof *a);
}

static float half_to_float(uint16_t h)
{
    int s = h >> 15, e = (h >> 10) & 31, m = h & 1023;
    float v;
    if (e == 0) v = ldexpf((float)m, -24);
    else if (e == 31) v = m ? NAN : INFINITY;
    else v = ldexpf((float)(m | 1024), e - 25);
    return s ? -v : v;
}

/* Finds 'key': in the header dict and returns a pointer just past the colon. */
static const char *dict_value(const char *hdr, const char *key)
{
    const char *p = strstr(hdr, key);
    if (!p) return NULL;
    p = strchr(p + strlen(key), ':');
    if (!p) return NULL;
    p++;
    while (*p == ' ') p++;
    return p;
}

g3d_status g3d_npy_parse(const unsigned char *buf, size_t n, const char *label, g3d_array *out)
{
    memset(out, 0, sizeof *out);
    if (n < 10 || memcmp(buf, "\x93NUMPY", 6) != 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: not an .npy array (bad magic)", label);
    int major = buf[6];
    size_t hlen, hstart;
    if (major == 1) { hlen = buf[8] | (size_t)buf[9] << 8; hstart = 10; }
    else if (major == 2 || major == 3) {
        if (n < 12) return G3D_ERR(G3D_ERR_FORMAT, "%s: truncated .npy header", label);
        hlen = buf[8] | (size_t)buf[9] << 8 | (size_t)buf[10] << 16 | (size_t)buf[11] << 24;
        hstart = 12;
    } else return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: .npy format version %d is not supported", label, major);
    if (hlen > 65536 || hstart + hlen > n) return G3D_ERR(G3D_ERR_FORMAT, "%s: truncated .npy header", label);
    char hdr[65537];
    memcpy(hdr, buf + hstart, hlen);
    hdr[hlen] = 0;

    const char *d = dict_value(hdr, "'descr'"), *f = dict_value(hdr, "'fortran_order'"), *s = dict_value(hdr, "'shape'");
    if (!d || !f || !s || *d != '\'' || *s != '(') return G3D_ERR(G3D_ERR_FORMAT, "%s: malformed .npy header", label);
    if (!strncmp(f, "True", 4)) return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: Fortran-order arrays are not supported", label);
    char descr[16] = {0};
    const char *q = strchr(d + 1, '\'');
    if (!q || q - d - 1 >= (int)sizeof descr) return G3D_ERR(G3D_ERR_FORMAT, "%s: malformed dtype in .npy header", label);
    memcpy(descr, d + 1, (size_t)(q - d - 1));
    char order = descr[0];
    const char *kind = descr + 1;
    int esize;
    if (!strcmp(kind, "f4")) esize = 4;
    else if (!strcmp(kind, "f2") || !strcmp(kind, "u2")) esize = 2;
    else if (!strcmp(kind, "f8")) esize = 8;
    else if (!strcmp(kind, "u1") || !strcmp(kind, "b1")) esize = 1;
    else return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: dtype '%s' is not supported (float16/32/64, uint8, uint16)", label, descr);
    if (order != '<' && order != '>' && order != '|' && order != '=')
        return G3D_ERR(G3D_ERR_FORMAT, "%s: bad byte order in dtype '%s'", label, descr);
    int big = order == '>';

    uint64_t count = 1;
    s++;
    for (;;) {
        while (*s == ' ' || *s == ',') s++;
        if (*s == ')') break;
        char *end;
        long long v = strtoll(s, &end, 10);
        if (end == s || v < 0 || out->ndim >= 8) return G3D_ERR(G3D_ERR_FORMAT, "%s: malformed shape in .npy header", label);
        out->shape[out->ndim++] = v;
        if (v > 0 && count > MAX_NPY_BYTES / (uint64_t)v) return G3D_ERR(G3D_ERR_FORMAT, "%s: absurd array shape", label);
        count *= (uint64_t)v;
        s = end;
    }
    size_t data_off = hstart + hlen;
    if (count > (n - data_off) / (uint64_t)esize)
        return G3D_ERR(G3D_ERR_FORMAT, "%s: truncated .npy data (%llu elements declared, %zu bytes present)", label,
                       (unsigned long long)count, n - data_off);
    out->data = g3d_calloc(count ? count : 1, sizeof(float), label);
    if (!out->data) return G3D_ERR_NOMEM;
    out->integer = kind[0] != 'f';
    const unsigned char *p = buf + data_off;
    for (uint64_t i = 0; i < count; i++, p += esize) {
        unsigned char b[8];
        for (int k = 0; k < esize; k++) b[k] = big ? p[esize - 1 - k] : p[k];
        float v;
        if (esize == 4 && kind[0] == 'f') { memcpy(&v, b, 4); }
        else if (esize == 8) { double x; memcpy(&x, b, 8); v = (float)x; }
        else if (esize == 2 && kind[0] == 'f') v = half_to_float((uint16_t)(b[0] | b[1] << 8));
        else if (esize == 2) v = (float)(b[0] | b[1] << 8);
        else v = (float)b[0];
        out->data[i] = v;
    }
    return G3D_OK;
}

g3d_status g3d_npy_load(const char *path, g3d_array *out)
{
    unsigned char *buf;
    size_t n;
    memset(out, 0, sizeof *out);
    G3D_TRY(g3d_read_file(path, (size_t)MAX_NPY_BYTES, &buf, &n));
    g3d_status rc = g3d_npy_parse(buf, n, path, out);
    free(buf);
    return rc;
}

g3d_status g3d_npz_load(const char *path, const char *member, g3d_array *out)
{
    unsigned char *buf, *ent = NULL;
    size_t n;
    uint64_t en;
    g3d_zip z;
    memset(out, 0, sizeof *out);
    G3D_TRY(g3d_read_file(path, (size_t)MAX_NPY_BYTES, &buf, &n));
    g3d_status rc = g3d_zip_open(&z, buf, n, path);
    if (rc != G3D_OK) { free(buf); return rc; }
    int64_t idx = -1;
    char name[512];
    const char *want = member ? member : "arr_0";
    snprintf(name, sizeof name, "%s", want);
    idx = g3d_zip_find(&z, name);
    if (idx < 0) {
        snprintf(name, sizeof name, "%s.npy", want);
        idx = g3d_zip_find(&z, name);
    }
    if (idx < 0 && !member && z.n_entries > 0) idx = 0; /* np.savez names its first array arr_0 */
    if (idx < 0) {
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: no array named '%s' in the archive (%lld members)", path, want, (long long)z.n_entries);
    } else {
        rc = g3d_zip_extract(&z, idx, MAX_NPY_BYTES, &ent, &en);
        if (rc == G3D_OK) {
            char label[1024];
            snprintf(label, sizeof label, "%s:%s", path, z.entries[idx].name);
            rc = g3d_npy_parse(ent, (size_t)en, label, out);
        }
    }
    free(ent);
    g3d_zip_close(&z);
    free(buf);
    return rc;
}

g3d_status g3d_npy_save(const char *path, const float *data, int ndim, const int64_t *shape)
{
    char hdr[256], dims[160] = "";
    size_t count = 1;
    int k = 0;
    if (ndim < 1 || ndim > 8) return G3D_ERR(G3D_ERR_ARG, "%s: bad array rank %d", path, ndim);
    for (int i = 0; i < ndim; i++) {
        k += snprintf(dims + k, sizeof dims - (size_t)k, "%lld,%s", (long long)shape[i], i + 1 < ndim ? " " : "");
        count *= (size_t)shape[i];
    }
    if (ndim > 1) dims[k - 1] = 0; /* (a, b) rather than (a, b,) */
    int hl = snprintf(hdr, sizeof hdr, "{'descr': '<f4', 'fortran_order': False, 'shape': (%s), }", dims);
    /* Pad with spaces so that the data starts on a 64-byte boundary, newline-terminated. */
    int total = 10 + hl + 1;
    int pad = (64 - total % 64) % 64;
    g3d_atomic_file af;
    G3D_TRY(g3d_atomic_open(&af, path));
    unsigned char pre[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, 0, 0};
    pre[8] = (unsigned char)((hl + pad + 1) & 255);
    pre[9] = (unsigned char)((hl + pad + 1) >> 8);
    fwrite(pre, 1, 10, af.fp);
    fwrite(hdr, 1, (size_t)hl, af.fp);
    for (int i = 0; i < pad; i++) fputc(' ', af.fp);
    fputc('\n', af.fp);
    fwrite(data, sizeof(float), count, af.fp); /* x86-64 and ARM64 are little-endian */
    return g3d_atomic_commit(&af);
}
