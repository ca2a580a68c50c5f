/* libFuzzer target: the zip reader (NPZ arrays, PyTorch checkpoints) on arbitrary bytes. */
#include "gen3d/zip.h"

#include <stdlib.h>

int LLVMFuzzerTestOneInput(const unsigned char *data, size_t n)
{
    g3d_zip z;
    if (g3d_zip_open(&z, data, n, "fuzz.zip") != G3D_OK) return 0;
    for (int64_t i = 0; i < z.n_entries; i++) {
        unsigned char *out;
        uint64_t on;
        if (g3d_zip_extract(&z, i, 1 << 22, &out, &on) == G3D_OK) free(out);
    }
    g3d_zip_close(&z);
    return 0;
}
