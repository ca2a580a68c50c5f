/* inpaint_recorder.h - an inpainter wrapper for tests: it checks every call (known pixels left
 * bit-identical, hole pixels changed, masks 0/1 and neither empty nor full) and keeps what the
 * first MAX_CALLS calls were given and returned. */
#ifndef G3D_TEST_INPAINT_RECORDER_H
#define G3D_TEST_INPAINT_RECORDER_H

#include "gen3d/providers.h"

#include <stdlib.h>
#include <string.h>

#define MAX_CALLS 8

/* Wraps an inpainter, checks every call and keeps what it was given and returned. */
typedef struct recorder {
    const g3d_inpainter *inner;
    int calls;
    g3d_image in[MAX_CALLS], mask[MAX_CALLS], out[MAX_CALLS];
    char *prompt[MAX_CALLS];   /* strdup'd, NULL when the call had none */
    size_t known_changed, holes_unchanged, bad_masks;
} recorder;

static g3d_status record(void *ctx, g3d_image *image, const g3d_image *mask, const char *prompt, uint64_t seed)
{
    recorder *r = ctx;
    g3d_image before = {0};
    G3D_TRY(g3d_image_clone(&before, image));
    g3d_status rc = r->inner->inpaint(r->inner->ctx, image, mask, prompt, seed);
    const size_t n = (size_t)image->w * image->h;
    size_t holes = 0;
    for (size_t i = 0; i < n && rc == G3D_OK; i++) {
        const int hole = mask->data[i] > 0.5f;
        holes += hole;
        r->bad_masks += mask->data[i] != 0.0f && mask->data[i] != 1.0f;
        int same = !memcmp(&before.data[3 * i], &image->data[3 * i], 3 * sizeof(float));
        if (!hole && !same) r->known_changed++;
        if (hole && same) r->holes_unchanged++;
    }
    r->bad_masks += holes == 0 || holes == n;
    if (rc == G3D_OK && r->calls < MAX_CALLS) {
        int k = r->calls;
        r->in[k] = before;
        before.data = NULL;
        r->prompt[k] = prompt ? strdup(prompt) : NULL;
        if (g3d_image_clone(&r->mask[k], mask) != G3D_OK || g3d_image_clone(&r->out[k], image) != G3D_OK)
            rc = G3D_ERR(G3D_ERR_NOMEM, "out of memory");
    }
    r->calls++;
    g3d_image_free(&before);
    return rc;
}

static void recorder_free(recorder *r)
{
    for (int k = 0; k < MAX_CALLS; k++) {
        g3d_image_free(&r->in[k]);
        g3d_image_free(&r->mask[k]);
        g3d_image_free(&r->out[k]);
        free(r->prompt[k]);
    }
    memset(r, 0, sizeof *r);
}

#endif
