/* libFuzzer target: the checkpoint readers (safetensors and PyTorch zip) must reject or accept
 * any bytes without crashing,

 * and every tensor they accept must be readable. Build with -DG3D_FUZZ=ON (clang); run with
 * scripts/fuzz.sh. */
#include "gen3d/ckpt.h"

#include <stdlib.h>

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t n)
{
    g3d_ckpt *ck;
    if (g3d_ckpt_open_memory(data, n, "fuzz.safetensors", &ck) != G3D_OK) return 0;
    for (int64_t i = 0; i < g3d_ckpt_count(ck); i++) {
        const g3d_tensor_info *t = g3d_ckpt_tensor(ck, i);
        if (t->numel > (1 << 20)) continue;
        float *v = NULL;
        if (g3d_ckpt_read_alloc(ck, t->name, 0, NULL, &v) == G3D_OK) free(v);
    }
    g3d_ckpt_free(ck);
    return 0;
}
