/* Helpers shared by all plug-in implementations: releasing a table, freeing a mask set. */
#include "gen3d/providers.h"

#include <stdlib.h>
#include <string.h>

void g3d_mask_set_free(g3d_mask_set *s)
{
    if (!s) return;
    free(s->masks);
    free(s->scores);
    memset(s, 0, sizeof *s);
}

/* Calls a table's own free hook on its context, then zeroes the table. */
static void release(void *table, size_t size, void (*free_hook)(void *), void *ctx)
{
    if (free_hook) free_hook(ctx);
    memset(table, 0, size);
}

void g3d_inpainter_free(g3d_inpainter *p) { if (p) release(p, sizeof *p, p->free, p->ctx); }
void g3d_depth_estimator_free(g3d_depth_estimator *p) { if (p) release(p, sizeof *p, p->free, p->ctx); }
void g3d_mask_provider_free(g3d_mask_provider *p) { if (p) release(p, sizeof *p, p->free, p->ctx); }
void g3d_prompt_provider_free(g3d_prompt_provider *p) { if (p) release(p, sizeof *p, p->free, p->ctx); }
