/* gen3d/ply.h - PLY files: coloured point clouds and the standard 3D Gaussian splatting layout.
 *
 * WRITING (binary little-endian, atomic)
 *   point cloud:  x y z (float) [nx ny nz (float)] red green blue (uchar)
 *   3DGS:         x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3,
 *                 all float, K = (d+1)^2 for SH degree d. Normals are written as zeros, opacity
 *                 as a logit, scales as logs, rotations as raw (w, x, y, z) — exactly the
 *                 g3d_gaussians fields. f_rest is grouped by colour channel (all red
 *                 coefficients 1..K-1, then green, then blue), as the reference implementation
 *                 writes it; g3d_gaussians stores coefficient-major, and the converter is here.
 *
 * READING
 *   ASCII, binary little- and big-endian; properties in any order and of any scalar type;
 *   unknown properties are skipped; the vertex element must come first (later elements such
 *   as faces are ignored) and may not hold list properties. The SH degree of a 3DGS file is
 *   inferred from its number of f_rest properties (0, 9, 24 or 45). Truncated data, absurd
 *   counts, missing properties and NaN/inf in Gaussian parameters are errors naming the file.
 */
#ifndef G3D_PLY_H
#define G3D_PLY_H

#include "gen3d/gaussians.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A coloured point cloud. */
typedef struct g3d_points {
    int64_t n;
    float *xyz;       /* (n, 3) world coordinates, metres */
    uint8_t *rgb;     /* (n, 3) */
    float *normals;   /* (n, 3) or NULL */
} g3d_points;

/* Allocates n points (zeroed), with normals if with_normals. */
g3d_status g3d_points_create(g3d_points *p, int64_t n, int with_normals);
void g3d_points_free(g3d_points *p);

g3d_status g3d_ply_write_points(const char *path, const g3d_points *p);
/* Reads x y z, and red green blue (uchar, or float in [0, 1]) and nx ny nz when present.
 * A 3DGS file is accepted too: colours then come from the SH DC term. Missing colours are
 * mid-grey. */
g3d_status g3d_ply_read_points(const char *path, g3d_points *p);

g3d_status g3d_ply_write_gaussians(const char *path, const g3d_gaussians *g);
/* *g is created by the call (free with g3d_gaussians_free). */
g3d_status g3d_ply_read_gaussians(const char *path, g3d_gaussians *g);

/* What a PLY file holds, without reading its data. */
typedef struct g3d_ply_info {
    int64_t n_vertices;
    int n_properties;
    int format;           /* 0 ascii, 1 binary little-endian, 2 binary big-endian */
    int is_gaussians;     /* has the 3DGS properties */
    int sh_degree;        /* for Gaussians, else -1 */
    int has_color, has_normals;
} g3d_ply_info;
g3d_status g3d_ply_probe(const char *path, g3d_ply_info *info);

#ifdef __cplusplus
}
#endif
#endif /* G3D_PLY_H */
