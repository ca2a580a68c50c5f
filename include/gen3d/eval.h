/* gen3d/eval.h - scoring a scene against real held-out views.
 *
 * VIEWS. A view set holds the held-out views to score, each with its own camera (intrinsics
 * and image size), ground-truth RGB, and optionally metric depth and a mask of the pixels to
 * score; and, when known, the INPUT view the scene was made from (camera, image, depth). It is
 * read from a transforms.json / cameras.json (cameras_json.h; image, mask and depth paths are
 * relative to the file's folder) or from a Middlebury-style stereo folder, whose left image is
 * the input view and whose right image is the one held-out view.
 *
 * REGIONS. Every view is scored twice:
 *   all         the pixels its mask keeps (every pixel without a mask);
 *   covisible   those of them whose ground truth the input camera sees too, found by
 *     - G3D_COVIS_VIEW_DEPTH: the view pixel, lifted with its ground-truth depth, projects into
 *       the input image (nearest pixel) no farther than the input depth there times 1.02;
 *     - G3D_COVIS_INPUT_WARP (no view depth): the pixels that a nearest-pixel, z-buffered
 *       forward warp of the input depth reaches;
 *     - G3D_COVIS_SCENE_ALPHA (no input depth): the pixels the scene covers (alpha >= 0.5);
 *     - G3D_COVIS_NONE: none of these is possible (no input depth, no scene): not scored.
 *
 * METRICS per region (g3d_eval_metrics): PSNR over pixels and the three channels (g3d_psnr,
 * +inf for an exact match), SSIM as evaluations report it (g3d_ssim: 11x11 Gaussian window,
 * sigma 1.5, averaged over the region's pixels at least 5 pixels inside the border), and where
 * the view has ground-truth depth: abs rel = mean |d - d*| / d*, RMSE = sqrt(mean (d - d*)^2) in
 * metres over the pixels with both a ground-truth and a predicted depth, and the coverage (the
 * fraction of ground-truth-depth pixels that have a predicted depth). Predictions are rounded to
 * 8 bits per channel first, as the frames a renderer saves would be.
 *
 * METHODS. "scene": the scene rendered at the view's camera (depth where alpha >= 0.5, as
 * render.h). The baselines, which tell whether the scene helps and need the input view:
 * "input_image": the input image (and depth) as if it were the view, resampled to the view's size
 * when they differ; "forward_warp": every input pixel moved with its depth to the nearest pixel of
 * the view, the nearest one winning (black where nothing lands; its depth is the warped depth).
 */
#ifndef G3D_EVAL_H
#define G3D_EVAL_H

#include "gen3d/camera.h"
#include "gen3d/gaussians.h"
#include "gen3d/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Relative depth slack of the view-depth co-visibility test. */
#define G3D_EVAL_COVIS_DEPTH_TOL 0.02

typedef struct g3d_eval_view {
    char *name;           /* label: the image path as the views file names it (owned) */
    g3d_camera cam;       /* its own intrinsics and image size */
    g3d_image rgb;        /* (h, w, 3) ground truth */
    g3d_image depth;      /* (h, w, 1) metres, 0 = unknown; empty when not given */
    g3d_image mask;       /* (h, w, 1) > 0.5 = scored; empty = every pixel */
} g3d_eval_view;

typedef struct g3d_eval_views {
    int n;
    g3d_eval_view *views; /* (n) the held-out views */
    g3d_eval_view input;  /* the input view; input.rgb.data == NULL when there is none */
    const char *kind;     /* "camera file" or "middlebury" (static) */
} g3d_eval_views;

typedef struct g3d_eval_views_params {
    int input_view;  /* which frame of a camera file is the input view, removed from the
                        scored views: >= 0 that frame; -1 (default) the frame posed at the
                        identity (a generated scene's world frame is its input camera), if any;
                        -2 none. A Middlebury folder's input is its left view, frame 0
                        (-2: none). */
    int max_side;    /* > 0: views (and the input) larger than this are downscaled so their
                        longer side is max_side: colour by area averaging, depth and masks by
                        nearest sampling, intrinsics along; 0 (default): as given */
} g3d_eval_views_params;

void g3d_eval_views_params_default(g3d_eval_views_params *p);

/* Reads a view set from `path`: a .json camera file, or a folder holding transforms.json,
 * cameras.json, or a Middlebury pair: calib.txt (cam0, cam1, doffs, baseline in mm) with im0.png,
 * im1.png, disp0.pfm and optionally disp1.pfm (the right view's ground-truth depth), or the
 * default input's files (motorcycle_left.png, motorcycle_right.png, motorcycle_disp.npz; see
 * frame.h). Depth is Z = baseline * f / (d + doffs); infinite disparities are unknown.
 * Every image, depth map and mask must exist and have its camera's size; NaN or negative values
 * in a ground-truth depth file are refused (0 and infinity mean unknown). Errors name the file
 * (and the frame) in one line; nothing is returned on failure. Free with g3d_eval_views_free. */
g3d_status g3d_eval_views_load(const char *path, const g3d_eval_views_params *p, g3d_eval_views *v);
void g3d_eval_views_free(g3d_eval_views *v);

/* ---- building blocks -------------------------------------------------------------------- */

typedef struct g3d_eval_metrics {
    int64_t pixels;          /* pixels scored; 0 = the region is empty (the rest are NAN) */
    double mse, psnr;        /* psnr = +INFINITY when mse = 0 */
    double ssim;             /* NAN when no scored pixel lies 5 pixels inside the border */
    int64_t depth_pixels;    /* pixels with both depths */
    double depth_abs_rel;    /* NAN without ground-truth depth or predicted depth */
    double depth_rmse;       /* metres */
    double depth_coverage;   /* NAN without ground-truth depth in the region */
} g3d_eval_metrics;

