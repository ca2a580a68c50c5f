/* gen3d view: one self-contained viewer.html for a scene, to open in a web browser. */
#include "cli.h"
#include "gen3d/trajectory.h"
#include "gen3d/render.h"
#include "gen3d/viewer.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *const g_description =
    "Writes one HTML file that shows the scene in a web browser: it works from file://, offline,\n"
    "with no server, and holds the scene (as .spz), the cameras and the viewer (three.js + Spark).\n"
    "It opens at the input camera with its field of view. Mouse: drag to orbit, right-drag to\n"
    "pan, wheel to zoom; keys W A S D / arrows fly, Q E down and up, R resets the view, 1 and 2\n"
    "play the generation and video paths; touch orbits and zooms (docs/viewer.md).\n"
    "  --cameras FILE   a cameras.json or transforms.json (gen3d generate's cameras.json): its\n"
    "                   frames without a mask are the generation path, the first is the input\n"
    "                   camera. Without it the input camera is the identity pose with\n"
    "                   --width/--height/--fov.\n"
    "  --video-trajectory  the video path: a preset of `gen3d render` around the input camera\n"
    "                   (resampled to --frames), a camera file played as given, or none.\n"
    "A scene larger than the page can hold (a 256 MB .spz) is refused; --max-gaussians keeps\n"
    "the largest, most opaque Gaussians and --sh-degree drops spherical-harmonics bands.\n";

typedef struct view_opts {
    const char *cameras, *video;
    int width, height, frames, fps, sh_degree;
    int64_t max_gaussians;
    double fov;
} view_opts;

/* The input camera and the generation path: the unmasked frames of --cameras (masked frames
 * are the partial extra views), else the identity pose with the preset intrinsics. */
static g3d_status input_cameras(const view_opts *o, g3d_camera **gen, int *n_gen)
{
    *gen = NULL;
    *n_gen = 0;
    if (!o->cameras) {
        *gen = malloc(sizeof **gen);
        if (!*gen) return G3D_ERR_NOMEM;
        (*gen)[0].K = g3d_intrinsics_from_fov(o->fov, o->width, o->height);
        (*gen)[0].c2w = g3d_mat4_identity();
        *n_gen = 1;
        return G3D_OK;
    }
    g3d_camera_list l;
    G3D_TRY(g3d_trajectory_load_list(o->cameras, &l));
    int n = 0;
    for (int i = 0; i < l.n; i++) n += !l.mask_paths[i];
    g3d_camera *c = g3d_calloc((size_t)(n ? n : l.n), sizeof *c, "cameras");
    if (c) {
        for (int i = 0, k = 0; i < l.n; i++)
            if (!n || !l.mask_paths[i]) c[k++] = l.cams[i];
        *gen = c;
        *n_gen = n ? n : l.n;
    }
    g3d_camera_list_free(&l);
    return c ? G3D_OK : G3D_ERR_NOMEM;
}

static g3d_status video_cameras(const view_opts *o, const g3d_gaussians *g, const g3d_camera *input,
                                 g3d_camera **cams, int *n)
{
    *cams = NULL;
    *n = 0;
    if (!strcmp(o->video, "none")) return G3D_OK;
    if (g3d_trajectory_is_file(o->video)) return g3d_trajectory_load(o->video, cams, n);
    return g3d_render_flythrough(o->video, NULL, g, input, 0, o->frames, cams, n);
}

