/* gen3d/depth_anything.h - Depth Anything V2: DINOv2 backbone + DPT head, loaded from the
 * official checkpoints (depth_anything_v2_vit{s,b,l}.pth or a safetensors file with the same
 * names: "pretrained.*" backbone, "depth_head.*" head), relative or metric.
 *
 * Relative models (the default) output the network's non-negative "disparity-like" map
 * (larger = nearer) with an arbitrary scale: not metres. The metric models
 * (depth_anything_v2_metric_{hypersim,vkitti}_vit*.pth) have the same tensors; their head ends
 * in a sigmoid instead of a ReLU and the output, times the training's maximum depth (20 m
 * Hypersim indoor, 80 m Virtual KITTI outdoor), is depth in metres. Nothing in the tensors
 * tells the two apart: g3d_dav2_set_metric chooses. Pre- and post-processing follow the official
 * infer_image: the image is resized keeping its aspect ratio so both sides reach the input
 * size, each rounded to a multiple of 14 (OpenCV bicubic), normalised with the ImageNet mean
 * and std; the prediction is resized back bilinearly (align_corners=True).
 */
#ifndef G3D_DEPTH_ANYTHING_H
#define G3D_DEPTH_ANYTHING_H

#include "gen3d/ckpt.h"
#include "gen3d/dinov2.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_dav2 g3d_dav2;   /* opaque, immutable after loading */

/* Intermediate tensors of one run, for inspection and tests. Set want = 1 before the call;
 * the run allocates and fills every field, freed with g3d_dav2_trace_free. */
typedef struct g3d_dav2_trace {
    int want;
    int net_w, net_h;           /* network input size (multiples of 14) */
    float *input;               /* [3, net_h, net_w] normalised input */
    g3d_dinov2_trace backbone;  /* patch embedding and every block output */
    float *feature[4];          /* [h*w, D] normalised block outputs fed to the head */
    float *path[4];             /* path[i] = output of refinenet(i+1), [F, path_h[i], path_w[i]]:
                                   8h x 8w, 4h x 4w, 2h x 2w, h x w for the h x w token grid */
    int path_h[4], path_w[4];
    float *depth;               /* [net_h, net_w] prediction before resizing back */
} g3d_dav2_trace;

void g3d_dav2_trace_free(g3d_dav2_trace *t);

/* Loads the model from an open checkpoint (the checkpoint may be freed afterwards). The
 * architecture is read from the tensor shapes: the encoder's width, depth, MLP width and
 * position grid, the head's features and per-level channels; the four blocks feeding the head
 * are the last of each quarter of the encoder (the official lists; ViT-L's first is block 4).
 * Every tensor is checked by name and shape; errors (G3D_ERR_MODEL, G3D_ERR_UNSUPPORTED for
 * the use_clstoken / use_bn head variants) name the tensor. Free with g3d_dav2_free. */
g3d_status g3d_dav2_load(const g3d_ckpt *ck, g3d_dav2 **out);
/* The same from a file path. */
g3d_status g3d_dav2_load_file(const char *path, g3d_dav2 **out);
void g3d_dav2_free(g3d_dav2 *m);

/* Makes m a metric model with this maximum depth in metres (> 0), or relative again (0).
 * Call after loading, before predicting (it is not safe while predictions run). */
void g3d_dav2_set_metric(g3d_dav2 *m, float max_depth);
/* The maximum depth set by g3d_dav2_set_metric; 0 for a relative model. */
float g3d_dav2_max_depth(const g3d_dav2 *m);
/* The official maximum depth implied by a checkpoint's file name: 20 for the Hypersim (indoor)
 * metric models, 80 for the Virtual KITTI (outdoor) ones, 0 (relative) otherwise. */
float g3d_dav2_metric_default(const char *path);

/* Network input size for an image of w x h at the given input size (official "lower_bound"
 * rule: scale so that both sides are >= input_size, round each side to the nearest multiple
 * of 14, ceil when that falls below input_size). G3D_ERR_ARG for sizes outside 14..32768. */
g3d_status g3d_dav2_net_size(int w, int h, int input_size, int *net_w, int *net_h);

/* Predicts relative depth (metric models: depth in metres) for rgb [h, w, 3] (row-major, interleaved, values in [0, 1]) into
 * depth [h, w] (caller-allocated). input_size: 518 is what the models were trained at;
 * multiples of 14 are customary. trace may be NULL. */
g3d_status g3d_dav2_predict(const g3d_dav2 *m, const float *rgb, int w, int h, int input_size, float *depth,
                            g3d_dav2_trace *trace);

#ifdef __cplusplus
}
#endif
#endif /* G3D_DEPTH_ANYTHING_H */