/* Scores a prediction against view gt on the pixels where region > 0.5 (region NULL: all) and
 * gt's mask keeps. rgb (h, w, 3) is used as given (round it first to score a saved frame);
 * depth (h, w, 1) metres with 0 = none, or NULL. Sizes must match gt's camera
 * (G3D_ERR_MISMATCH). */
g3d_status g3d_eval_score(const g3d_image *rgb, const g3d_image *depth, const g3d_eval_view *gt,
                          const g3d_image *region, g3d_eval_metrics *m);

/* Nearest-pixel, z-buffered forward warp of (rgb, depth) seen by camera src into camera dst:
 * each pixel with depth > 0 is lifted, projected into dst and rounded to the nearest pixel; the
 * smallest dst depth wins (the first in row-major order on a tie). out_depth (dst size, 1
 * channel) gets that depth, 0 where nothing lands; out_rgb (3 channels), when not NULL, the
 * winning colours, black elsewhere (rgb may then not be NULL). Outputs are created here. */
g3d_status g3d_eval_forward_warp(const g3d_camera *src, const g3d_image *rgb, const g3d_image *depth,
                                 const g3d_camera *dst, g3d_image *out_rgb, g3d_image *out_depth);

typedef enum g3d_covis_kind {
    G3D_COVIS_NONE = 0,
    G3D_COVIS_VIEW_DEPTH,
    G3D_COVIS_INPUT_WARP,
    G3D_COVIS_SCENE_ALPHA
} g3d_covis_kind;

/* "none", "view_depth", "input_depth_warp", "scene_alpha". */
const char *g3d_covis_kind_name(g3d_covis_kind k);

/* The co-visible pixels of `view` from depth (the first two rules above): *mask (view size,
 * 1 channel, 1 = co-visible) is created and *kind set. Without input depth (input NULL or its
 * depth empty) *kind = G3D_COVIS_NONE and *mask is left empty: the caller falls back to the
 * scene's alpha. */
g3d_status g3d_eval_covisible(const g3d_eval_view *input, const g3d_eval_view *view, g3d_image *mask,
                              g3d_covis_kind *kind);

/* ---- whole evaluations ---------------------------------------------------------------- */

enum { G3D_EVAL_SCENE, G3D_EVAL_INPUT_IMAGE, G3D_EVAL_FORWARD_WARP, G3D_EVAL_METHODS };

/* "scene", "input_image", "forward_warp". */
const char *g3d_eval_method_name(int method);

typedef struct g3d_eval_params {
    int baselines;          /* 1 (default): also score the baselines when the input view is
                               known (forward_warp also needs its depth) */
    const char *sheets_dir; /* existing folder for the contact sheets, or NULL for none */
    g3d_progress progress;  /* stage "eval", one step per view; may cancel */
} g3d_eval_params;

void g3d_eval_params_default(g3d_eval_params *p);

typedef struct g3d_eval_report {
    int n;                               /* views */
    int scored[G3D_EVAL_METHODS];        /* 1 where the method was scored */
    g3d_eval_metrics *all[G3D_EVAL_METHODS];        /* (n) per view, for scored methods */
    g3d_eval_metrics *covisible[G3D_EVAL_METHODS];  /* (n) */
    g3d_eval_metrics mean_all[G3D_EVAL_METHODS];    /* means over the views (below) */
    g3d_eval_metrics mean_covisible[G3D_EVAL_METHODS];
    g3d_covis_kind *covis_kind;          /* (n) how each view's co-visible pixels were found */
    double *covis_fraction;              /* (n) co-visible share of the view's scored pixels */
    char **sheets;                       /* (n) sheet file names relative to sheets_dir, or NULL */
} g3d_eval_report;

/* Means over views: each metric averages the views where it is defined (a view with an empty
 * region or no depth does not count); PSNR's mean is +inf if any view's is; pixel counts add
 * up. */

/* Scores `scene` (NULL: the baselines only) on every view of v. With p->sheets_dir it writes one
 * contact sheet per view there, <index>_<image name>.png: one row per method of ground truth |
 * prediction | error heat map (mean absolute error over the channels, black 0 -> red -> yellow
 * -> white at 0.25 and above on the co-visible pixels, black -> blue outside them, grey outside
 * the view's mask); panels are downscaled to at most 512 pixels on the longer side. *r is created here (g3d_eval_report_free). Errors: G3D_ERR_ARG (no views, nothing
 * to score: no scene and no input view), rendering and I/O errors. */
g3d_status g3d_eval_run(const g3d_gaussians *scene, const g3d_eval_views *v, const g3d_eval_params *p,
                        g3d_eval_report *r);
void g3d_eval_report_free(g3d_eval_report *r);

/* The evaluation as an output folder, written atomically (a failed run leaves nothing at `dir`;
 * an existing folder is replaced only if it is an earlier gen3d output, see base.h):
 *   eval.json        per view and mean metrics of every scored method (layout in docs/eval.md);
 *                    infinite PSNR is written as the string "inf", undefined metrics as null
 *   sheets/NNN_*.png the contact sheets
 * scene_label and views_label name the inputs in eval.json (either may be NULL). p->sheets_dir
 * is ignored. *r (may be NULL) receives the report (g3d_eval_report_free). */
g3d_status g3d_eval_to_dir(const g3d_gaussians *scene, const g3d_eval_views *v, const g3d_eval_params *p,
                           const char *dir, const char *scene_label, const char *views_label, g3d_eval_report *r);

#ifdef __cplusplus
}
#endif
#endif /* G3D_EVAL_H */
