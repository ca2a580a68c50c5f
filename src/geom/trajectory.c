/* Camera path presets and camera path files. */
#include "gen3d/trajectory.h"
#include "gen3d/cameras_json.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *const g_names[] = {"rotate", "lookdown", "lookaround", "rotate360", "push_in", "pull_out",
                                      "move_left", "move_right", "orbit_left", "orbit_right", "pan_left", "pan_right", NULL};
static const char *const g_desc[] = {
    "counter-clockwise rotating camera (paper): --steps poses up to --angle degrees of yaw",
    "LucidDreamer: 7 yaws (0, +-20, +-40, +-60) level, then looking down 22.5 degrees (14 poses)",
    "LucidDreamer: 7 yaws level, looking up and looking down 22.5 degrees (21 poses)",
    "LucidDreamer: a full turn in 36-degree steps (10 poses)",
    "WorldScore: move forward by s", "WorldScore: move backward by s",
    "WorldScore: move left by s/2", "WorldScore: move right by s/2",
    "WorldScore: orbit 30 degrees left about a pivot s ahead", "WorldScore: orbit 30 degrees right about a pivot s ahead",
    "WorldScore: turn 30 degrees left in place", "WorldScore: turn 30 degrees right in place",
};

const char *const *g3d_trajectory_names(void) { return g_names; }

const char *g3d_trajectory_describe(const char *name)
{
    for (int i = 0; g_names[i]; i++)
        if (!strcmp(g_names[i], name)) return g_desc[i];
    return NULL;
}

void g3d_trajectory_params_default(g3d_trajectory_params *p)
{
    *p = (g3d_trajectory_params){0, 0.0, 0.0, -1};
}

static const g3d_vec3 UP = {0, -1, 0};

g3d_mat4 g3d_pose_yaw_pitch(double yaw_deg, double pitch_deg, g3d_vec3 t)
{
    /* Yaw about world up, then pitch about the (yawed) camera x axis; pitch > 0 looks down,
     * i.e. turns forward (+z) towards +y. */
    g3d_mat4 r = g3d_mat4_mul(g3d_mat4_rotation(UP, yaw_deg * M_PI / 180.0),
                              g3d_mat4_rotation(g3d_v3(1, 0, 0), -pitch_deg * M_PI / 180.0));
    r.m[0][3] = t.x;
    r.m[1][3] = t.y;
    r.m[2][3] = t.z;
    return r;
}

/* Keyframe pair (identity, key) with `interp` slerped poses in between. */
static g3d_status keyframes(g3d_mat4 key, int interp, g3d_mat4 **poses, int *n)
{
    int total = interp + 2;
    *poses = malloc(sizeof(g3d_mat4) * (size_t)total);
    if (!*poses) return G3D_ERR(G3D_ERR_NOMEM, "trajectory: out of memory");
    for (int i = 0; i < total; i++) (*poses)[i] = g3d_pose_interp(g3d_mat4_identity(), key, (double)i / (total - 1));
    *n = total;
    return G3D_OK;
}

/* Rotation by yaw about a pivot `d` metres ahead of the camera, camera turning with it. */
static g3d_mat4 orbit(double yaw_deg, double d)
{
    g3d_mat4 r = g3d_mat4_rotation(UP, yaw_deg * M_PI / 180.0);
    g3d_vec3 pivot = g3d_v3(0, 0, d);
    g3d_vec3 c = g3d_v3_add(pivot, g3d_mat4_dir(r, g3d_v3(0, 0, -d)));
    r.m[0][3] = c.x;
    r.m[1][3] = c.y;
    r.m[2][3] = c.z;
    return r;
}

