/* PLY reading and writing. The reader parses the header into a property table, converts each
 * vertex row to doubles, and the two front ends (points, Gaussians) pick the columns they need. */
#include "gen3d/ply.h"

#include <ctype.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_PROPS 256
#define MAX_PLY_BYTES ((size_t)1 << 36)

enum { FMT_ASCII, FMT_LE, FMT_BE };

typedef struct prop {
    char name[64];
    int type;  /* index into type_names */
    int size;
} prop;

static const char *const type_names[] = {"char", "uchar", "short", "ushort", "int", "uint", "float", "double",
                                         "int8", "uint8", "int16", "uint16", "int32", "uint32", "float32", "float64"};
static const int type_sizes[] = {1, 1, 2, 2, 4, 4, 4, 8, 1, 1, 2, 2, 4, 4, 4, 8};

typedef struct ply_file {
    const char *path;
    unsigned char *buf;
    size_t n, data_off;
    int format;
    int64_t count;
    prop props[MAX_PROPS];
    int nprops, row_size;
} ply_file;

static int find_prop(const ply_file *f, const char *name)
{
    for (int i = 0; i < f->nprops; i++)
        if (!strcmp(f->props[i].name, name)) return i;
    return -1;
}

/* Parses the header; on success f->buf owns the file contents. */
static g3d_status ply_open(ply_file *f, const char *path)
{
    memset(f, 0, sizeof *f);
    f->path = path;
    G3D_TRY(g3d_read_file(path, MAX_PLY_BYTES, &f->buf, &f->n));
    g3d_status rc = G3D_OK;
    char line[512];
    size_t p = 0;
    int in_vertex = 0, seen_vertex = 0, line_no = 0, have_format = 0;
    while (1) {
        size_t k = 0;
        if (p >= f->n) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: PLY header has no end_header", path); break; }
        while (p < f->n && f->buf[p] != '\n' && k < sizeof line - 1) line[k++] = (char)f->buf[p++];
        if (p < f->n && f->buf[p] != '\n') { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: PLY header line too long", path); break; }
        p++;
        while (k && (line[k - 1] == '\r' || line[k - 1] == ' ')) k--;
        line[k] = 0;
        line_no++;
        if (line_no == 1) {
            if (strcmp(line, "ply")) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a PLY file", path); break; }
            continue;
        }
        char w0[64] = "", w1[64] = "", w2[64] = "", w3[64] = "";
        int nw = sscanf(line, "%63s %63s %63s %63s", w0, w1, w2, w3);
        if (nw <= 0 || !strcmp(w0, "comment") || !strcmp(w0, "obj_info")) continue;
        if (!strcmp(w0, "end_header")) break;
        if (!strcmp(w0, "format")) {
            if (!strcmp(w1, "ascii")) f->format = FMT_ASCII;
            else if (!strcmp(w1, "binary_little_endian")) f->format = FMT_LE;
            else if (!strcmp(w1, "binary_big_endian")) f->format = FMT_BE;
            else { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: unknown PLY format '%s'", path, w1); break; }
            have_format = 1;
        } else if (!strcmp(w0, "element")) {
            char *end;
            long long c = strtoll(w2, &end, 10);
            if (nw < 3 || *end || c < 0) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: malformed element line '%s'", path, line); break; }
            in_vertex = !strcmp(w1, "vertex");
            if (in_vertex) {
                if (seen_vertex) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: two vertex elements", path); break; }
                seen_vertex = 1;
                f->count = c;
            } else if (!seen_vertex) {
                rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: element '%s' before the vertices is not supported", path, w1);
                break;
            }
        } else if (!strcmp(w0, "property")) {
            if (!in_vertex) continue;
            if (!strcmp(w1, "list")) { rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: list property on vertices", path); break; }
            int t = -1;
            for (int i = 0; i < (int)(sizeof type_names / sizeof *type_names); i++)
                if (!strcmp(w1, type_names[i])) t = i;
            if (t < 0 || nw < 3) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: bad property line '%s'", path, line); break; }
            if (f->nprops >= MAX_PROPS) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: too many vertex properties", path); break; }
            prop *pr = &f->props[f->nprops++];
            snprintf(pr->name, sizeof pr->name, "%s", w2);
            pr->type = t;
            pr->size = type_sizes[t];
            f->row_size += pr->size;
        } else {
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: unexpected PLY header line '%s'", path, line);
            break;
        }
    }
    if (rc == G3D_OK && (!have_format || !seen_vertex))
        rc = G3D_ERR(G3D_ERR_FORMAT, "%s: PLY header lacks a format or a vertex element", path);
    if (rc == G3D_OK && f->nprops == 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: vertex element has no properties", path);
    f->data_off = p;
    /* Binary: the data must hold every declared vertex. ASCII: at least two bytes per value. */
    if (rc == G3D_OK) {
        size_t avail = f->n - f->data_off, per = f->format == FMT_ASCII ? (size_t)f->nprops * 2 : (size_t)f->row_size;
        if ((uint64_t)f->count > avail / per)
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: declares %lld vertices but holds data for at most %zu (truncated?)", path,
                         (long long)f->count, avail / per);
    }
    if (rc != G3D_OK) { free(f->buf); f->buf = NULL; }
    return rc;
}

static double read_scalar(const unsigned char *p, int type, int big)
{
    unsigned char b[8];
    int n = type_sizes[type];
    for (int i = 0; i < n; i++) b[i] = big ? p[n - 1 - i] : p[i];
    switch (type % 8) {
    case 0: return (double)(int8_t)b[0];
    case 1: return (double)b[0];
    case 2: { int16_t v; memcpy(&v, b, 2); return v; }
    case 3: { uint16_t v; memcpy(&v, b, 2); return v; }
    case 4: { int32_t v; memcpy(&v, b, 4); return v; }
    case 5: { uint32_t v; memcpy(&v, b, 4); return v; }
    case 6: { float v; memcpy(&v, b, 4); return v; }
    default: { double v; memcpy(&v, b, 8); return v; }
    }
}

/* Calls fn(user, i, row) for every vertex with the row's values as doubles. */
static g3d_status ply_rows(ply_file *f, void (*fn)(void *, int64_t, const double *), void *user)
{
    double row[MAX_PROPS];
    size_t p = f->data_off;
    for (int64_t i = 0; i < f->count; i++) {
        if (f->format == FMT_ASCII) {
            for (int k = 0; k < f->nprops; k++) {
                while (p < f->n && isspace(f->buf[p])) p++;
                if (p >= f->n) return G3D_ERR(G3D_ERR_FORMAT, "%s: truncated at vertex %lld of %lld", f->path, (long long)i, (long long)f->count);
                char *end;
                row[k] = strtod((const char *)f->buf + p, &end); /* f->buf is NUL-terminated */
                if (end == (char *)f->buf + p) return G3D_ERR(G3D_ERR_FORMAT, "%s: bad number at vertex %lld", f->path, (long long)i);
                p = (size_t)(end - (char *)f->buf);
            }
        } else {
            for (int k = 0; k < f->nprops; k++) {
                row[k] = read_scalar(f->buf + p, f->props[k].type, f->format == FMT_BE);
                p += (size_t)f->props[k].size;
            }
        }
        fn(user, i, row);
    }
    return G3D_OK;
}

g3d_status g3d_points_create(g3d_points *p, int64_t n, int with_normals)
{
    memset(p, 0, sizeof *p);
    p->xyz = g3d_calloc((size_t)(n ? n : 1), 3 * sizeof(float), "points");
    p->rgb = g3d_calloc((size_t)(n ? n : 1), 3, "points");
    if (with_normals) p->normals = g3d_calloc((size_t)(n ? n : 1), 3 * sizeof(float), "points");
    if (!p->xyz || !p->rgb || (with_normals && !p->normals)) { g3d_points_free(p); return G3D_ERR_NOMEM; }
    p->n = n;
    return G3D_OK;
}

void g3d_points_free(g3d_points *p)
{
    if (!p) return;
    free(p->xyz);
    free(p->rgb);
    free(p->normals);
    memset(p, 0, sizeof *p);
}

/* ---- reading points ---------------------------------------------------------------------- */

typedef struct points_ctx {
    g3d_points *p;
    int ix[3], ic[3], in[3], idc[3];
    int color_is_float;
} points_ctx;

static uint8_t to_u8(double v) { return (uint8_t)(v <= 0 ? 0 : v >= 255 ? 255 : lrint(v)); }

static void points_row(void *user, int64_t i, const double *r)
{
    points_ctx *c = user;
    for (int k = 0; k < 3; k++) {
        c->p->xyz[3 * i + k] = (float)r[c->ix[k]];
        if (c->ic[0] >= 0) c->p->rgb[3 * i + k] = to_u8(c->color_is_float ? 255.0 * r[c->ic[k]] : r[c->ic[k]]);
        else if (c->idc[0] >= 0) c->p->rgb[3 * i + k] = to_u8(255.0 * (0.5 + G3D_SH_C0 * r[c->idc[k]]));
        else c->p->rgb[3 * i + k] = 128;
        if (c->p->normals) c->p->normals[3 * i + k] = (float)r[c->in[k]];
    }
}

g3d_status g3d_ply_read_points(const char *path, g3d_points *p)
{
    ply_file f;
    points_ctx c;
    static const char *const xyz[3] = {"x", "y", "z"}, *const col[3] = {"red", "green", "blue"},
                             *const nrm[3] = {"nx", "ny", "nz"}, *const dc[3] = {"f_dc_0", "f_dc_1", "f_dc_2"};
    memset(p, 0, sizeof *p);
    G3D_TRY(ply_open(&f, path));
    memset(&c, 0, sizeof c);
    for (int k = 0; k < 3; k++) {
        c.ix[k] = find_prop(&f, xyz[k]);
        c.ic[k] = find_prop(&f, col[k]);
        c.in[k] = find_prop(&f, nrm[k]);
        c.idc[k] = find_prop(&f, dc[k]);
    }
    g3d_status rc = G3D_OK;
    if (c.ix[0] < 0 || c.ix[1] < 0 || c.ix[2] < 0) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: vertices lack x, y or z", path);
    if (c.ic[0] < 0 || c.ic[1] < 0 || c.ic[2] < 0) c.ic[0] = -1;
    if (c.idc[0] < 0 || c.idc[1] < 0 || c.idc[2] < 0) c.idc[0] = -1;
    int with_normals = c.in[0] >= 0 && c.in[1] >= 0 && c.in[2] >= 0;
    if (c.ic[0] >= 0) {
        int t = f.props[c.ic[0]].type % 8;
        c.color_is_float = t == 6 || t == 7;
    }
    if (rc == G3D_OK) rc = g3d_points_create(p, f.count, with_normals);
    if (rc == G3D_OK) {
        c.p = p;
        rc = ply_rows(&f, points_row, &c);
    }
    if (rc == G3D_OK)
        for (int64_t i = 0; i < 3 * p->n; i++)
            if (!isfinite(p->xyz[i])) { rc = G3D_ERR(G3D_ERR_FORMAT, "%s: vertex %lld has a non-finite coordinate", path, (long long)(i / 3)); break; }
    if (rc != G3D_OK) g3d_points_free(p);
    free(f.buf);
    return rc;
}

/* ---- reading Gaussians ------------------------------------------------------------------- */

typedef struct gauss_ctx {
    g3d_gaussians *g;
    int imean[3], idc[3], iop, iscale[3], irot[4];
    int irest[45];
    int K;
} gauss_ctx;

static void gauss_row(void *user, int64_t i, const double *r)
{
    gauss_ctx *c = user;
    g3d_gaussians *g = c->g;
    int K = c->K;
    for (int k = 0; k < 3; k++) {
        g->means[3 * i + k] = (float)r[c->imean[k]];
        g->log_scales[3 * i + k] = (float)r[c->iscale[k]];
        g->sh[((size_t)i * K) * 3 + k] = (float)r[c->idc[k]];
    }
    for (int k = 0; k < 4; k++) g->rots[4 * i + k] = (float)r[c->irot[k]];
    g->opacity_logits[i] = (float)r[c->iop];
    /* f_rest_{ch*(K-1) + (j-1)} holds coefficient j of channel ch. */
    for (int ch = 0; ch < 3; ch++)
        for (int j = 1; j < K; j++) g->sh[((size_t)i * K + j) * 3 + ch] = (float)r[c->irest[ch * (K - 1) + (j - 1)]];
}

static int count_rest(const ply_file *f)
{
    int n = 0;
    for (int i = 0; i < f->nprops; i++) n += !strncmp(f->props[i].name, "f_rest_", 7);
    return n;
}

static int degree_of_rest(int n)
{
    for (int d = 0; d <= G3D_SH_MAX_DEGREE; d++)
        if (n == 3 * (G3D_SH_COEFFS(d) - 1)) return d;
    return -1;
}

g3d_status g3d_ply_read_gaussians(const char *path, g3d_gaussians *g)
{
    ply_file f;
    gauss_ctx c;
    char name[32];
    memset(g, 0, sizeof *g);
    G3D_TRY(ply_open(&f, path));
    memset(&c, 0, sizeof c);
    g3d_status rc = G3D_OK;
    int nrest = count_rest(&f), deg = degree_of_rest(nrest);
    const char *missing = NULL;
    static const char *const xyz[3] = {"x", "y", "z"};
    for (int k = 0; k < 3 && !missing; k++) {
        if ((c.imean[k] = find_prop(&f, xyz[k])) < 0) missing = xyz[k];
        snprintf(name, sizeof name, "f_dc_%d", k);
        if (!missing && (c.idc[k] = find_prop(&f, name)) < 0) missing = "f_dc_*";
        snprintf(name, sizeof name, "scale_%d", k);
        if (!missing && (c.iscale[k] = find_prop(&f, name)) < 0) missing = "scale_*";
    }
    for (int k = 0; k < 4 && !missing; k++) {
        snprintf(name, sizeof name, "rot_%d", k);
        if ((c.irot[k] = find_prop(&f, name)) < 0) missing = "rot_*";
    }
    if (!missing && (c.iop = find_prop(&f, "opacity")) < 0) missing = "opacity";
    if (missing) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: not a 3D Gaussian splatting PLY (property '%s' missing)", path, missing);
    else if (deg < 0)
        rc = G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: %d f_rest properties match no SH degree 0..3 (expected 0, 9, 24 or 45)", path, nrest);
    if (rc == G3D_OK) {
        c.K = G3D_SH_COEFFS(deg);
        for (int k = 0; k < nrest; k++) {
            snprintf(name, sizeof name, "f_rest_%d", k);
            if ((c.irest[k] = find_prop(&f, name)) < 0) {
                rc = G3D_ERR(G3D_ERR_FORMAT, "%s: property '%s' missing", path, name);
                break;
            }
        }
    }
    if (rc == G3D_OK) rc = g3d_gaussians_create(g, f.count, deg);
    if (rc == G3D_OK) {
        c.g = g;
        g->n = f.count;
        rc = ply_rows(&f, gauss_row, &c);
    }
    if (rc == G3D_OK) rc = g3d_gaussians_validate(g, path);
    if (rc != G3D_OK) g3d_gaussians_free(g);
    free(f.buf);
    return rc;
}

g3d_status g3d_ply_probe(const char *path, g3d_ply_info *info)
{
    ply_file f;
    memset(info, 0, sizeof *info);
    G3D_TRY(ply_open(&f, path));
    info->n_vertices = f.count;
    info->n_properties = f.nprops;
    info->format = f.format == FMT_ASCII ? 0 : f.format == FMT_LE ? 1 : 2;
    info->is_gaussians = find_prop(&f, "opacity") >= 0 && find_prop(&f, "f_dc_0") >= 0 && find_prop(&f, "rot_0") >= 0;
    info->sh_degree = info->is_gaussians ? degree_of_rest(count_rest(&f)) : -1;
    info->has_color = find_prop(&f, "red") >= 0;
    info->has_normals = find_prop(&f, "nx") >= 0;
    free(f.buf);
    return G3D_OK;
}

/* ---- writing ----------------------------------------------------------------------------- */

g3d_status g3d_ply_write_points(const char *path, const g3d_points *p)
{
    g3d_atomic_file af;
    G3D_TRY(g3d_atomic_open(&af, path));
    fprintf(af.fp, "ply\nformat binary_little_endian 1.0\ncomment written by gen3d\nelement vertex %lld\n"
                   "property float x\nproperty float y\nproperty float z\n",
            (long long)p->n);
    if (p->normals) fprintf(af.fp, "property float nx\nproperty float ny\nproperty float nz\n");
    fprintf(af.fp, "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n");
    for (int64_t i = 0; i < p->n; i++) {
        fwrite(p->xyz + 3 * i, sizeof(float), 3, af.fp);
        if (p->normals) fwrite(p->normals + 3 * i, sizeof(float), 3, af.fp);
        fwrite(p->rgb + 3 * i, 1, 3, af.fp);
    }
    return g3d_atomic_commit(&af);
}

g3d_status g3d_ply_write_gaussians(const char *path, const g3d_gaussians *g)
{
    g3d_atomic_file af;
    int K = G3D_SH_COEFFS(g->sh_degree), nrest = 3 * (K - 1);
    G3D_TRY(g3d_gaussians_validate(g, path));
    G3D_TRY(g3d_atomic_open(&af, path));
    fprintf(af.fp, "ply\nformat binary_little_endian 1.0\nelement vertex %lld\n", (long long)g->n);
    fprintf(af.fp, "property float x\nproperty float y\nproperty float z\n");
    fprintf(af.fp, "property float nx\nproperty float ny\nproperty float nz\n");
    for (int k = 0; k < 3; k++) fprintf(af.fp, "property float f_dc_%d\n", k);
    for (int k = 0; k < nrest; k++) fprintf(af.fp, "property float f_rest_%d\n", k);
    fprintf(af.fp, "property float opacity\n");
    for (int k = 0; k < 3; k++) fprintf(af.fp, "property float scale_%d\n", k);
    for (int k = 0; k < 4; k++) fprintf(af.fp, "property float rot_%d\n", k);
    fprintf(af.fp, "end_header\n");
    float row[62];
    for (int64_t i = 0; i < g->n; i++) {
        int k = 0;
        for (int j = 0; j < 3; j++) row[k++] = g->means[3 * i + j];
        for (int j = 0; j < 3; j++) row[k++] = 0.0f;
        for (int j = 0; j < 3; j++) row[k++] = g->sh[((size_t)i * K) * 3 + j];
        for (int ch = 0; ch < 3; ch++)
            for (int j = 1; j < K; j++) row[k++] = g->sh[((size_t)i * K + j) * 3 + ch];
        row[k++] = g->opacity_logits[i];
        for (int j = 0; j < 3; j++) row[k++] = g->log_scales[3 * i + j];
        for (int j = 0; j < 4; j++) row[k++] = g->rots[4 * i + j];
        fwrite(row, sizeof(float), (size_t)k, af.fp);
    }
    return g3d_atomic_commit(&af);
}
