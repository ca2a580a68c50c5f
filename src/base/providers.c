/* Helpers shared by all plug-in implementations. */
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
