/* gen3d train: optimises 3D Gaussians on a dataset folder of posed images. */
#include "cli.h"
#include "gen3d/dataset.h"
#include "gen3d/init.h"
#include "gen3d/spz.h"
#include "gen3d/train.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

/* The training views: every frame, on its mask's pixels where it has one. */
static g3d_status make_views(const g3d_dataset *d, g3d_train_view **out)
{
    g3d_train_view *v = g3d_calloc((size_t)d->n, sizeof *v, "training views");
    if (!v) return G3D_ERR_NOMEM;
    for (int i = 0; i < d->n; i++)
        v[i] = (g3d_train_view){d->cams.cams[i], &d->images[i], d->masks[i].data ? &d->masks[i] : NULL};
    *out = v;
    return G3D_OK;
}

/* From the dataset's points.ply, else from random points around the cameras. */
static g3d_status init_model(const char *dir, const g3d_dataset *d, const g3d_train_view *views, int sh_degree,
                             uint64_t seed, g3d_gaussians *g)
{
    if (d->points.n == 0) {
        g3d_log(G3D_LOG_WARN, "%s/points.ply: no point cloud; starting from %d random points", dir, G3D_RANDOM_INIT_POINTS);
        return g3d_gaussians_init_random(g, views, d->n, G3D_RANDOM_INIT_POINTS, sh_degree, seed);
    }
    const g3d_points *pts = &d->points;
    float *rgb = g3d_calloc((size_t)pts->n, 3 * sizeof(float), "point colours");
    if (!rgb) return G3D_ERR_NOMEM;
    for (int64_t i = 0; i < 3 * pts->n; i++) rgb[i] = pts->rgb[i] / 255.0f;
    g3d_status rc = g3d_gaussians_init_from_points(g, pts->xyz, rgb, pts->n, sh_degree);
    free(rgb);
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

    g3d_dataset d;
    g3d_train_view *views = NULL;
    g3d_gaussians g = {0};
    g3d_status rc = g3d_dataset_load(data, down, &d);
    if (rc == G3D_OK) rc = make_views(&d, &views);
    if (rc == G3D_OK && !resume) rc = init_model(data, &d, views, sh_degree, (uint64_t)common.seed, &g);
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
    if (rc == G3D_OK) rc = g3d_train(&g, views, d.n, &tp, &res);
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
    free(views);
    g3d_dataset_free(&d);
    g3d_gaussians_free(&g);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_train = {"train", "optimise 3D Gaussians on a dataset folder of posed images", run};