g3d_status g3d_trajectory_make(const char *name, const g3d_trajectory_params *p, double scene_scale,
                               g3d_mat4 **poses, int *n)
{
    g3d_trajectory_params def;
    g3d_trajectory_params_default(&def);
    if (!p) p = &def;
    *poses = NULL;
    *n = 0;
    if (!(scene_scale > 0) || !isfinite(scene_scale)) return G3D_ERR(G3D_ERR_ARG, "trajectory: scene scale must be positive");
    double s = p->distance > 0 ? p->distance : 0.25 * scene_scale;
    int interp = p->interp >= 0 ? p->interp : 48;
    if (p->steps < 0 || p->steps > 1000) return G3D_ERR(G3D_ERR_ARG, "trajectory: steps %d out of range 0..1000", p->steps);
    if (interp > G3D_TRAJECTORY_MAX_INTERP) return G3D_ERR(G3D_ERR_ARG, "trajectory: %d interpolated poses is too many", interp);

    if (!strcmp(name, "rotate")) {
        int steps = p->steps ? p->steps : 8;
        double angle = p->angle_deg != 0 ? p->angle_deg : 60.0;
        if (fabs(angle) > 360) return G3D_ERR(G3D_ERR_ARG, "trajectory: angle %g beyond a full turn", angle);
        *poses = malloc(sizeof(g3d_mat4) * (size_t)(steps + 1));
        if (!*poses) return G3D_ERR(G3D_ERR_NOMEM, "trajectory: out of memory");
        for (int i = 0; i <= steps; i++) (*poses)[i] = g3d_pose_yaw_pitch(angle * i / steps, 0, g3d_v3(0, 0, 0));
        *n = steps + 1;
        return G3D_OK;
    }
    if (!strcmp(name, "lookdown") || !strcmp(name, "lookaround") || !strcmp(name, "rotate360")) {
        static const double yaws[7] = {0, 20, 40, 60, -20, -40, -60};
        double pitches[3] = {0, 22.5, 0};
        int npitch = 2, nyaw = 7;
        if (!strcmp(name, "lookaround")) { pitches[1] = -22.5; pitches[2] = 22.5; npitch = 3; }
        if (!strcmp(name, "rotate360")) { npitch = 1; nyaw = 10; }
        *poses = malloc(sizeof(g3d_mat4) * (size_t)(npitch * nyaw));
        if (!*poses) return G3D_ERR(G3D_ERR_NOMEM, "trajectory: out of memory");
        for (int j = 0; j < npitch; j++)
            for (int i = 0; i < nyaw; i++)
                (*poses)[j * nyaw + i] = g3d_pose_yaw_pitch(nyaw == 10 ? 36.0 * i : yaws[i], pitches[j], g3d_v3(0, 0, 0));
        *n = npitch * nyaw;
        return G3D_OK;
    }
    g3d_mat4 key = g3d_mat4_identity();
    if (!strcmp(name, "push_in")) key.m[2][3] = s;
    else if (!strcmp(name, "pull_out")) key.m[2][3] = -s;
    else if (!strcmp(name, "move_left")) key.m[0][3] = -0.5 * s;
    else if (!strcmp(name, "move_right")) key.m[0][3] = 0.5 * s;
    else if (!strcmp(name, "orbit_left")) key = orbit(-30, s);
    else if (!strcmp(name, "orbit_right")) key = orbit(30, s);
    else if (!strcmp(name, "pan_left")) key = g3d_pose_yaw_pitch(30, 0, g3d_v3(0, 0, 0));
    else if (!strcmp(name, "pan_right")) key = g3d_pose_yaw_pitch(-30, 0, g3d_v3(0, 0, 0));
    else {
        char list[256] = "";
        for (int i = 0; g_names[i]; i++) {
            strncat(list, g_names[i], sizeof list - strlen(list) - 1);
            if (g_names[i + 1]) strncat(list, ", ", sizeof list - strlen(list) - 1);
        }
        return G3D_ERR(G3D_ERR_ARG, "unknown trajectory '%s' (known: %s, or a cameras/transforms JSON file)", name, list);
    }
    return keyframes(key, interp, poses, n);
}

