/* gen3d/dataset.h - reading a dataset folder: posed images, optional validity masks and an
 * optional point cloud, as `gen3d world` writes them and nerfstudio tools read them.
 *
 * The folder holds transforms.json (nerfstudio) or cameras.json (ours; transforms.json wins
 * when both exist) listing every frame's camera and image path, relative to the folder, with
 * an optional mask_path (1 = train on the pixel), and optionally points.ply (a coloured point
 * cloud to start the Gaussians from). Images must have the size their camera gives.
 */
#ifndef G3D_DATASET_H
#define G3D_DATASET_H

#include "gen3d/cameras_json.h"
#include "gen3d/image.h"
#include "gen3d/ply.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_dataset {
    int n;                    /* frames */
    g3d_camera_list cams;     /* (n) cameras (intrinsics of the loaded, possibly downscaled, images),
                                 image names and mask paths as the file lists them */
    g3d_image *images;        /* (n) (h, w, 3) */
    g3d_image *masks;         /* (n) (h, w, 1), empty where a frame has no mask */
    g3d_points points;        /* points.ply; n = 0 when the folder has none */
} g3d_dataset;

/* Reads the folder `dir`. downscale (1..16) divides every image side (integer division;
 * colour by area averaging, masks by nearest sampling) and the intrinsics with it. Errors name
 * the file: no camera file, an empty list, a frame naming no image, an image whose size
 * disagrees with its camera, unreadable images, masks or points. *out is zeroed on failure. */
g3d_status g3d_dataset_load(const char *dir, int downscale, g3d_dataset *out);

/* Frees everything; NULL or zeroed is fine. */
void g3d_dataset_free(g3d_dataset *d);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DATASET_H */
