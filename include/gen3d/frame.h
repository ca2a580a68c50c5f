/* gen3d/frame.h - the input of the pipeline: one RGB image with metric depth and a camera.
 *
 * A frame is what every later stage starts from: RGB in [0, 1], depth in metres (0 =
 * invalid) of the same size, pinhole intrinsics, and the pose of the input camera (the
 * identity: the scene's world frame is this camera's frame, see camera.h). A frame may also
 * carry a real held-out second view with its camera, used to measure novel-view quality.
 */
#ifndef G3D_FRAME_H
#define G3D_FRAME_H

#include "gen3d/camera.h"
#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_frame {
    g3d_image rgb;        /* (h, w, 3) */
    g3d_image depth;      /* (h, w, 1) metres, 0 = invalid */
    g3d_camera cam;       /* intrinsics of rgb, pose = identity */
    g3d_image heldout;    /* optional (h2, w2, 3) real second view; empty if none */
    g3d_camera heldout_cam;
    char name[64];        /* short label, e.g. "middlebury-motorcycle" */
} g3d_frame;

void g3d_frame_free(g3d_frame *f);

/* Checks that rgb and depth agree in size, that depth has valid pixels, and that the
 * intrinsics match the image. `label` names the input in messages. */
g3d_status g3d_frame_validate(const g3d_frame *f, const char *label);

/* Where a frame comes from (g3d_frame_load): an RGB-D pair, an RGB image whose depth a model
 * predicts, or the built-in default input. */
typedef struct g3d_frame_params {
    const char *rgb_path;     /* colour image; NULL: the default input from default_dir */
    const char *depth_path;   /* depth map (depthio.h); NULL with rgb_path: the depth model's */
    double depth_scale;       /* 16-bit PNG / integer depth units per metre (1000: millimetres) */
    g3d_intrinsics K;         /* K.fx > 0: the focal length (K.fy <= 0: as fx; K.cx, K.cy < 0:
                                 the image centre); zero with cx = cy = -1 by default */
    double fov_deg;           /* horizontal field of view when K.fx is not given (0: the model's
                                 camera, else 60 degrees) */
    const char *default_dir;  /* folder of the default input ("cache/default-input") */
    int max_side;             /* > 0: downscale so that the longer side is at most this (the
                                 depth model predicts at that size), 16 at least; 0: as is */
} g3d_frame_params;

/* Fills the defaults above. */
void g3d_frame_params_default(g3d_frame_params *p);

/* Loads the frame p describes: g3d_frame_load_rgbd, g3d_frame_load_rgb with `model` (which
 * must then be given), or g3d_frame_load_middlebury (its error prefixed with a hint to fetch
 * the default input), then g3d_frame_limit_size. *f is created by the call. */
struct g3d_depth_estimator;
g3d_status g3d_frame_load(const g3d_frame_params *p, const struct g3d_depth_estimator *model, g3d_frame *f);

/* RGB file + depth file (any format of depthio.h; `depth_scale` as in g3d_depth_load) + the
 * camera: K.fx > 0 gives the focal length (K.fy <= 0: same as fx; K.cx, K.cy < 0: the image
 * centre); otherwise fov_deg > 0 gives the horizontal field of view; otherwise 60 degrees is
 * assumed and logged. K's width and height are taken from the image. */
g3d_status g3d_frame_load_rgbd(const char *rgb_path, const char *depth_path, double depth_scale,
                               g3d_intrinsics K, double fov_deg, g3d_frame *f);

/* RGB file + a monocular depth model (providers.h; e.g. depth_estimators.h) for the depth,
 * predicted after downscaling the image so its longer side is at most max_side (0: as is;
 * given pixel intrinsics are scaled along). The
 * camera: a given one (K.fx > 0, or fov_deg > 0, as for g3d_frame_load_rgbd) is handed to the
 * model, which must then keep it; otherwise the model's predicted intrinsics are used
 * (MoGe-2), or 60 degrees when it predicts none. The model must give metric depth without
 * known depth (MoGe-2, metric Depth Anything V2); its error is returned, prefixed with the
 * image path. */
g3d_status g3d_frame_load_rgb(const char *rgb_path, const struct g3d_depth_estimator *model, g3d_intrinsics K,
                              double fov_deg, int max_side, g3d_frame *f);
/* The same for a picture already in memory (e.g. a text-to-image model's): rgb (h, w, 3) is
 * taken over by the frame (zeroed here, freed on failure too); label names it in messages and
 * becomes the frame's name. */
g3d_status g3d_frame_from_image(g3d_image *rgb, const char *label, const struct g3d_depth_estimator *model,
                                g3d_intrinsics K, double fov_deg, int max_side, g3d_frame *f);
/* The built-in default input: Middlebury 2014 "Motorcycle" (the copy that scikit-image ships,
 * 741 x 500) from folder `dir`, holding motorcycle_left.png, motorcycle_right.png and
 * motorcycle_disp.npz (or the names im0.png, im1.png). Depth comes from the ground-truth
 * disparity and the calibration (f = 994.978 px, cx0 = 311.193, cy = 254.877,
 * doffs = 31.086 px, baseline 193.001 mm); the right image becomes the held-out view, a pure
 * translation of +0.193001 m along x with its own principal point cx1 = cx0 + doffs. */
g3d_status g3d_frame_load_middlebury(const char *dir, g3d_frame *f);

/* Lifts every `stride`-th pixel with valid depth to a coloured world point (the frame's
 * camera is the world frame). *out is created by the call. */
struct g3d_points;
g3d_status g3d_frame_to_points(const g3d_frame *f, int stride, struct g3d_points *out);

/* Writes the frame as a folder: rgb.png, depth.png (16-bit mm), depth.npy (metres),
 * cameras.json (the input camera, then the held-out camera if any), heldout.png, and
 * points.ply (the lifted cloud). Atomic: nothing is left at `dir` on failure. */
g3d_status g3d_frame_save(const g3d_frame *f, const char *dir);

/* Downscales the frame so that its longer side is at most max_side (no-op if it already is):
 * colour by area averaging, depth by nearest sampling (no invented depths at edges), the
 * intrinsics accordingly; the held-out view likewise. */
g3d_status g3d_frame_limit_size(g3d_frame *f, int max_side);

#ifdef __cplusplus
}
#endif
#endif /* G3D_FRAME_H */
