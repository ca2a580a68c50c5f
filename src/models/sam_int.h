/* Segment Anything internals shared by sam.c (weights, image encoder), sam_decoder.c (prompt
 * encoder, mask decoder, predictor) and sam_amg.c (automatic masks, mask provider). */
#ifndef G3D_SAM_INT_H
#define G3D_SAM_INT_H

#include "gen3d/nn.h"
#include "gen3d/sam.h"

#define SAM_DEC_HEADS 8 /* the two-way transformer's heads in every released model */

typedef struct sam_enc_block {
    float *n1w, *n1b, *n2w, *n2b, *relh, *relw;
    g3d_nn_lin qkv, proj, lin1, lin2;
    int window; /* 0: global attention */
} sam_enc_block;

typedef struct sam_attn {
    g3d_nn_lin q, k, v, o;
    int internal;
} sam_attn;

typedef struct sam_dec_layer {
    sam_attn self, t2i, i2t;
    float *n1w, *n1b, *n2w, *n2b, *n3w, *n3b, *n4w, *n4b;
    g3d_nn_lin lin1, lin2;
} sam_dec_layer;

typedef struct sam_mlp {
    int n;
    g3d_nn_lin *l;
} sam_mlp;

struct g3d_sam {
    /* image encoder */
    int S, patch, grid, D, depth, hd, heads, hidden, window, C;
    float *pew, *peb, *pos;
    sam_enc_block *blocks;
    float *neck0, *nln0w, *nln0b, *neck2, *nln1w, *nln1b;
    /* prompt encoder */
    float *gauss; /* [2, C/2] */
    float *point_emb[4], *not_a_point, *no_mask;
    int mask_ch;
    float *md0w, *md0b, *md1w, *md1b, *md3w, *md3b, *md4w, *md4b, *md6w, *md6b;
    /* mask decoder */
    int ndec, dec_hidden, nmask;
    sam_dec_layer *layers;
    sam_attn final_attn;
    float *nfw, *nfb, *iou_token, *mask_tokens;
    float *up0w, *up0b, *uplnw, *uplnb, *up3w, *up3b;
    sam_mlp *hyper, iou_head;
};

/* Copies n floats into a new buffer (NULL if out of memory). */
float *sam_dup(const float *x, size_t n);
/* x [rows, cols] -> y [cols, rows]. */
void sam_transpose(const float *x, int rows, int cols, float *y);

/* One prompt with coordinates already in the input frame (ResizeLongestSide applied): pts
 * [np, 2], box [4] or NULL. round_early: the coordinates become float32 before the half-pixel
 * shift (the predictor's numpy path) instead of after dividing by the input size (the
 * generator's float64 points). Masks whose predicted IoU is not above iou_floor are not resized
 * to the picture (their logits are left at 0: the generator drops them first). */
g3d_status sam_predict_scaled(const g3d_sam *m, const g3d_sam_image *img, int np, const double *pts, const int *labels,
                              const double *box, const float *mask_input, int multimask, int round_early,
                              float iou_floor, g3d_sam_prediction *out, g3d_sam_trace *tr);

#endif /* G3D_SAM_INT_H */
