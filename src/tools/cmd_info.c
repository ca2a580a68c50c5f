/* gen3d info: describes an image, depth map, array, PLY or camera file. */
#include "cli.h"
#include "gen3d/cameras_json.h"
#include "gen3d/ckpt.h"
#include "gen3d/depthio.h"
#include "gen3d/imageio.h"
#include "gen3d/npy.h"
#include "gen3d/ply.h"
#include "gen3d/recognize.h"

#include <cjson/cJSON.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *DESCRIPTION =
    "Prints what a file holds: sizes, types, value ranges and the fraction of invalid values.\n"
    "Images (.png .jpg): size, channels, value range; 16-bit PNGs are also read as depth in\n"
    "millimetres. Depth and arrays (.pfm .npy .npz): shape, range, invalid fraction.\n"
    "PLY (.ply): point cloud or 3D Gaussians, count, SH degree, bounds, opacity range.\n"
    "Cameras (.json): our cameras.json or nerfstudio transforms.json.\n"
    "Checkpoints (.safetensors, .pth, .pt, .ckpt, .bin): every tensor (name, dtype, shape), the parameter count, the\n"
    "metadata and the recognised architecture.";

static void range_line(const char *label, const float *v, size_t n, size_t stride)
{
    double lo = INFINITY, hi = -INFINITY, sum = 0;
    size_t valid = 0;
    for (size_t i = 0; i < n; i++) {
        float x = v[i * stride];
        if (!isfinite(x) || x <= 0) continue;
        lo = fmin(lo, x);
        hi = fmax(hi, x);
        sum += x;
        valid++;
    }
    if (valid)
        printf("%s: min %.4g, max %.4g, mean %.4g; invalid (0, negative, NaN, inf) %.2f %%\n", label, lo, hi, sum / valid,
               100.0 * (double)(n - valid) / (double)n);
    else
        printf("%s: no valid value\n", label);
}

static int info_image(const char *path)
{
    g3d_image img;
    g3d_status rc = g3d_image_load(path, 0, &img);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s: image %dx%d, %d channel%s\n", path, img.w, img.h, img.c, img.c > 1 ? "s" : "");
    for (int ch = 0; ch < img.c; ch++) {
        float lo = 1, hi = 0;
        for (size_t i = ch; i < g3d_image_size(&img); i += img.c) { lo = fminf(lo, img.data[i]); hi = fmaxf(hi, img.data[i]); }
        printf("  channel %d: %.4f .. %.4f\n", ch, lo, hi);
    }
    g3d_image_free(&img);
    g3d_image raw;
    g3d_error_clear();
    if (g3d_image_load_u16(path, &raw) == G3D_OK) {
        for (size_t i = 0; i < g3d_image_size(&raw); i++) raw.data[i] /= 1000.0f;
        range_line("  as 16-bit depth in millimetres (metres)", raw.data, g3d_image_size(&raw), 1);
        g3d_image_free(&raw);
    }
    return G3D_EXIT_OK;
}

static int info_array(const char *path, const char *ext)
{
    g3d_status rc;
    if (!strcmp(ext, "pfm")) {
        g3d_image img;
        if ((rc = g3d_pfm_load(path, &img)) != G3D_OK) return g3d_cli_fail(rc);
        printf("%s: PFM %dx%d, %d channel%s\n", path, img.w, img.h, img.c, img.c > 1 ? "s" : "");
        range_line("  values", img.data, g3d_image_size(&img), 1);
        g3d_image_free(&img);
        return G3D_EXIT_OK;
    }
    g3d_array a;
    rc = !strcmp(ext, "npy") ? g3d_npy_load(path, &a) : g3d_npz_load(path, NULL, &a);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    size_t n = 1;
    printf("%s: array of shape (", path);
    for (int i = 0; i < a.ndim; i++) { printf("%s%lld", i ? ", " : "", (long long)a.shape[i]); n *= (size_t)a.shape[i]; }
    printf(")%s, %s values\n", a.ndim == 1 ? "," : "", a.integer ? "integer" : "floating-point");
    range_line("  values", a.data, n, 1);
    g3d_array_free(&a);
    return G3D_EXIT_OK;
}

static int info_ply(const char *path)
{
    g3d_ply_info pi;
    g3d_status rc = g3d_ply_probe(path, &pi);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    static const char *const fmt[] = {"ascii", "binary little-endian", "binary big-endian"};
    if (pi.is_gaussians) {
        g3d_gaussians g;
        if ((rc = g3d_ply_read_gaussians(path, &g)) != G3D_OK) return g3d_cli_fail(rc);
        printf("%s: 3D Gaussian splats (%s), %lld Gaussians, SH degree %d, %d properties\n", path, fmt[pi.format],
               (long long)g.n, g.sh_degree, pi.n_properties);
        for (int k = 0; k < 3; k++) {
            static const char axis[] = "xyz";
            float lo = INFINITY, hi = -INFINITY;
            for (int64_t i = 0; i < g.n; i++) { lo = fminf(lo, g.means[3 * i + k]); hi = fmaxf(hi, g.means[3 * i + k]); }
            printf("  %c: %.4g .. %.4g\n", axis[k], lo, hi);
        }
        double olo = 1, ohi = 0, slo = INFINITY, shi = 0;
        for (int64_t i = 0; i < g.n; i++) {
            double o = 1.0 / (1.0 + exp(-g.opacity_logits[i]));
            olo = fmin(olo, o);
            ohi = fmax(ohi, o);
            for (int k = 0; k < 3; k++) { double s = exp(g.log_scales[3 * i + k]); slo = fmin(slo, s); shi = fmax(shi, s); }
        }
        if (g.n) printf("  opacity: %.4f .. %.4f\n  scale: %.4g .. %.4g\n", olo, ohi, slo, shi);
        g3d_gaussians_free(&g);
    } else {
        g3d_points p;
        if ((rc = g3d_ply_read_points(path, &p)) != G3D_OK) return g3d_cli_fail(rc);
        printf("%s: point cloud (%s), %lld points, %d properties%s%s\n", path, fmt[pi.format], (long long)p.n,
               pi.n_properties, pi.has_color ? ", colours" : "", pi.has_normals ? ", normals" : "");
        for (int k = 0; k < 3; k++) {
            static const char axis[] = "xyz";
            float lo = INFINITY, hi = -INFINITY;
            for (int64_t i = 0; i < p.n; i++) { lo = fminf(lo, p.xyz[3 * i + k]); hi = fmaxf(hi, p.xyz[3 * i + k]); }
            printf("  %c: %.4g .. %.4g\n", axis[k], lo, hi);
        }
        g3d_points_free(&p);
    }
    return G3D_EXIT_OK;
}

