/* gen3d train: optimises 3D Gaussians on a dataset folder of posed images. */
#include "cli.h"
#include "gen3d/cameras_json.h"
#include "gen3d/imageio.h"
#include "gen3d/init.h"
#include "gen3d/ply.h"
#include "gen3d/raster.h"
#include "gen3d/resize.h"
#include "gen3d/spz.h"
#include "gen3d/train.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *DESCRIPTION =
    "Trains 3D Gaussians on a dataset folder: a transforms.json (nerfstudio) or cameras.json listing\n"
    "the images, with optional per-frame mask_path (training then uses only pixels where the mask is\n"
    "set), and points.ply to start from - exactly what `gen3d world` writes (without points.ply:\n"
    "50000 random points around the cameras). Writes scene.ply (the standard 3DGS layout),\n"
    "scene.spz and train.json (settings, seed, final loss and PSNR).\n"
    "While training, the whole state is saved every --checkpoint-every iterations to\n"
    "OUT.checkpoint.safetensors (removed when training completes, unless --keep-checkpoint);\n"
    "--resume FILE continues from\n"
    "such a file with the same data, seed and settings, ending exactly where an uninterrupted run\n"
    "would.";

typedef struct dataset {
    g3d_camera_list cams;
    g3d_image *images, *masks;
    g3d_train_view *views;
    int n;
} dataset;

static void dataset_free(dataset *d)
{
    for (int i = 0; i < d->n; i++) {
        if (d->images) g3d_image_free(&d->images[i]);
        if (d->masks) g3d_image_free(&d->masks[i]);
    }
    free(d->images);
    free(d->masks);
    free(d->views);
    g3d_camera_list_free(&d->cams);
    memset(d, 0, sizeof *d);
}

static g3d_status load_scaled(const char *dir, const char *rel, int channels, int w, int h, int down, g3d_image *out)
{
    char *p = g3d_path_join(dir, rel);
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_image img = {0};
    g3d_status rc = g3d_image_load(p, channels, &img);
    if (rc == G3D_OK && (img.w != w || img.h != h))
        rc = G3D_ERR(G3D_ERR_MISMATCH, "%s: image is %dx%d but its camera says %dx%d", p, img.w, img.h, w, h);
    free(p);
    if (rc != G3D_OK) {
        g3d_image_free(&img);
        return rc;
    }
    if (down == 1) { *out = img; return G3D_OK; }
    rc = g3d_image_resize(&img, w / down, h / down, channels == 1 ? G3D_RESIZE_NEAREST : G3D_RESIZE_AREA, out);
    g3d_image_free(&img);
    return rc;
}

static g3d_status dataset_load(const char *dir, int down, dataset *d)
{
    memset(d, 0, sizeof *d);
    char *tj = g3d_path_join(dir, "transforms.json"), *cj = g3d_path_join(dir, "cameras.json");
    struct stat st;
    g3d_status rc = !tj || !cj ? G3D_ERR(G3D_ERR_NOMEM, "out of memory")
                  : stat(tj, &st) == 0 ? g3d_camera_list_load(tj, &d->cams)
                  : stat(cj, &st) == 0 ? g3d_camera_list_load(cj, &d->cams)
                                       : G3D_ERR(G3D_ERR_IO, "%s: no transforms.json or cameras.json", dir);
    free(tj);
    free(cj);
    if (rc != G3D_OK) return rc;
    if (d->cams.n == 0) return G3D_ERR(G3D_ERR_FORMAT, "%s: the camera list is empty", dir);
    d->images = calloc((size_t)d->cams.n, sizeof *d->images);
    d->masks = calloc((size_t)d->cams.n, sizeof *d->masks);
    d->views = calloc((size_t)d->cams.n, sizeof *d->views);
    if (!d->images || !d->masks || !d->views) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    d->n = d->cams.n;
    for (int i = 0; i < d->n && rc == G3D_OK; i++) {
        g3d_camera *c = &d->cams.cams[i];
        if (!d->cams.names[i]) return G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d names no image", dir, i);
        rc = load_scaled(dir, d->cams.names[i], 3, c->K.width, c->K.height, down, &d->images[i]);
        if (rc == G3D_OK && d->cams.mask_paths[i])
            rc = load_scaled(dir, d->cams.mask_paths[i], 1, c->K.width, c->K.height, down, &d->masks[i]);
        if (down > 1) c->K = g3d_intrinsics_resize(c->K, c->K.width / down, c->K.height / down);
        d->views[i].cam = *c;
        d->views[i].image = &d->images[i];
        d->views[i].mask = d->masks[i].data ? &d->masks[i] : NULL;
    }
    return rc;
}

