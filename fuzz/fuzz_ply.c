/* libFuzzer target: the PLY reader, through a temporary file (it reads paths). */
#include "gen3d/ply.h"

#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t n)
{
    char path[64];
    snprintf(path, sizeof path, "/tmp/g3d-fuzz-%ld.ply", (long)getpid());
    FILE *f = fopen(path, "wb");
    if (!f) return 0;
    fwrite(data, 1, n, f);
    fclose(f);
    g3d_points p;
    g3d_gaussians g;
    if (g3d_ply_read_points(path, &p) == G3D_OK) g3d_points_free(&p);
    if (g3d_ply_read_gaussians(path, &g) == G3D_OK) g3d_gaussians_free(&g);
    remove(path);
    return 0;
}
