/* WorldScore camera paths: chained keyframe moves, world-to-camera interpolation, and the
 * benchmark's camera_data.json. */
#include "gen3d/worldscore.h"

#include "gen3d/trajectory.h"
#include "io/json_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_MOVES 64

static const char *const g_moves[] = {"push_in", "pull_out", "move_left", "move_right",
                                      "orbit_left", "orbit_right", "pan_left", "pan_right", NULL};

g3d_intrinsics g3d_worldscore_intrinsics(void)
{
    const double c = (G3D_WORLDSCORE_SIDE - 1) / 2.0;
    return g3d_intrinsics_make(G3D_WORLDSCORE_FOCAL, G3D_WORLDSCORE_FOCAL, c, c, G3D_WORLDSCORE_SIDE,
                               G3D_WORLDSCORE_SIDE);
}

/* The keyframe of one move relative to the camera it starts from: the trajectory preset of
 * the same name without interpolated poses, its distance set to the speed. */
static g3d_status move_pose(const char *name, size_t len, double speed, g3d_mat4 *out)
{
    char buf[32];
    int known = 0;
    for (int i = 0; g_moves[i]; i++) known |= strlen(g_moves[i]) == len && !strncmp(g_moves[i], name, len);
    if (!known) {
        char list[160] = "";
        for (int i = 0; g_moves[i]; i++) {
            strncat(list, g_moves[i], sizeof list - strlen(list) - 1);
            if (g_moves[i + 1]) strncat(list, ", ", sizeof list - strlen(list) - 1);
        }
        return G3D_ERR(G3D_ERR_ARG, "worldscore: unknown move '%.*s' (known: %s)", (int)(len < 40 ? len : 40), name, list);
    }
    memcpy(buf, name, len);
    buf[len] = '\0';
    g3d_trajectory_params p;
    g3d_trajectory_params_default(&p);
    p.distance = speed;
    p.interp = 0;
    g3d_mat4 *poses;
    int n;
    G3D_TRY(g3d_trajectory_make(buf, &p, speed, &poses, &n));
    *out = poses[n - 1];
    free(poses);
    return G3D_OK;
}

g3d_status g3d_worldscore_path(const char *moves, double speed, g3d_camera **cams, int *n)
{
    *cams = NULL;
    *n = 0;
    if (!(speed > 0) || !isfinite(speed)) return G3D_ERR(G3D_ERR_ARG, "worldscore: camera speed must be positive");
    g3d_mat4 keys[MAX_MOVES + 1];
    int k = 0;
    keys[0] = g3d_mat4_identity();
    for (const char *s = moves;; k++) {
        const char *end = strchr(s, ',');
        size_t len = end ? (size_t)(end - s) : strlen(s);
        if (k == MAX_MOVES) return G3D_ERR(G3D_ERR_ARG, "worldscore: more than %d moves", MAX_MOVES);
        if (len == 0) return G3D_ERR(G3D_ERR_ARG, "worldscore: empty move in '%s'", moves);
        g3d_mat4 m;
        G3D_TRY(move_pose(s, len, speed, &m));
        keys[k + 1] = g3d_mat4_mul(keys[k], m);
        if (!end) {
            k++;
            break;
        }
        s = end + 1;
    }
    const int total = 1 + G3D_WORLDSCORE_FRAMES_PER_MOVE * k;
    g3d_camera *c = g3d_calloc((size_t)total, sizeof *c, "cameras");
    if (!c) return G3D_ERR_NOMEM;
    const g3d_intrinsics K = g3d_worldscore_intrinsics();
    for (int i = 0; i < total; i++) c[i].K = K;
    c[0].c2w = keys[0];
    for (int j = 0; j < k; j++) {
        const g3d_mat4 w0 = g3d_mat4_inverse_rigid(keys[j]), w1 = g3d_mat4_inverse_rigid(keys[j + 1]);
        for (int i = 1; i < G3D_WORLDSCORE_FRAMES_PER_MOVE; i++) {
            double t = (double)i / G3D_WORLDSCORE_FRAMES_PER_MOVE;
            c[j * G3D_WORLDSCORE_FRAMES_PER_MOVE + i].c2w = g3d_mat4_inverse_rigid(g3d_pose_interp(w0, w1, t));
        }
        c[(j + 1) * G3D_WORLDSCORE_FRAMES_PER_MOVE].c2w = keys[j + 1];
    }
    *cams = c;
    *n = total;
    return G3D_OK;
}

/* OpenCV c2w -> WorldScore's: diag(-1,-1,1) on the world side (OpenCV -> PyTorch3D axes of the
 * first camera), diag(1,-1,-1) on the camera side (OpenCV -> Blender camera axes). */
static cJSON *worldscore_matrix(g3d_mat4 c2w)
{
    static const double world[3] = {-1, -1, 1}, cam[3] = {1, -1, -1};
    cJSON *rows = cJSON_CreateArray();
    for (int r = 0; r < 4; r++) {
        cJSON *row = cJSON_CreateArray();
        for (int col = 0; col < 4; col++) {
            double v = c2w.m[r][col] * (r < 3 ? world[r] : 1.0) * (col < 3 ? cam[col] : 1.0);
            cJSON_AddItemToArray(row, cJSON_CreateNumber(v == 0 ? 0.0 : v));
        }
        cJSON_AddItemToArray(rows, row);
    }
    return rows;
}

g3d_status g3d_worldscore_write_camera_data(const char *path, const g3d_camera *cams, int n, double speed)
{
    if (n < 1 + G3D_WORLDSCORE_FRAMES_PER_MOVE || (n - 1) % G3D_WORLDSCORE_FRAMES_PER_MOVE)
        return G3D_ERR(G3D_ERR_ARG, "%s: %d cameras is not a WorldScore path (1 + 49 k)", path, n);
    cJSON *root = cJSON_CreateObject(), *keys = cJSON_CreateArray(), *all = cJSON_CreateArray();
    cJSON_AddNumberToObject(root, "focal_length", G3D_WORLDSCORE_FOCAL);
    cJSON_AddNumberToObject(root, "scale", speed);
    for (int i = 0; i < n; i++) {
        if (i % G3D_WORLDSCORE_FRAMES_PER_MOVE == 0) cJSON_AddItemToArray(keys, worldscore_matrix(cams[i].c2w));
        cJSON_AddItemToArray(all, worldscore_matrix(cams[i].c2w));
    }
    cJSON_AddItemToObject(root, "cameras", keys);
    cJSON_AddItemToObject(root, "cameras_interp", all);
    return g3d_json_save(path, root);
}
