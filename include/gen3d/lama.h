/* gen3d/lama.h - LaMa inpainting: the FFC ResNet generator with fast Fourier convolutions
 * (big-lama and the other FFC generators of advimman/lama), loaded from the official checkpoint
 * (big-lama/models/best.ckpt, a PyTorch Lightning file whose state dict holds the generator
 * under "generator.model.N..."; a bare generator state dict "model.N..." works too).
 *
 * The configuration comes from the tensors: input and output channels, widths, the number
 * of downsampling layers and residual blocks, each layer's split into local and global
 * channels, and whether a spectral transform has a local Fourier unit. Not in the tensors: the
 * output activation, which is the sigmoid of every released FFC configuration. BatchNorm is
 * folded into the convolutions at load time; FFTs go through the layer library (FFTW).
 *
 * Pre- and post-processing are the official predict script's (bin/predict.py): picture in
 * [0, 1], bottom and right padded to a multiple of 8 by mirroring with the edge repeated
 * (numpy 'symmetric'), [picture * (1 - mask), mask] into the generator, its prediction used
 * inside the hole only, cropped back. The official script writes uint8 by truncation; gen3d
 * rounds when saving, so known pixels keep their exact values.
 */
#ifndef G3D_LAMA_H
#define G3D_LAMA_H

#include "gen3d/ckpt.h"
#include "gen3d/image.h"
#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_lama g3d_lama; /* opaque; one forward pass at a time (it owns its scratch) */

/* Loads the generator from an open checkpoint (which may be freed afterwards). Errors:
 * G3D_ERR_MODEL naming the first missing tensor or a tensor of the wrong shape ("no LaMa
 * generator" when the first layer is absent), G3D_ERR_UNSUPPORTED for gated FFCs and other
 * variants no released model uses. Free with g3d_lama_free. */
g3d_status g3d_lama_load(const g3d_ckpt *ck, g3d_lama **out);
/* The same from a file path. */
g3d_status g3d_lama_load_file(const char *path, g3d_lama **out);
void g3d_lama_free(g3d_lama *m);

/* One line describing the configuration ("FFC ResNet generator: 4 -> 3 channels, width 64, 3
 * downsamplings, 18 residual blocks of 512 channels (384 global), ...") into buf; returns buf. */
const char *g3d_lama_describe(const g3d_lama *m, char *buf, size_t n);

/* Called with each stage's output during g3d_lama_forward: "init", "down0".., "block0"..,
 * "up0".., "pred"; x [c, h, w] (local channels first, then global) is valid during the call. */
typedef void (*g3d_lama_tap)(void *user, const char *name, const float *x, int c, int h, int w);

/* The generator alone: x [in, h, w] (channels first; h and w multiples of 2^downsamplings,
 * large enough for the reflection pads) -> y [out, h, w] after the sigmoid. tap may be NULL.
 * G3D_ERR_ARG for sizes the network cannot take (a local Fourier unit needs a square
 * bottleneck of even side), G3D_ERR_NOMEM. */
g3d_status g3d_lama_forward(g3d_lama *m, const float *x, int h, int w, float *y, g3d_lama_tap tap, void *user);

/* The official predict pipeline on image (h, w, 3) in [0, 1], in place: pixels where
 * mask (h, w, 1) > 0.5 get the prediction, all others stay bit-identical. *filled (may be
 * NULL) receives the number of hole pixels. A mask without holes changes nothing and returns
 * G3D_OK without running the network. Errors: G3D_ERR_MISMATCH (mask of another size),
 * G3D_ERR_ARG (a mask covering every pixel, an image under 16 pixels a side or not RGB). */
g3d_status g3d_lama_inpaint(g3d_lama *m, g3d_image *image, const g3d_image *mask, int64_t *filled);

/* An inpainter plug-in (providers.h, name "lama") that runs g3d_lama_inpaint with the
 * generator in the checkpoint at `path` (loaded once, here). The prompt and seed are ignored
 * (the network is deterministic). Calls must not overlap. Release with g3d_inpainter_free. */
g3d_status g3d_inpainter_lama_create(const char *path, g3d_inpainter *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_LAMA_H */
