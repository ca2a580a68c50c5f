/* moge_int.h - MoGe-2 internals shared by its loader (moge.c: configuration and weights) and
 * its network (moge_net.c: forward pass and inference). */
#ifndef G3D_MOGE_INT_H
#define G3D_MOGE_INT_H

#include "gen3d/dinov2.h"
#include "gen3d/moge.h"
#include "gen3d/nn.h"

#define PATCH 14
#define MAX_LEVELS 8
#define MAX_LAYERS 8
#define MAX_MLP 8

typedef struct conv {
    float *w, *b;   /* w [cout, cin, k, k] (ConvTranspose: [cin, cout, k, k]) */
    int cin, cout, k;
    g3d_nn_conv nc; /* the layer over w and b, prepared at load (3x3: replicate padding) */
} conv;

typedef enum resampler { RS_CONV_TRANSPOSE, RS_BILINEAR, RS_NEAREST } resampler;

/* The official ConvStack: per level an optional 1x1 input conv added to the running tensor,
 * residual blocks, an optional 1x1 output conv, then a x2 resampler to the next level. */
typedef struct stack {
    int nlev;
    int dim[MAX_LEVELS];    /* channels of the running tensor per level */
    int din[MAX_LEVELS];    /* input channels, -1 = identity input */
    int dout[MAX_LEVELS];   /* output channels, -1 = identity output */
    int nres[MAX_LEVELS], hidden[MAX_LEVELS];
    resampler rs[MAX_LEVELS];
    conv in[MAX_LEVELS], out[MAX_LEVELS], up[MAX_LEVELS], upconv[MAX_LEVELS];
    conv *res[MAX_LEVELS];  /* 2 * nres[l] convs: (layers.2, layers.5) per block */
} stack;

enum { HEAD_POINTS, HEAD_NORMAL, HEAD_MASK, NHEADS };
static const int HEAD_CH[NHEADS] = {3, 3, 1};

typedef enum remap { REMAP_LINEAR, REMAP_SINH, REMAP_EXP, REMAP_SINH_EXP } remap;

struct g3d_moge {
    g3d_dinov2 *backbone;
    char backbone_name[64];
    int D, nlayers, layers[MAX_LAYERS], dim_out;
    conv proj[MAX_LAYERS];
    float mean[3], std[3];
    stack neck, head[NHEADS];
    int has_head[NHEADS];
    int nmlp, mlp_dims[MAX_MLP + 1];
    float *mlp_w[MAX_MLP], *mlp_b[MAX_MLP];
    remap remap;
    int tokens_min, tokens_max;
};

/* Channels a stack emits at level i. */
static inline int stack_out_ch(const stack *s, int i) { return s->dout[i] > 0 ? s->dout[i] : s->dim[i]; }

#endif /* G3D_MOGE_INT_H */