/* Without a point cloud the model starts from random points, as nerfstudio's splatfacto does:
 * uniform in a cube around the cameras (10x their spread), grey, seeded. */
static g3d_status random_points(const dataset *d, uint64_t seed, int64_t n, float **xyz, float **rgb)
{
    g3d_vec3 c = g3d_v3(0, 0, 0);
    for (int i = 0; i < d->n; i++) c = g3d_v3_add(c, g3d_mat4_translation(d->views[i].cam.c2w));
    c = g3d_v3_scale(c, 1.0 / d->n);
    double half = 10.0 * g3d_train_scene_extent(d->views, d->n) / 1.1;
    *xyz = malloc(sizeof(float) * 3 * (size_t)n);
    *rgb = malloc(sizeof(float) * 3 * (size_t)n);
    if (!*xyz || !*rgb) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    g3d_rng r;
    g3d_rng_seed(&r, seed, 11);
    const double cc[3] = {c.x, c.y, c.z};
    for (int64_t i = 0; i < 3 * n; i++) {
        (*xyz)[i] = (float)(cc[i % 3] + half * (2.0 * g3d_rng_float(&r) - 1.0));
        (*rgb)[i] = 0.5f;
    }
    return G3D_OK;
}

static g3d_status init_model(const char *dir, const dataset *d, int sh_degree, uint64_t seed, g3d_gaussians *g)
{
    char *p = g3d_path_join(dir, "points.ply");
    if (!p) return G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    struct stat st;
    if (stat(p, &st) != 0) {
        g3d_log(G3D_LOG_WARN, "%s: no point cloud; starting from 50000 random points", p);
        free(p);
        float *xyz = NULL, *rgb = NULL;
        g3d_status rc = random_points(d, seed, 50000, &xyz, &rgb);
        if (rc == G3D_OK) rc = g3d_gaussians_init_from_points(g, xyz, rgb, 50000, sh_degree);
        free(xyz);
        free(rgb);
        return rc;
    }
    g3d_points pts;
    g3d_status rc = g3d_ply_read_points(p, &pts);
    free(p);
    if (rc != G3D_OK) return rc;
    float *rgb = malloc(sizeof(float) * 3 * (size_t)(pts.n ? pts.n : 1));
    if (!rgb) { g3d_points_free(&pts); return G3D_ERR(G3D_ERR_NOMEM, "out of memory"); }
    for (int64_t i = 0; i < 3 * pts.n; i++) rgb[i] = pts.rgb[i] / 255.0f;
    rc = g3d_gaussians_init_from_points(g, pts.xyz, rgb, pts.n, sh_degree);
    free(rgb);
    g3d_points_free(&pts);
    return rc;
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    const char *data = NULL;
    const char *resume = NULL;
    int iters = 3000, sh_degree = 3, down = 1, ckpt_every = 500, keep_ckpt = 0;
    g3d_cli_common_init(&common);
    common.output = "trained";
    common.seed = 42;
    g3d_opt opts[] = {
        {0, "data", G3D_OPT_STRING, &data, "DIR", "dataset folder (transforms.json or cameras.json, images, points.ply)"},
        {0, "iters", G3D_OPT_INT, &iters, "N", "training iterations"},
        {0, "sh-degree", G3D_OPT_INT, &sh_degree, "D", "spherical-harmonics degree of the model (0..3)"},
        {0, "downscale", G3D_OPT_INT, &down, "F", "train on images downscaled by this integer factor"},
        {0, "checkpoint-every", G3D_OPT_INT, &ckpt_every, "N", "save the training state every N iterations (0: never)"},
        {0, "keep-checkpoint", G3D_OPT_FLAG, &keep_ckpt, NULL, "keep the last checkpoint after training completes"},
        {0, "resume", G3D_OPT_STRING, &resume, "FILE", "continue from a checkpoint written by an earlier run"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts), "gen3d train --data DIR [options] -o DIR", DESCRIPTION, pos, 0, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (!data) return g3d_cli_errorf(G3D_EXIT_USAGE, "train needs --data DIR");
    if (iters < 1 || iters > 1000000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--iters must be in 1..1000000");
    if (sh_degree < 0 || sh_degree > 3) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sh-degree must be in 0..3");
    if (down < 1 || down > 16) return g3d_cli_errorf(G3D_EXIT_USAGE, "--downscale must be in 1..16");
    if (ckpt_every < 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "--checkpoint-every must be >= 0");
    g3d_cli_common_apply(&common);

    dataset d;
    g3d_gaussians g = {0};
    g3d_status rc = dataset_load(data, down, &d);
    if (rc == G3D_OK && !resume) rc = init_model(data, &d, sh_degree, (uint64_t)common.seed, &g);
    size_t olen = strlen(common.output);
    char *ckpt = malloc(olen + 32);
    if (!ckpt) rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    else snprintf(ckpt, olen + 32, "%s.checkpoint.safetensors", common.output);
    g3d_train_params tp;
    g3d_train_params_default(&tp, iters);
    tp.seed = (uint64_t)common.seed;
    tp.progress = g3d_cli_progress();
    tp.checkpoint_path = ckpt;
    tp.checkpoint_every = ckpt_every;
    tp.resume_path = resume;
    g3d_train_result res = {0};
    int64_t n0 = g.n;
    if (rc == G3D_OK) rc = g3d_train(&g, d.views, d.n, &tp, &res);
    char *tmp = NULL, *p;
    if (rc == G3D_OK) rc = g3d_atomic_dir_begin(common.output, &tmp);
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "scene.ply"); rc = g3d_ply_write_gaussians(p, &g); free(p); }
    if (rc == G3D_OK) { p = g3d_path_join(tmp, "scene.spz"); rc = g3d_spz_save(p, &g); free(p); }
    if (rc == G3D_OK) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "data", data);
        cJSON_AddNumberToObject(o, "iterations", iters);
        cJSON_AddNumberToObject(o, "seed", (double)common.seed);
        cJSON_AddNumberToObject(o, "sh_degree", sh_degree);
        cJSON_AddNumberToObject(o, "downscale", down);
        if (resume) cJSON_AddStringToObject(o, "resumed_from", resume);
        cJSON_AddNumberToObject(o, "views", d.n);
        if (!resume) cJSON_AddNumberToObject(o, "initial_gaussians", (double)n0);
        cJSON_AddNumberToObject(o, "gaussians", (double)g.n);
        cJSON_AddNumberToObject(o, "final_loss", res.last_loss);
        cJSON_AddNumberToObject(o, "final_psnr_db", res.last_psnr);
        char *text = cJSON_Print(o);
        cJSON_Delete(o);
        p = g3d_path_join(tmp, "train.json");
        rc = text && p ? g3d_write_file_atomic(p, text, strlen(text)) : G3D_ERR(G3D_ERR_NOMEM, "out of memory");
        free(p);
        free(text);
    }
    if (rc == G3D_OK) rc = g3d_atomic_dir_commit(tmp, common.output);
    if (rc != G3D_OK && tmp) g3d_atomic_dir_abort(tmp);
    if (rc == G3D_OK && ckpt && !keep_ckpt) remove(ckpt);
    free(tmp);
    free(ckpt);
    if (rc == G3D_OK)
        g3d_log(G3D_LOG_INFO, "train: %d views, %lld -> %lld Gaussians, loss %.4f, PSNR %.2f dB, %.1f s", d.n, (long long)n0,
                (long long)g.n, res.last_loss, res.last_psnr, res.seconds);
    dataset_free(&d);
    g3d_gaussians_free(&g);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_train = {"train", "optimise 3D Gaussians on a dataset folder of posed images", run};