static int info_cameras(const char *path)
{
    g3d_camera_list l;
    g3d_status rc = g3d_camera_list_load(path, &l);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s: %d camera%s\n", path, l.n, l.n == 1 ? "" : "s");
    for (int i = 0; i < l.n && i < 20; i++) {
        const g3d_camera *c = &l.cams[i];
        g3d_vec3 t = g3d_camera_center(c);
        printf("  %3d %-28s %dx%d  fx %.1f  fov %.1f deg  centre (%.3f, %.3f, %.3f)\n", i, l.names[i] ? l.names[i] : "-",
               c->K.width, c->K.height, c->K.fx, g3d_intrinsics_fov_x_deg(c->K), t.x, t.y, t.z);
    }
    if (l.n > 20) printf("  ... %d more\n", l.n - 20);
    g3d_camera_list_free(&l);
    return G3D_EXIT_OK;
}

static int info_checkpoint(const char *path)
{
    g3d_ckpt *ck;
    g3d_status rc = g3d_ckpt_open(path, &ck);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    char arch[1024];
    const char *a = g3d_model_describe(ck, arch, sizeof arch);
    printf("%s: checkpoint, %lld tensors, %lld parameters%s%s\n", path, (long long)g3d_ckpt_count(ck),
           (long long)g3d_ckpt_numel(ck), a ? ", " : "", a ? a : "");
    const cJSON *meta = g3d_ckpt_meta(ck);
    for (const cJSON *m = meta ? meta->child : NULL; m; m = m->next) {
        /* PyTorch files carry whole objects (e.g. MoGe's model_config): shown as JSON when short */
        char *js = cJSON_IsString(m) ? NULL : cJSON_PrintUnformatted(m);
        if (cJSON_IsString(m)) printf("  metadata %s: %s\n", m->string, m->valuestring);
        else if (js && strlen(js) <= 2000) printf("  metadata %s: %s\n", m->string, js);
        else printf("  metadata %s: (%d entries)\n", m->string, cJSON_GetArraySize(m));
        free(js);
    }
    for (int64_t i = 0; i < g3d_ckpt_count(ck); i++) {
        const g3d_tensor_info *t = g3d_ckpt_tensor(ck, i);
        char shape[160];
        int k = snprintf(shape, sizeof shape, "[");
        for (int d = 0; d < t->ndim && k < (int)sizeof shape; d++) k += snprintf(shape + k, sizeof shape - k, "%s%lld", d ? ", " : "", (long long)t->shape[d]);
        if (k < (int)sizeof shape) snprintf(shape + k, sizeof shape - k, "]");
        printf("  %-60s %-4s %s\n", t->name, g3d_dtype_name(t->dtype), shape);
    }
    g3d_ckpt_free(ck);
    return G3D_EXIT_OK;
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_common_init(&common);
    g3d_opt opts[] = {G3D_COMMON_OPTS(&common)};
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d info FILE", DESCRIPTION, pos, 1, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (npos != 1) return g3d_cli_errorf(G3D_EXIT_USAGE, "info needs one FILE (see gen3d info --help)");
    common.quiet = 1; /* no seed line: info is not random */
    g3d_cli_common_apply(&common);
    char ext[16];
    g3d_path_ext(pos[0], ext, sizeof ext);
    if (!strcmp(ext, "png") || !strcmp(ext, "jpg") || !strcmp(ext, "jpeg")) return info_image(pos[0]);
    if (!strcmp(ext, "pfm") || !strcmp(ext, "npy") || !strcmp(ext, "npz")) return info_array(pos[0], ext);
    if (!strcmp(ext, "ply")) return info_ply(pos[0]);
    if (!strcmp(ext, "json")) return info_cameras(pos[0]);
    if (!strcmp(ext, "safetensors") || !strcmp(ext, "pth") || !strcmp(ext, "pt") || !strcmp(ext, "ckpt") ||
        !strcmp(ext, "bin"))
        return info_checkpoint(pos[0]);
    return g3d_cli_errorf(G3D_EXIT_FAIL, "%s: unknown file type '.%s' (png, jpg, pfm, npy, npz, ply, json, safetensors, pth, ckpt, bin)", pos[0], ext);
}

const g3d_command g3d_cmd_info = {"info", "describe an image, depth map, array, PLY, camera file or checkpoint", run};
