/* Scene files by extension: the standard 3DGS .ply or .spz. */
#include "gen3d/gaussians.h"

#include "gen3d/ply.h"
#include "gen3d/spz.h"

#include <string.h>
#include <sys/stat.h>

g3d_status g3d_gaussians_load(const char *path, g3d_gaussians *g)
{
    char ext[16];
    struct stat st;
    memset(g, 0, sizeof *g);
    if (stat(path, &st) != 0) return G3D_ERR(G3D_ERR_IO, "%s: no such scene file", path);
    g3d_path_ext(path, ext, sizeof ext);
    if (!strcmp(ext, "ply")) G3D_TRY(g3d_ply_read_gaussians(path, g));
    else if (!strcmp(ext, "spz")) G3D_TRY(g3d_spz_load(path, g));
    else return G3D_ERR(G3D_ERR_UNSUPPORTED, "%s: unknown scene format '.%s' (expected .ply or .spz)", path, ext);
    if (g->n == 0) {
        g3d_gaussians_free(g);
        return G3D_ERR(G3D_ERR_FORMAT, "%s: the scene holds no Gaussians", path);
    }
    return G3D_OK;
}
