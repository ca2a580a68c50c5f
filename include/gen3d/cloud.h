/* gen3d/cloud.h - the aggregated coloured point cloud of world generation: lifting pixels
 * into it (f_2d->3d) and rendering it into a camera with a z-buffer (f_3d->2d).
 *
 * Each point remembers the view it came from and its footprint on the surface: the world-space
 * vectors spanning the pixel it was lifted from (towards the right and lower neighbours when
 * they lie on the same surface, else parallel to the image plane). When rendered, a point
 * covers the target pixels whose centres fall inside its projected footprint parallelogram,
 * so a densely lifted surface shows no sampling holes when the camera moves closer, sideways
 * or sees it at a grazing angle, while depth edges keep their one-pixel footprint.
 *
 * Rendering is a two-pass soft z-buffer: pass 1 finds the nearest depth per pixel; pass 2
 * blends the points within a relative depth tolerance of it (weighted by their distance to
 * the pixel centre). Pixels no point reaches are holes (mask 0); disocclusions therefore stay
 * holes instead of being smeared with foreground colour. One-pixel cracks inside a single
 * surface (all neighbours valid at similar depth) are closed afterwards.
 * Deterministic: points are processed in order on one thread per render.
 */
#ifndef G3D_CLOUD_H
#define G3D_CLOUD_H

#include "gen3d/camera.h"
#include "gen3d/image.h"
#include "gen3d/ply.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_cloud {
    int64_t n, capacity;
    float *xyz;       /* (capacity, 3) world position, metres */
    float *rgb;       /* (capacity, 3) colour in [0, 1] */
    float *size;      /* (capacity) world width of the source pixel (depth / focal), metres */
    float *span;      /* (capacity, 6) footprint vectors: one source pixel to the right, one down */
    int32_t *view;    /* (capacity) index of the view the point was lifted from */
} g3d_cloud;

g3d_status g3d_cloud_init(g3d_cloud *c);
void g3d_cloud_free(g3d_cloud *c);
/* Grows capacity to at least n points. */
g3d_status g3d_cloud_reserve(g3d_cloud *c, int64_t n);

/* Lifts the pixels of (rgb, depth) seen by cam into the cloud: every pixel with depth > 0 and,
 * if lift_mask is given, lift_mask > 0.5. rgb (h, w, 3), depth and lift_mask (h, w, 1) must
 * match cam's image size. Returns the number of points added in *added (may be NULL). */
g3d_status g3d_cloud_lift(g3d_cloud *c, const g3d_image *rgb, const g3d_image *depth, const g3d_camera *cam,
                          const g3d_image *lift_mask, int32_t view, int64_t *added);

/* The same at a lower density: each stride x stride block of lifted pixels becomes one point
 * at its first pixel with a footprint `stride` pixels wide, unless that pixel is not lifted;
 * then the block's lifted pixels become points of their own, so that regions narrower than a
 * block keep every pixel. stride 1 is g3d_cloud_lift; 1..16. */
g3d_status g3d_cloud_lift_sparse(g3d_cloud *c, const g3d_image *rgb, const g3d_image *depth, const g3d_camera *cam,
                                 const g3d_image *lift_mask, int32_t view, int stride, int64_t *added);

typedef struct g3d_cloud_render_params {
    float depth_tolerance;  /* relative: points within z_min * (1 + tol) are blended (0.02) */
    float footprint_scale;  /* multiplies each point's projected footprint (1.0) */
    int fill_cracks;        /* close one-pixel holes inside one surface (1) */
} g3d_cloud_render_params;
/* Fills the defaults above. */
void g3d_cloud_render_params_default(g3d_cloud_render_params *p);

/* Renders the cloud into cam: rgb (h, w, 3), depth (h, w, 1) metres (0 in holes) and mask
 * (h, w, 1) 1 where some point landed. Outputs are created by the call; any may be NULL. */
g3d_status g3d_cloud_render(const g3d_cloud *c, const g3d_camera *cam, const g3d_cloud_render_params *p,
                            g3d_image *rgb, g3d_image *depth, g3d_image *mask);

/* Copies the cloud into a PLY point set (colours rounded to 8 bits). */
g3d_status g3d_cloud_to_points(const g3d_cloud *c, g3d_points *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_CLOUD_H */