g3d_status g3d_trajectory_orbits(const g3d_mat4 *poses, int n, int count, double pivot, double angle_deg,
                                 g3d_mat4 **out, int *n_out)
{
    static const double offs[5][2] = {{1, 0}, {0, -1}, {0, 1}, {-1, 0}, {1, 1}};
    if (count < 0 || count > 5) return G3D_ERR(G3D_ERR_ARG, "orbit views: count %d out of range 0..5", count);
    if (!(pivot > 0)) return G3D_ERR(G3D_ERR_ARG, "orbit views: pivot distance must be positive");
    *out = malloc(sizeof(g3d_mat4) * (size_t)(n * count + 1));
    if (!*out) return G3D_ERR(G3D_ERR_NOMEM, "orbit views: out of memory");
    int k = 0;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < count; j++) {
            /* Rotate about the pivot in the camera's own frame, then compose with the pose. */
            g3d_mat4 r = g3d_pose_yaw_pitch(offs[j][0] * angle_deg, offs[j][1] * angle_deg, g3d_v3(0, 0, 0));
            g3d_vec3 c = g3d_v3_add(g3d_v3(0, 0, pivot), g3d_mat4_dir(r, g3d_v3(0, 0, -pivot)));
            r.m[0][3] = c.x;
            r.m[1][3] = c.y;
            r.m[2][3] = c.z;
            (*out)[k++] = g3d_mat4_mul(poses[i], r);
        }
    *n_out = k;
    return G3D_OK;
}

/* ---- camera path files ----------------------------------------------------------------------- */

int g3d_trajectory_is_file(const char *name)
{
    char ext[16];
    struct stat st;
    return strchr(name, '/') || !strcmp(g3d_path_ext(name, ext, sizeof ext), "json") || stat(name, &st) == 0;
}

g3d_status g3d_trajectory_load_list(const char *path, g3d_camera_list *l)
{
    G3D_TRY(g3d_camera_list_load(path, l));
    g3d_status rc = G3D_OK;
    if (l->n < 1) rc = G3D_ERR(G3D_ERR_FORMAT, "%s: the camera list is empty", path);
    for (int i = 0; i < l->n && rc == G3D_OK; i++) {
        const g3d_intrinsics K = l->cams[i].K;
        if (K.width < 1 || K.height < 1 || K.width > G3D_MAX_IMAGE_SIDE || K.height > G3D_MAX_IMAGE_SIDE)
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: image size %dx%d out of range 1..%d", path, i, K.width,
                         K.height, G3D_MAX_IMAGE_SIDE);
        else if (!(K.fx > 0 && K.fy > 0))
            rc = G3D_ERR(G3D_ERR_FORMAT, "%s: frame %d: focal lengths must be positive", path, i);
    }
    if (rc != G3D_OK) g3d_camera_list_free(l);
    return rc;
}

g3d_status g3d_trajectory_load(const char *path, g3d_camera **cams, int *n)
{
    g3d_camera_list l;
    *cams = NULL;
    *n = 0;
    G3D_TRY(g3d_trajectory_load_list(path, &l));
    *cams = l.cams;  /* taken over from the list */
    *n = l.n;
    l.cams = NULL;
    g3d_camera_list_free(&l);
    return G3D_OK;
}

g3d_status g3d_trajectory_pick(const g3d_mat4 *poses, int n, int n_out, g3d_mat4 **out)
{
    *out = NULL;
    if (n < 1 || n_out < 1) return G3D_ERR(G3D_ERR_ARG, "picking %d of %d poses", n_out, n);
    g3d_mat4 *o = g3d_calloc((size_t)n_out, sizeof *o, "poses");
    if (!o) return G3D_ERR_NOMEM;
    for (int i = 0; i < n_out; i++) o[i] = poses[n_out > 1 ? (int)lround((double)i * (n - 1) / (n_out - 1)) : 0];
    *out = o;
    return G3D_OK;
}
