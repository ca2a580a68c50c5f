/* gen3d/inpaint_classic.h - weight-free inpainting: multi-scale exemplar-based hole filling
 * (PatchMatch nearest-neighbour search + patch voting, coarse to fine) and a smooth
 * diffusion fill used for tiny holes and as a baseline.
 *
 * Images are g3d_image (h, w, c), row-major, channels interleaved, any c in 1..16.
 * Masks are (h, w, 1); a pixel is a hole where mask > 0.5. Pixels outside the hole are
 * never written, so they stay bit-identical.
 * All functions are deterministic for a given seed; they are reentrant (no global state).
 */
#ifndef G3D_INPAINT_CLASSIC_H
#define G3D_INPAINT_CLASSIC_H

#include "gen3d/image.h"
#include "gen3d/providers.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct g3d_inpaint_params {
    int patch;        /* patch side in pixels, odd, 3..15 (default 7)                     */
    int em_iters;     /* search + vote iterations per scale (default 4)                    */
    int pm_passes;    /* PatchMatch propagation/random-search passes per iteration (2)     */
    int coarse_side;  /* stop building the pyramid below this shorter side (default 48)    */
} g3d_inpaint_params;

/* Fills p with the defaults above. */
void g3d_inpaint_params_default(g3d_inpaint_params *p);
/* Writes the parameters as one line to the log at INFO level. */
void g3d_inpaint_params_print(const g3d_inpaint_params *p);

/* Exemplar-based fill of image where mask > 0.5, using only patches lying wholly in the
 * known region as sources. image: (h, w, c), modified in place inside the hole only.
 * mask: (h, w, 1). params: NULL for defaults. Returns G3D_ERR_MISMATCH when the sizes
 * differ, G3D_ERR_ARG for bad params or when the mask leaves no known pixel; on failure
 * the image is untouched. A mask without holes returns G3D_OK and changes nothing.
 * Images too small for one full source patch fall back to the diffusion fill. */
g3d_status g3d_inpaint_patchmatch(g3d_image *image, const g3d_image *mask, const g3d_inpaint_params *params,
                                  uint64_t seed);

/* Smooth (harmonic / Laplace) fill of image where mask > 0.5 from the boundary values,
 * solved coarse to fine. Same shapes, errors and guarantees as g3d_inpaint_patchmatch. */
g3d_status g3d_inpaint_diffusion(g3d_image *image, const g3d_image *mask);

/* Wraps g3d_inpaint_patchmatch as a g3d_inpainter (name "classic"; the prompt is ignored).
 * params: copied; NULL for defaults; invalid ones give G3D_ERR_ARG. Release with
 * g3d_inpainter_free. */
g3d_status g3d_inpainter_classic_create(const g3d_inpaint_params *params, g3d_inpainter *out);

#ifdef __cplusplus
}
#endif
#endif /* G3D_INPAINT_CLASSIC_H */