static int run(int argc, char **argv)
{
    g3d_cli_common common;
    g3d_cli_common_init(&common);
    common.output = "viewer.html";
    view_opts o = {NULL, "swing", 512, 384, 120, 30, -1, 0, 60.0};
    g3d_opt opts[] = {
        {0, "cameras", G3D_OPT_STRING, &o.cameras, "FILE", "cameras.json / transforms.json: input camera and generation path"},
        {0, "video-trajectory", G3D_OPT_STRING, &o.video, "NAME|FILE", "video path: a render preset, a camera file, or none"},
        {0, "frames", G3D_OPT_INT, &o.frames, "N", "cameras of a preset video path"},
        {0, "fps", G3D_OPT_INT, &o.fps, "N", "video path playback, cameras per second"},
        {0, "width", G3D_OPT_INT, &o.width, "W", "input image width without --cameras, pixels"},
        {0, "height", G3D_OPT_INT, &o.height, "H", "input image height without --cameras, pixels"},
        {0, "fov", G3D_OPT_DOUBLE, &o.fov, "DEG", "input horizontal field of view without --cameras, degrees"},
        {0, "max-gaussians", G3D_OPT_INT64, &o.max_gaussians, "N", "keep the N largest, most opaque Gaussians (0: all)"},
        {0, "sh-degree", G3D_OPT_INT, &o.sh_degree, "D", "keep spherical harmonics up to degree D (-1: all)"},
        G3D_COMMON_OPTS(&common),
    };
    const char *pos[1];
    int npos, prc = g3d_cli_parse(argc, argv, opts, G3D_COUNTOF(opts),
                                  "gen3d view SCENE(.ply|.spz) [--cameras cameras.json] [options] -o viewer.html",
                                  g_description, pos, 1, &npos);
    if (prc) return prc < 0 ? G3D_EXIT_OK : prc;
    if (npos != 1) return g3d_cli_errorf(G3D_EXIT_USAGE, "view needs one scene file (.ply or .spz)");
    if (o.width < 1 || o.height < 1 || o.width > G3D_MAX_IMAGE_SIDE || o.height > G3D_MAX_IMAGE_SIDE)
        return g3d_cli_errorf(G3D_EXIT_USAGE, "--width and --height must be in 1..%d", G3D_MAX_IMAGE_SIDE);
    if (!(o.fov > 1.0 && o.fov < 179.0)) return g3d_cli_errorf(G3D_EXIT_USAGE, "--fov must be in 1..179 degrees");
    if (o.frames < 2 || o.frames > 100000) return g3d_cli_errorf(G3D_EXIT_USAGE, "--frames must be in 2..100000");
    if (o.fps < 1 || o.fps > 240) return g3d_cli_errorf(G3D_EXIT_USAGE, "--fps must be in 1..240");
    if (o.max_gaussians < 0) return g3d_cli_errorf(G3D_EXIT_USAGE, "--max-gaussians must be >= 0");
    if (o.sh_degree < -1 || o.sh_degree > G3D_SH_MAX_DEGREE) return g3d_cli_errorf(G3D_EXIT_USAGE, "--sh-degree must be in -1..3");
    struct stat st;
    if (stat(common.output, &st) == 0 && S_ISDIR(st.st_mode))
        return g3d_cli_errorf(G3D_EXIT_USAGE, "%s is a folder; -o names the HTML file to write", common.output);
    g3d_cli_common_apply(&common);

    const char *scene = pos[0];
    g3d_gaussians loaded = {0}, g = {0};
    g3d_camera *gen = NULL, *video = NULL;
    int n_gen = 0, n_video = 0;
    g3d_status rc = g3d_gaussians_load(scene, &loaded);
    if (rc == G3D_OK) rc = g3d_viewer_reduce(&loaded, o.max_gaussians, o.sh_degree, &g);
    g3d_gaussians_free(&loaded);
    if (rc == G3D_OK) rc = input_cameras(&o, &gen, &n_gen);
    if (rc == G3D_OK && g.n > 0) rc = video_cameras(&o, &g, &gen[0], &video, &n_video);
    g3d_viewer_path paths[2];
    int npaths = 0;
    if (o.cameras) paths[npaths++] = (g3d_viewer_path){"generation", gen, n_gen, 1.0};
    if (n_video) paths[npaths++] = (g3d_viewer_path){"video", video, n_video, o.fps};
    g3d_viewer_params vo;
    g3d_viewer_params_default(&vo);
    vo.label = scene;
    if (rc == G3D_OK) rc = g3d_viewer_write(common.output, &g, &gen[0], paths, npaths, &vo);
    if (rc == G3D_OK && stat(common.output, &st) == 0)
        g3d_log(G3D_LOG_INFO, "view: %lld Gaussians (SH degree %d), %.1f MB page", (long long)g.n, g.sh_degree,
                (double)st.st_size / (1 << 20));
    free(gen);
    free(video);
    g3d_gaussians_free(&g);
    if (rc != G3D_OK) return g3d_cli_fail(rc);
    printf("%s\n", common.output);
    return G3D_EXIT_OK;
}

const g3d_command g3d_cmd_view = {"view", "write a self-contained viewer.html to explore a scene in a web browser", run};
