/* gen3d/inpaint_classic.h - weight-free exemplar inpainting: fills holes with texture copied
 * from the rest of the image, used whenever no inpainting model is given.
 *
 * Multi-scale patch-based completion (Wexler, Shechtman and Irani's expectation-maximisation
 * over a PatchMatch nearest-neighbour field): on an image pyramid, each level alternates
 *   (1) for every patch that overlaps the hole, the most similar patch lying entirely in the
 *       known region (PatchMatch: propagation from neighbours + a random search, seeded), and
 *   (2) every hole pixel = weighted vote of the pixels those source patches put there.
 * The coarsest level starts from a smooth membrane fill; each finer level starts from the
 * upsampled result and field. Holes touching the image border, large holes (most of the
 * image) and thin cracks are all handled. Same image, mask and seed -> same output.
 */
#ifndef G3D_INPAINT_CLASSIC_H
#define G3D_INPAINT_CLASSIC_H

#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_patchmatch_params {
    int patch;          /* patch side, odd (7) */
    int em_iters;       /* expectation-maximisation rounds per level (finest level; coarser get more) (3) */
    int pm_iters;       /* PatchMatch sweeps per round (3) */
    int min_size;       /* coarsest pyramid level's shorter side (24) */
} g3d_patchmatch_params;
g3d_patchmatch_params g3d_patchmatch_params_default(void);

/* Fills image (h, w, 3) where mask (h, w, 1) > 0.5; other pixels are left bit-identical. */
g3d_status g3d_inpaint_patchmatch(g3d_image *image, const g3d_image *mask, const g3d_patchmatch_params *p, uint64_t seed);

/* Fills the masked pixels by harmonic (membrane) interpolation of the surrounding colours: a
 * smooth fill, the baseline the exemplar method is measured against. */
g3d_status g3d_inpaint_smooth(g3d_image *image, const g3d_image *mask);

/* The exemplar inpainter as a plug-in (providers.h). params NULL = defaults. */
g3d_status g3d_inpainter_classic_create(const g3d_patchmatch_params *params, g3d_inpainter *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_INPAINT_CLASSIC_H */
